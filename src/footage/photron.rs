//! Photron footage: the raw frames (`.mraw`: 8-bit, 12-bit packed two pixels in three bytes, or
//! 16-bit little-endian, rows top first, frames back to back) described by a header beside
//! them, either `.cih` (text lines `Key : Value`) or `.cihx` (XML inside `<cih>`, possibly after
//! a binary preamble). From the header: size, bit depth and its significant bits, frame rate,
//! shutter, and the start frame (the camera's number of the first frame saved, relative to the
//! trigger), hence the trigger frame. Photron's own frame times are frame number / rate.

use super::{
    check_frames, check_size, err, file_name, rate_meta, read_at, FileInfo, FootageError,
    FrameFile, Timing,
};
use crate::session::{FrameMeta, SessionReader};
use std::fs::File;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

/// Longest header read (real ones are a few kilobytes).
const MAX_HEADER_BYTES: u64 = 1 << 20;

/// Whether the bytes begin a Photron header: a CIH's first line, or a CIHX's XML.
pub fn is_header(head: &[u8]) -> bool {
    let text = String::from_utf8_lossy(head);
    text.trim_start_matches('\u{feff}')
        .starts_with("#Camera Information Header")
        || (text.contains("<cih>") || (text.contains("<?xml") && text.contains("<cih")))
}

/// The header beside a .mraw (same name, extension .cih or .cihx in either case), if one exists.
pub fn header_beside(mraw: &Path) -> Option<PathBuf> {
    ["cihx", "cih", "CIHX", "CIH"]
        .iter()
        .map(|e| mraw.with_extension(e))
        .find(|p| p.is_file())
}

/// The .mraw beside a header.
fn mraw_beside(header: &Path) -> Option<PathBuf> {
    ["mraw", "MRAW"]
        .iter()
        .map(|e| header.with_extension(e))
        .find(|p| p.is_file())
}

/// A header's fields by the CIH's key names (a CIHX's elements are mapped onto them).
struct Header {
    fields: Vec<(String, String)>,
}

impl Header {
    fn get(&self, key: &str) -> Option<&str> {
        self.fields
            .iter()
            .find(|(k, _)| k.eq_ignore_ascii_case(key))
            .map(|(_, v)| v.as_str())
    }

    fn read(path: &Path) -> Result<Header, FootageError> {
        let mut bytes = Vec::new();
        File::open(path)
            .and_then(|f| f.take(MAX_HEADER_BYTES).read_to_end(&mut bytes))
            .map_err(|e| err(path, format!("cannot read the header: {e}")))?;
        let text = String::from_utf8_lossy(&bytes);
        if let (Some(a), Some(b)) = (text.find("<cih>"), text.rfind("</cih>")) {
            return Ok(Header {
                fields: cihx_fields(&text[a..b]),
            });
        }
        let text = text.trim_start_matches('\u{feff}');
        if !text.starts_with("#Camera Information Header") {
            return Err(err(
                path,
                "not a Photron header: expected a .cih starting \"#Camera Information Header\" or a .cihx holding <cih>…</cih>",
            ));
        }
        let fields = text
            .lines()
            .skip(1)
            .take_while(|l| !l.trim().is_empty())
            .filter_map(|l| {
                let (k, v) = l.split_once(" : ")?;
                Some((k.trim().to_string(), v.trim().to_string()))
            })
            .collect();
        Ok(Header { fields })
    }
}

/// The text of the element at `path` (nested names) inside `xml`.
fn xml_text<'a>(xml: &'a str, path: &[&str]) -> Option<&'a str> {
    let mut scope = xml;
    for name in path {
        let open = format!("<{name}>");
        let close = format!("</{name}>");
        let start = scope.find(&open)? + open.len();
        let end = start + scope[start..].find(&close)?;
        scope = &scope[start..end];
    }
    Some(scope.trim())
}

/// A CIHX's elements under the CIH's key names.
fn cihx_fields(xml: &str) -> Vec<(String, String)> {
    [
        ("Record Rate(fps)", &["recordInfo", "recordRate"][..]),
        ("Shutter Speed(s)", &["recordInfo", "shutterSpeed"]),
        ("Total Frame", &["frameInfo", "totalFrame"]),
        ("Start Frame", &["frameInfo", "startFrame"]),
        ("Original Total Frame", &["frameInfo", "recordedFrame"]),
        ("Image Width", &["imageDataInfo", "resolution", "width"]),
        ("Image Height", &["imageDataInfo", "resolution", "height"]),
        ("Color Type", &["imageDataInfo", "colorInfo", "type"]),
        ("Color Bit", &["imageDataInfo", "colorInfo", "bit"]),
        (
            "EffectiveBit Depth",
            &["imageDataInfo", "effectiveBit", "depth"],
        ),
        (
            "EffectiveBit Side",
            &["imageDataInfo", "effectiveBit", "side"],
        ),
        ("File Format", &["imageFileInfo", "fileFormat"]),
        ("Camera Type", &["deviceInfo", "deviceName"]),
    ]
    .iter()
    .filter_map(|(key, path)| Some((key.to_string(), xml_text(xml, path)?.to_string())))
    .collect()
}

pub struct Mraw {
    path: PathBuf,
    file: File,
    info: FileInfo,
    bits: u32,
    significant_bits: u32,
    frame_bytes_on_disk: usize,
    meta: Vec<FrameMeta>,
    packed: Vec<u8>,
}

impl Mraw {
    /// Opens a .cih/.cihx (and the .mraw beside it) or a .mraw (and the header beside it).
    pub fn open(path: &Path) -> Result<Mraw, FootageError> {
        let mut head = [0u8; 4096];
        let n = File::open(path)
            .and_then(|mut f| super::read_up_to(&mut f, &mut head))
            .map_err(|e| err(path, format!("cannot open: {e}")))?;
        // A CIHX may open with a binary preamble longer than the bytes looked at.
        let named_header = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("cih") || e.eq_ignore_ascii_case("cihx"));
        let (header_path, mraw_path) = if is_header(&head[..n]) || named_header {
            let m = mraw_beside(path).ok_or_else(|| {
                err(path, "no .mraw beside this header: expected the frames in a file of the same name ending .mraw")
            })?;
            (path.to_path_buf(), m)
        } else {
            let h = header_beside(path).ok_or_else(|| {
                err(path, "no .cih or .cihx beside this .mraw: expected Photron's header in a file of the same name")
            })?;
            (h, path.to_path_buf())
        };
        let h = Header::read(&header_path)?;
        let need = |key: &str| {
            h.get(key).ok_or_else(|| {
                err(
                    &header_path,
                    format!("{key}: missing, expected it in a Photron header"),
                )
            })
        };
        let int = |key: &str| -> Result<i64, FootageError> {
            let v = need(key)?;
            v.parse::<i64>()
                .map_err(|_| err(&header_path, format!("{key}: {v:?} is not a whole number")))
        };
        let format = need("File Format")?;
        if !format.eq_ignore_ascii_case("mraw") {
            return Err(err(
                &header_path,
                format!("File Format: {format:?}, expected MRaw (other Photron formats are exported as images)"),
            ));
        }
        if let Some(t) = h.get("Color Type") {
            if !t.eq_ignore_ascii_case("mono") {
                return Err(err(
                    &header_path,
                    format!("Color Type: {t:?}, expected Mono (colour footage is not read)"),
                ));
            }
        }
        let bits = int("Color Bit")?;
        let (w, hgt) = check_size(
            &header_path,
            "Image Width/Image Height",
            int("Image Width")?,
            int("Image Height")?,
        )?;
        let frame_bytes_on_disk = match bits {
            8 => w as u64 * hgt as u64,
            16 => 2 * w as u64 * hgt as u64,
            12 if (w as u64 * hgt as u64).is_multiple_of(2) => 3 * w as u64 * hgt as u64 / 2,
            12 => {
                return Err(err(
                    &header_path,
                    format!(
                    "Color Bit: 12 with {w}×{hgt} px, expected an even number of pixels per frame"
                ),
                ))
            }
            b => {
                return Err(err(
                    &header_path,
                    format!("Color Bit: {b}, expected 8, 12 or 16"),
                ))
            }
        };
        let significant_bits = match (
            bits,
            h.get("EffectiveBit Depth"),
            h.get("EffectiveBit Side"),
        ) {
            (16, Some(d), side) => {
                let d: u32 = d.parse().map_err(|_| {
                    err(
                        &header_path,
                        format!("EffectiveBit Depth: {d:?} is not a whole number"),
                    )
                })?;
                // Higher: the significant bits are already the top ones.
                if side.is_some_and(|s| s.eq_ignore_ascii_case("higher")) || !(1..=16).contains(&d)
                {
                    16
                } else {
                    d
                }
            }
            (b, _, _) => b as u32,
        };
        let rate: f64 = {
            let v = need("Record Rate(fps)")?;
            v.parse()
                .ok()
                .filter(|r: &f64| r.is_finite() && *r > 0.0)
                .ok_or_else(|| {
                    err(
                        &header_path,
                        format!("Record Rate(fps): {v:?}, expected a positive number"),
                    )
                })?
        };
        let total = int("Total Frame")?;
        let mut file =
            File::open(&mraw_path).map_err(|e| err(&mraw_path, format!("cannot open: {e}")))?;
        let len = file
            .metadata()
            .map_err(|e| err(&mraw_path, format!("cannot read: {e}")))?
            .len();
        let n = check_frames(
            &mraw_path,
            &format!("{} (Total Frame)", file_name(&header_path)),
            u64::try_from(total).unwrap_or(0),
            len / frame_bytes_on_disk,
        )?;
        let start = h.get("Start Frame").and_then(|v| v.parse::<i64>().ok());
        let exposure_s = h.get("Shutter Speed(s)").and_then(parse_shutter);
        let mut notes = Vec::new();
        let container = if bits == 8 { 8 } else { 16 };
        if significant_bits < container {
            notes.push(format!(
                "{significant_bits}-bit pixels scaled ×{} to the 16-bit range",
                1u32 << (16 - significant_bits)
            ));
        }
        // Nothing else reads the .mraw's own few bytes: one read checks that it opens.
        let mut probe = [0u8; 1];
        read_at(&mut file, &mraw_path, 0, &mut probe, "frame 0")?;
        let info = FileInfo {
            kind: "mraw",
            name: file_name(&mraw_path),
            width: w,
            height: hgt,
            bytes_per_pixel: if bits == 8 { 1 } else { 2 },
            frame_rate_hz: Some(rate),
            timing: Timing::Rate,
            trigger_frame: start.map(|s| -s).filter(|t| (0..n as i64).contains(t)),
            first_frame_number: start,
            exposure_s,
            header: h.fields.clone(),
            notes,
        };
        Ok(Mraw {
            path: mraw_path,
            file,
            info,
            bits: bits as u32,
            significant_bits,
            frame_bytes_on_disk: frame_bytes_on_disk as usize,
            meta: rate_meta(n, rate),
            packed: Vec::new(),
        })
    }
}

/// "1/20000", "0.00005" or "50 us" style shutter values, s.
fn parse_shutter(v: &str) -> Option<f64> {
    let s = if let Some((a, b)) = v.split_once('/') {
        a.trim().parse::<f64>().ok()? / b.trim().parse::<f64>().ok()?
    } else {
        v.trim().parse::<f64>().ok()?
    };
    (s.is_finite() && s > 0.0).then_some(s)
}

impl FrameFile for Mraw {
    fn info(&self) -> &FileInfo {
        &self.info
    }
    fn frames(&self) -> &[FrameMeta] {
        &self.meta
    }
    fn read(&mut self, i: usize, buf: &mut Vec<u8>) -> Result<(), FootageError> {
        let at = i as u64 * self.frame_bytes_on_disk as u64;
        let what = format!("frame {i}");
        match self.bits {
            12 => {
                self.packed.resize(self.frame_bytes_on_disk, 0);
                read_at(&mut self.file, &self.path, at, &mut self.packed, &what)?;
                buf.clear();
                buf.reserve(self.frame_bytes_on_disk / 3 * 4);
                for c in self.packed.chunks_exact(3) {
                    let (b0, b1, b2) = (u16::from(c[0]), u16::from(c[1]), u16::from(c[2]));
                    let p0 = (b0 << 4) | (b1 >> 4);
                    let p1 = ((b1 & 0x0f) << 8) | b2;
                    buf.extend_from_slice(&(p0 << 4).to_le_bytes());
                    buf.extend_from_slice(&(p1 << 4).to_le_bytes());
                }
                Ok(())
            }
            _ => {
                buf.resize(self.frame_bytes_on_disk, 0);
                read_at(&mut self.file, &self.path, at, buf, &what)?;
                if self.bits == 16 {
                    super::widen_le16(buf, self.significant_bits);
                }
                Ok(())
            }
        }
    }
}

/// Writes a session as `OUT.mraw` and `OUT.cih` (8-bit, or 16-bit with 16 significant bits):
/// Photron's viewers and pyMRAW open it. The frame rate is the session's; its device times are
/// not kept (an MRAW has none). Returns the frames written.
pub fn export(session: &mut SessionReader, out: &Path) -> Result<usize, FootageError> {
    let mraw = out.with_extension("mraw");
    let cih = out.with_extension("cih");
    let n = session.frames.len();
    let bits = 8 * session.bytes_per_pixel;
    let start = session
        .manifest
        .trigger
        .fired_in_frame
        .map_or(0, |k| -(k as i64));
    super::write_whole(&mraw, |w| {
        let mut buf = Vec::new();
        for i in 0..n {
            session
                .read_frame(i, &mut buf)
                .map_err(|e| std::io::Error::other(e.to_string()))?;
            w.write_all(&buf)?;
        }
        Ok(())
    })?;
    let text = cih_text(
        session.width,
        session.height,
        bits,
        session.manifest.camera.frame_rate_hz,
        n,
        start,
    );
    super::write_whole(&cih, |w| w.write_all(text.as_bytes()))?;
    Ok(n)
}

/// A CIH header for `n` frames.
pub fn cih_text(
    width: u32,
    height: u32,
    bits: usize,
    rate_hz: f64,
    n: usize,
    start: i64,
) -> String {
    let effective = bits;
    format!(
        "#Camera Information Header\nRecord Rate(fps) : {rate_hz}\nTotal Frame : {n}\nOriginal Total Frame : {n}\nStart Frame : {start}\nImage Width : {width}\nImage Height : {height}\nColor Type : Mono\nColor Bit : {bits}\nFile Format : MRaw\nEffectiveBit Depth : {effective}\nEffectiveBit Side : Lower\nComment Text : written by impactcam\n\n"
    )
}

/// Writes raw frames (already in the file's layout) and a CIH: for tests.
pub fn write(
    out: &Path,
    width: u32,
    height: u32,
    bits: usize,
    rate_hz: f64,
    start: i64,
    frames: &[Vec<u8>],
) -> Result<(), FootageError> {
    super::write_whole(&out.with_extension("mraw"), |w| {
        frames.iter().try_for_each(|f| w.write_all(f))
    })?;
    let text = cih_text(width, height, bits, rate_hz, frames.len(), start);
    super::write_whole(&out.with_extension("cih"), |w| w.write_all(text.as_bytes()))
}
