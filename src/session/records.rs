//! The manifest's records of the devices: what a camera and a relay say of themselves. They
//! belong to the session format; the camera and trigger modules fill them in.

use crate::config::PixelFormat;
use serde::{Deserialize, Serialize};

/// The manifest's `camera` record.
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

/// The trigger as its backend describes it (the manifest's `trigger` adds the pulse).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct TriggerInfo {
    pub backend: String,
    pub port: Option<String>,
    pub protocol: Option<String>,
    pub channel: Option<u8>,
}
