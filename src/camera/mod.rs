//! Cameras: one trait for a frame source, one module per backend. The simulator is a backend
//! like any other, so the experiment runs the same code in tests and in the lab.
//!
//! This module owns opening a camera from the config and delivering frames with device frame ids
//! and timestamps. It does not buffer, record or interpret frames (that is `recorder` and
//! `analysis`).

#[cfg(feature = "aravis")]
pub mod aravis;
pub mod sim;

use crate::config::{CameraBackend, Config, PixelFormat};
use serde::{Deserialize, Serialize};
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

/// What a camera is; also the manifest's `camera` record.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct CameraInfo {
    pub backend: String,
    pub device: String,
    pub width: u32,
    pub height: u32,
    pub pixel_format: PixelFormat,
    pub frame_rate_hz: f64,
}

impl CameraInfo {
    pub fn frame_bytes(&self) -> usize {
        self.width as usize * self.height as usize * self.pixel_format.bytes_per_pixel()
    }
}

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
    /// Ground truth for the given (frame id, timestamp ns) pairs — only a simulator knows it.
    fn ground_truth(&self, _frames: &[(u64, u64)]) -> Option<serde_json::Value> {
        None
    }
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
        CameraBackend::V4l => Err(CameraError::NotBuilt("v4l".into())),
    }
}
