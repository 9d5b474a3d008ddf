//! A session exported as a multi-page greyscale TIFF for Fiji/ImageJ, with ImageJ's description
//! (frame count and interval) so that Fiji shows time in seconds. Reading TIFF stacks is
//! `footage::tiff_stack`.

use super::{SessionError, SessionReader};
use std::fs::File;
use std::io::BufWriter;
use std::path::Path;
use tiff::encoder::{colortype, TiffEncoder};
use tiff::tags::Tag;

fn fmt_err(path: &Path, message: String) -> SessionError {
    SessionError::Format {
        path: path.to_path_buf(),
        message,
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
    let description = imagej_description(session);
    for i in 0..session.frames.len() {
        session.read_frame(i, &mut buf)?;
        // ImageJ reads its description from the first page only.
        let first = (i == 0).then_some(description.as_str());
        let r = if session.bytes_per_pixel == 1 {
            write_page::<colortype::Gray8, _>(&mut enc, w, h, &buf, first)
        } else {
            let px: Vec<u16> = buf
                .chunks_exact(2)
                .map(|c| u16::from_le_bytes([c[0], c[1]]))
                .collect();
            write_page::<colortype::Gray16, _>(&mut enc, w, h, &px, first)
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

/// ImageJ's description of a time series: every page a frame, `finterval` seconds apart (the
/// session's frame rate), `unit` the pixel (the views' scales differ, so no spatial unit).
fn imagej_description(session: &SessionReader) -> String {
    let n = session.frames.len();
    let rate = session.manifest.camera.frame_rate_hz;
    format!(
        "ImageJ=1.11a\nimages={n}\nframes={n}\nfinterval={}\ntunit=s\nunit=pixel\nloop=false\n",
        1.0 / rate
    )
}

/// One page, with the ImageJ description on the first.
fn write_page<C, W>(
    enc: &mut TiffEncoder<W>,
    w: u32,
    h: u32,
    data: &[C::Inner],
    description: Option<&str>,
) -> tiff::TiffResult<()>
where
    C: colortype::ColorType,
    [C::Inner]: tiff::encoder::TiffValue,
    W: std::io::Write + std::io::Seek,
{
    let mut image = enc.new_image::<C>(w, h)?;
    if let Some(d) = description {
        image.encoder().write_tag(Tag::ImageDescription, d)?;
    }
    image.write_data(data)
}
