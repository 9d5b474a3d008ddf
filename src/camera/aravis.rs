//! GenICam cameras (GigE Vision, USB3 Vision) through Aravis — the `aravis` cargo feature, over
//! Debian's libaravis 0.8. Streams with a pool of buffers; keeps the device's frame ids
//! (unwrapping the 16-bit GigE counter) and timestamps; a buffer that arrives incomplete or
//! failed is dropped and shows as a gap in the ids; no frame for a second is a disconnect.
//!
//! Devices named `Fake…` are Aravis's in-process fake camera: for those the GigE and USB3
//! interfaces are disabled before any discovery, so opening one sends nothing on the network.

use super::{Camera, CameraError, CameraInfo, Frame};
use crate::config::{CameraConfig, CameraTrigger, PixelFormat};
use aravis::glib::prelude::Cast;
use aravis::prelude::*;
use aravis::{BufferStatus, Stream};
use std::time::Instant;

const BUFFERS: usize = 32;
const FRAME_TIMEOUT_US: u64 = 1_000_000;

pub struct AravisBackend {
    camera: aravis::Camera,
    stream: Option<Stream>,
    info: CameraInfo,
    payload: usize,
    id_base: u64,
    last_raw_id: Option<u64>,
    software_trigger: bool,
}

fn open_err(message: String) -> CameraError {
    CameraError::Open {
        backend: "aravis".into(),
        message,
    }
}

fn glib_err(what: &str) -> impl Fn(aravis::glib::Error) -> CameraError + '_ {
    move |e| open_err(format!("{what}: {e}"))
}

impl AravisBackend {
    pub fn open(cfg: &CameraConfig) -> Result<AravisBackend, CameraError> {
        if cfg.device.starts_with("Fake") {
            // SAFETY: plain C calls with static NUL-terminated names; aravis copies nothing.
            unsafe {
                aravis_sys::arv_disable_interface(c"GigEVision".as_ptr());
                aravis_sys::arv_disable_interface(c"USB3Vision".as_ptr());
                aravis_sys::arv_enable_interface(c"Fake".as_ptr());
            }
        }
        let name = (!cfg.device.is_empty()).then_some(cfg.device.as_str());
        let camera = aravis::Camera::new(name)
            .map_err(|e| open_err(format!("device {:?}: {e}", cfg.device)))?;
        let format = match cfg.pixel_format {
            PixelFormat::Mono8 => aravis::PixelFormat::MONO_8,
            PixelFormat::Mono16 => aravis::PixelFormat::MONO_16,
        };
        camera
            .set_pixel_format(format)
            .map_err(glib_err("pixel format"))?;
        camera
            .set_region(0, 0, cfg.width as i32, cfg.height as i32)
            .map_err(glib_err("region"))?;
        camera
            .set_frame_rate(cfg.frame_rate_hz)
            .map_err(glib_err("frame rate"))?;
        if let Some(us) = cfg.exposure_us {
            camera.set_exposure_time(us).map_err(glib_err("exposure"))?;
        }
        let (_, _, w, h) = camera.region().map_err(glib_err("region"))?;
        if (w as u32, h as u32) != (cfg.width, cfg.height) {
            return Err(open_err(format!(
                "camera gave a {w}×{h} region, camera.width/height ask for {}×{}",
                cfg.width, cfg.height
            )));
        }
        let rate = camera.frame_rate().map_err(glib_err("frame rate"))?;
        if (rate - cfg.frame_rate_hz).abs() > 0.01 * cfg.frame_rate_hz {
            return Err(open_err(format!(
                "camera runs at {rate} Hz, camera.frame_rate_hz asks for {}",
                cfg.frame_rate_hz
            )));
        }
        match cfg.trigger_mode {
            CameraTrigger::FreeRun => camera.clear_triggers().map_err(glib_err("free-run"))?,
            CameraTrigger::Software => camera
                .set_trigger("Software")
                .map_err(glib_err("software trigger"))?,
            CameraTrigger::Hardware => camera
                .set_trigger(&cfg.trigger_line)
                .map_err(glib_err("camera.trigger_line"))?,
        }
        if cfg.trigger_mode == CameraTrigger::Software {
            // The fake camera polls for software triggers 25 times a second unless told otherwise.
            if let Some(fake) = camera
                .device()
                .and_then(|d| d.downcast::<aravis::FakeDevice>().ok())
                .and_then(|d| d.fake_camera())
            {
                fake.set_trigger_frequency(10_000.0);
            }
        }
        let payload = camera.payload().map_err(glib_err("payload"))? as usize;
        let device = camera
            .device_id()
            .map(|s| s.to_string())
            .unwrap_or_else(|_| cfg.device.clone());
        Ok(AravisBackend {
            camera,
            stream: None,
            info: CameraInfo {
                backend: "aravis".into(),
                device,
                width: cfg.width,
                height: cfg.height,
                pixel_format: cfg.pixel_format,
                frame_rate_hz: rate,
            },
            payload,
            id_base: 0,
            last_raw_id: None,
            software_trigger: cfg.trigger_mode == CameraTrigger::Software,
        })
    }

    /// GigE Vision frame ids are 16-bit and skip 0: 65535 is followed by 1.
    fn extend_id(&mut self, raw: u64) -> u64 {
        if let Some(last) = self.last_raw_id {
            if raw <= last && last > 0xF000 {
                self.id_base += 0xFFFF;
            }
        }
        self.last_raw_id = Some(raw);
        self.id_base + raw
    }
}

impl Camera for AravisBackend {
    fn info(&self) -> CameraInfo {
        self.info.clone()
    }

    fn start(&mut self) -> Result<(), CameraError> {
        let stream = self
            .camera
            .create_stream()
            .map_err(|e| CameraError::Failed(format!("aravis stream: {e}")))?;
        for _ in 0..BUFFERS {
            stream.push_buffer(aravis::Buffer::new_allocate(self.payload));
        }
        self.camera
            .start_acquisition()
            .map_err(|e| CameraError::Failed(format!("aravis start: {e}")))?;
        self.stream = Some(stream);
        Ok(())
    }

    fn next_frame(&mut self, mut buf: Vec<u8>) -> Result<Frame, CameraError> {
        let need = self.info.frame_bytes();
        if self.software_trigger {
            self.camera
                .software_trigger()
                .map_err(|e| CameraError::Failed(format!("aravis software trigger: {e}")))?;
        }
        loop {
            let stream = self
                .stream
                .as_ref()
                .ok_or_else(|| CameraError::Failed("aravis: not started".into()))?;
            let Some(buffer) = stream.timeout_pop_buffer(FRAME_TIMEOUT_US) else {
                return Err(CameraError::Disconnected(format!(
                    "aravis {}: no frame within {} ms",
                    self.info.device,
                    FRAME_TIMEOUT_US / 1000
                )));
            };
            if buffer.status() != BufferStatus::Success {
                // Lost on the wire: the frame id gap records it.
                stream.push_buffer(buffer);
                continue;
            }
            let (ptr, len) = buffer.data();
            if ptr.is_null() || len < need {
                stream.push_buffer(buffer);
                return Err(CameraError::Failed(format!(
                    "aravis: a buffer of {len} bytes, expected {need}"
                )));
            }
            buf.clear();
            // SAFETY: aravis owns `len` valid bytes at `ptr` until the buffer is pushed back.
            buf.extend_from_slice(unsafe { std::slice::from_raw_parts(ptr, need) });
            let (raw_id, ts) = (buffer.frame_id(), buffer.timestamp());
            stream.push_buffer(buffer);
            let frame_id = self.extend_id(raw_id);
            return Ok(Frame {
                frame_id,
                timestamp_ns: ts,
                host_time: Instant::now(),
                data: buf,
            });
        }
    }

    fn stop(&mut self) -> Result<(), CameraError> {
        let r = self
            .camera
            .stop_acquisition()
            .map_err(|e| CameraError::Failed(format!("aravis stop: {e}")));
        self.stream = None;
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fake(w: u32, h: u32, fps: f64) -> CameraConfig {
        CameraConfig {
            backend: crate::config::CameraBackend::Aravis,
            device: "Fake_1".into(),
            width: w,
            height: h,
            frame_rate_hz: fps,
            ..CameraConfig::default()
        }
    }

    #[test]
    fn fake_camera_streams_frames_with_rising_ids_and_timestamps() {
        let mut cam = AravisBackend::open(&fake(64, 64, 200.0)).unwrap();
        cam.start().unwrap();
        let mut last: Option<(u64, u64)> = None;
        let mut buf = Vec::new();
        for _ in 0..20 {
            let f = cam.next_frame(buf).unwrap();
            assert_eq!(f.data.len(), 64 * 64);
            if let Some((id, ts)) = last {
                assert!(f.frame_id > id && f.timestamp_ns > ts);
            }
            last = Some((f.frame_id, f.timestamp_ns));
            buf = f.data;
        }
        cam.stop().unwrap();
    }

    #[test]
    fn software_triggered_frames_arrive_one_per_trigger() {
        let mut c = fake(64, 64, 100.0);
        c.trigger_mode = CameraTrigger::Software;
        let mut cam = AravisBackend::open(&c).unwrap();
        cam.start().unwrap();
        let mut buf = Vec::new();
        let mut ids = Vec::new();
        for _ in 0..10 {
            let f = cam.next_frame(buf).unwrap();
            ids.push(f.frame_id);
            buf = f.data;
        }
        assert!(ids.windows(2).all(|w| w[1] > w[0]), "{ids:?}");
        cam.stop().unwrap();
    }

    #[test]
    fn an_unknown_device_is_a_clear_error() {
        let mut c = fake(64, 64, 100.0);
        c.device = "Fake_does_not_exist".into();
        let e = AravisBackend::open(&c).err().unwrap().to_string();
        assert!(e.contains("Fake_does_not_exist"), "{e}");
    }

    #[test]
    fn frame_ids_unwrap_the_16_bit_counter() {
        let mut cam = AravisBackend::open(&fake(64, 64, 100.0)).unwrap();
        let ids: Vec<u64> = [65533, 65534, 65535, 1, 2]
            .iter()
            .map(|&r| cam.extend_id(r))
            .collect();
        assert_eq!(ids, vec![65533, 65534, 65535, 65536, 65537]);
    }
}
