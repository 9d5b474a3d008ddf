//! The lab clock: seconds since the lab started (real time), or the time of the frame being
//! rendered (free-run). It is the simulated camera's device clock, and the relay stamps the
//! switches it hears with it.

use crate::config::Pace;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// Seconds since the lab started (real time), or the time of the frame being rendered
/// (free-run): the device clock of the simulated camera either way.
pub struct LabClock {
    epoch: Instant,
    pace: Pace,
    free_run_now_bits: AtomicU64,
}

impl LabClock {
    pub fn new(pace: Pace) -> LabClock {
        LabClock {
            epoch: Instant::now(),
            pace,
            free_run_now_bits: AtomicU64::new(0f64.to_bits()),
        }
    }
    pub fn now_s(&self) -> f64 {
        match self.pace {
            Pace::RealTime => self.epoch.elapsed().as_secs_f64(),
            Pace::FreeRun => f64::from_bits(self.free_run_now_bits.load(Ordering::Acquire)),
        }
    }
    pub(crate) fn set_free_run_now(&self, t: f64) {
        self.free_run_now_bits.store(t.to_bits(), Ordering::Release);
    }
    pub(crate) fn epoch(&self) -> Instant {
        self.epoch
    }
    pub(crate) fn pace(&self) -> Pace {
        self.pace
    }
}
