//! The simulated relay module: a real pseudo-terminal whose far end speaks the LCUS/CH340
//! binary protocol (`A0 ch state sum`, 9600 8N1). impactcam opens the slave path like any serial
//! port; this side decodes what arrives and logs, on the lab clock, when the relay closed and
//! opened. The lab learns that the spheres were released only from this log.

use crate::clock::LabClock;
use serde::Serialize;
use serialport::TTYPort;
use std::io::Read;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

#[derive(Clone, Copy, Debug, Serialize, PartialEq)]
pub struct RelayEvent {
    /// Lab (= simulated camera) clock, s.
    pub time_s: f64,
    pub closed: bool,
}

#[derive(Debug, Default)]
pub struct RelayLog {
    pub events: Vec<RelayEvent>,
    /// Byte sequences that were not a valid LCUS frame for channel 1.
    pub bad_frames: u64,
}

pub struct SimRelay {
    port_path: String,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    // Held open so the pseudo-terminal stays alive when no client has it open.
    _slave: TTYPort,
}

impl SimRelay {
    pub fn spawn(clock: Arc<LabClock>, log: Arc<Mutex<RelayLog>>) -> std::io::Result<SimRelay> {
        let (mut master, slave, port_path) = crate::pty::pair(Duration::from_millis(20))?;
        let stop = Arc::new(AtomicBool::new(false));
        let stop2 = stop.clone();
        let thread = std::thread::Builder::new()
            .name("sim-relay".into())
            .spawn(move || {
                let mut pending: Vec<u8> = Vec::new();
                let mut buf = [0u8; 64];
                while !stop2.load(Ordering::Relaxed) {
                    match master.read(&mut buf) {
                        Ok(0) => std::thread::sleep(Duration::from_millis(1)),
                        Ok(n) => {
                            pending.extend_from_slice(&buf[..n]);
                            decode(&mut pending, &clock, &log);
                        }
                        Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
                        Err(_) => std::thread::sleep(Duration::from_millis(1)),
                    }
                }
            })?;
        Ok(SimRelay {
            port_path,
            stop,
            thread: Some(thread),
            _slave: slave,
        })
    }

    /// The serial device a client opens to drive this relay.
    pub fn port_path(&self) -> &str {
        &self.port_path
    }
}

/// The lab's relay is channel 1; a frame for another channel is as bad as garbage.
fn decode(pending: &mut Vec<u8>, clock: &LabClock, log: &Mutex<RelayLog>) {
    for heard in crate::lcus::decode(pending) {
        let Ok(mut l) = log.lock() else { continue };
        match heard {
            crate::lcus::Heard::Switch { channel: 1, closed } => l.events.push(RelayEvent {
                time_s: clock.now_s(),
                closed,
            }),
            _ => l.bad_frames += 1,
        }
    }
}

impl Drop for SimRelay {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
