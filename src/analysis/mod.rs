//! Analysis: pure functions from recorded frames to a report. It never touches hardware — it
//! reads sessions or TIFF stacks — which is what makes `replay` exact: the same frames and the
//! same config give the same report, bit for bit.
//!
//! Pipeline: segment each view → sub-pixel circles (`circle`) → a/b labels and world centres
//! (`tracking`) → ballistic fits before/after, impact, normal, e, spins with uncertainties
//! (`observations`, through `kinematics`, `spin` and `impulse`) → `report`. This file holds the
//! two passes over the frames (`analyze_detailed`) and the geometry's σ re-runs. Imperfect footage gives a report with warnings and a list of the
//! frames that could not be measured; it fails only when no honest result exists (no spheres,
//! no impact, too few frames).

mod backdrop;
pub(crate) mod calibration;
pub mod circle;
pub mod detect;
mod flight_misfit;
pub mod geometry;
mod geometry_sigma;
mod handedness;
pub mod image;
mod impulse;
pub mod kinematics;
pub mod lens;
pub mod line_fit;
pub mod linear;
pub mod markers;
mod momentum;
mod names_through_impact;
mod observations;
mod overlap;
mod phases;
mod radius_misfit;
pub mod report;
pub mod rotation;
mod second_pass;
pub mod source;
pub mod stages;
mod survey;
pub use survey::{blob_survey, blobs, measure, BlobSurvey};
pub mod spin;
mod spin_search;
pub mod spin_tracks;
pub mod thesis;
pub mod tracking;
pub mod tracks;
mod uncertainty;
mod world;

use crate::config::Config;
use crate::session::SessionError;
use geometry::View;
use kinematics::V3;
use observations::observations_once;
use report::*;
use second_pass::rim_dots;
pub use source::{FileSource, FrameSource, SessionSource};
use tracking::{FrameObs, SecondPass};

#[derive(Debug, thiserror::Error)]
pub enum AnalysisError {
    #[error(transparent)]
    Session(#[from] SessionError),
    #[error("{source_name}: {message}")]
    Input {
        source_name: String,
        message: String,
    },
    #[error("{source_name}: no impact found: {message}")]
    NoImpact {
        source_name: String,
        message: String,
    },
}

/// How far beyond [0, 1] a measured e may lie, in its own σ, before the contact it was
/// measured at is taken as not the impact.
const RESTITUTION_BOUND_SIGMA: f64 = 3.0;

/// Why a coefficient of restitution `e` ± `sigma` cannot come from a collision, if it cannot:
/// below 0 the spheres would still approach along the normal after the contact (they would
/// pass through each other), above 1 they would leave with more energy than they met with;
/// beyond `RESTITUTION_BOUND_SIGMA` either way, the impact time and normal it was measured at
/// are wrong, and so is every velocity taken there. Why: on a defocused grazing impact
/// (offset 0.97), a build whose disc fits differed only in where their edge width started
/// put the joint contact 4.4 ms early (σ 0.3 ms) and reported e −0.31 ± 0.03 against 0.90,
/// every y velocity 11–14σ off, without a warning (docs/accuracy.md, session 32). No result,
/// with the reason, is better than that.
fn unphysical_restitution(e: f64, sigma: f64) -> Option<String> {
    if !(e.is_finite() && sigma.is_finite()) {
        return None;
    }
    let beyond = if e < 0.0 { -e } else { e - 1.0 };
    (beyond > RESTITUTION_BOUND_SIGMA * sigma).then(|| {
        format!(
            "the contact found gives e = {e:.3} ± {sigma:.3}, beyond [0, 1] by more than {RESTITUTION_BOUND_SIGMA}σ: {} — that contact is not the impact (a grazing impact whose trajectories barely turn can put it milliseconds off)",
            if e < 0.0 {
                "the spheres would still approach after it"
            } else {
                "they would leave with more energy than they met with"
            }
        )
    })
}

/// The final report, or why its e is no collision's (`unphysical_restitution`). Only the final
/// one: the first pass's report serves for its spins (the dots it carries), and a re-run with a
/// map stepped by its σ (`geometry_sigma`) only widens.
fn physical(
    analysed: Result<(Report, Details), AnalysisError>,
) -> Result<(Report, Details), AnalysisError> {
    let (report, details) = analysed?;
    if let Some(message) = report
        .e
        .as_ref()
        .and_then(|e| unphysical_restitution(e.value, e.uncertainty))
    {
        return Err(AnalysisError::NoImpact {
            source_name: report.source.name.clone(),
            message,
        });
    }
    Ok((report, details))
}

/// Threads the analysis of one input may use (0: as many as the machine has).
static THREADS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// Sets the threads the analysis of one input may use (`--jobs`; 0: as many as the machine
/// has). The report does not depend on it (`tracking::ahead`).
pub fn set_threads(n: usize) {
    THREADS.store(n, std::sync::atomic::Ordering::Relaxed);
}

/// The threads the analysis of one input uses.
pub fn threads() -> usize {
    match THREADS.load(std::sync::atomic::Ordering::Relaxed) {
        0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
        n => n,
    }
}

/// Analyses any frame source with the given config.
pub fn analyze(
    src: &mut dyn FrameSource,
    cfg: &Config,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Report, AnalysisError> {
    analyze_detailed(src, cfg, progress).map(|(r, _)| r)
}

/// The intermediate results behind a report, for accuracy studies and the thesis baseline.
pub struct Details {
    pub views: Vec<View>,
    pub obs: Vec<FrameObs>,
    /// Impact time on the source's clock, s.
    pub impact_time_s: f64,
    /// Frame indices of [a pre, b pre, a post, b post].
    pub phases: [Vec<usize>; 4],
    /// Spin measurements of [a pre, b pre, a post, b post].
    pub spins: Vec<spin::SpinMeasurement>,
    /// Where the markers said a view's image is mirrored otherwise than the config does
    /// (`handedness`): the spins were measured as they turn.
    pub handedness: Option<handedness::Verdict>,
}

pub fn analyze_detailed(
    src: &mut dyn FrameSource,
    cfg: &Config,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(Report, Details), AnalysisError> {
    let info = src.source();
    let input_err = |message: String| AnalysisError::Input {
        source_name: info.name.clone(),
        message,
    };
    if src.is_empty() {
        return Err(input_err("no frames to analyse".into()));
    }
    let (w, h) = src.dimensions();
    let views = geometry::views(cfg);
    for v in &views {
        let [x, y, vw, vh] = v.region;
        if x + vw > w || y + vh > h {
            return Err(input_err(format!(
                "geometry.{}.region {:?} does not fit the {w}×{h} frames",
                v.kind.name(),
                v.region
            )));
        }
    }
    // In linear light, where the camera encodes with a gamma.
    let src = &mut linear::Linear::new(src, cfg);
    // Each frame is measured against what stands still in its view, bright side up.
    stages::set_pass(0);
    let backdrop = stages::timed(stages::Stage::Backdrop, || {
        backdrop::Backdrop::estimate(src, &views)
    })?;
    let src = &mut source::Filtered {
        inner: src,
        filter: backdrop,
    };
    // The first pass's fits, for the second to finish.
    let memo = tracking::FitMemo::default();
    // Two passes over the frames, each counted as half of the progress: the first finds the
    // markers and spins, the second measures the circles to the end, without the dots that the
    // spins put on each rim.
    let (obs, unmeasured) = tracking::measure_all(
        src,
        &views,
        cfg,
        &SecondPass::default(),
        &memo,
        &mut |i, n| progress(i / 2, n),
    )?;
    let first_unmeasured = unmeasured.clone();
    let (warnings, frames_dropped) = (src.warnings(), src.frames_dropped());
    let input = || Input {
        info: info.clone(),
        warnings: warnings.clone(),
        frames_dropped,
        first_pass_spins: [None; 4],
        settle_handedness: true,
        handedness_doubt: None,
    };
    // The first pass's report gives the spins that carry its dots round each rim; the
    // geometry's uncertainty (re-running the fits) is added to the final one only.
    let mut first = stages::timed(stages::Stage::Fits, || {
        observations_once(input(), obs, unmeasured, views.clone(), cfg)
    })?;
    // The markers turn as if a view's image were mirrored otherwise than the config says
    // (`handedness`): from here on that view sees the other hemisphere, its first-pass
    // markers lifted so too, so that the dots carried into the second pass and its own markers
    // agree with the spins; the report keeps the warning.
    let mut views = views;
    let mut handedness_warning = None;
    let mut handedness_doubt = None;
    let verdict = first.1.handedness.take();
    if let Some(verdict) = verdict.as_ref().filter(|v| !v.clear()) {
        handedness_doubt = Some(verdict.clone());
    }
    if let Some(verdict) = verdict.filter(|v| v.clear()) {
        handedness_warning = Some(handedness::warning(&verdict, &views));
        views = handedness::reflected_views(&views, &verdict);
        let mut obs = std::mem::take(&mut first.1.obs);
        handedness::reflect_markers(&mut obs, &verdict);
        first = stages::timed(stages::Stage::Fits, || {
            let input = Input {
                settle_handedness: false,
                ..input()
            };
            observations_once(input, obs, first_unmeasured.clone(), views.clone(), cfg)
        })?;
    }
    let pass = SecondPass {
        dots: rim_dots(&first.1, cfg),
        radii: radius_misfit::held_radii(
            &first.1.obs,
            cfg.camera.exposure_us.map_or(0.0, |us| us * 1e-6),
        ),
    };
    // The first pass's grey-level fits stopped after their box rounds: the second finishes
    // them, with the rim dots masked where there are any, a blurred disc's radius held at
    // its sphere's first-pass radii round that frame, and a disc that moved while the shutter
    // was open modelled over the exposure.
    stages::set_pass(1);
    memo.start_second_pass();
    let (obs, unmeasured) = tracking::measure_all(src, &views, cfg, &pass, &memo, &mut |i, n| {
        progress((n + i) / 2, n)
    })?;
    let first_pass_spins: [Option<V3>; 4] = [0, 1, 2, 3].map(|k| {
        first
            .1
            .spins
            .get(k)
            .and_then(|m| m.fit.as_ref())
            .map(|f| f.omega)
    });
    stages::timed(stages::Stage::Fits, || {
        analyze_observations(
            Input {
                first_pass_spins,
                warnings: warnings.iter().cloned().chain(handedness_warning).collect(),
                settle_handedness: false,
                handedness_doubt,
                ..input()
            },
            obs,
            unmeasured,
            views,
            cfg,
        )
    })
}

/// Analyses centres digitised elsewhere (see `tracks` for the CSV columns).
pub fn analyze_tracks(path: &std::path::Path, cfg: &Config) -> Result<Report, AnalysisError> {
    let views = geometry::views(cfg);
    let (input, obs) = tracks::read(path, &views, cfg.camera.frame_rate_hz)?;
    analyze_observations(input, obs, Vec::new(), views, cfg).map(|(r, _)| r)
}

/// What the analysis needs to know about its input besides the measurements.
#[derive(Clone)]
pub struct Input {
    pub info: Source,
    pub warnings: Vec<String>,
    pub frames_dropped: u64,
    /// The first pass's marker spins of [a pre, b pre, a post, b post], where it measured them
    /// (`analyze_detailed`): each spin the second pass measures carries its difference from it
    /// as one more error (`widen_by_first_pass`). None for centres digitised elsewhere.
    pub first_pass_spins: [Option<V3>; 4],
    /// Whether this run's markers may settle which hemisphere each view sees (`handedness`):
    /// the first pass's. The second pass and the geometry's re-runs keep the views it settled
    /// on (each check is 16 spin fits, for nothing once the views are settled).
    pub settle_handedness: bool,
    /// Where the first pass's markers could not settle which hemisphere a view sees
    /// (`handedness`, a doubt): each spin's σ takes in the other way's spin.
    pub handedness_doubt: Option<handedness::Verdict>,
}

/// Everything after per-frame measurement: calibration, fits, impact, spins, the report, with
/// the geometry's own uncertainty in every estimate (`geometry_sigma`). Also the entry point
/// for centres digitised elsewhere (`tracks`).
pub fn analyze_observations(
    input: Input,
    obs: Vec<FrameObs>,
    unmeasured: Vec<Unmeasured>,
    views: Vec<View>,
    cfg: &Config,
) -> Result<(Report, Details), AnalysisError> {
    // A config that says nothing of its maps' uncertainty needs no copies for the re-runs.
    if geometry_sigma::terms(&cfg.geometry).is_empty() {
        return physical(observations_once(input, obs, unmeasured, views, cfg));
    }
    let (mut report, details) =
        observations_once(input.clone(), obs.clone(), unmeasured, views.clone(), cfg)?;
    add_geometry_uncertainty(&mut report, &input, &obs, &views, cfg);
    physical(Ok((report, details)))
}

/// Re-runs the analysis of the observations with each geometry parameter whose uncertainty the
/// config gives stepped by it, and widens every estimate's σ by what that changed.
fn add_geometry_uncertainty(
    report: &mut Report,
    input: &Input,
    obs: &[FrameObs],
    views: &[View],
    cfg: &Config,
) {
    let terms = geometry_sigma::terms(&cfg.geometry);
    if terms.is_empty() {
        return;
    }
    let run = |term: Option<&geometry_sigma::Term>| {
        let views = geometry_sigma::turned_views(views, term);
        observations_once(input.clone(), obs.to_vec(), Vec::new(), views, cfg)
            .ok()
            .map(|r| r.0)
    };
    let Some(baseline) = run(None) else {
        return;
    };
    let turned: Vec<Option<Report>> = terms.iter().map(|t| run(Some(t))).collect();
    geometry_sigma::widen(report, &terms, &baseline, &turned);
}

#[cfg(test)]
mod tests;
