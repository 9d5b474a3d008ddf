//! Serial relay modules. The LCUS/CH340 binary protocol: `[0xA0, channel, state, sum]` with
//! state 1 = closed, 0 = open, and sum the low byte of the first three, at 9600 8N1. These modules
//! do not answer, so a write error is the only failure we can see.

use super::{Relay, TriggerError, TriggerInfo};
use serialport::SerialPort;
use std::io::Write;
use std::time::Duration;

/// The LCUS frame that sets `channel` closed or open.
pub fn lcus_frame(channel: u8, closed: bool) -> [u8; 4] {
    let state = u8::from(closed);
    [
        0xA0,
        channel,
        state,
        0xA0u8.wrapping_add(channel).wrapping_add(state),
    ]
}

pub struct LcusRelay {
    port: Box<dyn SerialPort>,
    path: String,
    channel: u8,
    backend: &'static str,
}

impl LcusRelay {
    pub fn open(
        path: &str,
        baud_rate: u32,
        channel: u8,
        backend: &'static str,
    ) -> Result<LcusRelay, TriggerError> {
        let port = serialport::new(path, baud_rate)
            .timeout(Duration::from_millis(200))
            .open()
            .map_err(|e| TriggerError::Open {
                port: path.into(),
                message: e.to_string(),
            })?;
        let mut r = LcusRelay {
            port,
            path: path.into(),
            channel,
            backend,
        };
        // A module may power up (or be left by a crashed run) closed: start from a known state.
        r.set_closed(false)?;
        Ok(r)
    }
}

impl Relay for LcusRelay {
    fn set_closed(&mut self, closed: bool) -> Result<(), TriggerError> {
        let frame = lcus_frame(self.channel, closed);
        self.port
            .write_all(&frame)
            .and_then(|_| self.port.flush())
            .map_err(|e| TriggerError::Io {
                port: self.path.clone(),
                message: e.to_string(),
            })
    }

    fn info(&self) -> TriggerInfo {
        TriggerInfo {
            backend: self.backend.into(),
            port: Some(self.path.clone()),
            protocol: Some("lcus".into()),
            channel: Some(self.channel),
        }
    }
}

impl Drop for LcusRelay {
    fn drop(&mut self) {
        let _ = self.set_closed(false);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lcus_frames_match_the_module_documentation() {
        assert_eq!(lcus_frame(1, true), [0xA0, 0x01, 0x01, 0xA2]);
        assert_eq!(lcus_frame(1, false), [0xA0, 0x01, 0x00, 0xA1]);
        assert_eq!(lcus_frame(2, true), [0xA0, 0x02, 0x01, 0xA3]);
    }

    #[test]
    fn missing_port_is_a_clear_error() {
        let e = LcusRelay::open("/dev/does-not-exist-relay", 9600, 1, "serial")
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("/dev/does-not-exist-relay"), "{e}");
    }
}
