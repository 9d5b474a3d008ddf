//! `impactcam import` and `impactcam export`: another camera's file becomes a session (its frames
//! copied losslessly as the reader gives them, its own metadata in the manifest's `imported`),
//! so that `replay`, the page's viewer and campaigns work on it as on a recording; and a
//! session is written out as TIFF, MRAW or FMF.

use super::{err, FootageError, FrameFile, Timing};
use crate::config::{Config, PixelFormat};
use crate::session::CameraInfo;
use crate::session::{FrameMeta, ManifestTrigger, SessionReader, SessionWriter, Status};
use serde_json::json;
use std::path::{Path, PathBuf};

/// Frames copied per write (pixels, then their index lines in one write).
const BATCH_FRAMES: usize = 32;

/// What an import made.
pub struct Imported {
    pub session: PathBuf,
    pub frames: usize,
    pub kind: &'static str,
    pub width: u32,
    pub height: u32,
    pub frame_rate_hz: f64,
}

/// Imports `file` as the new session directory `out`. `config` (possibly unvalidated, see
/// `Config::load_unchecked`) describes the rig; without it the embedded default. Its camera size
/// and, where the file states one, its rate are the file's. The session appears whole or not at
/// all: it is written under a temporary name beside `out` and renamed at the end.
pub fn import(file: &Path, out: &Path, config: Option<&Config>) -> Result<Imported, FootageError> {
    if out.exists() {
        return Err(err(
            out,
            "already exists, expected a new directory for the session",
        ));
    }
    let mut base = config.cloned().unwrap_or_else(Config::default_config);
    let mut src = super::open(file, Some(base.camera.frame_rate_hz))?;
    let info = src.info().clone();
    let rate = info.frame_rate_hz.unwrap_or(base.camera.frame_rate_hz);
    // The session's config describes what it holds: the file's frames, no pre-trigger ring
    // (nothing was recorded here), the file's pixel format; then validated like any.
    base.recording.frames = u32::try_from(src.len()).unwrap_or(u32::MAX);
    base.recording.pre_trigger_frames = 0;
    base.camera.pixel_format = if info.bytes_per_pixel == 1 {
        PixelFormat::Mono8
    } else {
        PixelFormat::Mono16
    };
    let cfg = base
        .for_footage(info.width, info.height, Some(rate))
        .map_err(|m| {
            err(
                file,
                format!(
                    "the config does not suit this footage ({}×{} px at {rate} frames/s): {m}",
                    info.width, info.height
                ),
            )
        })?;
    let camera = CameraInfo {
        backend: "import".into(),
        device: format!("{}:{}", info.kind, info.name),
        width: info.width,
        height: info.height,
        pixel_format: if info.bytes_per_pixel == 1 {
            PixelFormat::Mono8
        } else {
            PixelFormat::Mono16
        },
        frame_rate_hz: rate,
    };
    let trigger_frame = info.trigger_frame.and_then(|k| usize::try_from(k).ok());
    let trigger = ManifestTrigger {
        backend: "none".into(),
        port: None,
        protocol: None,
        channel: None,
        pulse_ms: 0.0,
        fired_at_ns: trigger_frame.map(|k| src.meta(k).timestamp_ns),
        fired_in_frame: trigger_frame.map(|k| k as u64),
    };
    let final_name = out
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .ok_or_else(|| err(out, "expected a directory name for the session"))?;
    let tmp = out.with_file_name(format!(".{final_name}.importing-{}", std::process::id()));
    let session_err = |e: crate::session::SessionError| err(out, e.to_string());
    let mut w = SessionWriter::create_at(&tmp, &camera, trigger, &cfg).map_err(session_err)?;
    let copied = copy_frames(src.as_mut(), &mut w);
    let result = copied.map(|()| {
        let m = w.manifest_mut();
        m.id = final_name.clone();
        m.imported = Some(json!({
            "kind": info.kind,
            "file": info.name,
            "frame_rate_hz": info.frame_rate_hz,
            "timestamps": match info.timing {
                Timing::File => "the file's own frame times",
                Timing::Rate => "frame number / frame rate",
            },
            "trigger_frame": info.trigger_frame,
            "first_frame_number": info.first_frame_number,
            "exposure_s": info.exposure_s,
            "header": info.header.iter().cloned().collect::<std::collections::BTreeMap<_, _>>(),
            "notes": info.notes,
        }));
    });
    match result {
        Ok(()) => {
            let dir = w.finish(Status::Complete, None).map_err(session_err)?;
            std::fs::rename(&dir, out).map_err(|e| {
                let _ = std::fs::remove_dir_all(&dir);
                err(
                    out,
                    format!("cannot move the imported session into place: {e}"),
                )
            })?;
            Ok(Imported {
                session: out.to_path_buf(),
                frames: src.len(),
                kind: info.kind,
                width: info.width,
                height: info.height,
                frame_rate_hz: rate,
            })
        }
        Err(e) => {
            w.abandon();
            Err(e)
        }
    }
}

fn copy_frames(src: &mut dyn FrameFile, w: &mut SessionWriter) -> Result<(), FootageError> {
    let n = src.len();
    let mut bufs: Vec<Vec<u8>> = vec![Vec::new(); BATCH_FRAMES.min(n)];
    let mut start = 0;
    while start < n {
        let end = (start + BATCH_FRAMES).min(n);
        let metas: Vec<FrameMeta> = (start..end).map(|k| src.meta(k)).collect();
        for (k, buf) in (start..end).zip(bufs.iter_mut()) {
            src.read(k, buf)?;
        }
        let batch: Vec<(FrameMeta, &[u8])> = metas
            .iter()
            .zip(&bufs)
            .map(|(m, b)| (*m, b.as_slice()))
            .collect();
        w.append_batch(&batch)
            .map_err(|e| err(w.dir(), e.to_string()))?;
        start = end;
    }
    Ok(())
}

/// Formats `export` writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExportFormat {
    Tiff,
    Mraw,
    Fmf,
}

/// What an export wrote, and what its reader must know.
pub struct Exported {
    pub frames: usize,
    /// Set when the format loses something the session has (frame times across dropped frames).
    pub caveat: Option<String>,
}

/// Writes the session at `session` to `out` in `format`. MRAW writes `out` with the
/// extensions .mraw and .cih.
pub fn export(session: &Path, format: ExportFormat, out: &Path) -> Result<Exported, FootageError> {
    let mut reader = SessionReader::open(session).map_err(|e| err(session, e.to_string()))?;
    let dropped = crate::session::count_gaps(&reader.frames);
    let frames = match format {
        ExportFormat::Tiff => crate::session::tiff::export_session(&mut reader, out)
            .map_err(|e| err(out, e.to_string()))?,
        ExportFormat::Mraw => super::photron::export(&mut reader, out)?,
        ExportFormat::Fmf => super::fmf::export(&mut reader, out)?,
    };
    // TIFF and MRAW hold no frame times: a reader puts frame k at k / rate, so every frame after
    // a drop would be read as earlier than it was. FMF keeps each frame's time.
    let caveat = (dropped > 0 && format != ExportFormat::Fmf).then(|| {
        format!("the session dropped {dropped} frame(s); this format holds no frame times, so frames after a drop will be read as earlier than they were (FMF keeps the times)")
    });
    Ok(Exported { frames, caveat })
}
