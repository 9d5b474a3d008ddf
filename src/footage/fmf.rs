//! FMF ("fly movie format", motmot; written by strand-braid and other machine-vision recorders),
//! versions 1 and 3, MONO8 and MONO16: a little-endian header (version; for v3 the format name
//! and bits per pixel; height and row width; the chunk size; the frame count, 0 when the writer
//! did not know it) and then fixed-size chunks, each an f64 timestamp in seconds followed by the
//! raw frame. Writers differ on whether a MONO16 row width is in pixels or bytes; the chunk size
//! decides.

use super::{
    check_frames, check_size, err, file_name, read_at, FileInfo, FootageError, FrameFile, Timing,
};
use crate::session::{FrameMeta, SessionReader};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

/// Longest format name accepted (real ones are a few characters).
const MAX_FORMAT_LEN: u32 = 64;

/// Whether the bytes begin like an FMF header (version 1, or 3 with a short printable format
/// name).
pub fn is_fmf(head: &[u8]) -> bool {
    let u32_at = |o: usize| {
        head.get(o..o + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    match u32_at(0) {
        Some(3) => match u32_at(4) {
            Some(n @ 1..=MAX_FORMAT_LEN) => head
                .get(8..8 + n as usize)
                .is_some_and(|s| s.iter().all(|b| b.is_ascii_graphic())),
            _ => false,
        },
        // Version 1 is MONO8 with height and width next: both plausible sizes.
        Some(1) => {
            matches!((u32_at(4), u32_at(8)), (Some(h @ 1..=16384), Some(w @ 1..=16384)) if h > 0 && w > 0)
        }
        _ => false,
    }
}

pub struct Fmf {
    path: std::path::PathBuf,
    file: File,
    info: FileInfo,
    chunk_start: u64,
    chunk_bytes: u64,
    frame_bytes: usize,
    meta: Vec<FrameMeta>,
}

impl Fmf {
    pub fn open(path: &Path, frame_rate_hz: Option<f64>) -> Result<Fmf, FootageError> {
        let mut file = File::open(path).map_err(|e| err(path, format!("cannot open: {e}")))?;
        let len = file
            .metadata()
            .map_err(|e| err(path, format!("cannot read: {e}")))?
            .len();
        let mut u32b = [0u8; 4];
        read_at(&mut file, path, 0, &mut u32b, "FMF header")?;
        let version = u32::from_le_bytes(u32b);
        let mut at = 4u64;
        let (format, bits) = match version {
            1 => ("MONO8".to_string(), 8),
            3 => {
                read_at(&mut file, path, at, &mut u32b, "FMF header")?;
                let n = u32::from_le_bytes(u32b);
                if !(1..=MAX_FORMAT_LEN).contains(&n) {
                    return Err(err(
                        path,
                        format!("FMF format name of {n} bytes, expected 1 to {MAX_FORMAT_LEN}"),
                    ));
                }
                let mut name = vec![0u8; n as usize];
                read_at(&mut file, path, at + 4, &mut name, "FMF format name")?;
                at += 4 + u64::from(n);
                read_at(&mut file, path, at, &mut u32b, "FMF header")?;
                at += 4;
                (
                    String::from_utf8_lossy(&name).into_owned(),
                    u32::from_le_bytes(u32b),
                )
            }
            v => return Err(err(path, format!("FMF version {v}, expected 1 or 3"))),
        };
        let bytes_per_pixel = match (format.as_str(), bits) {
            ("MONO8" | "RAW8", 8) => 1,
            ("MONO16" | "RAW16", 16) => 2,
            (f, b) if f.starts_with("MONO8:") && b == 8 => 1,
            (f, b) => {
                return Err(err(
                    path,
                    format!(
                    "FMF format {f:?} at {b} bits per pixel, expected MONO8 or MONO16 greyscale"
                ),
                ))
            }
        };
        let mut rest = [0u8; 24];
        read_at(&mut file, path, at, &mut rest, "FMF header")?;
        let height = u32::from_le_bytes([rest[0], rest[1], rest[2], rest[3]]);
        let row = u32::from_le_bytes([rest[4], rest[5], rest[6], rest[7]]);
        let chunk_bytes = u64::from_le_bytes([
            rest[8], rest[9], rest[10], rest[11], rest[12], rest[13], rest[14], rest[15],
        ]);
        let claimed = u64::from_le_bytes([
            rest[16], rest[17], rest[18], rest[19], rest[20], rest[21], rest[22], rest[23],
        ]);
        let chunk_start = at + 24;
        // The row width is in pixels or in bytes depending on the writer: the chunk says which.
        let pixels = u64::from(height) * u64::from(row);
        let width = if chunk_bytes == 8 + pixels * bytes_per_pixel as u64 {
            row
        } else if bytes_per_pixel == 2 && chunk_bytes == 8 + pixels && row % 2 == 0 {
            row / 2
        } else {
            return Err(err(
                path,
                format!("FMF chunk of {chunk_bytes} bytes does not hold an 8-byte timestamp and one {row}×{height} {format} frame"),
            ));
        };
        let (width, height) = check_size(path, "FMF header", i64::from(width), i64::from(height))?;
        let held = len.saturating_sub(chunk_start) / chunk_bytes;
        // 0 frames in the header: the writer stopped before it could say; count whole chunks.
        let n = if claimed == 0 {
            check_frames(path, "FMF file (whole chunks)", held, held)?
        } else {
            check_frames(path, "FMF header", claimed, held)?
        };
        let mut meta = Vec::with_capacity(n);
        let mut first = None;
        let mut nan = false;
        for k in 0..n {
            let mut t = [0u8; 8];
            read_at(
                &mut file,
                path,
                chunk_start + k as u64 * chunk_bytes,
                &mut t,
                &format!("frame {k}'s timestamp"),
            )?;
            let t = f64::from_le_bytes(t);
            if !t.is_finite() {
                nan = true;
                break;
            }
            let t0 = *first.get_or_insert(t);
            let rel = t - t0;
            let prev = meta.last().map(|m: &FrameMeta| m.timestamp_ns);
            let ns = (rel * 1e9).round();
            if !(0.0..1.8e19).contains(&ns) || prev.is_some_and(|p| ns as u64 <= p) {
                return Err(err(
                    path,
                    format!("frame {k}'s timestamp {t} s does not follow the one before, expected rising times"),
                ));
            }
            meta.push(FrameMeta {
                frame_id: k as u64,
                timestamp_ns: ns as u64,
            });
        }
        let mut notes = Vec::new();
        let timing = if nan {
            // motmot writes NaN when given no time: the frame rate must say.
            let rate = super::need_rate(
                path,
                frame_rate_hz,
                "the FMF frames carry no timestamps (NaN)",
            )?;
            meta = super::rate_meta(n, rate);
            notes.push("the FMF timestamps are NaN: frame k is at k / camera.frame_rate_hz".into());
            Timing::Rate
        } else {
            Timing::File
        };
        let info = FileInfo {
            kind: "fmf",
            name: file_name(path),
            width,
            height,
            bytes_per_pixel,
            frame_rate_hz: None,
            timing,
            trigger_frame: None,
            first_frame_number: None,
            exposure_s: None,
            header: vec![
                ("version".into(), version.to_string()),
                ("format".into(), format),
                ("bits_per_pixel".into(), bits.to_string()),
                ("frames".into(), n.to_string()),
            ],
            notes,
        };
        Ok(Fmf {
            path: path.to_path_buf(),
            file,
            info,
            chunk_start,
            chunk_bytes,
            frame_bytes: width as usize * height as usize * bytes_per_pixel,
            meta,
        })
    }
}

impl FrameFile for Fmf {
    fn info(&self) -> &FileInfo {
        &self.info
    }
    fn frames(&self) -> &[FrameMeta] {
        &self.meta
    }
    fn read(&mut self, i: usize, buf: &mut Vec<u8>) -> Result<(), FootageError> {
        buf.resize(self.frame_bytes, 0);
        let at = self.chunk_start + i as u64 * self.chunk_bytes + 8;
        read_at(&mut self.file, &self.path, at, buf, &format!("frame {i}"))
    }
}

/// Writes a session as FMF v3 (MONO8 or MONO16, rows in pixels as motmot writes them; the
/// timestamps are the session's, in seconds from its first frame). Returns the frames written.
pub fn export(session: &mut SessionReader, out: &Path) -> Result<usize, FootageError> {
    let t0 = session.frames.first().map_or(0, |m| m.timestamp_ns);
    let times: Vec<f64> = session
        .frames
        .iter()
        .map(|m| m.timestamp_ns.saturating_sub(t0) as f64 * 1e-9)
        .collect();
    let (w, h, bpp) = (session.width, session.height, session.bytes_per_pixel);
    write_with(out, w, h, bpp, times.len(), |i, buf| {
        session
            .read_frame(i, buf)
            .map_err(|e| std::io::Error::other(e.to_string()))?;
        Ok(times[i])
    })?;
    Ok(times.len())
}

/// Writes frames as FMF v3 with the given timestamps, s (tests; `export` for sessions).
pub fn write(
    out: &Path,
    width: u32,
    height: u32,
    bytes_per_pixel: usize,
    frames: &[(f64, Vec<u8>)],
) -> Result<(), FootageError> {
    write_with(
        out,
        width,
        height,
        bytes_per_pixel,
        frames.len(),
        |i, buf| {
            buf.clone_from(&frames[i].1);
            Ok(frames[i].0)
        },
    )
}

/// The FMF v3 writer: `frame(i, buf)` fills frame i's pixels and returns its time, s.
fn write_with(
    out: &Path,
    width: u32,
    height: u32,
    bytes_per_pixel: usize,
    n: usize,
    mut frame: impl FnMut(usize, &mut Vec<u8>) -> std::io::Result<f64>,
) -> Result<(), FootageError> {
    let format: &[u8] = if bytes_per_pixel == 1 {
        b"MONO8"
    } else {
        b"MONO16"
    };
    let frame_bytes = width as u64 * height as u64 * bytes_per_pixel as u64;
    super::write_whole(out, |w: &mut BufWriter<File>| {
        w.write_all(&3u32.to_le_bytes())?;
        w.write_all(&(format.len() as u32).to_le_bytes())?;
        w.write_all(format)?;
        w.write_all(&(8 * bytes_per_pixel as u32).to_le_bytes())?;
        w.write_all(&height.to_le_bytes())?;
        w.write_all(&width.to_le_bytes())?;
        w.write_all(&(8 + frame_bytes).to_le_bytes())?;
        w.write_all(&(n as u64).to_le_bytes())?;
        let mut buf = Vec::new();
        for i in 0..n {
            let t = frame(i, &mut buf)?;
            if buf.len() as u64 != frame_bytes {
                return Err(std::io::Error::other(format!(
                    "frame {i} has {} bytes, expected {frame_bytes}",
                    buf.len()
                )));
            }
            w.write_all(&t.to_le_bytes())?;
            w.write_all(&buf)?;
        }
        Ok(())
    })
}
