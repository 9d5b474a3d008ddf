//! The lab clock: seconds since the lab started (real time), or the time of the frame being
//! rendered (free-run). It is the simulated camera's device clock, and the relay stamps the
//! switches it hears with it.
//!
//! In real time the world must not run ahead of the camera that films it. A renderer slower
//! than the frame rate (a debug build, a loaded machine) would otherwise fall behind the wall
//! clock while the relay, stamped on the wall clock, released the spheres in frames not yet
//! drawn: the recording would start late in the flight, or after the impact. So while a camera
//! streams, the clock is held at the time of the next frame it owes; the world waits for the
//! renderer, as it would for a real camera that never lags. A renderer that keeps pace never
//! meets the hold, and the clock is the wall clock.

use crate::config::Pace;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// Seconds since the lab started (real time, held back to a streaming camera's next frame), or
/// the time of the frame being rendered (free-run): the device clock of the simulated camera
/// either way. Never goes backwards.
pub struct LabClock {
    epoch: Instant,
    pace: Pace,
    free_run_now_bits: AtomicU64,
    /// The time of the next frame a streaming camera owes (f64 bits; +∞: no camera streams).
    hold_bits: AtomicU64,
    /// The latest time returned (f64 bits of a non-negative number, so their order is the
    /// numbers' order): a hold set below it does not turn the clock back.
    floor_bits: AtomicU64,
}

impl LabClock {
    pub fn new(pace: Pace) -> LabClock {
        LabClock {
            epoch: Instant::now(),
            pace,
            free_run_now_bits: AtomicU64::new(0f64.to_bits()),
            hold_bits: AtomicU64::new(f64::INFINITY.to_bits()),
            floor_bits: AtomicU64::new(0f64.to_bits()),
        }
    }
    pub fn now_s(&self) -> f64 {
        match self.pace {
            Pace::RealTime => {
                let wall = self.epoch.elapsed().as_secs_f64();
                let hold = f64::from_bits(self.hold_bits.load(Ordering::Acquire));
                let t = wall.min(hold).max(0.0);
                let floor = self.floor_bits.fetch_max(t.to_bits(), Ordering::AcqRel);
                t.max(f64::from_bits(floor))
            }
            Pace::FreeRun => f64::from_bits(self.free_run_now_bits.load(Ordering::Acquire)),
        }
    }
    pub(crate) fn set_free_run_now(&self, t: f64) {
        self.free_run_now_bits.store(t.to_bits(), Ordering::Release);
    }
    /// A streaming camera owes its next frame at `t`: the real-time clock waits there.
    pub(crate) fn hold_at(&self, t: f64) {
        self.hold_bits.store(t.to_bits(), Ordering::Release);
    }
    /// No camera streams: the real-time clock is the wall clock again.
    pub(crate) fn release_hold(&self) {
        self.hold_bits
            .store(f64::INFINITY.to_bits(), Ordering::Release);
    }
    pub(crate) fn epoch(&self) -> Instant {
        self.epoch
    }
    pub(crate) fn pace(&self) -> Pace {
        self.pace
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_held_clock_waits_for_the_camera_and_never_goes_back() {
        let c = LabClock::new(Pace::RealTime);
        std::thread::sleep(std::time::Duration::from_millis(20));
        let before = c.now_s();
        assert!(before >= 0.02, "{before}");
        // A camera that owes a frame from 5 ms: the clock does not turn back to it…
        c.hold_at(0.005);
        assert!(c.now_s() >= before);
        // …and does not pass a hold ahead of it until the camera moves on.
        let ahead = c.now_s() + 0.01;
        c.hold_at(ahead);
        std::thread::sleep(std::time::Duration::from_millis(30));
        assert_eq!(c.now_s(), ahead);
        c.release_hold();
        assert!(c.now_s() >= ahead + 0.015);
    }
}
