//! Serial relay modules, three protocols behind one `SerialRelay`:
//! - `lcus` (LCUS/CH340 boards): `[0xA0, channel, state, sum]`, state 1 = closed, sum the low
//!   byte of the first three, 9600 8N1. The board does not answer; a write error is the only
//!   failure visible.
//! - `numato` (Numato Lab USB relay boards): ASCII `relay on N\r` / `relay off N\r`, echoed, then
//!   a `>` prompt. After each switch the board is asked `relay read N\r` and must answer the state
//!   just set, so a board that did not switch is an error.
//! - `generic`: configured bytes for on and off (`generic_on_hex`, `generic_off_hex`), and
//!   optionally the bytes the module answers (`generic_reply_hex`), checked after each switch.

use super::{Relay, TriggerError, TriggerInfo};
use crate::config::{parse_hex, RelayProtocol, TriggerConfig};
use serialport::SerialPort;
use std::io::{Read, Write};
use std::time::{Duration, Instant};

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

enum Protocol {
    Lcus,
    Numato,
    Generic {
        on: Vec<u8>,
        off: Vec<u8>,
        reply: Option<Vec<u8>>,
    },
}

pub struct SerialRelay {
    port: Box<dyn SerialPort>,
    path: String,
    channel: u8,
    protocol: Protocol,
    backend: &'static str,
}

const REPLY_TIMEOUT: Duration = Duration::from_millis(300);

impl SerialRelay {
    pub fn open(
        t: &TriggerConfig,
        path: &str,
        backend: &'static str,
    ) -> Result<SerialRelay, TriggerError> {
        let protocol = match t.protocol {
            RelayProtocol::Lcus => Protocol::Lcus,
            RelayProtocol::Numato => Protocol::Numato,
            RelayProtocol::Generic => {
                // Validated with the config; a bad value cannot reach here, but say so if it does.
                let hex = |v: &Option<String>, key: &str| {
                    v.as_deref()
                        .and_then(parse_hex)
                        .ok_or_else(|| TriggerError::Open {
                            port: path.into(),
                            message: format!(
                                "trigger.{key}: expected hex bytes such as \"A0 01 01 A2\""
                            ),
                        })
                };
                Protocol::Generic {
                    on: hex(&t.generic_on_hex, "generic_on_hex")?,
                    off: hex(&t.generic_off_hex, "generic_off_hex")?,
                    reply: t.generic_reply_hex.as_deref().and_then(parse_hex),
                }
            }
        };
        let port = serialport::new(path, t.baud_rate)
            .timeout(Duration::from_millis(50))
            .open()
            .map_err(|e| TriggerError::Open {
                port: path.into(),
                message: e.to_string(),
            })?;
        let mut r = SerialRelay {
            port,
            path: path.into(),
            channel: t.channel,
            protocol,
            backend,
        };
        // A module may power up (or be left by a crashed run) closed: start from a known state.
        r.set_closed(false)?;
        Ok(r)
    }

    fn io(&self, message: String) -> TriggerError {
        TriggerError::Io {
            port: self.path.clone(),
            message,
        }
    }

    fn send(&mut self, bytes: &[u8]) -> Result<(), TriggerError> {
        self.port
            .write_all(bytes)
            .and_then(|_| self.port.flush())
            .map_err(|e| self.io(e.to_string()))
    }

    /// Reads until `done` says the answer is complete, or the timeout.
    fn read_until(&mut self, done: &dyn Fn(&[u8]) -> bool) -> Result<Vec<u8>, TriggerError> {
        let mut got = Vec::new();
        let start = Instant::now();
        let mut buf = [0u8; 64];
        while !done(&got) {
            if start.elapsed() > REPLY_TIMEOUT {
                return Err(self.io(format!(
                    "no complete answer within {} ms (got {:?})",
                    REPLY_TIMEOUT.as_millis(),
                    String::from_utf8_lossy(&got)
                )));
            }
            match self.port.read(&mut buf) {
                Ok(n) => got.extend_from_slice(&buf[..n]),
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
                Err(e) => return Err(self.io(e.to_string())),
            }
        }
        Ok(got)
    }

    fn numato(&mut self, command: &str) -> Result<String, TriggerError> {
        self.send(format!("{command}\r").as_bytes())?;
        let answer = self.read_until(&|g| g.contains(&b'>'))?;
        let text = String::from_utf8_lossy(&answer).into_owned();
        if !text.contains(command) {
            return Err(self.io(format!(
                "sent {command:?}, the module answered {text:?} (expected the command echoed)"
            )));
        }
        Ok(text)
    }
}

impl Relay for SerialRelay {
    fn set_closed(&mut self, closed: bool) -> Result<(), TriggerError> {
        match &self.protocol {
            Protocol::Lcus => {
                let frame = lcus_frame(self.channel, closed);
                self.send(&frame)
            }
            Protocol::Numato => {
                let state = if closed { "on" } else { "off" };
                self.numato(&format!("relay {state} {}", self.channel))?;
                let read = self.numato(&format!("relay read {}", self.channel))?;
                let after_echo = read
                    .split(&format!("relay read {}", self.channel))
                    .nth(1)
                    .unwrap_or("");
                if !after_echo.contains(state) {
                    return Err(self.io(format!(
                        "relay {} should be {state}, the module reports {:?}",
                        self.channel,
                        after_echo.trim()
                    )));
                }
                Ok(())
            }
            Protocol::Generic { on, off, reply } => {
                let (bytes, reply) = (if closed { on.clone() } else { off.clone() }, reply.clone());
                self.send(&bytes)?;
                if let Some(expected) = reply {
                    let got = self.read_until(&|g| g.len() >= expected.len())?;
                    if got[..expected.len()] != expected[..] {
                        return Err(
                            self.io(format!("expected reply {expected:02X?}, got {got:02X?}"))
                        );
                    }
                }
                Ok(())
            }
        }
    }

    fn info(&self) -> TriggerInfo {
        let protocol = match self.protocol {
            Protocol::Lcus => "lcus",
            Protocol::Numato => "numato",
            Protocol::Generic { .. } => "generic",
        };
        TriggerInfo {
            backend: self.backend.into(),
            port: Some(self.path.clone()),
            protocol: Some(protocol.into()),
            channel: Some(self.channel),
        }
    }
}

impl Drop for SerialRelay {
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
    fn hex_parsing() {
        assert_eq!(parse_hex("A0 01 0x01 a2"), Some(vec![0xA0, 1, 1, 0xA2]));
        assert_eq!(parse_hex("A0 zz"), None);
    }

    use crate::trigger::{CameraLive, Trigger};
    use hw_sim::modules::{Emulator, Kind};
    use std::sync::atomic::AtomicBool;
    use std::sync::Arc;

    fn config(protocol: RelayProtocol, channel: u8) -> TriggerConfig {
        TriggerConfig {
            protocol,
            channel,
            ..TriggerConfig::default()
        }
    }

    fn pulse(relay: SerialRelay, ms: f64) {
        let t = Trigger::new(Box::new(relay), ms, 500.0);
        t.fire(&CameraLive::confirmed(3), Arc::new(AtomicBool::new(false)))
            .unwrap()
            .finish()
            .unwrap();
    }

    #[test]
    fn lcus_bytes_on_the_wire_and_pulse_timing() {
        let emu = Emulator::start(Kind::Lcus).unwrap();
        let relay =
            SerialRelay::open(&config(RelayProtocol::Lcus, 1), emu.path(), "serial").unwrap();
        pulse(relay, 40.0);
        // Opened at start, closed, opened by the pulse, opened again when the relay is dropped.
        let s = emu.switches();
        assert_eq!(
            emu.bytes(),
            [
                lcus_frame(1, false),
                lcus_frame(1, true),
                lcus_frame(1, false),
                lcus_frame(1, false)
            ]
            .concat()
        );
        let held = s[2].0 - s[1].0;
        // The wire adds a little on each edge; the pulse is never shorter than a few ms less.
        assert!(
            held >= Duration::from_millis(35) && held < Duration::from_millis(500),
            "{held:?}"
        );
    }

    #[test]
    fn numato_switches_and_verifies_the_state() {
        let emu = Emulator::start(Kind::Numato).unwrap();
        let relay =
            SerialRelay::open(&config(RelayProtocol::Numato, 0), emu.path(), "serial").unwrap();
        pulse(relay, 20.0);
        let text = String::from_utf8_lossy(&emu.bytes()).into_owned();
        assert!(
            text.contains("relay on 0\r")
                && text.contains("relay off 0\r")
                && text.contains("relay read 0\r"),
            "{text:?}"
        );
        assert_eq!(emu.switches().last().map(|s| s.1), Some(false));
    }

    #[test]
    fn a_stuck_numato_relay_is_an_error_and_the_relay_is_told_to_open() {
        let emu = Emulator::start(Kind::NumatoStuck).unwrap();
        let mut relay =
            SerialRelay::open(&config(RelayProtocol::Numato, 2), emu.path(), "serial").unwrap();
        let e = relay.set_closed(true).unwrap_err().to_string();
        assert!(e.contains("should be on"), "{e}");
        drop(relay);
        assert!(
            String::from_utf8_lossy(&emu.bytes()).ends_with("relay read 2\r"),
            "opened on drop and checked"
        );
    }

    #[test]
    fn generic_protocol_checks_the_reply() {
        let emu = Emulator::start(Kind::Generic { reply: 0x55 }).unwrap();
        let mut cfg = config(RelayProtocol::Generic, 1);
        cfg.generic_on_hex = Some("01".into());
        cfg.generic_off_hex = Some("00".into());
        cfg.generic_reply_hex = Some("55".into());
        let relay = SerialRelay::open(&cfg, emu.path(), "serial").unwrap();
        pulse(relay, 10.0);
        assert_eq!(
            emu.switches().iter().map(|s| s.1).collect::<Vec<_>>(),
            vec![false, true, false, false]
        );
        let emu2 = Emulator::start(Kind::Generic { reply: 0x00 }).unwrap();
        let e = SerialRelay::open(&cfg, emu2.path(), "serial")
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("expected reply"), "{e}");
    }

    #[test]
    fn a_busy_port_is_refused() {
        let emu = Emulator::start(Kind::Lcus).unwrap();
        let _first =
            SerialRelay::open(&config(RelayProtocol::Lcus, 1), emu.path(), "serial").unwrap();
        let e = SerialRelay::open(&config(RelayProtocol::Lcus, 1), emu.path(), "serial")
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains(emu.path()), "{e}");
    }

    #[test]
    fn missing_port_is_a_clear_error() {
        let t = TriggerConfig::default();
        let e = SerialRelay::open(&t, "/dev/does-not-exist-relay", "serial")
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("/dev/does-not-exist-relay"), "{e}");
    }
}
