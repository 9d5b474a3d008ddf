//! Reading a recorded session: the index's lines checked as they are parsed, the manifest,
//! and the frames the container holds in full (a crash mid-write leaves a prefix, which is
//! read and said).

use super::{
    io_err, FrameMeta, Manifest, SessionError, Status, FRAMES_HEADER_BYTES, FRAMES_MAGIC,
    SESSION_SCHEMA,
};
use crate::config::Config;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

/// Largest frame side a session may declare, px (as `camera.width`/`height`).
pub const MAX_SIDE_PX: u32 = 16_384;

/// The index's lines: `frame_id,timestamp_ns`, ids strictly increasing, timestamps rising
/// with them, and no step in time implausible for the step in ids at `frame_rate_hz` (more
/// than 100 periods per id, plus a second). A line cut short by a crash (no newline) ends the
/// index. Errors name the line.
pub fn parse_index(text: &str, frame_rate_hz: f64) -> Result<Vec<FrameMeta>, String> {
    let period_ns = if frame_rate_hz.is_finite() && frame_rate_hz > 0.0 {
        1e9 / frame_rate_hz
    } else {
        1e9
    };
    let mut frames: Vec<FrameMeta> = Vec::new();
    for (lineno, line) in text.split_inclusive('\n').enumerate().skip(1) {
        let Some(line) = line.strip_suffix('\n') else {
            break;
        };
        let n = lineno + 1;
        let mut parts = line.split(',');
        let parse = |p: Option<&str>| p.and_then(|s| s.trim().parse::<u64>().ok());
        let (Some(frame_id), Some(timestamp_ns), None) =
            (parse(parts.next()), parse(parts.next()), parts.next())
        else {
            return Err(format!(
                "line {n}: expected frame_id,timestamp_ns (two whole numbers)"
            ));
        };
        if let Some(prev) = frames.last() {
            if frame_id <= prev.frame_id {
                return Err(format!(
                    "line {n}: frame id {frame_id} after {}, expected ids strictly increasing",
                    prev.frame_id
                ));
            }
            if timestamp_ns <= prev.timestamp_ns {
                return Err(format!(
                    "line {n}: timestamp {timestamp_ns} ns after {} ns, expected time to rise",
                    prev.timestamp_ns
                ));
            }
            let ids = (frame_id - prev.frame_id) as f64;
            let dt = (timestamp_ns - prev.timestamp_ns) as f64;
            if dt > ids * period_ns * 100.0 + 1e9 {
                return Err(format!(
                    "line {n}: timestamp {timestamp_ns} ns is {:.3} s after the previous frame, implausible for {ids} frame(s) at {frame_rate_hz} Hz",
                    dt / 1e9
                ));
            }
        }
        frames.push(FrameMeta {
            frame_id,
            timestamp_ns,
        });
    }
    Ok(frames)
}

/// A recorded session opened for reading.
pub struct SessionReader {
    pub dir: PathBuf,
    pub manifest: Manifest,
    pub frames: Vec<FrameMeta>,
    /// Frames the index promised but the container does not hold in full (crash mid-write).
    pub frames_truncated: u64,
    pub width: u32,
    pub height: u32,
    pub bytes_per_pixel: usize,
    file: File,
}

impl SessionReader {
    pub fn open(dir: &Path) -> Result<SessionReader, SessionError> {
        if !dir.is_dir() {
            return Err(io_err(
                dir,
                "not a session directory (does not exist or is not a directory)",
            ));
        }
        let mpath = dir.join("session.json");
        let text = std::fs::read_to_string(&mpath).map_err(|e| {
            io_err(&mpath, format!("cannot read the session manifest ({e}); is this an impactcam session directory?"))
        })?;
        let manifest: Manifest = serde_json::from_str(&text).map_err(|e| SessionError::Format {
            path: mpath.clone(),
            message: format!("not a valid session manifest: {e}"),
        })?;
        if manifest.schema != SESSION_SCHEMA {
            return Err(SessionError::Format {
                path: mpath,
                message: format!(
                    "schema {:?} is not supported, expected {SESSION_SCHEMA:?}",
                    manifest.schema
                ),
            });
        }
        let fpath = dir.join("frames.bin");
        let mut file = File::open(&fpath).map_err(|e| io_err(&fpath, e))?;
        let mut header = [0u8; FRAMES_HEADER_BYTES as usize];
        file.read_exact(&mut header)
            .map_err(|_| SessionError::Format {
                path: fpath.clone(),
                message: "frame container header is missing or short".into(),
            })?;
        if &header[..8] != FRAMES_MAGIC {
            return Err(SessionError::Format {
                path: fpath,
                message: "not an impactcam frame container (bad magic)".into(),
            });
        }
        let word =
            |i: usize| u32::from_le_bytes([header[i], header[i + 1], header[i + 2], header[i + 3]]);
        let (width, height, bpp) = (word(8), word(12), word(16) as usize);
        let cam = &manifest.camera;
        if (width, height, bpp) != (cam.width, cam.height, cam.pixel_format.bytes_per_pixel()) {
            return Err(SessionError::Format {
                path: fpath,
                message: format!(
                    "frame container says {width}×{height} at {bpp} bytes per pixel, expected {}×{} at {} as session.json's camera says",
                    cam.width,
                    cam.height,
                    cam.pixel_format.bytes_per_pixel()
                ),
            });
        }
        // The manifest's config is checked like any config (its camera size bounds the frames).
        manifest
            .config
            .validate()
            .map_err(|e| SessionError::Format {
                path: mpath.clone(),
                message: format!("config: {e}"),
            })?;
        if width == 0 || height == 0 || width > MAX_SIDE_PX || height > MAX_SIDE_PX {
            return Err(SessionError::Format {
                path: fpath,
                message: format!(
                    "frame container says {width}×{height}, expected 1 to {MAX_SIDE_PX} px each"
                ),
            });
        }
        let frame_bytes = u64::from(width) * u64::from(height) * bpp as u64;
        let len = file.metadata().map_err(|e| io_err(&fpath, e))?.len();
        let whole_frames = len.saturating_sub(FRAMES_HEADER_BYTES) / frame_bytes;
        let ipath = dir.join("frames.idx");
        let itext = std::fs::read_to_string(&ipath).map_err(|e| io_err(&ipath, e))?;
        let frames =
            parse_index(&itext, cam.frame_rate_hz).map_err(|message| SessionError::Format {
                path: ipath.clone(),
                message,
            })?;
        let mut frames = frames;
        let truncated = (frames.len() as u64).saturating_sub(whole_frames);
        frames.truncate(whole_frames.min(frames.len() as u64) as usize);
        Ok(SessionReader {
            dir: dir.to_path_buf(),
            manifest,
            frames,
            frames_truncated: truncated,
            width,
            height,
            bytes_per_pixel: bpp,
            file,
        })
    }

    pub fn frame_bytes(&self) -> usize {
        self.width as usize * self.height as usize * self.bytes_per_pixel
    }

    /// Raw bytes of frame `i` (by position in the session, not frame id).
    pub fn read_frame(&mut self, i: usize, buf: &mut Vec<u8>) -> Result<(), SessionError> {
        let n = self.frame_bytes();
        let fpath = self.dir.join("frames.bin");
        if i >= self.frames.len() {
            return Err(io_err(
                &fpath,
                format!("frame {i}: the session holds {} frames", self.frames.len()),
            ));
        }
        buf.resize(n, 0);
        // In range: i < frames.len() ≤ whole frames in the file, so the offset fits its length.
        let offset = FRAMES_HEADER_BYTES + i as u64 * n as u64;
        self.file
            .seek(SeekFrom::Start(offset))
            .and_then(|_| self.file.read_exact(buf))
            .map_err(|e| io_err(&fpath, format!("frame {i}: {e}")))
    }

    /// Whether the recording was finalised; a crash or kill leaves "recording".
    pub fn is_complete(&self) -> bool {
        self.manifest.status == Status::Complete
    }

    pub fn config(&self) -> &Config {
        &self.manifest.config
    }
}
