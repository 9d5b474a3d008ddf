//! V4L2 cameras through the `v4l` crate — the `v4l` cargo feature (needs libclang-dev to build).
//! mmap streaming; the format is negotiated from what the device offers (`v4l_format::choose`)
//! at the configured size and frame interval; kernel sequence numbers are the frame ids, so
//! drops show as gaps; the kernel's timestamp is the device time.
//!
//! This machine has no /dev/video device and cannot load vivid or v4l2loopback: this code is
//! built in CI but its device path has never run here. `v4l_format` holds the parts that are
//! tested.

use super::v4l_format::{choose, extend_sequence, to_grey, Fourcc};
use super::{Camera, CameraError, CameraInfo, Frame};
use crate::config::CameraConfig;
use std::time::Instant;
use v4l::buffer::Type;
use v4l::io::traits::CaptureStream;
use v4l::video::Capture;

/// The mmap stream owns its buffers and a handle to the device; it is used by one thread at a
/// time (the acquisition thread the recorder moves the camera to).
struct SendStream(v4l::io::mmap::Stream<'static>);
// SAFETY: the stream is only ever used from the thread that owns the camera, never shared.
unsafe impl Send for SendStream {}

pub struct V4lBackend {
    device: v4l::Device,
    stream: Option<SendStream>,
    info: CameraInfo,
    fourcc: Fourcc,
    stride: usize,
    last_seq: Option<u64>,
}

fn open_err(message: String) -> CameraError {
    CameraError::Open {
        backend: "v4l".into(),
        message,
    }
}

impl V4lBackend {
    pub fn open(cfg: &CameraConfig) -> Result<V4lBackend, CameraError> {
        let path = if cfg.device.is_empty() {
            "/dev/video0"
        } else {
            cfg.device.as_str()
        };
        let device = v4l::Device::with_path(path).map_err(|e| open_err(format!("{path}: {e}")))?;
        let offered: Vec<[u8; 4]> = device
            .enum_formats()
            .map_err(|e| open_err(format!("{path}: cannot list formats: {e}")))?
            .iter()
            .map(|d| d.fourcc.repr)
            .collect();
        let fourcc = choose(&offered, cfg.pixel_format).ok_or_else(|| {
            open_err(format!(
                "{path} offers {:?}, none of GREY, Y16 or YUYV",
                offered
                    .iter()
                    .map(|c| String::from_utf8_lossy(c).into_owned())
                    .collect::<Vec<_>>()
            ))
        })?;
        let mut fmt = device
            .format()
            .map_err(|e| open_err(format!("{path}: {e}")))?;
        fmt.width = cfg.width;
        fmt.height = cfg.height;
        fmt.fourcc = v4l::FourCC::new(&fourcc.code());
        let fmt = device
            .set_format(&fmt)
            .map_err(|e| open_err(format!("{path}: cannot set format: {e}")))?;
        if (fmt.width, fmt.height) != (cfg.width, cfg.height) {
            return Err(open_err(format!(
                "{path} gives {}×{}, camera.width/height ask for {}×{}",
                fmt.width, fmt.height, cfg.width, cfg.height
            )));
        }
        let params = device
            .set_params(&v4l::video::capture::Parameters::with_fps(
                cfg.frame_rate_hz.round() as u32,
            ))
            .map_err(|e| open_err(format!("{path}: cannot set the frame interval: {e}")))?;
        let rate = params.interval.denominator as f64 / params.interval.numerator.max(1) as f64;
        Ok(V4lBackend {
            device,
            stream: None,
            info: CameraInfo {
                backend: "v4l".into(),
                device: path.into(),
                width: cfg.width,
                height: cfg.height,
                pixel_format: cfg.pixel_format,
                frame_rate_hz: rate,
            },
            fourcc,
            stride: fmt.stride as usize,
            last_seq: None,
        })
    }
}

impl Camera for V4lBackend {
    fn info(&self) -> CameraInfo {
        self.info.clone()
    }

    fn start(&mut self) -> Result<(), CameraError> {
        let stream = v4l::io::mmap::Stream::with_buffers(&self.device, Type::VideoCapture, 16)
            .map_err(|e| CameraError::Failed(format!("v4l stream: {e}")))?;
        self.stream = Some(SendStream(stream));
        Ok(())
    }

    fn next_frame(&mut self, mut buf: Vec<u8>) -> Result<Frame, CameraError> {
        let stream = self
            .stream
            .as_mut()
            .ok_or_else(|| CameraError::Failed("v4l: not started".into()))?;
        let (data, meta) = stream
            .0
            .next()
            .map_err(|e| CameraError::Disconnected(format!("v4l {}: {e}", self.info.device)))?;
        let (w, h) = (self.info.width as usize, self.info.height as usize);
        to_grey(
            data,
            self.fourcc,
            w,
            h,
            self.stride,
            self.info.pixel_format,
            &mut buf,
        )
        .ok_or_else(|| {
            CameraError::Failed(format!(
                "v4l: a {}-byte buffer is too short for {w}×{h}",
                data.len()
            ))
        })?;
        let frame_id = extend_sequence(self.last_seq, meta.sequence);
        self.last_seq = Some(frame_id);
        let timestamp_ns =
            meta.timestamp.sec as u64 * 1_000_000_000 + meta.timestamp.usec as u64 * 1000;
        Ok(Frame {
            frame_id,
            timestamp_ns,
            host_time: Instant::now(),
            data: buf,
        })
    }

    fn stop(&mut self) -> Result<(), CameraError> {
        self.stream = None;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_device_is_a_clear_error() {
        let cfg = CameraConfig {
            backend: crate::config::CameraBackend::V4l,
            device: "/dev/video-not-here".into(),
            ..CameraConfig::default()
        };
        let e = V4lBackend::open(&cfg).err().unwrap().to_string();
        assert!(e.contains("/dev/video-not-here"), "{e}");
    }
}
