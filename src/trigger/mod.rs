//! The trigger: "release the spheres" as a relay pulse of bounded length.
//!
//! This module is the only code that drives a relay. Its invariants: the relay is opened again
//! on every path (pulse elapsed, abort, error, panic, drop), it is never held closed longer than
//! `relay_pulse_ms_max`, and it cannot be fired without proof that the camera is delivering
//! frames (`CameraLive`, which only the recorder can create). A real relay is switched by the
//! relay guard (`guard`), a child process that opens it even when this process is killed.

#[cfg(feature = "gpio")]
pub mod gpio;
pub mod guard;
pub mod serial;

use crate::config::{Config, TriggerBackend};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

#[derive(Debug, thiserror::Error)]
pub enum TriggerError {
    #[error("relay on {port}: cannot open: {message}")]
    Open { port: String, message: String },
    #[error("relay on {port}: {message}")]
    Io { port: String, message: String },
    #[error("relay pulse of {requested_ms} ms refused: the maximum is {max_ms} ms (trigger.relay_pulse_ms_max)")]
    PulseTooLong { requested_ms: f64, max_ms: f64 },
}

/// What a relay is: the session format's record of it.
pub use crate::session::TriggerInfo;

/// A relay module: closes and opens one contact. Implementations do no timing.
pub trait Relay: Send {
    fn set_closed(&mut self, closed: bool) -> Result<(), TriggerError>;
    fn info(&self) -> TriggerInfo;
}

/// Proof that the camera is delivering frames; only the recorder creates one.
pub struct CameraLive {
    pub frames_seen: u64,
}

impl CameraLive {
    pub(crate) fn confirmed(frames_seen: u64) -> CameraLive {
        CameraLive { frames_seen }
    }
}

/// The config as the simulated module sees it: it speaks LCUS, whatever the config says for
/// real modules.
fn sim_trigger(t: &crate::config::TriggerConfig) -> crate::config::TriggerConfig {
    crate::config::TriggerConfig {
        protocol: crate::config::RelayProtocol::Lcus,
        ..t.clone()
    }
}

/// Opens a relay in this process: `backend` is "serial", "sim" (the simulator's PTY, always
/// LCUS) or "gpio".
pub(crate) fn open_direct(
    t: &crate::config::TriggerConfig,
    port: &str,
    backend: &str,
) -> Result<Box<dyn Relay>, TriggerError> {
    match backend {
        "serial" => Ok(Box::new(serial::SerialRelay::open(t, port, "serial")?)),
        "sim" => Ok(Box::new(serial::SerialRelay::open(&sim_trigger(t), port, "sim")?)),
        #[cfg(feature = "gpio")]
        "gpio" => Ok(Box::new(gpio::GpioRelay::open(t)?)),
        #[cfg(not(feature = "gpio"))]
        "gpio" => Err(TriggerError::Open {
            port: t.gpio_chip.clone(),
            message: "the gpio trigger backend is not built into this binary (rebuild with `--features gpio`)".into(),
        }),
        other => Err(TriggerError::Open {
            port: port.into(),
            message: format!("unknown relay backend {other:?}"),
        }),
    }
}

/// No relay: for footage of spheres released by other means. Firing does nothing.
struct NoRelay;

impl Relay for NoRelay {
    fn set_closed(&mut self, _closed: bool) -> Result<(), TriggerError> {
        Ok(())
    }
    fn info(&self) -> TriggerInfo {
        TriggerInfo {
            backend: "none".into(),
            port: None,
            protocol: None,
            channel: None,
        }
    }
}

pub struct Trigger {
    relay: Arc<Mutex<Box<dyn Relay>>>,
    pulse: Duration,
    pulse_max: Duration,
}

impl Trigger {
    /// Opens the relay the config names; `sim_port` is the simulated relay's pseudo-terminal.
    /// A real relay (serial, GPIO, the simulator's PTY) is driven through the relay guard, a
    /// child process that opens it if this process dies (`guard`), whenever the executable
    /// has named itself (`guard::set_executable`); otherwise in this process.
    pub fn open(cfg: &Config, sim_port: Option<&str>) -> Result<Trigger, TriggerError> {
        let t = &cfg.trigger;
        let (port, backend): (&str, &'static str) = match t.backend {
            TriggerBackend::None => {
                return Ok(Trigger::new(
                    Box::new(NoRelay),
                    t.relay_pulse_ms,
                    t.relay_pulse_ms_max,
                ))
            }
            TriggerBackend::Serial => (&t.port, "serial"),
            TriggerBackend::Gpio => (&t.gpio_chip, "gpio"),
            TriggerBackend::Sim => (
                sim_port.ok_or_else(|| TriggerError::Open {
                    port: "sim".into(),
                    message: "no simulated lab was set up".into(),
                })?,
                "sim",
            ),
        };
        let relay: Box<dyn Relay> = match guard::executable() {
            Some(exe) => Box::new(guard::GuardedRelay::spawn(exe, t, port, backend)?),
            None => open_direct(t, port, backend)?,
        };
        Ok(Trigger::new(relay, t.relay_pulse_ms, t.relay_pulse_ms_max))
    }

    pub fn new(relay: Box<dyn Relay>, pulse_ms: f64, pulse_max_ms: f64) -> Trigger {
        Trigger {
            relay: Arc::new(Mutex::new(relay)),
            pulse: Duration::from_secs_f64(pulse_ms.max(0.0) / 1000.0),
            pulse_max: Duration::from_secs_f64(pulse_max_ms.max(0.0) / 1000.0),
        }
    }

    pub fn info(&self) -> TriggerInfo {
        match self.relay.lock() {
            Ok(r) => r.info(),
            Err(p) => p.into_inner().info(),
        }
    }

    pub fn pulse_ms(&self) -> f64 {
        self.pulse.as_secs_f64() * 1000.0
    }

    /// Closes the relay now and opens it again after the configured pulse (or at once when
    /// `abort` is set). The returned `Pulse` opens the relay when dropped, whatever happened.
    pub fn fire(&self, _live: &CameraLive, abort: Arc<AtomicBool>) -> Result<Pulse, TriggerError> {
        if self.pulse > self.pulse_max {
            return Err(TriggerError::PulseTooLong {
                requested_ms: self.pulse.as_secs_f64() * 1000.0,
                max_ms: self.pulse_max.as_secs_f64() * 1000.0,
            });
        }
        let mut guard = ReleaseGuard {
            relay: self.relay.clone(),
            armed: true,
        };
        lock(&self.relay).set_closed(true)?;
        let closed_at = Instant::now();
        let cancel = Arc::new(AtomicBool::new(false));
        let cancel2 = cancel.clone();
        let pulse = self.pulse;
        guard.armed = false;
        let relay = self.relay.clone();
        let thread = std::thread::Builder::new()
            .name("relay-pulse".into())
            .spawn(move || {
                let guard = ReleaseGuard { relay, armed: true };
                while closed_at.elapsed() < pulse
                    && !cancel2.load(Ordering::Relaxed)
                    && !abort.load(Ordering::Relaxed)
                {
                    let left = pulse.saturating_sub(closed_at.elapsed());
                    std::thread::sleep(left.min(Duration::from_millis(1)));
                }
                guard.release()
            });
        match thread {
            Ok(thread) => Ok(Pulse {
                thread: Some(thread),
                cancel,
                closed_at,
            }),
            Err(e) => {
                // No timer thread: open the relay now rather than leave it closed.
                let r = ReleaseGuard {
                    relay: self.relay.clone(),
                    armed: true,
                }
                .release();
                r?;
                Err(TriggerError::Io {
                    port: self.info().port.unwrap_or_default(),
                    message: format!("cannot start pulse timer: {e}"),
                })
            }
        }
    }

    /// Opens the relay (idempotent); for shutdown paths that do not hold a `Pulse`.
    pub fn release(&self) -> Result<(), TriggerError> {
        lock(&self.relay).set_closed(false)
    }
}

/// Raises `flag` when any thread panics, before the panic is reported. Pass the flag given to
/// `Trigger::fire`: a pulse in progress watches it every millisecond and opens the relay. Why
/// before the report: the default hook writes the panic's backtrace where RUST_BACKTRACE asks
/// for one, and only the unwinding after it reaches the pulse's own release; with three busy
/// loops beside it a debug build held the relay 640–650 ms past the panic that way, 2–8 ms now
/// (tests/faults.rs, docs/ARCHITECTURE.md's invariants).
pub fn raise_on_panic(flag: Arc<AtomicBool>) {
    let previous = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        flag.store(true, Ordering::SeqCst);
        previous(info);
    }));
}

fn lock(relay: &Mutex<Box<dyn Relay>>) -> std::sync::MutexGuard<'_, Box<dyn Relay>> {
    // A panic while holding the lock leaves the relay object usable; releasing it matters more.
    relay.lock().unwrap_or_else(|p| p.into_inner())
}

/// Opens the relay when dropped, unless disarmed.
struct ReleaseGuard {
    relay: Arc<Mutex<Box<dyn Relay>>>,
    armed: bool,
}

impl ReleaseGuard {
    fn release(mut self) -> Result<PulseRecord, TriggerError> {
        self.armed = false;
        let mut last = Ok(());
        for _ in 0..3 {
            last = lock(&self.relay).set_closed(false);
            if last.is_ok() {
                break;
            }
        }
        last.map(|_| PulseRecord {
            opened_at: Instant::now(),
        })
    }
}

impl Drop for ReleaseGuard {
    fn drop(&mut self) {
        if self.armed {
            let _ = lock(&self.relay).set_closed(false);
        }
    }
}

pub struct PulseRecord {
    pub opened_at: Instant,
}

/// A relay pulse in progress. Dropping it ends the pulse early and opens the relay.
pub struct Pulse {
    thread: Option<JoinHandle<Result<PulseRecord, TriggerError>>>,
    cancel: Arc<AtomicBool>,
    closed_at: Instant,
}

impl Pulse {
    pub fn closed_at(&self) -> Instant {
        self.closed_at
    }

    /// Waits for the pulse to end; the relay is open when this returns Ok.
    pub fn finish(mut self) -> Result<PulseRecord, TriggerError> {
        self.join()
    }

    /// Ends the pulse now.
    pub fn cancel(mut self) -> Result<PulseRecord, TriggerError> {
        self.cancel.store(true, Ordering::Relaxed);
        self.join()
    }

    fn join(&mut self) -> Result<PulseRecord, TriggerError> {
        match self.thread.take() {
            Some(t) => t.join().unwrap_or_else(|_| {
                Err(TriggerError::Io {
                    port: String::new(),
                    message: "relay pulse thread panicked".into(),
                })
            }),
            None => Ok(PulseRecord {
                opened_at: Instant::now(),
            }),
        }
    }
}

impl Drop for Pulse {
    fn drop(&mut self) {
        self.cancel.store(true, Ordering::Relaxed);
        let _ = self.join();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A relay that records every switch and can be told to fail.
    struct Recording {
        log: Arc<Mutex<Vec<(Instant, bool)>>>,
        fail_close: bool,
    }

    impl Relay for Recording {
        fn set_closed(&mut self, closed: bool) -> Result<(), TriggerError> {
            self.log.lock().unwrap().push((Instant::now(), closed));
            if closed && self.fail_close {
                return Err(TriggerError::Io {
                    port: "test".into(),
                    message: "write failed".into(),
                });
            }
            Ok(())
        }
        fn info(&self) -> TriggerInfo {
            TriggerInfo {
                backend: "test".into(),
                port: None,
                protocol: None,
                channel: None,
            }
        }
    }

    /// What a `Recording` relay saw: each switching, when and whether it closed.
    type SwitchLog = Arc<Mutex<Vec<(Instant, bool)>>>;

    fn trigger(pulse_ms: f64, max_ms: f64, fail_close: bool) -> (Trigger, SwitchLog) {
        let log = Arc::new(Mutex::new(Vec::new()));
        (
            Trigger::new(
                Box::new(Recording {
                    log: log.clone(),
                    fail_close,
                }),
                pulse_ms,
                max_ms,
            ),
            log,
        )
    }

    #[test]
    fn pulse_closes_then_opens_after_the_pulse() {
        let (t, log) = trigger(20.0, 100.0, false);
        let p = t
            .fire(&CameraLive::confirmed(3), Arc::new(AtomicBool::new(false)))
            .unwrap();
        p.finish().unwrap();
        let l = log.lock().unwrap();
        assert_eq!(l.iter().map(|e| e.1).collect::<Vec<_>>(), vec![true, false]);
        let held = l[1].0 - l[0].0;
        assert!(held >= Duration::from_millis(20), "held {held:?}");
    }

    #[test]
    fn dropping_a_pulse_opens_the_relay_early() {
        let (t, log) = trigger(5000.0, 10000.0, false);
        let p = t
            .fire(&CameraLive::confirmed(3), Arc::new(AtomicBool::new(false)))
            .unwrap();
        drop(p);
        let l = log.lock().unwrap();
        assert_eq!(l.last().map(|e| e.1), Some(false));
        assert!(l[1].0 - l[0].0 < Duration::from_millis(1000));
    }

    #[test]
    fn a_panic_on_another_thread_raises_the_flag_before_it_unwinds() {
        let flag = Arc::new(AtomicBool::new(false));
        raise_on_panic(flag.clone());
        let seen = flag.clone();
        // The panicking thread looks at the flag from a value it drops while unwinding: by then
        // the hook must have raised it.
        struct Look(Arc<AtomicBool>, Arc<Mutex<Option<bool>>>);
        impl Drop for Look {
            fn drop(&mut self) {
                *self.1.lock().unwrap() = Some(self.0.load(Ordering::SeqCst));
            }
        }
        let during = Arc::new(Mutex::new(None));
        let d = during.clone();
        let joined = std::thread::spawn(move || {
            let _look = Look(seen, d);
            panic!("a panic the test asks for");
        })
        .join();
        assert!(joined.is_err());
        assert_eq!(
            *during.lock().unwrap(),
            Some(true),
            "raised before unwinding"
        );
        assert!(flag.load(Ordering::SeqCst));
    }

    #[test]
    fn abort_flag_opens_the_relay() {
        let (t, log) = trigger(5000.0, 10000.0, false);
        let abort = Arc::new(AtomicBool::new(false));
        let p = t.fire(&CameraLive::confirmed(3), abort.clone()).unwrap();
        abort.store(true, Ordering::Relaxed);
        p.finish().unwrap();
        assert_eq!(log.lock().unwrap().last().map(|e| e.1), Some(false));
    }

    #[test]
    fn failed_close_still_opens_the_relay() {
        let (t, log) = trigger(20.0, 100.0, true);
        assert!(t
            .fire(&CameraLive::confirmed(3), Arc::new(AtomicBool::new(false)))
            .is_err());
        assert_eq!(log.lock().unwrap().last().map(|e| e.1), Some(false));
    }

    #[test]
    fn pulse_longer_than_max_is_refused_without_touching_the_relay() {
        let (t, log) = trigger(200.0, 100.0, false);
        assert!(matches!(
            t.fire(&CameraLive::confirmed(3), Arc::new(AtomicBool::new(false))),
            Err(TriggerError::PulseTooLong { .. })
        ));
        assert!(log.lock().unwrap().is_empty());
    }

    #[test]
    fn panic_while_pulsing_still_opens_the_relay() {
        let (t, log) = trigger(5000.0, 10000.0, false);
        let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            let _p = t
                .fire(&CameraLive::confirmed(3), Arc::new(AtomicBool::new(false)))
                .unwrap();
            panic!("analysis blew up mid-pulse");
        }));
        assert!(r.is_err());
        assert_eq!(log.lock().unwrap().last().map(|e| e.1), Some(false));
    }
}
