//! Analysis: pure functions from recorded frames to a report. It never touches hardware — it
//! reads sessions or TIFF stacks — which is what makes `replay` exact: the same frames and the
//! same config give the same report, bit for bit.
//!
//! Pipeline: segment each view → sub-pixel circles (`circle`) → a/b labels and world centres
//! (`tracking`) → ballistic fits before/after, impact, normal, e with uncertainties
//! (`kinematics`) → `report`. Imperfect footage gives a report with warnings and a list of the
//! frames that could not be measured; it fails only when no honest result exists (no spheres,
//! no impact, too few frames).

mod backdrop;
pub(crate) mod calibration;
pub mod circle;
pub mod detect;
pub mod geometry;
mod geometry_sigma;
pub mod image;
mod impulse;
pub mod kinematics;
pub mod lens;
pub mod line_fit;
pub mod linear;
pub mod markers;
mod momentum;
mod names_through_impact;
mod overlap;
mod phases;
mod radius_misfit;
pub mod report;
pub mod rotation;
mod second_pass;
pub mod source;
pub mod stages;
mod survey;
pub use survey::{blob_survey, blobs, measure};
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
use geometry::{View, ViewKind};
use kinematics::{derive, Bodies, ImpactError, SideFit, Spins, V3};
use report::*;
use rotation::SpinFit;
use tracking::{FrameObs, SecondPass};

use calibration::calibrate_mirror;
use phases::{fit_all, flight_phases, phases_missing_axis, relift_on_trajectories};
use second_pass::rim_dots;
pub use source::{FileSource, FrameSource, SessionSource};
use uncertainty::{beta_where_defined, combined_uncertainties, spin_estimate};

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
    let src = &mut backdrop::Normalised {
        inner: src,
        backdrop,
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
    let (warnings, frames_dropped) = (src.warnings(), src.frames_dropped());
    let input = || Input {
        info: info.clone(),
        warnings: warnings.clone(),
        frames_dropped,
        first_pass_spins: [None; 4],
    };
    // The first pass's report gives the spins that carry its dots round each rim; the
    // geometry's uncertainty (re-running the fits) is added to the final one only.
    let first = stages::timed(stages::Stage::Fits, || {
        observations_once(input(), obs, unmeasured, views.clone(), cfg)
    })?;
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
                ..input()
            },
            obs,
            unmeasured,
            views,
            cfg,
        )
    })
}

/// A spin the second pass measured, its difference from the first pass's added to its
/// covariance (in full, along the difference) and to its influences as one more source. Why:
/// the two passes measure the same markers on centres that differ by hundredths of a pixel
/// (the rim dots masked), so their spins should differ by far less than either's σ; where they
/// differ by more, the fit rests on something those hundredths move, which its σ from the
/// tracks' scatter does not see. Seed 3118 of the bench: b's spin after the impact moved by 5.4
/// rad/s between the passes, its σ 1.3 rad/s, and was 7.3 rad/s off (5.5σ; docs/accuracy.md,
/// session 38).
fn widen_by_first_pass(fit: &mut SpinFit, earlier: V3, phase: usize) {
    let d = fit.omega - earlier;
    if !d.iter().all(|x| x.is_finite()) || d.norm() == 0.0 {
        return;
    }
    fit.cov += d * d.transpose();
    // A source of its own per phase, apart from every frame and from `spin_tracks`' model terms.
    fit.frame_influence.push((usize::MAX - 1 - phase, d));
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

/// Everything after per-frame measurement, the config's geometry taken as exact.
fn observations_once(
    input: Input,
    obs: Vec<FrameObs>,
    unmeasured: Vec<Unmeasured>,
    views: Vec<View>,
    cfg: &Config,
) -> Result<(Report, Details), AnalysisError> {
    let Input {
        info,
        warnings: input_warnings,
        frames_dropped,
        first_pass_spins,
    } = input;
    let input_err = |message: String| AnalysisError::Input {
        source_name: info.name.clone(),
        message,
    };
    let (mut views, mut obs) = (views, obs);
    markers::drop_in_the_other_disc(&mut obs);
    // Names checked through the impact before anything pairs the spheres' frames up (the
    // closest approach does not depend on the names).
    let renamed = match phases::closest_approach(&obs, &views, 0) {
        Some((t, _)) => {
            let names: Vec<&str> = views.iter().map(|v| v.kind.name()).collect();
            let r_mm = cfg.spheres.sphere(0).0.min(cfg.spheres.sphere(1).0) / 2.0;
            let radii_px: Vec<f64> = views.iter().map(|v| v.px_per_mm * r_mm).collect();
            names_through_impact::check(&mut obs, &names, &radii_px, t)
        }
        None => Vec::new(),
    };
    radius_misfit::widen(&mut obs);
    world::place(&mut obs, &views);
    let mut calibration = calibrate_mirror(&obs, &mut views);
    // What the refined mirror scale is known to, as a fraction (its z velocities carry it).
    let mirror_scale_sigma = if calibration.as_ref().is_some_and(|c| c.refined) {
        world::place(&mut obs, &views);
        calibration::mirror_scale_sigma(&obs, &views).unwrap_or(0.0)
    } else {
        0.0
    };
    let hidden_notes = overlap::widen_hidden(&mut obs, &views);
    let g = cfg.analysis.gravity_mm_s2;
    let contact_mm = cfg.spheres.contact_mm();
    let period = 1.0 / info.frame_rate_hz;
    let primary = 0; // views[0] is direct when present, else the mirror

    let closest = phases::closest_approach(&obs, &views, primary);
    let Some((mut split, _)) = closest else {
        return Err(input_err(format!(
            "spheres a and b were never both measured in the {} view ({} frames; see the geometry and threshold settings)",
            views[primary].kind.name(),
            obs.len()
        )));
    };
    let min_side = cfg.analysis.min_frames_per_side as usize;
    let radii = [cfg.spheres.sphere(0).0 / 2.0, cfg.spheres.sphere(1).0 / 2.0];
    let masses = [cfg.spheres.sphere(0).1, cfg.spheres.sphere(1).1];
    let momentum_ok = masses.iter().all(|m| m.is_finite() && *m > 0.0);
    // An axis one phase did not measure is taken from the others' momentum where the masses are
    // known (`phases::keep_common_axes`).
    let masses_known = momentum_ok.then_some(masses);
    let fits_at =
        |split: f64| fit_all(&obs, &views, split, 0.5 * period, g, min_side, masses_known);
    for _ in 0..8 {
        let fits = fits_at(split);
        for (k, side) in fits.iter().enumerate() {
            let n = side.axes[0].map(|l| l.n).unwrap_or(0);
            if n < min_side {
                let which = ["a before", "b before", "a after", "b after"][k];
                return Err(input_err(format!(
                    "only {n} usable frame(s) of sphere {which} the impact, need analysis.min_frames_per_side = {min_side}"
                )));
            }
        }
        let d = match derive(&fits, None, radii, contact_mm, g) {
            Ok(d) => d,
            Err(ImpactError::NoContact { closest_mm }) => {
                return Err(AnalysisError::NoImpact {
                    source_name: info.name.clone(),
                    message: format!(
                        "the spheres' trajectories come no closer than {closest_mm:.2} mm, but contact is at {contact_mm:.2} mm"
                    ),
                })
            }
            Err(ImpactError::NotApproaching) => {
                return Err(AnalysisError::NoImpact {
                    source_name: info.name.clone(),
                    message: "the spheres are not approaching each other before the closest frame".into(),
                })
            }
        };
        let new_split = split + d.tau_c;
        let moved = (new_split - split).abs();
        split = new_split;
        if moved < 1e-7 {
            break;
        }
    }
    // Final fits referenced at the impact time, so p0 and v are the state at impact.
    let fits = fits_at(split);
    let mut warnings = input_warnings;
    warnings.extend(renamed);
    warnings.extend(hidden_notes);
    // Momentum across the impact (`momentum`): the four phases' velocities checked against it
    // and, where they agree within 3σ, combined under it from here on.
    let bodies = Bodies {
        radii,
        momentum: match momentum_ok
            .then(|| momentum::check(&fits, masses))
            .flatten()
        {
            Some((_, _, true)) => Some(momentum::Momentum::of(&fits, masses)),
            Some((chi2, dof, false)) => {
                warnings.push(format!(
                    "the velocities before and after the impact do not conserve momentum (χ² = {chi2:.1} for {dof} degree(s) of freedom, beyond 3σ; masses from spheres.mass_g): they are reported as fitted, not combined"
                ));
                None
            }
            None => None,
        },
    };

    // Spins, one constant vector per sphere and flight phase.
    let method = cfg.analysis.rotation;
    let ph = flight_phases(&obs, &views, split, 0.5 * period, g, min_side);
    // Each phase's x velocity from the direct view against the mirror's (`x_views_disagree`):
    // where they differ beyond twice their σ, the excess is one more error of that velocity.
    let x_views: [Option<f64>; 4] = [0, 1, 2, 3].map(|k| {
        let (d, sigma, excess) = phases::x_views_disagree(&obs, &views, k % 2, &ph[k], split)?;
        // Said beyond 3σ, as the momentum check: with honest σ one phase in twenty lands
        // beyond 2σ by chance, and adds a sliver to its σ without a word.
        if d.abs() > 3.0 * sigma {
            warnings.push(format!(
            "sphere {} {} the impact: its x velocity from the direct view and from the mirror differ by {d:+.1} ± {sigma:.1} mm/s; {excess:.1} mm/s added to its σ, and carried into everything derived from it",
            ["a", "b"][k % 2],
            ["before", "after"][k / 2],
            ));
        }
        Some(excess)
    });
    // Each phase's velocity bias the centres may share: the views' x disagreement, and the
    // misfits their radii show (`phases::stray_velocity`), the larger of the two on x; and on
    // z, which the mirror alone measures, what the refined mirror scale's σ does to it
    // (`calibration::mirror_scale_sigma`), in quadrature.
    let shared_bias: [[f64; 3]; 4] = [0, 1, 2, 3].map(|k| {
        let mut stray = phases::stray_velocity(&obs, &views, k % 2, &ph[k]);
        let drift = phases::diameter_drift_velocity(&obs, &views, k % 2, &ph[k]);
        for (a, b) in stray.iter_mut().zip(drift) {
            *a = a.hypot(b);
        }
        stray[0] = stray[0].max(x_views[k].unwrap_or(0.0));
        if let Some(z) = &fits[k].axes[2] {
            stray[2] = stray[2].hypot(z.v.abs() * mirror_scale_sigma);
        }
        stray
    });
    if let Some(c) = calibration.as_mut() {
        warnings.extend(calibration::check_geometry(c, &obs, &views, &ph, g));
    }
    let obs_spin = relift_on_trajectories(&obs, &views, &fits, &ph, split, g, radii);
    let measured: Vec<spin::SpinMeasurement> = (0..4)
        .map(|k| {
            let mut m = spin::measure(&obs_spin, &ph[k], k % 2, method);
            if let (Some(fit), Some(earlier)) = (m.fit.as_mut(), first_pass_spins[k]) {
                widen_by_first_pass(fit, earlier, k);
            }
            m
        })
        .collect();
    // The impulse–spin check (impulse.rs): the velocities' change fixes each sphere's spin
    // change; the spins are checked against it, combined with it, or completed by it.
    let mut reconciled: [Option<SpinFit>; 4] =
        [0, 1, 2, 3].map(|k| measured[k].reportable().cloned());
    let mut spin_checks: [Option<report::SpinCheck>; 2] = [None, None];
    let k_inertia = cfg.spheres.inertia_factor;
    // The velocities' and the normal's σ with the jackknife over frames (the propagated
    // covariance alone understated the predicted Δω's scatter about twofold on the bench).
    if let (Ok(d0), Ok(s0)) = (
        derive(&fits, None, bodies, contact_mm, g),
        combined_uncertainties(
            &obs,
            &views,
            &ph,
            &fits,
            None,
            bodies,
            &shared_bias,
            contact_mm,
            split,
            g,
            masses_known,
        ),
    ) {
        let measured_3d = s0.velocities.iter().all(|v| v.iter().all(|x| *x > 0.0));
        for s in 0..2 {
            if !measured_3d {
                break;
            }
            let n = if s == 0 { d0.normal } else { -d0.normal };
            let dv = d0.velocities[2 + s] - d0.velocities[s];
            let dv_sigma = (s0.velocities[s].component_mul(&s0.velocities[s])
                + s0.velocities[2 + s].component_mul(&s0.velocities[2 + s]))
            .map(f64::sqrt);
            let imp = impulse::predicted(n, s0.normal, dv, dv_sigma, radii[s], k_inertia);
            let (pre, post, check, warning) =
                impulse::reconcile(s, reconciled[s].as_ref(), reconciled[2 + s].as_ref(), &imp);
            reconciled[s] = pre;
            reconciled[2 + s] = post;
            spin_checks[s] = Some(check);
            warnings.extend(warning);
        }
    }
    // The primary view lost the spheres for a whole phase (they overlap in it, as after an
    // impact at different depths), so that phase came from the other view alone and an axis was
    // lost: the velocities are 2-D, the contact impulse cannot check the markers' spins, and the
    // markers there can be wrong by many times their own σ (validation v03: 20σ). Not reported.
    let axis_lost = views.len() == 2 && (0..3).any(|i| fits.iter().all(|f| f.axes[i].is_none()));
    if axis_lost
        && phases::primary_view_lost(&obs, split, 0.5 * period)
        && reconciled.iter().any(Option::is_some)
    {
        reconciled = [None, None, None, None];
        warnings.push(
            "spins not reported: the direct view lost the spheres for a whole phase, so the velocities are 2-D and the contact impulse cannot check the markers' spins".into(),
        );
    }
    let phase_names = ["a before", "b before", "a after", "b after"];
    let missing: Vec<&str> = (0..4)
        .filter(|&k| reconciled[k].is_none())
        .map(|k| phase_names[k])
        .collect();
    for (k, m) in measured.iter().enumerate() {
        if m.searched && m.reportable().is_some() {
            warnings.push(format!(
                "sphere {} {} the impact: its markers turned too far between frames to be followed from rest; its spin ({:.0} rad/s) was followed from a search over rotations per frame",
                ["a", "b"][k % 2],
                ["before", "after"][k / 2],
                m.fit.as_ref().map_or(0.0, |f| f.omega.norm()),
            ));
        }
    }
    let spin_fits: Option<[&SpinFit; 4]> = match [0, 1, 2, 3].map(|k| reconciled[k].as_ref()) {
        [Some(a), Some(b), Some(c), Some(d)] => Some([a, b, c, d]),
        _ => None,
    };
    let spins = if let Some(f) = spin_fits {
        Some(Spins {
            omega: f.map(|f| f.omega),
            cov: f.map(|f| f.cov),
        })
    } else {
        warnings.push(format!(
            "spin not measured for sphere {} the impact (too few markers tracked over too few frames): spins there, beta, psi1, psi2 and branch_hint are null",
            missing.join(", ")
        ));
        None
    };
    let impact_err = |e: ImpactError| AnalysisError::NoImpact {
        source_name: info.name.clone(),
        message: format!("{e:?}"),
    };
    let d = derive(
        &fits,
        spins.as_ref().map(|s| &s.omega),
        bodies,
        contact_mm,
        g,
    )
    .map_err(impact_err)?;
    let sd = combined_uncertainties(
        &obs,
        &views,
        &ph,
        &fits,
        spin_fits,
        bodies,
        &shared_bias,
        contact_mm,
        split,
        g,
        masses_known,
    )
    .map_err(impact_err)?;
    let t_c = split + d.tau_c;
    if d.closest_mm > contact_mm {
        warnings.push(format!(
            "the fitted trajectories come no closer than {:.2} mm, but contact is at {contact_mm:.2} mm; the spheres' relative velocity changed as only a collision changes it, so the contact was taken where they come closest (their positions are biased by about the difference)",
            d.closest_mm
        ));
    }

    // Axes some view measures, but not for every sphere in every phase: dropped by fit_all.
    let seen_axes: Vec<usize> = (0..3)
        .filter(|&i| views.iter().any(|v| v.axes.contains(&i)))
        .collect();
    let lost_axes: Vec<usize> = seen_axes
        .iter()
        .copied()
        .filter(|&i| fits.iter().all(|f| f.axes[i].is_none()))
        .collect();
    let three_d = views.len() == 2 && lost_axes.is_empty();
    if views.len() < 2 {
        warnings.push(format!(
            "only the {} view is configured: results are 2-D (the missing coordinate is taken as constant)",
            views[0].kind.name()
        ));
    }
    for &i in &lost_axes {
        let missing = phases_missing_axis(&obs, &views, split, 0.5 * period, g, i, min_side);
        // The view that alone measures this axis, where the spheres hid each other.
        let only = views
            .iter()
            .find(|v| v.axes.contains(&i) && !(i == 0 && views.len() == 2))
            .map(|v| v.kind.name())
            .unwrap_or("either");
        warnings.push(format!(
            "{} was not measured for sphere {} the impact (in the {only} view the spheres overlap or hide each other there): results are 2-D, without {}; its components are reported as 0 ± 0",
            ["x", "y", "z"][i],
            missing.join(", "),
            ["x", "y", "z"][i]
        ));
    }
    // Axes one phase took from the others' momentum (`phases::keep_common_axes`).
    for i in (0..3).filter(|&i| fits.iter().any(|f| f.axes[i].is_some_and(|l| l.n == 0))) {
        let missing = phases_missing_axis(&obs, &views, split, 0.5 * period, g, i, min_side);
        warnings.push(format!(
            "{axis} was not measured for sphere {} the impact (the spheres overlap or hide each other in the one view that sees {axis} there): its {axis} velocity there is taken from momentum conservation (masses from spheres.mass_g) and its {axis} at the impact from its own track in the other phase",
            missing.join(", "),
            axis = ["x", "y", "z"][i],
        ));
    }
    let dropped = frames_dropped;
    if dropped > 0 {
        warnings.push(format!(
            "{dropped} frame(s) were dropped by the camera (gaps in frame ids)"
        ));
    }
    let dt_check = (d.tau_intersection - d.tau_contact_distance).abs();
    if dt_check > 2.0 * period {
        warnings.push(format!(
            "impact time from contact distance and from the trajectory intersection differ by {:.3} ms: check spheres.diameter_mm and px_per_mm",
            dt_check * 1e3
        ));
    }

    let beta = beta_where_defined(d.beta.zip(sd.beta), d.psi1.zip(sd.psi1), &mut warnings);
    let est3 = |v: V3, s: V3| Estimate {
        value: [v.x, v.y, v.z],
        uncertainty: [s.x, s.y, s.z],
    };
    let impact_frame = obs
        .iter()
        .min_by(|p, q| (p.time_s - t_c).abs().total_cmp(&(q.time_s - t_c).abs()))
        .map(|f| f.index)
        .unwrap_or(0);
    // 3-D RMS distance of the centres from the fitted trajectory.
    let rms = |f: &SideFit| {
        f.axes
            .iter()
            .flatten()
            .map(|l| l.rms * l.rms)
            .sum::<f64>()
            .sqrt()
    };
    let diameters = |s: usize, kind: ViewKind| -> Option<Scalar> {
        let vi = views.iter().position(|v| v.kind == kind)?;
        let mut ds: Vec<f64> = obs
            .iter()
            .filter_map(|f| f.spheres[s][vi].as_ref().map(|m| m.diameter_px))
            .collect();
        if ds.is_empty() {
            return None;
        }
        ds.sort_by(f64::total_cmp);
        let med = ds[ds.len() / 2];
        let mut dev: Vec<f64> = ds.iter().map(|x| (x - med).abs()).collect();
        dev.sort_by(f64::total_cmp);
        let sigma = 1.4826 * dev[dev.len() / 2];
        Some(Estimate {
            value: med,
            uncertainty: sigma / (ds.len() as f64).sqrt(),
        })
    };
    let tracked_frames: Vec<usize> = obs
        .iter()
        .filter(|f| f.spheres.iter().any(|s| s.iter().any(|m| m.is_some())))
        .map(|f| f.index as usize)
        .collect();
    let position_at_impact = |s: usize| {
        let p = kinematics::pos_vel(&fits[s], d.tau_c, g).0;
        let sd = |i: usize| {
            fits[s].axes[i]
                .map(|l| l.cov[(0, 0)].max(0.0).sqrt())
                .unwrap_or(0.0)
        };
        Estimate {
            value: [p.x, p.y, p.z],
            uncertainty: [sd(0), sd(1), sd(2)],
        }
    };
    let sphere = |s: usize| SphereResult {
        position_impact_mm: Some(position_at_impact(s)),
        velocity_pre_mm_s: est3(d.velocities[s], sd.velocities[s]),
        velocity_post_mm_s: est3(d.velocities[2 + s], sd.velocities[2 + s]),
        spin_pre_rad_s: reconciled[s].as_ref().map(spin_estimate),
        spin_post_rad_s: reconciled[2 + s].as_ref().map(spin_estimate),
        spin_check: spin_checks[s].clone(),
        diameter_px: ViewValues {
            direct: diameters(s, ViewKind::Direct),
            mirror: diameters(s, ViewKind::Mirror),
        },
        markers_tracked: tracked_frames
            .iter()
            .map(|&k| {
                measured[s]
                    .markers_per_frame
                    .get(&k)
                    .or_else(|| measured[2 + s].markers_per_frame.get(&k))
                    .copied()
                    .unwrap_or(0)
            })
            .collect(),
    };
    let tracks: Vec<TrackFrame> = obs
        .iter()
        .filter(|f| f.spheres.iter().any(|s| s.iter().any(|m| m.is_some())))
        .map(|f| {
            let one = |s: usize| -> Option<SphereTrack> {
                let per_view = |kind: ViewKind| {
                    let vi = views.iter().position(|v| v.kind == kind)?;
                    f.spheres[s][vi].as_ref().map(|m| ViewTrack {
                        centre_px: m.centre_px,
                        uncertainty_px: m.sigma_px,
                        diameter_px: m.diameter_px,
                        markers_px: m.markers.iter().map(|k| k.centre_px).collect(),
                    })
                };
                let (direct, mirror) = (per_view(ViewKind::Direct), per_view(ViewKind::Mirror));
                if direct.is_none() && mirror.is_none() {
                    return None;
                }
                let mut centre: [Option<f64>; 3] = [None; 3];
                for (vi, view) in views.iter().enumerate().rev() {
                    if let Some(m) = &f.spheres[s][vi] {
                        for (axis, val) in view.unproject(m.centre_px, f.position_mm[s].as_ref()) {
                            centre[axis] = Some(val);
                        }
                    }
                }
                Some(SphereTrack {
                    direct,
                    mirror,
                    centre_mm: centre,
                })
            };
            TrackFrame {
                frame: f.index,
                frame_id: f.frame_id,
                time_s: f.time_s,
                a: one(0),
                b: one(1),
            }
        })
        .collect();
    let used = |k: usize| fits[k].axes[0].map(|l| l.n as u64).unwrap_or(0);
    let report = Report {
        schema: REPORT_SCHEMA.into(),
        software: Software {
            name: "impactcam".into(),
            version: env!("CARGO_PKG_VERSION").into(),
        },
        source: info,
        dimensionality: if three_d { "3d" } else { "2d" }.into(),
        impact: Impact {
            time_s: Estimate {
                value: t_c,
                uncertainty: sd.tau_c,
            },
            frame: impact_frame,
            time_intersection_s: split + d.tau_intersection,
            contact_distance_mm: contact_mm,
        },
        normal: est3(d.normal, sd.normal),
        e: Some(Estimate {
            value: d.e,
            uncertainty: sd.e,
        }),
        beta,
        psi1: d
            .psi1
            .zip(sd.psi1)
            .map(|(value, uncertainty)| Estimate { value, uncertainty }),
        psi2: d
            .psi2
            .zip(sd.psi2)
            .map(|(value, uncertainty)| Estimate { value, uncertainty }),
        branch_hint: d.psi2.zip(sd.psi2).and_then(|(v, u)| branch_hint(v, u)),
        spheres: Spheres {
            a: sphere(0),
            b: sphere(1),
        },
        tracks,
        quality: Quality {
            frames_total: obs.len() as u64,
            frames_dropped: dropped,
            frames_used_pre: PerSphere {
                a: used(0),
                b: used(1),
            },
            frames_used_post: PerSphere {
                a: used(2),
                b: used(3),
            },
            fit_residual_rms_mm: FitResiduals {
                a_pre: rms(&fits[0]),
                b_pre: rms(&fits[1]),
                a_post: rms(&fits[2]),
                b_post: rms(&fits[3]),
            },
            calibration,
            unmeasured,
            warnings,
        },
    };
    Ok((
        report,
        Details {
            views,
            obs,
            impact_time_s: t_c,
            phases: ph,
            spins: measured,
        },
    ))
}

/// Which Walton branch the data suggest, from the sign of ψ2 alone: sliding keeps the slip's
/// direction (ψ2 > 0 unless just above the break point), sticking with β0 > 0 reverses it. Null
/// when ψ2 is within two standard deviations of zero.
fn branch_hint(psi2: f64, sigma: f64) -> Option<String> {
    if psi2.abs() <= 2.0 * sigma {
        None
    } else if psi2 > 0.0 {
        Some("sliding".into())
    } else {
        Some("sticking".into())
    }
}

#[cfg(test)]
mod tests {
    use super::kinematics::{Fits, Series};
    use super::phases::{free_flight, keep_common_axes};
    use super::second_pass::carry_orientation;
    use super::uncertainty::spin_variance;
    use super::*;
    use nalgebra::Rotation3;

    /// A restitution outside [0, 1] beyond 3σ is no collision's; one within reach of the
    /// bounds by its σ (a plastic impact measured a little below 0, a hard one a little
    /// above 1) is.
    #[test]
    fn a_restitution_no_collision_can_give_is_not_reported() {
        for (e, sigma) in [(-0.31, 0.029), (1.2, 0.05), (-0.05, 0.01)] {
            let why = unphysical_restitution(e, sigma).expect("beyond 3σ");
            assert!(why.contains(&format!("{e:.3}")), "{why}");
        }
        for (e, sigma) in [
            (0.9, 0.01),
            (-0.02, 0.01),
            (1.02, 0.01),
            (0.0, 0.0),
            (1.0, 0.0),
        ] {
            assert_eq!(unphysical_restitution(e, sigma), None, "{e} ± {sigma}");
        }
    }

    /// Frame `k` of a synthetic recording at `dt` s a frame: sphere a measured at `centres_px`
    /// in the views (σ 0.02 px, the default look's diameter, no markers) with its radius
    /// straying by `radius_stray_px`; sphere b nowhere.
    /// Thirty frames 1 ms apart of a alone flying steadily through both views, its radius
    /// straying by `stray_px(k)` in frame k (`frame_of_a`).
    fn steady_phase_of_a(views: &[View], stray_px: &dyn Fn(usize) -> f64) -> Vec<FrameObs> {
        let dt = 1e-3;
        let v = V3::new(400.0, -300.0, 20.0);
        (0..30)
            .map(|k| {
                let p = V3::new(-20.0, 10.0, 0.0) + v * (k as f64 * dt);
                frame_of_a(
                    k,
                    dt,
                    [views[0].project(&p), views[1].project(&p)],
                    stray_px(k),
                )
            })
            .collect()
    }

    fn frame_of_a(k: usize, dt: f64, centres_px: [[f64; 2]; 2], radius_stray_px: f64) -> FrameObs {
        let m = |px: [f64; 2]| {
            Some(tracking::Measurement {
                centre_px: px,
                blob_centroid_px: px,
                sigma_px: [0.02, 0.02],
                diameter_px: 13.7,
                edge_width_px: f64::NAN,
                markers: Vec::new(),
                hidden_in_part: None,
                radius_stray_px,
            })
        };
        FrameObs {
            index: k as u64,
            frame_id: k as u64,
            time_s: k as f64 * dt,
            spheres: [centres_px.map(m).to_vec(), vec![None, None]],
            position_mm: [None, None],
        }
    }

    /// After the impact (no tube there), a sphere the direct view sees in fewer frames than a
    /// phase needs takes its phase from the span the mirror saw it in; before the impact it
    /// keeps the direct view's span (the mirror may see it still rolling in its tube).
    #[test]
    fn a_phase_after_the_impact_the_direct_view_hardly_saw_takes_the_mirrors_span() {
        let dt = 1e-3;
        let mut obs: Vec<FrameObs> = (0..40)
            .map(|k| frame_of_a(k, dt, [[100.0, 40.0], [100.0, 140.0]], 0.0))
            .collect();
        // Direct view: frames 5–8 before the split (19.5 ms), 24–27 after; the mirror all along.
        for (k, f) in obs.iter_mut().enumerate() {
            if !(5..=8).contains(&k) && !(24..=27).contains(&k) {
                f.spheres[0][0] = None;
            }
        }
        let (split, guard) = (19.5e-3, 0.5e-3);
        let after = phases::side_frames(&obs, 0, false, split, guard, 5);
        assert_eq!(after, (21..40).collect::<Vec<_>>());
        // Where four direct frames are a phase's worth, the direct view's span is kept.
        assert_eq!(
            phases::side_frames(&obs, 0, false, split, guard, 4),
            (24..=27).collect::<Vec<_>>()
        );
        let before = phases::side_frames(&obs, 0, true, split, guard, 5);
        assert_eq!(before, (5..=8).collect::<Vec<_>>());
    }

    #[test]
    fn an_axis_missing_in_one_phase_is_dropped_from_all_four() {
        let times: Vec<f64> = (0..10).map(|k| k as f64 * 1e-3).collect();
        let line = |v: f64| -> kinematics::Series { times.iter().map(|&t| (t, v * t)).collect() };
        let full = [line(100.0), line(-200.0), line(5.0)];
        let no_z = [line(100.0), line(-200.0), Vec::new()];
        let mut fits: Fits = [
            SideFit::fit(&full, 0.0, 0.0),
            SideFit::fit(&full, 0.0, 0.0),
            SideFit::fit(&no_z, 0.0, 0.0),
            SideFit::fit(&full, 0.0, 0.0),
        ];
        assert!(fits[0].axes[2].is_some());
        assert_eq!(keep_common_axes(&mut fits, None), vec![2]);
        assert!(fits
            .iter()
            .all(|f| f.axes[2].is_none() && f.axes[0].is_some()));
        // Nothing to drop when every phase has every axis it had.
        assert!(keep_common_axes(&mut fits, None).is_empty());
    }

    /// A spin the second pass measured 5 rad/s from the first pass's, with a σ of 1 rad/s:
    /// its σ along the difference becomes √26, across it stays 1, and its influences still
    /// sum to its covariance (which `uncertainty::spin_variance` relies on); the same spin
    /// measured again leaves it as it was.
    #[test]
    fn a_spin_the_passes_disagree_on_carries_the_difference_in_its_sigma() {
        let omega = V3::new(1.0, -25.0, 230.0);
        let influence = [
            (3, V3::new(1.0, 0.0, 0.0)),
            (4, V3::new(0.0, 1.0, 0.0)),
            (5, V3::new(0.0, 0.0, 1.0)),
        ];
        let fit = SpinFit {
            omega,
            cov: nalgebra::Matrix3::identity(),
            pairs: 20,
            frame_influence: influence.to_vec(),
        };
        let mut widened = fit.clone();
        widen_by_first_pass(&mut widened, omega - V3::new(5.0, 0.0, 0.0), 3);
        assert!((widened.cov[(0, 0)] - 26.0).abs() < 1e-12);
        assert_eq!(widened.cov[(1, 1)], 1.0);
        assert_eq!(widened.cov[(0, 1)], 0.0);
        let sum = widened
            .frame_influence
            .iter()
            .fold(nalgebra::Matrix3::zeros(), |c, (_, d)| {
                c + d * d.transpose()
            });
        assert!((sum - widened.cov).norm() < 1e-12);
        // One source more, apart from the frames'.
        assert_eq!(widened.frame_influence.len(), 4);
        assert!(influence
            .iter()
            .all(|(f, _)| *f != widened.frame_influence[3].0));
        let mut same = fit.clone();
        widen_by_first_pass(&mut same, omega, 3);
        assert_eq!(same.cov, fit.cov);
        assert_eq!(same.frame_influence.len(), 3);
    }

    /// With the masses known, a coordinate one phase lacks is taken from the other three:
    /// its velocity from momentum (a after, masses 2 and 1 g: 2·(v − 5) + 1·(−7 − 9) = 0, v = 13),
    /// its position at the impact the same sphere's before it, and the variance those give
    /// it; two phases without it, or no masses, and it is dropped as before.
    #[test]
    fn an_axis_one_phase_lacks_is_taken_from_the_others_momentum() {
        let times: Vec<f64> = (0..10).map(|k| k as f64 * 1e-3 - 5e-3).collect();
        let series = |z0: f64, vz: f64, noise: f64| -> [kinematics::Series; 3] {
            let jitter = |k: usize| if k.is_multiple_of(2) { noise } else { -noise };
            let line = |p0: f64, v: f64| -> kinematics::Series {
                times
                    .iter()
                    .enumerate()
                    .map(|(k, &t)| (t, p0 + v * t + jitter(k)))
                    .collect()
            };
            [line(0.0, 100.0), line(0.0, -200.0), line(z0, vz)]
        };
        let no_z = |s: [kinematics::Series; 3]| [s[0].clone(), s[1].clone(), Vec::new()];
        let fits_with = |missing: &[usize]| -> Fits {
            let zs = [(1.5, 5.0), (-1.5, 9.0), (1.5, 0.0), (-1.5, -7.0)];
            [0, 1, 2, 3].map(|k| {
                let s = series(zs[k].0, zs[k].1, 1e-3);
                SideFit::fit(&if missing.contains(&k) { no_z(s) } else { s }, 0.0, 0.0)
            })
        };
        let masses = [2.0, 1.0];
        let mut fits = fits_with(&[2]);
        assert!(keep_common_axes(&mut fits, Some(masses)).is_empty());
        let z = fits[2].axes[2].expect("a's z after the impact, from the others");
        let fitted = |k: usize| fits[k].axes[2].expect("measured");
        let v = fitted(0).v + (fitted(1).v - fitted(3).v) / 2.0;
        assert!(
            (z.v - v).abs() < 1e-9 && (v - 13.0).abs() < 0.1,
            "v {} vs {v}",
            z.v
        );
        assert_eq!(z.p0, fitted(0).p0);
        assert!((z.p0 - 1.5).abs() < 1e-3, "p0 {}", z.p0);
        assert_eq!(z.n, 0, "marked as measured by no frame");
        let var = |k: usize| fits[k].axes[2].map_or(f64::NAN, |l| l.cov[(1, 1)]);
        let expected = var(0) + (var(1) + var(3)) / 4.0;
        assert!(var(0) > 0.0 && (z.cov[(1, 1)] - expected).abs() < 1e-9 * expected);
        // The momentum check leaves that axis out: it holds there by construction.
        assert!(momentum::combination(&fits, [-2.0, -1.0, 2.0, 1.0])
            .iter()
            .all(|(i, _, _)| *i != 2));
        let mut two = fits_with(&[2, 3]);
        assert_eq!(keep_common_axes(&mut two, Some(masses)), vec![2]);
        let mut unknown = fits_with(&[2]);
        assert_eq!(keep_common_axes(&mut unknown, None), vec![2]);
    }

    /// A sphere seen rolling down its tube (vertical acceleration a fifth of g) for 30 frames,
    /// then flying for 40 before the impact: only the flight is kept for the fit.
    #[test]
    fn frames_still_in_the_tube_are_left_out_of_the_flight() {
        let cfg = Config::default_config();
        let views = geometry::views(&cfg);
        let g = cfg.analysis.gravity_mm_s2;
        let dt = 1e-3;
        let exit = 30;
        // Positions and velocities at the tube exit, then ballistic.
        let (p_exit, v_exit) = (V3::new(-40.0, 20.0, 0.0), V3::new(400.0, -300.0, 0.0));
        let obs: Vec<FrameObs> = (0..70)
            .map(|k| {
                let tau = (k as f64 - exit as f64) * dt;
                let a = if k < exit { 0.2 * g } else { g };
                let p = p_exit + v_exit * tau + V3::new(0.0, -0.5 * a * tau * tau, 0.0);
                frame_of_a(k, dt, [views[0].project(&p), views[1].project(&p)], 0.0)
            })
            .collect();
        let all: Vec<usize> = (0..70).collect();
        let kept = free_flight(&obs, &views, 0, &all, true, g);
        assert!(
            kept.first()
                .is_some_and(|&f| (exit - 2..=exit + 1).contains(&f))
                && kept.len() >= 38,
            "kept frames {:?}..{:?} ({})",
            kept.first(),
            kept.last(),
            kept.len()
        );
    }

    /// A phase whose x the mirror sees drifting away from the direct view's by 20 mm/s (a bias
    /// one view's centres share from frame to frame, which that view's own line fit and the
    /// jackknife over frames cannot see) gives its difference and the excess beyond twice its
    /// σ; the same phase with both views agreeing gives nothing to add.
    #[test]
    fn an_x_velocity_the_views_disagree_on_gives_its_excess() {
        let cfg = Config::default_config();
        let views = geometry::views(&cfg);
        let dt = 1e-3;
        let v = V3::new(400.0, -300.0, 20.0);
        let recording = |mirror_drift_mm_s: f64| -> Vec<FrameObs> {
            (0..30)
                .map(|k| {
                    let t = k as f64 * dt;
                    let p = V3::new(-20.0, 10.0, 0.0) + v * t;
                    // Centre noise of ±0.02 px, the same in every run of the test.
                    let wobble = 0.02 * ((k * 7919) % 13) as f64 / 6.0 - 0.02;
                    let at = |vi: usize, drift_mm: f64| {
                        let px = views[vi].project(&(p + V3::new(drift_mm, 0.0, 0.0)));
                        [px[0] + wobble, px[1] - wobble]
                    };
                    frame_of_a(k, dt, [at(0, 0.0), at(1, mirror_drift_mm_s * t)], 0.0)
                })
                .collect()
        };
        let frames: Vec<usize> = (0..30).collect();
        let biased = recording(20.0);
        let (d, sigma, excess) = phases::x_views_disagree(&biased, &views, 0, &frames, 0.015)
            .expect("a 20 mm/s disagreement is beyond twice its σ");
        assert!((d + 20.0).abs() < 1.0, "direct − mirror {d:+.2} mm/s");
        assert!(sigma < 2.0, "σ {sigma:.2} mm/s");
        assert!((excess * excess - (d * d - 4.0 * sigma * sigma)).abs() < 1e-9);
        assert!(excess > 15.0, "excess {excess:.2} mm/s");
        let agreeing = recording(0.0);
        assert!(phases::x_views_disagree(&agreeing, &views, 0, &frames, 0.015).is_none());
    }

    /// A phase of 30 frames whose last four radii stray by 0.5 px (a blurred neighbour's edge
    /// before contact): their possible shift of the velocity, in full over the run, is what
    /// comes back for the axes the direct view measures; strays at the radius's noise level
    /// alone, scattered through the phase, give next to nothing.
    #[test]
    fn a_run_of_misfit_radii_at_one_end_of_a_phase_bounds_its_velocity() {
        let cfg = Config::default_config();
        let views = geometry::views(&cfg);
        let recording = |stray_px: &dyn Fn(usize) -> f64| steady_phase_of_a(&views, stray_px);
        let frames: Vec<usize> = (0..30).collect();
        // Noise-level strays, ±0.02 px, alternating.
        let noise = |k: usize| if k.is_multiple_of(2) { 0.02 } else { -0.02 };
        let clean = phases::stray_velocity(&recording(&noise), &views, 0, &frames);
        assert!(clean.iter().all(|x| *x < 1e-9), "{clean:?} mm/s");
        let misfit = |k: usize| if k >= 26 { 0.5 } else { noise(k) };
        let shift = phases::stray_velocity(&recording(&misfit), &views, 0, &frames);
        // Frames 26–29 lie 11.5–14.5 frames after the phase's mean time; Σ(t − t̄)² = 2247.5 ms².
        let px_per_mm = views[0].px_per_mm;
        let beyond = (0.25f64 - 0.02f64.powi(2) * 1.4826f64.powi(2)).sqrt();
        let expected = (11.5 + 12.5 + 13.5 + 14.5) * 1e-3 * beyond
            / std::f64::consts::SQRT_2
            / px_per_mm
            / 2247.5e-6;
        for axis in [0, 1] {
            assert!(
                (shift[axis] - expected).abs() < 1e-6 * expected,
                "axis {axis}: {:.3} mm/s, expected {expected:.3}",
                shift[axis]
            );
        }
        assert!(
            shift[2] > 0.0,
            "the mirror's z has the same strays: {shift:?}"
        );
    }

    /// A phase of 30 frames whose diameters rise by 0.1 px in both views, steadily (a blurred
    /// disc's held radius drifting along its phase): half that rise in mm/s, split over each
    /// view's two axes, comes back as the velocity it may have moved; diameters that only
    /// scatter give nothing.
    #[test]
    fn a_drift_of_the_diameters_along_a_phase_bounds_its_velocity() {
        let cfg = Config::default_config();
        let views = geometry::views(&cfg);
        let recording = |diameter_px: &dyn Fn(usize) -> f64| -> Vec<FrameObs> {
            let mut obs = steady_phase_of_a(&views, &|_| 0.0);
            for (k, f) in obs.iter_mut().enumerate() {
                for m in f.spheres[0].iter_mut().flatten() {
                    m.diameter_px = diameter_px(k);
                }
            }
            obs
        };
        let frames: Vec<usize> = (0..30).collect();
        let noise = |k: usize| if k.is_multiple_of(2) { 0.01 } else { -0.01 };
        let still =
            phases::diameter_drift_velocity(&recording(&|k| 13.7 + noise(k)), &views, 0, &frames);
        assert_eq!(still, [0.0; 3], "diameters that only scatter");
        let rising = |k: usize| 13.7 + 0.1 * k as f64 / 29.0 + noise(k);
        let drift = phases::diameter_drift_velocity(&recording(&rising), &views, 0, &frames);
        // 0.1 px over 29 ms, in mm at each view's scale, halved, over √2; x is the larger of
        // the two views', y the direct view's, z the mirror's.
        let of = |vi: usize| 0.5 * (0.1 / 29e-3 / views[vi].px_per_mm) / std::f64::consts::SQRT_2;
        let expected = [of(0).max(of(1)), of(0), of(1)];
        for (axis, (d, e)) in drift.iter().zip(expected).enumerate() {
            assert!(
                (d - e).abs() < 0.1 * e,
                "axis {axis}: {d:.3} mm/s, expected about {e:.3}"
            );
        }
    }

    /// A dot seen before the impact is carried to a frame after it by the spin before the
    /// impact up to it and the spin after it from there; its σ grows with both; and it is not
    /// carried across where the spin on the far side is unknown.
    #[test]
    fn dots_are_carried_through_the_impact_with_both_spins() {
        let fit = |w: V3, sigma: f64| SpinFit {
            omega: w,
            cov: nalgebra::Matrix3::identity() * (sigma * sigma / 3.0),
            pairs: 10,
            frame_influence: Vec::new(),
        };
        let (before, after) = (
            fit(V3::new(0.0, 0.0, 200.0), 1.0),
            fit(V3::new(50.0, 0.0, 120.0), 2.0),
        );
        let (t_c, t0, t1) = (0.100, 0.090, 0.104);
        let (turn, sigma) = carry_orientation(t0, t1, t_c, Some(&before), Some(&after)).unwrap();
        let expected = Rotation3::from_scaled_axis(after.omega * 0.004)
            * Rotation3::from_scaled_axis(before.omega * 0.010);
        assert!((turn.matrix() - expected.matrix()).norm() < 1e-12);
        assert!(
            (sigma - (1.0 * 0.010 + 2.0 * 0.004)).abs() < 1e-12,
            "{sigma}"
        );
        // Back again: the inverse turn.
        let (back, _) = carry_orientation(t1, t0, t_c, Some(&before), Some(&after)).unwrap();
        assert!(((back * turn).matrix() - nalgebra::Matrix3::identity()).norm() < 1e-12);
        // One spin of the pair was not measured: only its own side is reachable.
        assert!(carry_orientation(t0, t1, t_c, Some(&before), None).is_none());
        assert!(carry_orientation(t0, 0.095, t_c, Some(&before), None).is_some());
    }

    /// One frame that turns both spheres' spins after the impact by opposite amounts leaves
    /// R_a·ω_a + R_b·ω_b, and so β, unchanged: the spins' variance of β must see that, where
    /// propagating each spin's covariance on its own would not. The same turn in the same
    /// direction doubles β's change.
    #[test]
    fn spins_moved_by_the_same_frame_are_propagated_together() {
        let g = 9806.65;
        let radius = 3.0;
        // Oblique along x, slipping along y: g_t ≠ 0, t along y, n along x.
        let times = |sign: f64| -> Vec<f64> { (1..15).map(|k| sign * k as f64 * 1e-3).collect() };
        let side = |p0: V3, v: V3, ts: &[f64]| {
            let line = |i: usize| -> Series {
                let gi = if i == 1 { -g } else { 0.0 };
                ts.iter()
                    .map(|&t| (t, p0[i] + v[i] * t + 0.5 * gi * t * t))
                    .collect()
            };
            SideFit::fit(&[line(0), line(1), line(2)], 0.0, g)
        };
        let (va, vb) = (V3::new(500.0, 100.0, 0.0), V3::new(-500.0, -100.0, 0.0));
        let (va2, vb2) = (V3::new(-450.0, 60.0, 0.0), V3::new(450.0, -60.0, 0.0));
        let (pa, pb) = (V3::new(-radius, 0.0, 0.0), V3::new(radius, 0.0, 0.0));
        let fits: Fits = [
            side(pa, va, &times(-1.0)),
            side(pb, vb, &times(-1.0)),
            side(pa, va2, &times(1.0)),
            side(pb, vb2, &times(1.0)),
        ];
        let omega = [
            V3::new(0.0, 0.0, -80.0),
            V3::new(0.0, 0.0, 90.0),
            V3::new(0.0, 0.0, -60.0),
            V3::new(0.0, 0.0, 70.0),
        ];
        let fit = |influence: Vec<(usize, V3)>| SpinFit {
            omega: V3::zeros(),
            cov: nalgebra::Matrix3::zeros(),
            pairs: 10,
            frame_influence: influence,
        };
        let still = fit(Vec::new());
        let turn = V3::new(0.0, 0.0, 2.0);
        let beta_var = |a_post: &SpinFit, b_post: &SpinFit| {
            let v = spin_variance(
                &fits,
                &omega,
                [&still, &still, a_post, b_post],
                [radius; 2].into(),
                2.0 * radius,
                g,
            )
            .unwrap();
            v[v.len() - 1]
        };
        let (only_a, opposite, same) = (
            beta_var(&fit(vec![(20, turn)]), &still),
            beta_var(&fit(vec![(20, turn)]), &fit(vec![(20, -turn)])),
            beta_var(&fit(vec![(20, turn)]), &fit(vec![(20, turn)])),
        );
        assert!(only_a > 1e-6, "one spin turned must move β: {only_a}");
        assert!(
            opposite < 1e-9 * only_a,
            "opposite turns cancel: {opposite} against {only_a}"
        );
        assert!(
            (same / only_a - 4.0).abs() < 1e-3,
            "same turns add: {same} against {only_a}"
        );
        // Different frames are independent: their variances add.
        let apart = beta_var(&fit(vec![(20, turn)]), &fit(vec![(21, -turn)]));
        assert!(
            (apart / only_a - 2.0).abs() < 1e-3,
            "{apart} against {only_a}"
        );
    }
}
