//! Where the analysis's time goes, stage by stage, for `impactcam bench analysis`: each stage's
//! time is added up per thread and per pass (the first pass finds markers and spins, the second
//! measures the circles again with the rim dots masked). Inclusive: `Measure` holds the reads,
//! detection, circle fits and markers of its pass; the bench takes the differences. Always on —
//! a clock read per stage call, a few dozen per frame — so the figures are those of the program
//! as shipped, not of a special build.

use std::cell::Cell;
use std::time::{Duration, Instant};

/// A stage of the analysis (see the module's doc for how they nest).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// Reading and decoding a frame, and subtracting the backdrop.
    Read = 0,
    /// Estimating the backdrop (what stands still in each view), once per analysis.
    Backdrop,
    /// Grey levels of a view and its blobs.
    Detect,
    /// Sub-pixel circle fits: edge points, grey-level fits, splits of merged silhouettes.
    Circles,
    /// Finding the markers on a sphere.
    Markers,
    /// The whole per-frame measurement of a pass (includes the four above).
    Measure,
    /// Everything after measurement: calibration, trajectory fits, impact, spins, report.
    Fits,
}

/// The number of stages.
pub const STAGES: usize = 7;

/// Seconds spent per [pass][stage] (`Stage as usize`).
pub type StageTimes = [[f64; STAGES]; 2];

thread_local! {
    static PASS: Cell<usize> = const { Cell::new(0) };
    static MODEL_SAMPLES: Cell<u64> = const { Cell::new(0) };
    static TIMES: Cell<[[Duration; STAGES]; 2]> = const { Cell::new([[Duration::ZERO; STAGES]; 2]) };
}

/// Runs `f`, adding its time to `stage` of the current pass on this thread.
pub fn timed<T>(stage: Stage, f: impl FnOnce() -> T) -> T {
    let t0 = Instant::now();
    let out = f();
    let dt = t0.elapsed();
    let pass = PASS.with(Cell::get);
    TIMES.with(|t| {
        let mut all = t.get();
        all[pass][stage as usize] += dt;
        t.set(all);
    });
    out
}

/// Adds `n` evaluations of the grey-level circle model (`circle::profile`: one per pixel, three
/// per pixel the edge crosses in the last round, one per pixel for each of a fit's linear
/// starts) to this thread's count. A count, not a time:
/// the work the fits did, the same on any machine and under any load, so that a change to the
/// fits can be compared where the clock scatters by ±15 %.
pub(crate) fn count_model_samples(n: usize) {
    MODEL_SAMPLES.with(|c| c.set(c.get() + n as u64));
}

/// The grey-level model evaluations counted on this thread since the last call; resets them.
pub fn take_model_samples() -> u64 {
    MODEL_SAMPLES.with(|c| c.replace(0))
}

/// Which pass the following stages belong to (0 or 1).
pub(crate) fn set_pass(pass: usize) {
    PASS.with(|p| p.set(pass.min(1)));
}

/// The times added up on this thread since the last `take`, s; resets them.
pub fn take() -> StageTimes {
    PASS.with(|p| p.set(0));
    TIMES
        .with(|t| t.replace([[Duration::ZERO; STAGES]; 2]))
        .map(|pass| pass.map(|d| d.as_secs_f64()))
}
