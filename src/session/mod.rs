//! Sessions on disk: one directory per experiment. This module owns the format (documented in
//! docs/session-format.md): the manifest `session.json` (always replaced atomically), the frame
//! container `frames.bin` (fixed-size records, append-only, so a crash keeps its prefix), the
//! index `frames.idx` (one line per frame, written after the frame's pixels), the config snapshot
//! `config.toml`, and the analysis outputs. It knows nothing of cameras or analysis.

pub mod disk;
mod reader;
mod records;
pub mod tiff;

use crate::config::Config;
pub use reader::{parse_index, SessionReader, MAX_SIDE_PX};
pub use records::{CameraInfo, TriggerInfo};
use serde::{Deserialize, Serialize};
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

pub const SESSION_SCHEMA: &str = "impactcam.session/1";
pub const FRAMES_MAGIC: &[u8; 8] = b"ICAMFRM1";
pub const FRAMES_HEADER_BYTES: u64 = 32;

#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    #[error("{path}: {message}")]
    Io { path: PathBuf, message: String },
    #[error("{path}: {message}")]
    Format { path: PathBuf, message: String },
}

fn io_err(path: &Path, e: impl std::fmt::Display) -> SessionError {
    SessionError::Io {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    Recording,
    Complete,
    Incomplete,
    Failed,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct ManifestTrigger {
    pub backend: String,
    pub port: Option<String>,
    pub protocol: Option<String>,
    pub channel: Option<u8>,
    pub pulse_ms: f64,
    /// When the relay closed, on the camera clock (ns), mapped from the host clock through the
    /// arrival time of the latest frame.
    pub fired_at_ns: Option<u64>,
    /// The saved frame (by index) during whose period the relay closed.
    pub fired_in_frame: Option<u64>,
}

impl ManifestTrigger {
    pub fn new(info: &TriggerInfo, pulse_ms: f64) -> Self {
        ManifestTrigger {
            backend: info.backend.clone(),
            port: info.port.clone(),
            protocol: info.protocol.clone(),
            channel: info.channel,
            pulse_ms,
            fired_at_ns: None,
            fired_in_frame: None,
        }
    }
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Manifest {
    pub schema: String,
    pub id: String,
    pub status: Status,
    pub reason: Option<String>,
    pub software_version: String,
    pub created_utc: String,
    pub camera: CameraInfo,
    pub trigger: ManifestTrigger,
    pub frames_recorded: u64,
    pub frames_dropped: u64,
    pub config: Config,
    /// A session made by `impactcam import` from another camera's file: the file's format and
    /// name and its own metadata (header fields, trigger frame, exposure). Absent for a
    /// recording.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub imported: Option<serde_json::Value>,
}

/// One index line: where a frame sits and what the device said about it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameMeta {
    pub frame_id: u64,
    pub timestamp_ns: u64,
}

/// Frames lost between saved frames, from the device frame ids.
pub fn count_gaps(frames: &[FrameMeta]) -> u64 {
    frames
        .windows(2)
        .map(|w| {
            w[1].frame_id
                .saturating_sub(w[0].frame_id.saturating_add(1))
        })
        .sum()
}

/// Writes a session while it is recorded.
pub struct SessionWriter {
    dir: PathBuf,
    manifest: Manifest,
    frames: File,
    index: File,
    frame_bytes: usize,
}

/// "YYYYmmdd-HHMMSS" in UTC, from the system clock.
pub fn utc_stamp() -> (String, String) {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    let days = (secs / 86_400) as i64;
    let rem = secs % 86_400;
    // Civil-from-days (H. Hinnant).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    let (hh, mm, ss) = (rem / 3600, rem % 3600 / 60, rem % 60);
    (
        format!("{y:04}{m:02}{d:02}-{hh:02}{mm:02}{ss:02}"),
        format!("{y:04}-{m:02}-{d:02}T{hh:02}:{mm:02}:{ss:02}Z"),
    )
}

impl SessionWriter {
    /// Creates a new session directory under `parent` and writes the manifest (status
    /// "recording"), the config snapshot and the empty frame container.
    pub fn create(
        parent: &Path,
        camera: &CameraInfo,
        trigger: ManifestTrigger,
        config: &Config,
    ) -> Result<SessionWriter, SessionError> {
        std::fs::create_dir_all(parent).map_err(|e| io_err(parent, e))?;
        let (stamp, iso) = utc_stamp();
        let mut n = 1;
        let dir = loop {
            let d = parent.join(format!("{stamp}-{n:02}"));
            match std::fs::create_dir(&d) {
                Ok(()) => break d,
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && n < 999 => n += 1,
                Err(e) => return Err(io_err(&d, e)),
            }
        };
        // Nothing half-written is left behind: a session that cannot be set up completely is
        // removed (nothing has been fired yet, see recorder).
        match Self::fill(dir.clone(), iso, camera, trigger, config) {
            Ok(w) => Ok(w),
            Err(e) => {
                let _ = std::fs::remove_dir_all(&dir);
                Err(e)
            }
        }
    }

    /// Creates the session directory `dir` itself (which must not exist yet; its parent is
    /// created), as `create` does under a parent.
    pub fn create_at(
        dir: &Path,
        camera: &CameraInfo,
        trigger: ManifestTrigger,
        config: &Config,
    ) -> Result<SessionWriter, SessionError> {
        if let Some(parent) = dir.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(parent).map_err(|e| io_err(parent, e))?;
        }
        std::fs::create_dir(dir).map_err(|e| {
            if e.kind() == std::io::ErrorKind::AlreadyExists {
                io_err(
                    dir,
                    "already exists, expected a new directory for the session",
                )
            } else {
                io_err(dir, e)
            }
        })?;
        let (_, iso) = utc_stamp();
        match Self::fill(dir.to_path_buf(), iso, camera, trigger, config) {
            Ok(w) => Ok(w),
            Err(e) => {
                let _ = std::fs::remove_dir_all(dir);
                Err(e)
            }
        }
    }

    fn fill(
        dir: PathBuf,
        iso: String,
        camera: &CameraInfo,
        trigger: ManifestTrigger,
        config: &Config,
    ) -> Result<SessionWriter, SessionError> {
        let id = dir
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        // The daemon's token is a secret, and sessions are copied, shared and served by the
        // session viewer; replay does not need it.
        let mut redacted = config.clone();
        redacted.daemon.token = None;
        let config = &redacted;
        let cpath = dir.join("config.toml");
        File::create(&cpath)
            .and_then(|mut f| {
                f.write_all(config.to_toml().as_bytes())?;
                f.sync_all()
            })
            .map_err(|e| io_err(&cpath, e))?;
        let fpath = dir.join("frames.bin");
        let mut frames = File::create(&fpath).map_err(|e| io_err(&fpath, e))?;
        let mut header = Vec::with_capacity(FRAMES_HEADER_BYTES as usize);
        header.extend_from_slice(FRAMES_MAGIC);
        header.extend_from_slice(&camera.width.to_le_bytes());
        header.extend_from_slice(&camera.height.to_le_bytes());
        header.extend_from_slice(&(camera.pixel_format.bytes_per_pixel() as u32).to_le_bytes());
        header.resize(FRAMES_HEADER_BYTES as usize, 0);
        frames
            .write_all(&header)
            .and_then(|_| frames.sync_all())
            .map_err(|e| io_err(&fpath, e))?;
        let ipath = dir.join("frames.idx");
        let mut index = File::create(&ipath).map_err(|e| io_err(&ipath, e))?;
        index
            .write_all(b"frame_id,timestamp_ns\n")
            .and_then(|_| index.sync_all())
            .map_err(|e| io_err(&ipath, e))?;
        let manifest = Manifest {
            schema: SESSION_SCHEMA.into(),
            id,
            status: Status::Recording,
            reason: None,
            software_version: env!("CARGO_PKG_VERSION").into(),
            created_utc: iso,
            camera: camera.clone(),
            trigger,
            frames_recorded: 0,
            frames_dropped: 0,
            config: config.clone(),
            imported: None,
        };
        let w = SessionWriter {
            dir,
            manifest,
            frames,
            index,
            frame_bytes: camera.frame_bytes(),
        };
        w.write_manifest()?;
        disk::sync_dir(&w.dir).map_err(|e| io_err(&w.dir, e))?;
        Ok(w)
    }

    /// Reserves disk blocks for `frames` frames (and their index lines), so the recording
    /// cannot run out of space from its own writes. `finish` gives back what was not used.
    pub fn reserve(&mut self, frames: u64) -> Result<(), SessionError> {
        let fpath = self.dir.join("frames.bin");
        let bytes = (self.frame_bytes as u64)
            .checked_mul(frames)
            .and_then(|b| b.checked_add(FRAMES_HEADER_BYTES))
            .ok_or_else(|| io_err(&fpath, format!("{frames} frames overflow a file size")))?;
        disk::reserve(&self.frames, bytes).map_err(|e| {
            io_err(
                &fpath,
                format!("cannot reserve {bytes} bytes for {frames} frames: {e}"),
            )
        })
    }

    /// Removes a session that was set up but never fired (a preflight check failed).
    pub fn abandon(self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }

    /// The manifest as it stands.
    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    pub fn manifest_mut(&mut self) -> &mut Manifest {
        &mut self.manifest
    }

    /// Appends one frame: pixels first, then its index line, so an indexed frame is always
    /// complete on disk.
    pub fn append(&mut self, meta: FrameMeta, data: &[u8]) -> Result<(), SessionError> {
        self.append_batch(&[(meta, data)])
    }

    /// Appends frames in order: each frame's pixels, then the index entries of all those
    /// written, in one write — a frame counts only once both are on disk, and a burst of frames
    /// costs one index write instead of one per frame. If a frame's pixels fail, the frames
    /// before it are still indexed, and the error is returned.
    pub fn append_batch(&mut self, frames: &[(FrameMeta, &[u8])]) -> Result<(), SessionError> {
        let mut failed = None;
        let mut written = 0;
        for (meta, data) in frames {
            if data.len() != self.frame_bytes {
                failed = Some(SessionError::Format {
                    path: self.dir.join("frames.bin"),
                    message: format!(
                        "frame {} has {} bytes, expected {}",
                        meta.frame_id,
                        data.len(),
                        self.frame_bytes
                    ),
                });
                break;
            }
            if let Err(e) = self.frames.write_all(data) {
                failed = Some(io_err(&self.dir.join("frames.bin"), e));
                break;
            }
            written += 1;
        }
        let mut lines = String::with_capacity(32 * written);
        for (meta, _) in &frames[..written] {
            use std::fmt::Write as _;
            let _ = writeln!(lines, "{},{}", meta.frame_id, meta.timestamp_ns);
        }
        if written > 0 {
            self.index
                .write_all(lines.as_bytes())
                .map_err(|e| io_err(&self.dir.join("frames.idx"), e))?;
            self.manifest.frames_recorded += written as u64;
        }
        match failed {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }

    pub fn write_manifest(&self) -> Result<(), SessionError> {
        let text =
            serde_json::to_string_pretty(&self.manifest).map_err(|e| io_err(&self.dir, e))?;
        write_atomic(&self.dir.join("session.json"), text.as_bytes())
    }

    /// Gives back the reserved space the frames did not use, flushes frames to stable storage
    /// and writes the final manifest.
    pub fn finish(
        mut self,
        status: Status,
        reason: Option<String>,
    ) -> Result<PathBuf, SessionError> {
        let fpath = self.dir.join("frames.bin");
        let used = FRAMES_HEADER_BYTES + self.manifest.frames_recorded * self.frame_bytes as u64;
        self.frames
            .set_len(used)
            .and_then(|_| self.frames.sync_data())
            .map_err(|e| io_err(&fpath, e))?;
        self.index
            .sync_data()
            .map_err(|e| io_err(&self.dir.join("frames.idx"), e))?;
        self.manifest.status = status;
        self.manifest.reason = reason;
        self.write_manifest()?;
        Ok(self.dir)
    }
}

/// Write to a temporary file and rename over the target, so readers see old or new, never half.
/// The temporary name is unique to this process and call (two writers never share one), it is
/// removed when anything fails, and the directory is fsynced after the rename.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), SessionError> {
    static COUNTER: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let name = path
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = path.with_file_name(format!(".{name}.{}-{n}.tmp", std::process::id()));
    let written = File::create(&tmp)
        .and_then(|mut f| {
            f.write_all(bytes)?;
            f.sync_data()
        })
        .map_err(|e| io_err(path, e))
        .and_then(|_| std::fs::rename(&tmp, path).map_err(|e| io_err(path, e)));
    if let Err(e) = written {
        let _ = std::fs::remove_file(&tmp);
        return Err(e);
    }
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        disk::sync_dir(parent).map_err(|e| io_err(parent, e))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests;
