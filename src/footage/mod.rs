//! Footage from other cameras and software, read frame by frame without holding the file in
//! memory: Photron MRAW with its CIH/CIHX header (`photron`), Phantom CINE (`cine`), FMF
//! (`fmf`), numbered image sequences of PNG, TIFF or BMP (`sequence`) and multi-page TIFF stacks
//! (`tiff_stack`); and the writers behind `impactcam export` (MRAW, FMF; TIFF is in
//! `session::tiff`) and a CINE writer from the format's description, for tests. `open` decides
//! the format by the file's content, never its extension.
//!
//! Every reader checks its header against the file's length before it believes a size, and
//! allocates only what one frame needs (at most `MAX_SIDE_PX`² pixels of two bytes).
//! Frames come out as the analysis and sessions take them: one or two bytes per pixel,
//! little-endian, top row first; footage with fewer significant bits than its container
//! (12-bit) is scaled to the container's full range, and `FileInfo::notes` says so: where the
//! header says so (MRAW, CINE), and in the formats that cannot say it (TIFF, PNG, FMF) where
//! no pixel of the whole file reaches the top of a 10-, 12- or 14-bit range (`LowBits`).

pub mod cine;
pub mod fmf;
pub mod import;
pub mod photron;
pub mod sequence;
pub mod tiff_stack;

use crate::session::{FrameMeta, MAX_SIDE_PX};
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

/// Most frames a file may hold (as `recording.frames`).
pub const MAX_FILE_FRAMES: u64 = crate::config::MAX_FRAMES as u64;

#[derive(Debug, thiserror::Error)]
#[error("{path}: {message}")]
pub struct FootageError {
    pub path: PathBuf,
    pub message: String,
}

pub(crate) fn err(path: &Path, message: impl Into<String>) -> FootageError {
    FootageError {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// Where a file's frame times come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Timing {
    /// Each frame's own time, stored in the file (CINE's time block, FMF's timestamps).
    File,
    /// Frame number / frame rate (the rate from the file's header where it has one).
    Rate,
}

/// What a file says about itself.
#[derive(Clone, Debug)]
pub struct FileInfo {
    /// "mraw", "cine", "fmf", "sequence", "tiff".
    pub kind: &'static str,
    /// The file's (or the sequence's first file's) name, not its path.
    pub name: String,
    pub width: u32,
    pub height: u32,
    /// 1 or 2.
    pub bytes_per_pixel: usize,
    /// The frame rate the file states, Hz.
    pub frame_rate_hz: Option<f64>,
    pub timing: Timing,
    /// Index (in the file) of the trigger frame, where the file records one and it is among
    /// the frames held.
    pub trigger_frame: Option<i64>,
    /// The camera's number of the file's first frame, relative to the trigger (negative before
    /// it), where the file records it.
    pub first_frame_number: Option<i64>,
    /// Exposure time, s, where the file records it.
    pub exposure_s: Option<f64>,
    /// The header's own fields, kept in an imported session's manifest.
    pub header: Vec<(String, String)>,
    /// What a reader of the report must know about how the file was read.
    pub notes: Vec<String>,
}

/// Frames of one file, read one at a time.
pub trait FrameFile: Send {
    fn info(&self) -> &FileInfo;
    /// Every frame's id and time. Ids are the position in the file unless the file numbers its
    /// frames (an image sequence with gaps); times start at 0 for the first frame.
    fn frames(&self) -> &[FrameMeta];
    fn len(&self) -> usize {
        self.frames().len()
    }
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    fn meta(&self, i: usize) -> FrameMeta {
        self.frames()[i]
    }
    /// Frame `i`'s pixels into `buf` (resized to width × height × bytes per pixel).
    fn read(&mut self, i: usize, buf: &mut Vec<u8>) -> Result<(), FootageError>;
}

/// One greyscale image file (PNG, BMP, or a one-page TIFF) into `buf`, little-endian: (width,
/// height, bytes per pixel). That file alone, even where its name is numbered like a sequence's.
/// A 16-bit image whose pixels stay within a 10-, 12- or 14-bit range is scaled to the 16-bit
/// range (`LowBits`).
pub fn read_image(path: &Path, buf: &mut Vec<u8>) -> Result<(u32, u32, usize), FootageError> {
    let (w, h, bpp) = sequence::decode(path, buf)?;
    if bpp == 2 {
        if let Some(bits) = low_depth(max_le16(buf)) {
            widen_le16(buf, bits);
        }
    }
    Ok((w, h, bpp))
}

/// Opens footage by its content: a directory of numbered images, a `%d` pattern, a Photron
/// header (.cih/.cihx) or the .mraw beside one, a CINE, an FMF, a TIFF stack, or one image of
/// a numbered sequence. `frame_rate_hz` is used where the file has no rate of its own.
pub fn open(path: &Path, frame_rate_hz: Option<f64>) -> Result<Box<dyn FrameFile>, FootageError> {
    if path.is_dir() || sequence::is_pattern(path) {
        return LowBits::wrap(
            path,
            Box::new(sequence::Sequence::open(path, frame_rate_hz)?),
        );
    }
    let mut head = [0u8; 4096];
    let n = {
        let mut f = File::open(path).map_err(|e| err(path, format!("cannot open: {e}")))?;
        read_up_to(&mut f, &mut head).map_err(|e| err(path, format!("cannot read: {e}")))?
    };
    let head = &head[..n];
    if photron::is_header(head) {
        return Ok(Box::new(photron::Mraw::open(path)?));
    }
    if cine::is_cine(head) {
        return Ok(Box::new(cine::Cine::open(path)?));
    }
    if fmf::is_fmf(head) {
        return LowBits::wrap(path, Box::new(fmf::Fmf::open(path, frame_rate_hz)?));
    }
    if head.starts_with(b"II*\0") || head.starts_with(b"MM\0*") {
        let stack = tiff_stack::TiffStack::open(path, frame_rate_hz)?;
        // One page: a frame of a numbered sequence, when its name is numbered.
        if stack.len() == 1 && sequence::numbered(path).is_some() {
            return LowBits::wrap(
                path,
                Box::new(sequence::Sequence::open(path, frame_rate_hz)?),
            );
        }
        return LowBits::wrap(path, Box::new(stack));
    }
    if head.starts_with(b"\x89PNG") || head.starts_with(b"BM") {
        return LowBits::wrap(
            path,
            Box::new(sequence::Sequence::open(path, frame_rate_hz)?),
        );
    }
    // A .mraw has no signature of its own: it is known by its header beside it (and said to
    // lack one by its name).
    if photron::header_beside(path).is_some()
        || path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("mraw"))
    {
        return Ok(Box::new(photron::Mraw::open(path)?));
    }
    Err(err(
        path,
        "not footage impactcam reads: expected a session directory, a Photron .cih/.cihx (or the .mraw beside one), a Phantom .cine, an FMF, a TIFF stack, or numbered PNG/TIFF/BMP images",
    ))
}

/// Whether `path` names one input for `analyze` (a file, a session, a `%d` pattern, or a
/// directory of numbered images without sessions in it), not a batch of sessions.
pub fn is_one_input(path: &Path) -> bool {
    if path.is_file() || crate::batch::is_session(path) || sequence::is_pattern(path) {
        return true;
    }
    path.is_dir() && !crate::batch::holds_sessions(path) && sequence::holds_numbered_images(path)
}

/// Reads into `buf` until it is full or the file ends; the number of bytes read.
pub(crate) fn read_up_to(r: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match r.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(n)
}

/// Reads exactly `buf.len()` bytes at `offset`, naming what was being read when the file is
/// shorter.
pub(crate) fn read_at(
    f: &mut File,
    path: &Path,
    offset: u64,
    buf: &mut [u8],
    what: &str,
) -> Result<(), FootageError> {
    f.seek(SeekFrom::Start(offset))
        .and_then(|_| f.read_exact(buf))
        .map_err(|e| {
            if e.kind() == std::io::ErrorKind::UnexpectedEof {
                err(
                    path,
                    format!(
                        "{what}: the file ends before byte {} (cut short?)",
                        offset + buf.len() as u64
                    ),
                )
            } else {
                err(path, format!("{what}: {e}"))
            }
        })
}

/// Checks a frame size from a header: each side 1 to `MAX_SIDE_PX`.
pub(crate) fn check_size(
    path: &Path,
    what: &str,
    w: i64,
    h: i64,
) -> Result<(u32, u32), FootageError> {
    let max = i64::from(MAX_SIDE_PX);
    if !(1..=max).contains(&w) || !(1..=max).contains(&h) {
        return Err(err(
            path,
            format!("{what} says {w}×{h} px, expected 1 to {MAX_SIDE_PX} px each"),
        ));
    }
    Ok((w as u32, h as u32))
}

/// Checks a frame count from a header against the bound and against what the file can hold.
pub(crate) fn check_frames(
    path: &Path,
    what: &str,
    claimed: u64,
    held: u64,
) -> Result<usize, FootageError> {
    if claimed == 0 {
        return Err(err(
            path,
            format!("{what} says 0 frames, expected at least 1"),
        ));
    }
    if claimed > MAX_FILE_FRAMES {
        return Err(err(
            path,
            format!("{what} says {claimed} frames, expected at most {MAX_FILE_FRAMES}"),
        ));
    }
    if claimed > held {
        return Err(err(
            path,
            format!("{what} says {claimed} frames, but the file holds only {held} (cut short?)"),
        ));
    }
    Ok(claimed as usize)
}

/// Times of frames at `rate` Hz: frame k at round(k / rate) ns.
pub(crate) fn rate_meta(n: usize, rate: f64) -> Vec<FrameMeta> {
    (0..n)
        .map(|k| FrameMeta {
            frame_id: k as u64,
            timestamp_ns: (k as f64 * 1e9 / rate).round() as u64,
        })
        .collect()
}

/// A frame rate given from outside the file (config), checked.
pub(crate) fn need_rate(path: &Path, rate: Option<f64>, why: &str) -> Result<f64, FootageError> {
    match rate {
        Some(r) if r.is_finite() && r > 0.0 => Ok(r),
        Some(r) => Err(err(
            path,
            format!("frame rate {r} Hz, expected a positive number"),
        )),
        None => Err(err(
            path,
            format!("{why}: give a config with camera.frame_rate_hz"),
        )),
    }
}

/// The file name of `path`, for reports (never the path: a moved file analyses identically).
pub(crate) fn file_name(path: &Path) -> String {
    path.file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// Scales 16-bit samples with `bits` significant (low) bits to the full 16-bit range.
pub(crate) fn widen_le16(buf: &mut [u8], bits: u32) {
    if bits >= 16 || bits == 0 {
        return;
    }
    let shift = 16 - bits;
    for c in buf.chunks_exact_mut(2) {
        let v = u16::from_le_bytes([c[0], c[1]]);
        // A sample beyond the stated bits (a header that understates them) is the top of the
        // range, not wrapped round to a dark level.
        let wide = if u32::from(v) >> bits == 0 {
            v << shift
        } else {
            u16::MAX
        };
        c.copy_from_slice(&wide.to_le_bytes());
    }
}

/// The camera depths a 16-bit container holds in its low bits, shallowest first.
const LOW_DEPTHS: [u32; 3] = [10, 12, 14];

/// The shallowest of `LOW_DEPTHS` whose range holds `max`, if any.
fn low_depth(max: u16) -> Option<u32> {
    LOW_DEPTHS.into_iter().find(|&b| u32::from(max) < 1 << b)
}

/// The largest sample of 16-bit little-endian pixels.
fn max_le16(buf: &[u8]) -> u16 {
    buf.chunks_exact(2)
        .map(|c| u16::from_le_bytes([c[0], c[1]]))
        .max()
        .unwrap_or(0)
}

/// 16-bit footage from a format that cannot state its significant bits (TIFF, PNG, FMF) whose
/// pixels never reach the top of a 10-, 12- or 14-bit range: a 12-bit camera's frames exported
/// as they are, which most camera software does. Scaled to the 16-bit range as a 12-bit MRAW
/// is, and the notes say so. Why: the analysis works on the 8-bit scale (`GreyImage::load`
/// divides 16-bit levels by 256), where a 12-bit camera's frames would span 16 grey levels with
/// a noise of an eighth of one, below the floors its tests keep against an 8-bit camera's
/// quantisation; on the independent renders made 12-bit so, the two backlit ones lost their
/// spins (docs/accuracy.md, session 49). A recording whose every pixel is that dark on a true
/// 16-bit camera is only made brighter, losslessly.
struct LowBits {
    inner: Box<dyn FrameFile>,
    info: FileInfo,
    bits: u32,
}

impl LowBits {
    /// `file` as it is, unless it is 16-bit and no pixel of any frame reaches 2¹⁴ (the scan stops
    /// at the first that does: a true 16-bit recording usually costs one frame's read).
    fn wrap(path: &Path, mut file: Box<dyn FrameFile>) -> Result<Box<dyn FrameFile>, FootageError> {
        if file.info().bytes_per_pixel != 2 {
            return Ok(file);
        }
        let mut buf = Vec::new();
        let mut max = 0u16;
        for i in 0..file.len() {
            file.read(i, &mut buf)?;
            max = max.max(max_le16(&buf));
            if low_depth(max).is_none() {
                return Ok(file);
            }
        }
        let Some(bits) = low_depth(max) else {
            return Ok(file);
        };
        let mut info = file.info().clone();
        info.notes.push(format!(
            "{}: no pixel reaches {} (the largest is {max}): taken as {bits}-bit pixels in 16 bits and scaled ×{} to the 16-bit range",
            file_name(path),
            1u32 << bits,
            1u32 << (16 - bits)
        ));
        Ok(Box::new(LowBits {
            inner: file,
            info,
            bits,
        }))
    }
}

impl FrameFile for LowBits {
    fn info(&self) -> &FileInfo {
        &self.info
    }
    fn frames(&self) -> &[FrameMeta] {
        self.inner.frames()
    }
    fn read(&mut self, i: usize, buf: &mut Vec<u8>) -> Result<(), FootageError> {
        self.inner.read(i, buf)?;
        widen_le16(buf, self.bits);
        Ok(())
    }
}

/// Writes `out` whole or not at all: into a temporary file beside it (removed on any failure),
/// flushed and synced, then renamed over `out`.
pub(crate) fn write_whole(
    out: &Path,
    body: impl FnOnce(&mut std::io::BufWriter<File>) -> std::io::Result<()>,
) -> Result<(), FootageError> {
    let name = file_name(out);
    let tmp = out.with_file_name(format!(".{name}.{}.tmp", std::process::id()));
    let result = (|| {
        let f = File::create(&tmp)?;
        let mut w = std::io::BufWriter::new(f);
        body(&mut w)?;
        let f = w.into_inner().map_err(|e| e.into_error())?;
        f.sync_all()?;
        std::fs::rename(&tmp, out)
    })();
    result.map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        err(out, format!("cannot write: {e}"))
    })
}

#[cfg(test)]
mod tests;
