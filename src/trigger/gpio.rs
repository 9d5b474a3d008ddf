//! A relay (or solenoid driver) on a GPIO line, through the Linux GPIO character device
//! (`/dev/gpiochipN`, uAPI v2) — the `gpio` cargo feature. Closed = the line active; with
//! `gpio_active_low` the kernel inverts it, so "active" is a low level on the pin.
//!
//! This machine has no GPIO chip and cannot load gpio-sim: the logic behind `Relay` is tested
//! against a recording line, and opening a chip that is not there is tested for its error; the
//! device path itself is untested here.

use super::{Relay, TriggerError, TriggerInfo};
use crate::config::TriggerConfig;

/// One output line: what `GpioRelay` drives.
pub trait Line: Send {
    fn set_active(&mut self, active: bool) -> Result<(), String>;
}

struct CdevLine(gpiocdev::Request);

impl Line for CdevLine {
    fn set_active(&mut self, active: bool) -> Result<(), String> {
        let v = if active {
            gpiocdev::line::Value::Active
        } else {
            gpiocdev::line::Value::Inactive
        };
        self.0.set_lone_value(v).map_err(|e| e.to_string())
    }
}

pub struct GpioRelay {
    line: Box<dyn Line>,
    chip: String,
    offset: u32,
}

impl GpioRelay {
    /// Requests the line as an output, inactive (relay open) from the start.
    pub fn open(t: &TriggerConfig) -> Result<GpioRelay, TriggerError> {
        let mut b = gpiocdev::Request::builder();
        b.on_chip(t.gpio_chip.clone())
            .with_consumer("impactcam")
            .with_line(t.gpio_line);
        if t.gpio_active_low {
            b.as_active_low();
        }
        let req = b
            .as_output(gpiocdev::line::Value::Inactive)
            .request()
            .map_err(|e| TriggerError::Open {
                port: format!("{} line {}", t.gpio_chip, t.gpio_line),
                message: e.to_string(),
            })?;
        Ok(GpioRelay::with_line(
            Box::new(CdevLine(req)),
            &t.gpio_chip,
            t.gpio_line,
        ))
    }

    pub fn with_line(line: Box<dyn Line>, chip: &str, offset: u32) -> GpioRelay {
        GpioRelay {
            line,
            chip: chip.into(),
            offset,
        }
    }
}

impl Relay for GpioRelay {
    fn set_closed(&mut self, closed: bool) -> Result<(), TriggerError> {
        self.line
            .set_active(closed)
            .map_err(|message| TriggerError::Io {
                port: format!("{} line {}", self.chip, self.offset),
                message,
            })
    }

    fn info(&self) -> TriggerInfo {
        TriggerInfo {
            backend: "gpio".into(),
            port: Some(format!("{} line {}", self.chip, self.offset)),
            protocol: None,
            channel: None,
        }
    }
}

impl Drop for GpioRelay {
    fn drop(&mut self) {
        let _ = self.set_closed(false);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trigger::{CameraLive, Trigger};
    use std::sync::atomic::AtomicBool;
    use std::sync::{Arc, Mutex};

    struct Recorded(Arc<Mutex<Vec<bool>>>);
    impl Line for Recorded {
        fn set_active(&mut self, active: bool) -> Result<(), String> {
            self.0.lock().unwrap().push(active);
            Ok(())
        }
    }

    #[test]
    fn a_pulse_drives_the_line_active_then_inactive() {
        let log = Arc::new(Mutex::new(Vec::new()));
        let relay = GpioRelay::with_line(Box::new(Recorded(log.clone())), "/dev/gpiochip0", 17);
        let t = Trigger::new(Box::new(relay), 10.0, 100.0);
        t.fire(&CameraLive::confirmed(3), Arc::new(AtomicBool::new(false)))
            .unwrap()
            .finish()
            .unwrap();
        drop(t);
        assert_eq!(*log.lock().unwrap(), vec![true, false, false]);
    }

    #[test]
    fn a_missing_chip_is_a_clear_error() {
        let t = TriggerConfig {
            gpio_chip: "/dev/gpiochip-not-here".into(),
            gpio_line: 17,
            ..TriggerConfig::default()
        };
        let e = GpioRelay::open(&t).err().unwrap().to_string();
        assert!(e.contains("/dev/gpiochip-not-here line 17"), "{e}");
    }
}
