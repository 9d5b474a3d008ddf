//! Cameras: one trait for a frame source, one module per backend. The simulator is a backend
//! like any other, so the experiment runs the same code in tests and in the lab.
//!
//! This module owns opening a camera from the config and delivering frames with device frame ids
//! and timestamps. It does not buffer, record or interpret frames (that is `recorder` and
//! `analysis`).

#[cfg(feature = "aravis")]
pub mod aravis;
pub mod sim;
#[cfg(feature = "v4l")]
pub mod v4l;
pub mod v4l_format;

use crate::config::{CameraBackend, Config};
use std::time::Instant;

/// One frame as delivered by a camera.
pub struct Frame {
    /// Device frame counter; a gap means frames were lost.
    pub frame_id: u64,
    /// Device clock, ns (mid-exposure where the device says so).
    pub timestamp_ns: u64,
    /// Host clock when the frame reached us; maps host events (relay firing) onto the device
    /// clock.
    pub host_time: Instant,
    /// Row-major pixels, 1 or 2 bytes per pixel (little-endian).
    pub data: Vec<u8>,
}

/// What a camera is: the manifest's `camera` record (it belongs to the session format).
pub use crate::session::CameraInfo;

#[derive(Debug, thiserror::Error)]
pub enum CameraError {
    #[error("camera {backend}: cannot open: {message}")]
    Open { backend: String, message: String },
    #[error("camera disconnected: {0}")]
    Disconnected(String),
    #[error("camera: {0}")]
    Failed(String),
    #[error("camera backend {0:?} is not built into this binary (rebuild with `--features {0}`)")]
    NotBuilt(String),
}

/// A frame source. Blocking: `next_frame` waits for the next frame.
pub trait Camera: Send {
    fn info(&self) -> CameraInfo;
    fn start(&mut self) -> Result<(), CameraError>;
    /// The next frame, written into `buf` (reused to avoid allocation on the hot path).
    fn next_frame(&mut self, buf: Vec<u8>) -> Result<Frame, CameraError>;
    fn stop(&mut self) -> Result<(), CameraError>;
    /// Preview for setting the rig up (the daemon's live view), on or off. A real camera shows
    /// what it sees either way; the simulator shows the spheres held still in both views (where
    /// they fly shortly before impact), as a user holds them to focus and check the geometry,
    /// instead of waiting out of view in their tubes.
    fn set_preview(&mut self, _on: bool) {}
}

/// Opens the camera the config names. `lab` is the simulated lab when the rig is simulated.
pub fn open(
    cfg: &Config,
    lab: Option<&std::sync::Arc<hw_sim::SimLab>>,
) -> Result<Box<dyn Camera>, CameraError> {
    match cfg.camera.backend {
        CameraBackend::Sim => {
            let lab = lab.ok_or_else(|| CameraError::Open {
                backend: "sim".into(),
                message: "no simulated lab was set up".into(),
            })?;
            Ok(Box::new(sim::SimBackend::new(lab.clone(), &cfg.camera)))
        }
        #[cfg(feature = "aravis")]
        CameraBackend::Aravis => Ok(Box::new(aravis::AravisBackend::open(&cfg.camera)?)),
        #[cfg(not(feature = "aravis"))]
        CameraBackend::Aravis => Err(CameraError::NotBuilt("aravis".into())),
        #[cfg(feature = "v4l")]
        CameraBackend::V4l => Ok(Box::new(v4l::V4lBackend::open(&cfg.camera)?)),
        #[cfg(not(feature = "v4l"))]
        CameraBackend::V4l => Err(CameraError::NotBuilt("v4l".into())),
    }
}

/// One line per camera this binary can see: the simulator, Aravis devices (discovery, on every
/// interface: this sends GigE Vision broadcasts), V4L2 device nodes.
pub fn list() -> Vec<String> {
    let mut out = vec!["sim          the simulated lab (always available)".to_string()];
    #[cfg(feature = "aravis")]
    {
        // SAFETY: plain C calls; the returned strings are owned by aravis and copied at once.
        unsafe {
            aravis_sys::arv_update_device_list();
            let n = aravis_sys::arv_get_n_devices();
            for i in 0..n {
                let id = aravis_sys::arv_get_device_id(i);
                if !id.is_null() {
                    out.push(format!(
                        "aravis       {}",
                        std::ffi::CStr::from_ptr(id).to_string_lossy()
                    ));
                }
            }
            if n == 0 {
                out.push("aravis       no GenICam camera found".into());
            }
        }
    }
    #[cfg(not(feature = "aravis"))]
    out.push(
        "aravis       not built into this binary (GenICam cameras need --features aravis)".into(),
    );
    #[cfg(feature = "v4l")]
    {
        let mut nodes: Vec<String> = std::fs::read_dir("/dev")
            .map(|d| {
                d.filter_map(|e| e.ok())
                    .map(|e| e.path().display().to_string())
                    .filter(|p| p.starts_with("/dev/video"))
                    .collect()
            })
            .unwrap_or_default();
        nodes.sort();
        if nodes.is_empty() {
            out.push("v4l          no /dev/video* device".into());
        }
        out.extend(nodes.into_iter().map(|n| format!("v4l          {n}")));
    }
    #[cfg(not(feature = "v4l"))]
    out.push("v4l          not built into this binary (V4L2 cameras need --features v4l)".into());
    out
}
