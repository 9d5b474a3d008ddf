//! Multi-page greyscale TIFF stacks (8- or 16-bit; ImageJ's included), read a page at a time:
//! opening walks the pages' directories (sizes and sample types, no pixels); a frame is decoded
//! when it is read. An ImageJ stack's frame interval (`finterval` in its description) is the
//! file's own frame rate.

use super::{
    err, file_name, rate_meta, FileInfo, FootageError, FrameFile, Timing, MAX_FILE_FRAMES,
};
use crate::session::{FrameMeta, MAX_SIDE_PX};
use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};
use tiff::decoder::{Decoder, DecodingResult};
use tiff::tags::Tag;
use tiff::ColorType;

/// The decoder's own limits: one page's buffer at most the largest frame (16384² at 16 bits),
/// tag values small (a crafted file cannot make it allocate gigabytes for one tag).
fn decoder_limits() -> tiff::decoder::Limits {
    let side = MAX_SIDE_PX as usize;
    let mut l = tiff::decoder::Limits::default();
    l.decoding_buffer_size = side * side * 2;
    l.intermediate_buffer_size = side * side * 2;
    l.ifd_value_size = 16 << 20;
    l
}

pub struct TiffStack {
    path: PathBuf,
    dec: Decoder<BufReader<File>>,
    /// The page the decoder is at.
    at: usize,
    meta: Vec<FrameMeta>,
    info: FileInfo,
}

/// The frame interval an ImageJ description gives (`finterval=…`, in its time unit, seconds
/// unless `tunit` says ms or µs), s.
fn imagej_interval_s(description: &str) -> Option<f64> {
    if !description.starts_with("ImageJ=") {
        return None;
    }
    let value = |key: &str| {
        description
            .lines()
            .find_map(|l| l.strip_prefix(key)?.strip_prefix('='))
            .map(str::trim)
    };
    let interval: f64 = value("finterval")?.parse().ok()?;
    let scale = match value("tunit") {
        None | Some("s" | "sec" | "second" | "seconds") => 1.0,
        Some("ms" | "msec") => 1e-3,
        Some("us" | "µs" | "usec") => 1e-6,
        Some(_) => return None,
    };
    let s = interval * scale;
    (s.is_finite() && s > 0.0).then_some(s)
}

impl TiffStack {
    /// Opens a stack; `frame_rate_hz` is used unless the file states its own.
    pub fn open(path: &Path, frame_rate_hz: Option<f64>) -> Result<TiffStack, FootageError> {
        let open = || -> Result<Decoder<BufReader<File>>, FootageError> {
            let file = File::open(path).map_err(|e| err(path, format!("cannot open: {e}")))?;
            Ok(Decoder::new(BufReader::new(file))
                .map_err(|e| err(path, format!("not a readable TIFF: {e}")))?
                .with_limits(decoder_limits()))
        };
        let mut dec = open()?;
        let description = dec.get_tag_ascii_string(Tag::ImageDescription).ok();
        let mut pages = 0usize;
        let (mut width, mut height, mut bpp) = (0, 0, 0);
        loop {
            let page = pages;
            let (w, h) = dec
                .dimensions()
                .map_err(|e| err(path, format!("page {page}: {e}")))?;
            let ct = dec
                .colortype()
                .map_err(|e| err(path, format!("page {page}: {e}")))?;
            let page_bpp = match ct {
                ColorType::Gray(8) => 1,
                ColorType::Gray(16) => 2,
                other => {
                    return Err(err(
                        path,
                        format!("page {page} is {other:?}, expected 8- or 16-bit greyscale (convert colour footage to grey first)"),
                    ))
                }
            };
            if w == 0 || h == 0 || w > MAX_SIDE_PX || h > MAX_SIDE_PX {
                return Err(err(
                    path,
                    format!("page {page} is {w}×{h}, expected 1 to {MAX_SIDE_PX} px each"),
                ));
            }
            if page == 0 {
                (width, height, bpp) = (w, h, page_bpp);
            } else if (w, h, page_bpp) != (width, height, bpp) {
                return Err(err(
                    path,
                    format!("page {page} is {w}×{h} at {} bits, expected {width}×{height} at {} bits like page 0", page_bpp * 8, bpp * 8),
                ));
            }
            pages += 1;
            if pages as u64 > MAX_FILE_FRAMES {
                return Err(err(
                    path,
                    format!("more than {MAX_FILE_FRAMES} pages, expected at most that many frames"),
                ));
            }
            if !dec.more_images() {
                break;
            }
            dec.next_image()
                .map_err(|e| err(path, format!("page {pages}: {e}")))?;
        }
        let file_rate = description
            .as_deref()
            .and_then(imagej_interval_s)
            .map(|s| 1.0 / s);
        let (rate, notes) = match (file_rate, frame_rate_hz) {
            (Some(r), _) => (r, Vec::new()),
            (None, given) => (
                super::need_rate(path, given, "a TIFF stack carries no frame times")?,
                Vec::new(),
            ),
        };
        let dec = open()?;
        Ok(TiffStack {
            path: path.to_path_buf(),
            dec,
            at: 0,
            meta: rate_meta(pages, rate),
            info: FileInfo {
                kind: "tiff",
                name: file_name(path),
                width,
                height,
                bytes_per_pixel: bpp,
                frame_rate_hz: file_rate,
                timing: Timing::Rate,
                trigger_frame: None,
                first_frame_number: None,
                exposure_s: None,
                header: description
                    .map(|d| {
                        vec![(
                            "ImageDescription".to_string(),
                            d.chars().take(4096).collect(),
                        )]
                    })
                    .unwrap_or_default(),
                notes,
            },
        })
    }
}

impl FrameFile for TiffStack {
    fn info(&self) -> &FileInfo {
        &self.info
    }
    fn frames(&self) -> &[FrameMeta] {
        &self.meta
    }
    fn read(&mut self, i: usize, buf: &mut Vec<u8>) -> Result<(), FootageError> {
        let path = &self.path;
        if i != self.at {
            self.dec
                .seek_to_image(i)
                .map_err(|e| err(path, format!("page {i}: {e}")))?;
            self.at = i;
        }
        let data = self
            .dec
            .read_image()
            .map_err(|e| err(path, format!("page {i} is unreadable (truncated?): {e}")))?;
        buf.clear();
        match data {
            DecodingResult::U8(v) => buf.extend_from_slice(&v),
            DecodingResult::U16(v) => buf.extend(v.iter().flat_map(|x| x.to_le_bytes())),
            _ => {
                return Err(err(
                    path,
                    format!("page {i}: unexpected sample type, expected 8- or 16-bit integers"),
                ))
            }
        }
        let want = self.info.width as usize * self.info.height as usize * self.info.bytes_per_pixel;
        if buf.len() != want {
            return Err(err(
                path,
                format!("page {i} holds {} bytes, expected {want}", buf.len()),
            ));
        }
        Ok(())
    }
}
