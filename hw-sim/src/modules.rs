//! Relay modules in software, on pseudo-terminals, for tests and `impactcam bench relay`: each
//! speaks one protocol (LCUS, Numato, a generic one) on the master side of a PTY pair and logs
//! when the relay closed and opened, so what went over the wire, and when, can be checked.

use serialport::TTYPort;
use std::io::{Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    Lcus,
    Numato,
    /// Numato that echoes but never switches (a stuck relay).
    NumatoStuck,
    /// Generic protocol answering `reply` after each command.
    Generic {
        reply: u8,
    },
}

pub struct Emulator {
    path: String,
    log: Arc<Mutex<Vec<(Instant, bool)>>>,
    raw: Arc<Mutex<Vec<u8>>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    _slave: TTYPort,
}

impl Emulator {
    pub fn start(kind: Kind) -> std::io::Result<Emulator> {
        let (mut master, slave, path) = crate::pty::pair(Duration::from_millis(5))?;
        let log = Arc::new(Mutex::new(Vec::new()));
        let raw = Arc::new(Mutex::new(Vec::new()));
        let stop = Arc::new(AtomicBool::new(false));
        let (log2, raw2, stop2) = (log.clone(), raw.clone(), stop.clone());
        let thread = std::thread::spawn(move || {
            let mut pending: Vec<u8> = Vec::new();
            let mut state = false;
            let mut buf = [0u8; 256];
            while !stop2.load(Ordering::Relaxed) {
                let n = match master.read(&mut buf) {
                    Ok(n) => n,
                    Err(_) => continue,
                };
                let now = Instant::now();
                raw2.lock()
                    .unwrap_or_else(|p| p.into_inner())
                    .extend_from_slice(&buf[..n]);
                pending.extend_from_slice(&buf[..n]);
                let record = |closed: bool| {
                    log2.lock()
                        .unwrap_or_else(|p| p.into_inner())
                        .push((now, closed))
                };
                match kind {
                    Kind::Lcus => {
                        for heard in crate::lcus::decode(&mut pending) {
                            if let crate::lcus::Heard::Switch { closed, .. } = heard {
                                record(closed);
                            }
                        }
                    }
                    Kind::Generic { reply } => {
                        // on = "01", off = "00": one byte per command.
                        for b in pending.drain(..) {
                            record(b == 1);
                            let _ = master.write_all(&[reply]);
                        }
                    }
                    Kind::Numato | Kind::NumatoStuck => {
                        while let Some(end) = pending.iter().position(|&b| b == b'\r') {
                            let line: Vec<u8> = pending.drain(..=end).collect();
                            let cmd = String::from_utf8_lossy(&line[..line.len() - 1])
                                .trim()
                                .to_string();
                            let mut answer = format!("{cmd}\n\r");
                            if cmd.starts_with("relay on") && kind == Kind::Numato {
                                state = true;
                                record(true);
                            } else if cmd.starts_with("relay off") && kind == Kind::Numato {
                                state = false;
                                record(false);
                            } else if cmd.starts_with("relay read") {
                                answer.push_str(if state { "on\n\r" } else { "off\n\r" });
                            }
                            answer.push('>');
                            let _ = master.write_all(answer.as_bytes());
                        }
                    }
                }
            }
        });
        Ok(Emulator {
            path,
            log,
            raw,
            stop,
            thread: Some(thread),
            _slave: slave,
        })
    }

    pub fn path(&self) -> &str {
        &self.path
    }

    /// (when, closed) for every switch the module saw.
    pub fn switches(&self) -> Vec<(Instant, bool)> {
        std::thread::sleep(Duration::from_millis(20));
        self.log.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }

    /// Every byte that arrived.
    pub fn bytes(&self) -> Vec<u8> {
        self.raw.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }
}

impl Drop for Emulator {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
