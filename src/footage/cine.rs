//! Phantom CINE (Vision Research), greyscale, uncompressed 8- or 16-bit: the file header (`CI`,
//! the first image's number relative to the trigger, image count, offsets, trigger time), the
//! bitmap header (size, bit depth; rows bottom first when the height is positive), the setup
//! (frame rate, real bits per pixel, shutter in ns, colour), the tagged blocks after the setup
//! (1002: each image's time as TIME64, 32.32 fixed-point seconds whose two lowest bits are
//! flags; 1003: each image's exposure), the table of image offsets, and each image behind its
//! annotation. Packed 10- and 12-bit and colour cines are refused with a message saying so.

use super::{
    check_frames, check_size, err, file_name, rate_meta, read_at, FileInfo, FootageError,
    FrameFile, Timing,
};
use crate::session::FrameMeta;
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Where the setup keeps what is read here (byte offsets into the SETUP structure).
const SETUP_MARK: u64 = 140;
const SETUP_LENGTH: u64 = 142;
const SETUP_FRAME_RATE16: u64 = 0;
const SETUP_IM_WIDTH: u64 = 737;
const SETUP_IM_HEIGHT: u64 = 739;
const SETUP_FRAME_RATE: u64 = 768;
const SETUP_ENABLE_COLOR: u64 = 788;
const SETUP_REAL_BPP: u64 = 896;
const SETUP_SHUTTER_NS: u64 = 1568;
const SETUP_BLACK_LEVEL: u64 = 5732;
/// Frame decimation (f32, 1 for none) and the high-precision frame rate (f64), in newer setups.
const SETUP_DECIMATION: u64 = 10388;
const SETUP_D_FRAME_RATE: u64 = 10400;
const SETUP_WHITE_LEVEL: u64 = 5736;
/// The setup's size in the current format (what `write` writes).
const SETUP_BYTES: usize = 12432;
/// Most tagged blocks looked at (a real cine has a handful).
const MAX_TAGGED_BLOCKS: usize = 64;

const TIME_BLOCK: u16 = 1002;
const EXPOSURE_BLOCK: u16 = 1003;

/// Whether the bytes begin a cine: `CI`, a 44-byte header, version 1.
pub fn is_cine(head: &[u8]) -> bool {
    head.len() >= 8 && head.starts_with(b"CI") && head[2..4] == [44, 0] && head[6..8] == [1, 0]
}

fn u16_at(b: &[u8], o: usize) -> u16 {
    u16::from_le_bytes([b[o], b[o + 1]])
}
fn u32_at(b: &[u8], o: usize) -> u32 {
    u32::from_le_bytes([b[o], b[o + 1], b[o + 2], b[o + 3]])
}
fn i32_at(b: &[u8], o: usize) -> i32 {
    u32_at(b, o) as i32
}

/// A TIME64 (fractions, seconds) as ns, the two flag bits of the fractions left out.
fn time64_ns(fractions: u32, seconds: u32) -> u64 {
    let frac = u64::from(fractions & !3);
    u64::from(seconds) * 1_000_000_000 + ((frac * 1_000_000_000 + (1 << 31)) >> 32)
}

pub struct Cine {
    path: PathBuf,
    file: File,
    info: FileInfo,
    offsets: Vec<u64>,
    meta: Vec<FrameMeta>,
    bottom_up: bool,
    row_bytes: usize,
    significant_bits: u32,
    raw: Vec<u8>,
}

impl Cine {
    pub fn open(path: &Path) -> Result<Cine, FootageError> {
        let mut file = File::open(path).map_err(|e| err(path, format!("cannot open: {e}")))?;
        let len = file
            .metadata()
            .map_err(|e| err(path, format!("cannot read: {e}")))?
            .len();
        let mut h = [0u8; 44];
        read_at(&mut file, path, 0, &mut h, "cine file header")?;
        if !is_cine(&h) {
            return Err(err(
                path,
                "not a cine: expected \"CI\", a 44-byte header, version 1",
            ));
        }
        let compression = u16_at(&h, 4);
        if compression != 0 {
            return Err(err(
                path,
                format!("cine Compression {compression}, expected 0 (grey, uncompressed); JPEG and raw-Bayer cines are not read"),
            ));
        }
        let first_no = i64::from(i32_at(&h, 16));
        let image_count = u64::from(u32_at(&h, 20));
        let (off_bih, off_setup, off_offsets) = (
            u64::from(u32_at(&h, 24)),
            u64::from(u32_at(&h, 28)),
            u64::from(u32_at(&h, 32)),
        );
        let trigger_ns = time64_ns(u32_at(&h, 36), u32_at(&h, 40));

        let mut bih = [0u8; 40];
        read_at(&mut file, path, off_bih, &mut bih, "cine bitmap header")?;
        let (bi_w, bi_h) = (i64::from(i32_at(&bih, 4)), i64::from(i32_at(&bih, 8)));
        let bit_count = u16_at(&bih, 14);
        let bi_compression = u32_at(&bih, 16);
        if bi_compression != 0 {
            return Err(err(
                path,
                format!("cine biCompression {bi_compression}, expected 0: packed 10- and 12-bit cines are not read (save them unpacked as 16-bit)"),
            ));
        }
        let bytes_per_pixel = match bit_count {
            8 => 1,
            16 => 2,
            b => {
                return Err(err(
                    path,
                    format!(
                    "cine biBitCount {b}, expected 8 or 16 (greyscale; colour cines are not read)"
                ),
                ))
            }
        };
        let (width, height) = check_size(path, "cine bitmap header", bi_w, bi_h.abs())?;
        let bottom_up = bi_h > 0;
        let row_bytes = width as usize * bytes_per_pixel;

        // The setup: its length says where the tagged blocks start; older setups are shorter,
        // so a field beyond the length is absent.
        let mut sl = [0u8; 4];
        read_at(
            &mut file,
            path,
            off_setup + SETUP_MARK,
            &mut sl,
            "cine setup",
        )?;
        let setup_len = u64::from(u16_at(&sl, 2));
        let field = |file: &mut File, at: u64, n: usize| -> Result<Option<Vec<u8>>, FootageError> {
            if at + n as u64 > setup_len {
                return Ok(None);
            }
            let mut b = vec![0u8; n];
            read_at(file, path, off_setup + at, &mut b, "cine setup")?;
            Ok(Some(b))
        };
        if field(&mut file, SETUP_ENABLE_COLOR, 4)?.is_some_and(|b| u32_at(&b, 0) != 0) {
            return Err(err(
                path,
                "a colour cine (bEnableColor), expected greyscale",
            ));
        }
        // The high-precision rate where the setup has it, else the whole-number one, else the
        // oldest 16-bit one.
        let precise = field(&mut file, SETUP_D_FRAME_RATE, 8)?
            .map(|b| f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]))
            .filter(|r| r.is_finite() && *r > 0.0 && *r <= 1e7);
        let rate = match (
            precise,
            field(&mut file, SETUP_FRAME_RATE, 4)?.map(|b| u32_at(&b, 0)),
        ) {
            (Some(r), _) => Some(r),
            (None, Some(r)) if r > 0 => Some(f64::from(r)),
            _ => field(&mut file, SETUP_FRAME_RATE16, 2)?
                .map(|b| f64::from(u16_at(&b, 0)))
                .filter(|r| *r > 0.0),
        };
        let real_bpp = field(&mut file, SETUP_REAL_BPP, 4)?
            .map(|b| u32_at(&b, 0))
            .filter(|b| (1..=16).contains(b));
        let shutter_ns = field(&mut file, SETUP_SHUTTER_NS, 4)?
            .map(|b| u32_at(&b, 0))
            .filter(|s| *s > 0);
        let levels = (
            field(&mut file, SETUP_BLACK_LEVEL, 4)?.map(|b| u32_at(&b, 0)),
            field(&mut file, SETUP_WHITE_LEVEL, 4)?.map(|b| u32_at(&b, 0)),
        );

        // The image offsets: the count is believed only as far as the file holds them.
        let held = len.saturating_sub(off_offsets) / 8;
        let n = check_frames(path, "cine header (ImageCount)", image_count, held)?;
        let mut table = vec![0u8; n * 8];
        read_at(
            &mut file,
            path,
            off_offsets,
            &mut table,
            "cine image offsets",
        )?;
        let offsets: Vec<u64> = table
            .chunks_exact(8)
            .map(|c| u64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
            .collect();
        let frame_bytes = row_bytes as u64 * u64::from(height);
        if let Some((k, o)) = offsets
            .iter()
            .enumerate()
            .find(|(_, o)| o.saturating_add(8 + frame_bytes) > len)
        {
            return Err(err(
                path,
                format!(
                    "image {k} is said to be at byte {o}, beyond what the file holds (cut short?)"
                ),
            ));
        }

        // Tagged blocks between the setup and the offsets: the time and exposure blocks.
        let mut times: Option<Vec<u64>> = None;
        let mut exposures: Option<f64> = None;
        let mut at = off_setup + setup_len;
        for _ in 0..MAX_TAGGED_BLOCKS {
            if setup_len == 0 || at + 8 > off_offsets {
                break;
            }
            let mut bh = [0u8; 8];
            read_at(&mut file, path, at, &mut bh, "cine tagged block")?;
            let (size, kind) = (u64::from(u32_at(&bh, 0)), u16_at(&bh, 4));
            if size < 8 || at + size > off_offsets {
                break;
            }
            let per = match kind {
                TIME_BLOCK => 8,
                EXPOSURE_BLOCK => 4,
                _ => 0,
            };
            if per > 0 && size - 8 >= per * n as u64 {
                let mut b = vec![0u8; per as usize * n];
                read_at(&mut file, path, at + 8, &mut b, "cine tagged block")?;
                if kind == TIME_BLOCK {
                    times = Some(
                        b.chunks_exact(8)
                            .map(|c| time64_ns(u32_at(c, 0), u32_at(c, 4)))
                            .collect(),
                    );
                } else if let Some(first) = b.chunks_exact(4).next() {
                    exposures = Some(f64::from(u32_at(first, 0)) * 2f64.powi(-32));
                }
            }
            at += size;
        }

        let mut notes = Vec::new();
        let (meta, timing) = match &times {
            Some(t) if t.windows(2).all(|w| w[1] > w[0]) => (
                t.iter()
                    .enumerate()
                    .map(|(k, ns)| FrameMeta {
                        frame_id: k as u64,
                        timestamp_ns: ns - t[0],
                    })
                    .collect(),
                Timing::File,
            ),
            other => {
                let r = rate.ok_or_else(|| {
                    err(
                        path,
                        "the cine has neither a time block nor a frame rate in its setup",
                    )
                })?;
                if other.is_some() {
                    notes.push(
                        "the cine's image times do not rise: frame k is at k / its frame rate"
                            .into(),
                    );
                }
                (rate_meta(n, r), Timing::Rate)
            }
        };
        let significant_bits = match (bytes_per_pixel, real_bpp) {
            (2, Some(b)) if b > 8 => b,
            (2, _) => 16,
            _ => 8,
        };
        if significant_bits < 16 && bytes_per_pixel == 2 {
            notes.push(format!(
                "{significant_bits}-bit pixels scaled ×{} to the 16-bit range",
                1u32 << (16 - significant_bits)
            ));
        }
        if let (Some(b), Some(w)) = levels {
            if b != 0 || (w != 0 && w + 1 != 1 << significant_bits) {
                notes.push(format!(
                    "the setup's black and white levels ({b}, {w}) are not applied: the analysis reads the pixels as stored"
                ));
            }
        }
        let trigger_frame = (-first_no >= 0 && -first_no < n as i64).then_some(-first_no);
        let header = vec![
            ("FirstImageNo".into(), first_no.to_string()),
            ("ImageCount".into(), n.to_string()),
            ("TriggerTime_ns".into(), trigger_ns.to_string()),
            ("biBitCount".into(), bit_count.to_string()),
            (
                "RealBPP".into(),
                real_bpp.map(|b| b.to_string()).unwrap_or_default(),
            ),
            (
                "FrameRate".into(),
                rate.map(|r| r.to_string()).unwrap_or_default(),
            ),
            (
                "ShutterNs".into(),
                shutter_ns.map(|s| s.to_string()).unwrap_or_default(),
            ),
            (
                "first_image_from_trigger_ns".into(),
                times
                    .as_ref()
                    .map(|t| (t[0] as i128 - trigger_ns as i128).to_string())
                    .unwrap_or_default(),
            ),
        ];
        let info = FileInfo {
            kind: "cine",
            name: file_name(path),
            width,
            height,
            bytes_per_pixel,
            frame_rate_hz: rate,
            timing,
            trigger_frame,
            first_frame_number: Some(first_no),
            exposure_s: shutter_ns.map(|s| f64::from(s) * 1e-9).or(exposures),
            header,
            notes,
        };
        Ok(Cine {
            path: path.to_path_buf(),
            file,
            info,
            offsets,
            meta,
            bottom_up,
            row_bytes,
            significant_bits,
            raw: Vec::new(),
        })
    }
}

impl FrameFile for Cine {
    fn info(&self) -> &FileInfo {
        &self.info
    }
    fn frames(&self) -> &[FrameMeta] {
        &self.meta
    }
    fn read(&mut self, i: usize, buf: &mut Vec<u8>) -> Result<(), FootageError> {
        let what = format!("image {i}");
        let at = self.offsets[i];
        let mut a = [0u8; 4];
        read_at(&mut self.file, &self.path, at, &mut a, &what)?;
        let annotation = u64::from(u32::from_le_bytes(a));
        if annotation < 8 {
            return Err(err(
                &self.path,
                format!("{what}: annotation of {annotation} bytes, expected at least 8"),
            ));
        }
        let mut s = [0u8; 4];
        read_at(
            &mut self.file,
            &self.path,
            at + annotation - 4,
            &mut s,
            &what,
        )?;
        let size = u32::from_le_bytes(s) as usize;
        let height = self.info.height as usize;
        let frame_bytes = self.row_bytes * height;
        // Rows may be padded to 4 bytes, as in a bitmap.
        let padded_row = self.row_bytes.div_ceil(4) * 4;
        let stride = if size == frame_bytes {
            self.row_bytes
        } else if size == padded_row * height {
            padded_row
        } else {
            return Err(err(
                &self.path,
                format!("{what}: {size} bytes, expected {frame_bytes} for {}×{height} at {} bytes per pixel", self.info.width, self.info.bytes_per_pixel),
            ));
        };
        self.raw.resize(stride * height, 0);
        read_at(
            &mut self.file,
            &self.path,
            at + annotation,
            &mut self.raw,
            &what,
        )?;
        buf.clear();
        buf.reserve(frame_bytes);
        for r in 0..height {
            let src = if self.bottom_up { height - 1 - r } else { r };
            buf.extend_from_slice(&self.raw[src * stride..src * stride + self.row_bytes]);
        }
        if self.info.bytes_per_pixel == 2 {
            super::widen_le16(buf, self.significant_bits);
        }
        Ok(())
    }
}

/// What `write` puts in a cine besides the frames.
pub struct CineSpec {
    pub width: u32,
    pub height: u32,
    /// 1 or 2.
    pub bytes_per_pixel: usize,
    /// Significant bits (8 for 8-bit; 12 for 12-bit data stored in 16).
    pub real_bpp: u32,
    pub frame_rate_hz: u32,
    pub shutter_ns: u32,
    /// The first image's number relative to the trigger.
    pub first_image_no: i32,
    /// Trigger time (TIME64: fractions, seconds).
    pub trigger: (u32, u32),
}

/// Writes a greyscale cine from the format's description, for tests and interchange: header,
/// bitmap header (rows bottom first), a setup of the current size, the time (1002) and
/// exposure (1003) blocks, the offsets, and each image behind an empty annotation. `frames` are
/// (TIME64 of the image, pixels top row first, little-endian).
pub fn write(
    out: &Path,
    spec: &CineSpec,
    frames: &[((u32, u32), Vec<u8>)],
) -> Result<(), FootageError> {
    let n = frames.len();
    let row = spec.width as usize * spec.bytes_per_pixel;
    let frame_bytes = row * spec.height as usize;
    let off_setup = 44 + 40;
    let time_block = 8 + 8 * n;
    let exposure_block = 8 + 4 * n;
    let off_offsets = off_setup + SETUP_BYTES + time_block + exposure_block;
    let first_image = off_offsets + 8 * n;
    super::write_whole(out, |w| {
        let mut h = Vec::with_capacity(44);
        h.extend_from_slice(b"CI");
        h.extend_from_slice(&44u16.to_le_bytes());
        h.extend_from_slice(&0u16.to_le_bytes());
        h.extend_from_slice(&1u16.to_le_bytes());
        h.extend_from_slice(&spec.first_image_no.to_le_bytes());
        h.extend_from_slice(&(n as u32).to_le_bytes());
        h.extend_from_slice(&spec.first_image_no.to_le_bytes());
        h.extend_from_slice(&(n as u32).to_le_bytes());
        h.extend_from_slice(&44u32.to_le_bytes());
        h.extend_from_slice(&(off_setup as u32).to_le_bytes());
        h.extend_from_slice(&(off_offsets as u32).to_le_bytes());
        h.extend_from_slice(&spec.trigger.0.to_le_bytes());
        h.extend_from_slice(&spec.trigger.1.to_le_bytes());
        w.write_all(&h)?;
        let mut bih = Vec::with_capacity(40);
        bih.extend_from_slice(&40u32.to_le_bytes());
        bih.extend_from_slice(&(spec.width as i32).to_le_bytes());
        bih.extend_from_slice(&(spec.height as i32).to_le_bytes());
        bih.extend_from_slice(&1u16.to_le_bytes());
        bih.extend_from_slice(&(8 * spec.bytes_per_pixel as u16).to_le_bytes());
        bih.extend_from_slice(&0u32.to_le_bytes());
        bih.extend_from_slice(&(frame_bytes as u32).to_le_bytes());
        bih.extend_from_slice(&[0u8; 16]);
        w.write_all(&bih)?;
        let mut setup = vec![0u8; SETUP_BYTES];
        let mut put = |at: u64, bytes: &[u8]| {
            setup[at as usize..at as usize + bytes.len()].copy_from_slice(bytes)
        };
        put(
            SETUP_FRAME_RATE16,
            &(spec.frame_rate_hz.min(65535) as u16).to_le_bytes(),
        );
        put(SETUP_MARK, b"ST");
        put(SETUP_LENGTH, &(SETUP_BYTES as u16).to_le_bytes());
        put(SETUP_IM_WIDTH, &(spec.width as u16).to_le_bytes());
        put(SETUP_IM_HEIGHT, &(spec.height as u16).to_le_bytes());
        put(SETUP_FRAME_RATE, &spec.frame_rate_hz.to_le_bytes());
        put(SETUP_REAL_BPP, &spec.real_bpp.to_le_bytes());
        put(SETUP_SHUTTER_NS, &spec.shutter_ns.to_le_bytes());
        put(SETUP_BLACK_LEVEL, &0u32.to_le_bytes());
        put(
            SETUP_WHITE_LEVEL,
            &((1u32 << spec.real_bpp) - 1).to_le_bytes(),
        );
        put(SETUP_DECIMATION, &1.0f32.to_le_bytes());
        put(
            SETUP_D_FRAME_RATE,
            &f64::from(spec.frame_rate_hz).to_le_bytes(),
        );
        w.write_all(&setup)?;
        w.write_all(&(time_block as u32).to_le_bytes())?;
        w.write_all(&TIME_BLOCK.to_le_bytes())?;
        w.write_all(&0u16.to_le_bytes())?;
        for ((frac, sec), _) in frames {
            w.write_all(&frac.to_le_bytes())?;
            w.write_all(&sec.to_le_bytes())?;
        }
        w.write_all(&(exposure_block as u32).to_le_bytes())?;
        w.write_all(&EXPOSURE_BLOCK.to_le_bytes())?;
        w.write_all(&0u16.to_le_bytes())?;
        let exposure = ((f64::from(spec.shutter_ns) * 1e-9) * 2f64.powi(32)).round() as u32;
        for _ in frames {
            w.write_all(&exposure.to_le_bytes())?;
        }
        for k in 0..n {
            w.write_all(&((first_image + k * (8 + frame_bytes)) as u64).to_le_bytes())?;
        }
        for (_, px) in frames {
            if px.len() != frame_bytes {
                return Err(std::io::Error::other(format!(
                    "a frame of {} bytes, expected {frame_bytes}",
                    px.len()
                )));
            }
            w.write_all(&8u32.to_le_bytes())?;
            w.write_all(&(frame_bytes as u32).to_le_bytes())?;
            for r in (0..spec.height as usize).rev() {
                w.write_all(&px[r * row..(r + 1) * row])?;
            }
        }
        Ok(())
    })
}

/// A time in ns as TIME64 (fractions, seconds), rounded to a multiple of 4 fractions (the two
/// lowest bits are flags): within 0.5 ns of `ns`.
pub fn time64(ns: u64) -> (u32, u32) {
    let sec = ns / 1_000_000_000;
    let rem = ns % 1_000_000_000;
    // The nearest multiple of 4 fractions: at most 2 fractions (0.47 ns) away.
    let frac = (((rem as u128) << 32) + 2_000_000_000) / 4_000_000_000 * 4;
    let frac = frac.min(0xffff_fffc);
    (frac as u32, sec as u32)
}
