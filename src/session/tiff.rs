//! Multi-page greyscale TIFF: import of footage recorded by other software (8- or 16-bit,
//! ImageJ stacks included) and export of a session for Fiji/ImageJ.

use super::{FrameMeta, SessionError, SessionReader};
use std::fs::File;
use std::io::{BufReader, BufWriter};
use std::path::{Path, PathBuf};
use tiff::decoder::{Decoder, DecodingResult};
use tiff::encoder::{colortype, TiffEncoder};
use tiff::ColorType;

/// Most pages a stack may have (as `recording.frames`).
pub const MAX_PAGES: usize = crate::config::MAX_FRAMES as usize;
/// Most pixel bytes a stack may hold: it is read into memory whole.
pub const MAX_STACK_BYTES: u64 = 4 << 30;

/// The decoder's own limits: one page's buffer at most the largest frame (16384² at 16 bits),
/// tag values small (a crafted file cannot make it allocate gigabytes for one tag).
fn decoder_limits() -> tiff::decoder::Limits {
    let side = super::MAX_SIDE_PX as usize;
    let mut l = tiff::decoder::Limits::default();
    l.decoding_buffer_size = side * side * 2;
    l.intermediate_buffer_size = side * side * 2;
    l.ifd_value_size = 16 << 20;
    l
}

/// A TIFF stack held in memory as raw little-endian frames.
pub struct TiffStack {
    pub path: PathBuf,
    pub width: u32,
    pub height: u32,
    pub bytes_per_pixel: usize,
    pub frames: Vec<Vec<u8>>,
}

fn fmt_err(path: &Path, message: String) -> SessionError {
    SessionError::Format {
        path: path.to_path_buf(),
        message,
    }
}

impl TiffStack {
    pub fn open(path: &Path) -> Result<TiffStack, SessionError> {
        let file = File::open(path).map_err(|e| SessionError::Io {
            path: path.into(),
            message: e.to_string(),
        })?;
        let mut dec = Decoder::new(BufReader::new(file))
            .map_err(|e| fmt_err(path, format!("not a readable TIFF: {e}")))?
            .with_limits(decoder_limits());
        let mut frames = Vec::new();
        let (mut width, mut height, mut bpp) = (0, 0, 0);
        let mut total_bytes = 0u64;
        loop {
            let page = frames.len();
            let (w, h) = dec
                .dimensions()
                .map_err(|e| fmt_err(path, format!("page {page}: {e}")))?;
            let ct = dec
                .colortype()
                .map_err(|e| fmt_err(path, format!("page {page}: {e}")))?;
            let page_bpp = match ct {
                ColorType::Gray(8) => 1,
                ColorType::Gray(16) => 2,
                other => {
                    return Err(fmt_err(
                        path,
                        format!("page {page} is {other:?}, expected 8- or 16-bit greyscale (convert colour footage to grey first)"),
                    ))
                }
            };
            if page >= MAX_PAGES {
                return Err(fmt_err(
                    path,
                    format!("more than {MAX_PAGES} pages, expected at most that many frames"),
                ));
            }
            if w == 0 || h == 0 || w > super::MAX_SIDE_PX || h > super::MAX_SIDE_PX {
                return Err(fmt_err(
                    path,
                    format!(
                        "page {page} is {w}×{h}, expected 1 to {} px each",
                        super::MAX_SIDE_PX
                    ),
                ));
            }
            let page_bytes = u64::from(w) * u64::from(h) * page_bpp as u64;
            if total_bytes + page_bytes > MAX_STACK_BYTES {
                return Err(fmt_err(
                    path,
                    format!(
                        "page {page}: the stack passes {} MiB, expected at most that much (split it)",
                        MAX_STACK_BYTES >> 20
                    ),
                ));
            }
            total_bytes += page_bytes;
            if page == 0 {
                (width, height, bpp) = (w, h, page_bpp);
            } else if (w, h, page_bpp) != (width, height, bpp) {
                return Err(fmt_err(
                    path,
                    format!("page {page} is {w}×{h} at {} bits, expected {width}×{height} at {} bits like page 0", page_bpp * 8, bpp * 8),
                ));
            }
            let data = match dec.read_image().map_err(|e| {
                fmt_err(path, format!("page {page} is unreadable (truncated?): {e}"))
            })? {
                DecodingResult::U8(v) => v,
                DecodingResult::U16(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
                _ => {
                    return Err(fmt_err(
                        path,
                        format!(
                            "page {page}: unexpected sample type, expected 8- or 16-bit integers"
                        ),
                    ))
                }
            };
            if data.len() as u64 != page_bytes {
                return Err(fmt_err(
                    path,
                    format!(
                        "page {page} holds {} bytes, expected {}",
                        data.len(),
                        page_bytes
                    ),
                ));
            }
            frames.push(data);
            if !dec.more_images() {
                break;
            }
            dec.next_image()
                .map_err(|e| fmt_err(path, format!("page {}: {e}", page + 1)))?;
        }
        Ok(TiffStack {
            path: path.into(),
            width,
            height,
            bytes_per_pixel: bpp,
            frames,
        })
    }

    /// Frame metadata for a stack without timestamps: frame k is at k/fps.
    pub fn meta(&self, frame_rate_hz: f64) -> Vec<FrameMeta> {
        (0..self.frames.len() as u64)
            .map(|k| FrameMeta {
                frame_id: k,
                timestamp_ns: (k as f64 * 1e9 / frame_rate_hz).round() as u64,
            })
            .collect()
    }
}

/// Writes every frame of a session into one multi-page TIFF.
/// The file appears whole or not at all: it is written beside `out` under a temporary name,
/// which is removed on any failure, and renamed over `out` at the end.
pub fn export_session(session: &mut SessionReader, out: &Path) -> Result<usize, SessionError> {
    let name = out
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = out.with_file_name(format!(".{name}.{}.tmp", std::process::id()));
    let written = write_stack(session, &tmp).and_then(|n| {
        std::fs::rename(&tmp, out).map_err(|e| SessionError::Io {
            path: out.into(),
            message: e.to_string(),
        })?;
        Ok(n)
    });
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

fn write_stack(session: &mut SessionReader, out: &Path) -> Result<usize, SessionError> {
    let file = File::create(out).map_err(|e| SessionError::Io {
        path: out.into(),
        message: e.to_string(),
    })?;
    let mut writer = BufWriter::new(file);
    let mut enc = TiffEncoder::new(&mut writer).map_err(|e| fmt_err(out, e.to_string()))?;
    let (w, h) = (session.width, session.height);
    let mut buf = Vec::new();
    for i in 0..session.frames.len() {
        session.read_frame(i, &mut buf)?;
        let r = if session.bytes_per_pixel == 1 {
            enc.write_image::<colortype::Gray8>(w, h, &buf)
        } else {
            let px: Vec<u16> = buf
                .chunks_exact(2)
                .map(|c| u16::from_le_bytes([c[0], c[1]]))
                .collect();
            enc.write_image::<colortype::Gray16>(w, h, &px)
        };
        r.map_err(|e| fmt_err(out, format!("frame {i}: {e}")))?;
    }
    // The encoder's borrow of the writer ends here. Flush and sync, so that a full disk is an
    // error, not a short file (a BufWriter's drop flushes silently).
    let file = writer
        .into_inner()
        .map_err(|e| fmt_err(out, e.error().to_string()))?;
    file.sync_all().map_err(|e| SessionError::Io {
        path: out.into(),
        message: e.to_string(),
    })?;
    Ok(session.frames.len())
}
