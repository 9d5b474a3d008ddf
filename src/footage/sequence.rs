//! Numbered image sequences: one greyscale image per frame (PNG, TIFF or 8-bit BMP with a grey
//! palette; 8 or 16 bits), named with a number (`frame_00017.png`), given as a directory, a
//! pattern (`frames/frame_%05d.png`) or any one of its files. The number is the frame's: a
//! missing number is a dropped frame. Image files carry no times, so frame k is at
//! (number − first number) / `camera.frame_rate_hz`.

use super::{
    err, file_name, need_rate, FileInfo, FootageError, FrameFile, Timing, MAX_FILE_FRAMES,
};
use crate::session::{FrameMeta, MAX_SIDE_PX};
use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

/// Whether the file name holds a printf-style frame number (`%d`, `%05d`).
pub fn is_pattern(path: &Path) -> bool {
    pattern_parts(path).is_some()
}

/// (prefix, suffix) around a `%d` / `%0Nd` in the file name.
fn pattern_parts(path: &Path) -> Option<(String, String)> {
    let name = path.file_name()?.to_str()?;
    let at = name.find('%')?;
    let rest = &name[at + 1..];
    let digits = rest.bytes().take_while(u8::is_ascii_digit).count();
    if rest.as_bytes().get(digits) != Some(&b'd') {
        return None;
    }
    Some((name[..at].to_string(), rest[digits + 1..].to_string()))
}

/// (prefix, number, suffix) of a file name whose stem ends in a number (the last run of digits
/// before the extension).
pub fn numbered(path: &Path) -> Option<(String, u64, String)> {
    let name = path.file_name()?.to_str()?;
    let ext_at = name.rfind('.').unwrap_or(name.len());
    let stem = &name[..ext_at];
    let digits = stem.bytes().rev().take_while(u8::is_ascii_digit).count();
    if digits == 0 || digits > 18 {
        return None;
    }
    let number = stem[stem.len() - digits..].parse().ok()?;
    Some((
        stem[..stem.len() - digits].to_string(),
        number,
        name[ext_at..].to_string(),
    ))
}

/// Whether the directory holds at least one numbered PNG, TIFF or BMP image.
pub fn holds_numbered_images(dir: &Path) -> bool {
    std::fs::read_dir(dir).is_ok_and(|entries| {
        entries.filter_map(|e| e.ok()).any(|e| {
            let p = e.path();
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| !n.starts_with('.') && is_image_name(n))
                && numbered(&p).is_some()
        })
    })
}

fn is_image_name(name: &str) -> bool {
    let lower = name.to_ascii_lowercase();
    [".png", ".tif", ".tiff", ".bmp"]
        .iter()
        .any(|e| lower.ends_with(e))
}

pub struct Sequence {
    files: Vec<PathBuf>,
    meta: Vec<FrameMeta>,
    info: FileInfo,
    dropped: u64,
}

impl Sequence {
    pub fn open(path: &Path, frame_rate_hz: Option<f64>) -> Result<Sequence, FootageError> {
        let (dir, want): (PathBuf, Option<(String, String)>) = if path.is_dir() {
            (path.to_path_buf(), None)
        } else if let Some(parts) = pattern_parts(path) {
            (parent(path), Some(parts))
        } else {
            let (prefix, _, suffix) = numbered(path).ok_or_else(|| {
                err(path, "an image without a frame number in its name: expected numbered images (frame_00017.png), a directory of them, or a pattern like frame_%05d.png")
            })?;
            (parent(path), Some((prefix, suffix)))
        };
        let entries =
            std::fs::read_dir(&dir).map_err(|e| err(&dir, format!("cannot list: {e}")))?;
        // Numbered images, grouped by what surrounds the number.
        let mut groups: std::collections::BTreeMap<(String, String), Vec<(u64, PathBuf)>> =
            Default::default();
        let mut seen = 0u64;
        for e in entries.filter_map(|e| e.ok()) {
            let p = e.path();
            let Some(name) = p.file_name().and_then(|n| n.to_str()) else {
                continue;
            };
            if name.starts_with('.') || !is_image_name(name) {
                continue;
            }
            let Some((prefix, number, suffix)) = numbered(&p) else {
                continue;
            };
            seen += 1;
            if seen > MAX_FILE_FRAMES {
                return Err(err(
                    &dir,
                    format!("more than {MAX_FILE_FRAMES} numbered images, expected at most that many frames"),
                ));
            }
            groups
                .entry((prefix, suffix))
                .or_default()
                .push((number, p));
        }
        let (key, mut files) = match want {
            Some(k) => {
                let files = groups.remove(&k).unwrap_or_default();
                (k, files)
            }
            // A directory: the largest group of numbered images in it.
            None => groups
                .into_iter()
                .max_by_key(|(_, v)| v.len())
                .ok_or_else(|| {
                    err(
                        &dir,
                        "no numbered PNG, TIFF or BMP images in this directory",
                    )
                })?,
        };
        if files.is_empty() {
            return Err(err(
                path,
                format!(
                    "no images named {}<number>{} in {}",
                    key.0,
                    key.1,
                    dir.display()
                ),
            ));
        }
        files.sort();
        if let Some(w) = files.windows(2).find(|w| w[0].0 == w[1].0) {
            return Err(err(
                &w[1].1,
                format!(
                    "frame number {} is also {}, expected one image per number",
                    w[0].0,
                    file_name(&w[0].1)
                ),
            ));
        }
        let rate = need_rate(path, frame_rate_hz, "image files carry no frame times")?;
        let first = files[0].0;
        let meta: Vec<FrameMeta> = files
            .iter()
            .map(|(n, _)| FrameMeta {
                frame_id: n - first,
                timestamp_ns: ((n - first) as f64 * 1e9 / rate).round() as u64,
            })
            .collect();
        let dropped = crate::session::count_gaps(&meta);
        let files: Vec<PathBuf> = files.into_iter().map(|(_, p)| p).collect();
        let mut probe = Vec::new();
        let (width, height, bytes_per_pixel) = decode(&files[0], &mut probe)?;
        let mut notes = Vec::new();
        if dropped > 0 {
            notes.push(format!(
                "{dropped} frame number(s) missing between the first and the last image"
            ));
        }
        let info = FileInfo {
            kind: "sequence",
            name: file_name(&files[0]),
            width,
            height,
            bytes_per_pixel,
            frame_rate_hz: None,
            timing: Timing::Rate,
            trigger_frame: None,
            first_frame_number: Some(first as i64),
            exposure_s: None,
            header: vec![
                ("pattern".into(), format!("{}<number>{}", key.0, key.1)),
                ("first_number".into(), first.to_string()),
                ("images".into(), files.len().to_string()),
            ],
            notes,
        };
        Ok(Sequence {
            files,
            meta,
            info,
            dropped,
        })
    }

    /// Frame numbers missing between the first and the last image.
    pub fn dropped(&self) -> u64 {
        self.dropped
    }
}

fn parent(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

impl FrameFile for Sequence {
    fn info(&self) -> &FileInfo {
        &self.info
    }
    fn frames(&self) -> &[FrameMeta] {
        &self.meta
    }
    fn read(&mut self, i: usize, buf: &mut Vec<u8>) -> Result<(), FootageError> {
        let path = &self.files[i];
        let got = decode(path, buf)?;
        let want = (self.info.width, self.info.height, self.info.bytes_per_pixel);
        if got != want {
            return Err(err(
                path,
                format!(
                    "{}×{} px at {} byte(s) per pixel, expected {}×{} at {} like the first image",
                    got.0, got.1, got.2, want.0, want.1, want.2
                ),
            ));
        }
        Ok(())
    }
}

/// Decodes one greyscale image into `buf` (little-endian): (width, height, bytes per pixel).
pub(super) fn decode(path: &Path, buf: &mut Vec<u8>) -> Result<(u32, u32, usize), FootageError> {
    let mut head = [0u8; 8];
    let mut f = File::open(path).map_err(|e| err(path, format!("cannot open: {e}")))?;
    let n =
        super::read_up_to(&mut f, &mut head).map_err(|e| err(path, format!("cannot read: {e}")))?;
    let head = &head[..n];
    if head.starts_with(b"\x89PNG") {
        decode_png(path, buf)
    } else if head.starts_with(b"BM") {
        decode_bmp(path, buf)
    } else if head.starts_with(b"II*\0") || head.starts_with(b"MM\0*") {
        let mut one = super::tiff_stack::TiffStack::open(path, Some(1.0))?;
        if one.len() != 1 {
            return Err(err(
                path,
                format!(
                    "{} pages, expected one image per file in a sequence",
                    one.len()
                ),
            ));
        }
        let i = one.info().clone();
        one.read(0, buf)?;
        Ok((i.width, i.height, i.bytes_per_pixel))
    } else {
        Err(err(path, "not a PNG, TIFF or BMP image"))
    }
}

fn decode_png(path: &Path, buf: &mut Vec<u8>) -> Result<(u32, u32, usize), FootageError> {
    let f = File::open(path).map_err(|e| err(path, format!("cannot open: {e}")))?;
    let side = MAX_SIDE_PX as usize;
    let mut dec = png::Decoder::new_with_limits(
        BufReader::new(f),
        png::Limits {
            bytes: side * side * 2,
        },
    );
    dec.set_transformations(png::Transformations::IDENTITY);
    let mut reader = dec
        .read_info()
        .map_err(|e| err(path, format!("not a readable PNG: {e}")))?;
    let info = reader.info();
    let (w, h) = (info.width, info.height);
    let bpp = match (info.color_type, info.bit_depth) {
        (png::ColorType::Grayscale, png::BitDepth::Eight) => 1,
        (png::ColorType::Grayscale, png::BitDepth::Sixteen) => 2,
        (c, d) => {
            return Err(err(
                path,
                format!("a {c:?} PNG of {d:?} bits, expected 8- or 16-bit greyscale"),
            ))
        }
    };
    super::check_size(path, "PNG header", i64::from(w), i64::from(h))?;
    buf.resize(reader.output_buffer_size(), 0);
    let frame = reader
        .next_frame(buf)
        .map_err(|e| err(path, format!("PNG data: {e}")))?;
    buf.truncate(frame.buffer_size());
    let want = w as usize * h as usize * bpp;
    if frame.line_size != w as usize * bpp || buf.len() != want {
        return Err(err(
            path,
            format!(
                "PNG rows of {} bytes, expected {}",
                frame.line_size,
                w as usize * bpp
            ),
        ));
    }
    if bpp == 2 {
        // PNG stores 16-bit samples big-endian.
        for c in buf.chunks_exact_mut(2) {
            c.swap(0, 1);
        }
    }
    Ok((w, h, bpp))
}

/// An uncompressed 8-bit BMP with a grey palette (rows bottom first unless the height is
/// negative, each padded to 4 bytes).
fn decode_bmp(path: &Path, buf: &mut Vec<u8>) -> Result<(u32, u32, usize), FootageError> {
    let mut f = File::open(path).map_err(|e| err(path, format!("cannot open: {e}")))?;
    let len = f
        .metadata()
        .map_err(|e| err(path, format!("cannot read: {e}")))?
        .len();
    let mut h = [0u8; 54];
    super::read_at(&mut f, path, 0, &mut h, "BMP header")?;
    let u32_at = |o: usize| u32::from_le_bytes([h[o], h[o + 1], h[o + 2], h[o + 3]]);
    let pixels_at = u64::from(u32_at(10));
    let dib = u64::from(u32_at(14));
    let (w, hh) = (i64::from(u32_at(18) as i32), i64::from(u32_at(22) as i32));
    let bits = u16::from_le_bytes([h[28], h[29]]);
    let compression = u32_at(30);
    if bits != 8 || compression != 0 {
        return Err(err(
            path,
            format!("a {bits}-bit BMP (compression {compression}), expected 8-bit uncompressed with a grey palette"),
        ));
    }
    let (width, height) = super::check_size(path, "BMP header", w, hh.abs())?;
    let colours = match u32_at(46) {
        0 => 256,
        c => c.min(256) as usize,
    };
    let mut palette = vec![0u8; colours * 4];
    super::read_at(&mut f, path, 14 + dib, &mut palette, "BMP palette")?;
    let grey: Vec<u8> = palette.chunks_exact(4).map(|c| c[0]).collect();
    if palette
        .chunks_exact(4)
        .any(|c| c[0] != c[1] || c[1] != c[2])
    {
        return Err(err(
            path,
            "a BMP with a colour palette, expected a grey one",
        ));
    }
    let stride = (width as usize).div_ceil(4) * 4;
    let bytes = stride as u64 * u64::from(height);
    if pixels_at + bytes > len {
        return Err(err(
            path,
            format!(
                "BMP pixels end at byte {}, beyond the file (cut short?)",
                pixels_at + bytes
            ),
        ));
    }
    let mut raw = vec![0u8; bytes as usize];
    super::read_at(&mut f, path, pixels_at, &mut raw, "BMP pixels")?;
    buf.clear();
    buf.reserve(width as usize * height as usize);
    for r in 0..height as usize {
        let src = if hh > 0 { height as usize - 1 - r } else { r };
        for &i in &raw[src * stride..src * stride + width as usize] {
            buf.push(*grey.get(i as usize).ok_or_else(|| {
                err(
                    path,
                    format!("BMP pixel index {i} beyond its {colours}-colour palette"),
                )
            })?);
        }
    }
    Ok((width, height, 1))
}
