//! The simulated camera backend: hw-sim's camera behind the `Camera` trait.

use super::{Camera, CameraError, CameraInfo, Frame};
use crate::config::CameraConfig;
use std::sync::Arc;
use std::time::Instant;

pub struct SimBackend {
    /// Keeps the lab (its clock and relay) alive as long as its camera.
    _lab: Arc<hw_sim::SimLab>,
    camera: hw_sim::SimCamera,
    info: CameraInfo,
}

impl SimBackend {
    pub fn new(lab: Arc<hw_sim::SimLab>, cfg: &CameraConfig) -> SimBackend {
        let camera = hw_sim::SimCamera::new(lab.clone());
        SimBackend {
            _lab: lab,
            camera,
            info: CameraInfo {
                backend: "sim".into(),
                device: "hw-sim".into(),
                width: cfg.width,
                height: cfg.height,
                pixel_format: cfg.pixel_format,
                frame_rate_hz: cfg.frame_rate_hz,
            },
        }
    }
}

impl Camera for SimBackend {
    fn info(&self) -> CameraInfo {
        self.info.clone()
    }
    fn start(&mut self) -> Result<(), CameraError> {
        self.camera.start();
        Ok(())
    }
    fn next_frame(&mut self, buf: Vec<u8>) -> Result<Frame, CameraError> {
        let f = self
            .camera
            .next_frame(buf)
            .map_err(|e| CameraError::Disconnected(e.to_string()))?;
        Ok(Frame {
            frame_id: f.frame_id,
            timestamp_ns: f.timestamp_ns,
            host_time: Instant::now(),
            data: f.data,
        })
    }
    fn stop(&mut self) -> Result<(), CameraError> {
        self.camera.stop();
        Ok(())
    }
    fn set_preview(&mut self, on: bool) {
        self.camera.set_preview(on);
    }
}
