//! Everything after per-frame measurement, for one geometry taken as exact: the spheres' names
//! through the impact, world centres, the mirror's refined map, the impact found by iterating
//! the four ballistic fits, momentum, the velocities' shared biases, the spins (`spins`) and
//! the report (`assemble`). `analysis::analyze_observations` runs it once, or again per
//! geometry term whose σ the config gives.

mod assemble;
mod spins;

#[cfg(test)]
pub(super) use spins::{first_pass_source, widen_by_first_pass};

use super::calibration::{self, calibrate_mirror};
use super::flight_misfit;
use super::geometry::View;
use super::kinematics::{derive, Bodies, Fits, ImpactError, SideFit};
use super::phases::{self, fit_all, flight_phases, phases_missing_axis};
use super::report::{Calibration, Report, Unmeasured};
use super::tracking::FrameObs;
use super::uncertainty::{beta_where_defined, combined_uncertainties};
use super::{
    markers, momentum, names_through_impact, overlap, radius_misfit, world, AnalysisError, Details,
    Input,
};
use crate::config::Config;

/// The config's numbers every step below reads, taken once.
struct Setup {
    /// Gravity, mm/s².
    g: f64,
    contact_mm: f64,
    /// The frame period, s.
    period: f64,
    min_side: usize,
    radii: [f64; 2],
    masses: [f64; 2],
    /// Where the masses are known: the phases' velocities may then be combined under momentum.
    masses_known: Option<[f64; 2]>,
}

impl Setup {
    fn of(cfg: &Config, frame_rate_hz: f64) -> Setup {
        let radii = [cfg.spheres.sphere(0).0 / 2.0, cfg.spheres.sphere(1).0 / 2.0];
        let masses = [cfg.spheres.sphere(0).1, cfg.spheres.sphere(1).1];
        let momentum_ok = masses.iter().all(|m| m.is_finite() && *m > 0.0);
        Setup {
            g: cfg.analysis.gravity_mm_s2,
            contact_mm: cfg.spheres.contact_mm(),
            period: 1.0 / frame_rate_hz,
            min_side: cfg.analysis.min_frames_per_side as usize,
            radii,
            masses,
            // An axis one phase did not measure is taken from the others' momentum where the
            // masses are known (`phases::keep_common_axes`).
            masses_known: momentum_ok.then_some(masses),
        }
    }

    fn fits_at(&self, obs: &[FrameObs], views: &[View], split: f64) -> Fits {
        fit_all(
            obs,
            views,
            split,
            0.5 * self.period,
            self.g,
            self.min_side,
            self.masses_known,
        )
    }
}

/// The observations named and placed in the world, with the mirror's map refined where it
/// could be.
struct Placed {
    views: Vec<View>,
    obs: Vec<FrameObs>,
    calibration: Option<Calibration>,
    /// What the refined mirror scale is known to, as a fraction (its z velocities carry it).
    mirror_scale_sigma: f64,
    /// What renaming and the hidden discs' widening said, in that order.
    notes: Vec<String>,
}

fn place(mut obs: Vec<FrameObs>, mut views: Vec<View>, cfg: &Config) -> Placed {
    markers::drop_in_the_other_disc(&mut obs);
    // Names checked through the impact before anything pairs the spheres' frames up (the
    // closest approach does not depend on the names).
    let mut notes = match names_through_impact::check_time(&obs, &views, cfg.spheres.contact_mm()) {
        Some(t) => {
            let names: Vec<&str> = views.iter().map(|v| v.kind.name()).collect();
            let r_mm = cfg.spheres.sphere(0).0.min(cfg.spheres.sphere(1).0) / 2.0;
            let radii_px: Vec<f64> = views.iter().map(|v| v.px_per_mm * r_mm).collect();
            names_through_impact::check(&mut obs, &names, &radii_px, t)
        }
        None => Vec::new(),
    };
    radius_misfit::widen(&mut obs);
    world::place(&mut obs, &views);
    let calibration = calibrate_mirror(&obs, &mut views);
    let mirror_scale_sigma = if calibration.as_ref().is_some_and(|c| c.refined) {
        world::place(&mut obs, &views);
        calibration::mirror_scale_sigma(&obs, &views).unwrap_or(0.0)
    } else {
        0.0
    };
    let diameters_mm = [cfg.spheres.sphere(0).0, cfg.spheres.sphere(1).0];
    radius_misfit::widen_against_the_map(&mut obs, &views, diameters_mm);
    notes.extend(overlap::widen_hidden(&mut obs, &views));
    Placed {
        views,
        obs,
        calibration,
        mirror_scale_sigma,
        notes,
    }
}

/// The impact time, s on the source's clock: the split between the phases moved to where the
/// four fits put the contact, until it stays (at most eight rounds).
fn impact_split(
    obs: &[FrameObs],
    views: &[View],
    set: &Setup,
    source_name: &str,
) -> Result<f64, AnalysisError> {
    let input_err = |message: String| AnalysisError::Input {
        source_name: source_name.to_string(),
        message,
    };
    let no_impact = |message: String| AnalysisError::NoImpact {
        source_name: source_name.to_string(),
        message,
    };
    let primary = 0; // views[0] is direct when present, else the mirror
    let Some((mut split, _)) = phases::closest_approach(obs, views, primary) else {
        return Err(input_err(format!(
            "spheres a and b were never both measured in the {} view ({} frames; see the geometry and threshold settings)",
            views[primary].kind.name(),
            obs.len()
        )));
    };
    let min_side = set.min_side;
    let contact_mm = set.contact_mm;
    // Closest in the first or the last frame where both views see both spheres, and far from
    // touching there: the recording does not hold the impact. Said so, rather than as a phase
    // with too few frames (a shallow tube's spheres roll slowly, and a 280-frame recording of
    // a 15° tube on hw-sim ended 16 ms before they met, 18 mm apart: "only 0 usable frame(s)
    // of sphere a before the impact").
    let seen = phases::separations_mm(obs, views);
    if let (Some(&(t, d)), Some(first), Some(last)) = (
        seen.iter().min_by(|a, b| a.1.total_cmp(&b.1)),
        seen.first(),
        seen.last(),
    ) {
        if d > 1.5 * contact_mm && (t == last.0 || t == first.0) {
            let (which, what) = if t == last.0 {
                (
                    "last",
                    "the impact comes after the recording ends (record longer, or trigger later)",
                )
            } else {
                (
                    "first",
                    "the impact came before the recording began (trigger earlier)",
                )
            };
            return Err(no_impact(format!(
                "the spheres are closest in the {which} frame where both views see both (t = {t:.4} s), {d:.1} mm apart (contact at {contact_mm:.2} mm): {what}"
            )));
        }
    }
    for _ in 0..8 {
        let fits = set.fits_at(obs, views, split);
        for (k, side) in fits.iter().enumerate() {
            let n = side.axes[0].map(|l| l.n).unwrap_or(0);
            if n < min_side {
                let which = ["a before", "b before", "a after", "b after"][k];
                return Err(input_err(format!(
                    "only {n} usable frame(s) of sphere {which} the impact, need analysis.min_frames_per_side = {min_side}"
                )));
            }
        }
        let d = match derive(&fits, None, set.radii, contact_mm, set.g) {
            Ok(d) => d,
            Err(ImpactError::NoContact { closest_mm }) => {
                return Err(no_impact(format!(
                    "the spheres' trajectories come no closer than {closest_mm:.2} mm, but contact is at {contact_mm:.2} mm"
                )))
            }
            Err(ImpactError::NotApproaching) => {
                return Err(no_impact(
                    "the spheres are not approaching each other before the closest frame".into(),
                ))
            }
        };
        let new_split = split + d.tau_c;
        let moved = (new_split - split).abs();
        split = new_split;
        if moved < 1e-7 {
            break;
        }
    }
    Ok(split)
}

/// The spheres as the impact sees them: momentum across the impact (`momentum`), the four
/// phases' velocities checked against it and, where they agree within 3σ, combined under it
/// from here on.
fn bodies(fits: &Fits, set: &Setup, warnings: &mut Vec<String>) -> Bodies {
    Bodies {
        radii: set.radii,
        impulse: None,
        momentum: match set
            .masses_known
            .and_then(|masses| momentum::check(fits, masses))
        {
            Some((_, _, true)) => Some(momentum::Momentum::of(fits, set.masses)),
            Some((chi2, dof, false)) => {
                warnings.push(format!(
                    "the velocities before and after the impact do not conserve momentum (χ² = {chi2:.1} for {dof} degree(s) of freedom, beyond 3σ; masses from spheres.mass_g): they are reported as fitted, not combined"
                ));
                None
            }
            None => None,
        },
    }
}

/// Each phase's velocity bias the centres may share, mm/s per axis: the views' x disagreement,
/// and the misfits their radii show (`phases::stray_velocity`), the larger of the two on x; and
/// on z, which the mirror alone measures, what the refined mirror scale's σ does to it
/// (`calibration::mirror_scale_sigma`), in quadrature.
fn shared_biases(
    placed: &Placed,
    fits: &Fits,
    ph: &[Vec<usize>; 4],
    split: f64,
    warnings: &mut Vec<String>,
) -> [[f64; 3]; 4] {
    let (obs, views) = (&placed.obs, &placed.views);
    // Each phase's x velocity from the direct view against the mirror's (`x_views_disagree`):
    // where they differ beyond twice their σ, the excess is one more error of that velocity.
    let x_views: [Option<f64>; 4] = [0, 1, 2, 3].map(|k| {
        let (d, sigma, excess) = phases::x_views_disagree(obs, views, k % 2, &ph[k], split)?;
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
    [0, 1, 2, 3].map(|k| {
        let mut stray = phases::stray_velocity(obs, views, k % 2, &ph[k]);
        let drift = phases::diameter_drift_velocity(obs, views, k % 2, &ph[k]);
        for (a, b) in stray.iter_mut().zip(drift) {
            *a = a.hypot(b);
        }
        stray[0] = stray[0].max(x_views[k].unwrap_or(0.0));
        if let Some(z) = &fits[k].axes[2] {
            stray[2] = stray[2].hypot(z.v.abs() * placed.mirror_scale_sigma);
        }
        stray
    })
}

/// Everything after per-frame measurement, the config's geometry taken as exact.
pub(super) fn observations_once(
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
        settle_handedness,
        handedness_doubt,
    } = input;
    let set = Setup::of(cfg, info.frame_rate_hz);
    let mut placed = place(obs, views, cfg);
    let split = impact_split(&placed.obs, &placed.views, &set, &info.name)?;
    // Final fits referenced at the impact time, so p0 and v are the state at impact.
    let fits = set.fits_at(&placed.obs, &placed.views, split);
    // Each sphere's flights meet where it was at the impact, or nothing after it is that
    // sphere's: no result rather than one a name or a view got wrong.
    names_through_impact::flights_meet(&fits, set.g, set.contact_mm).map_err(|message| {
        AnalysisError::NoImpact {
            source_name: info.name.clone(),
            message,
        }
    })?;
    let mut warnings = input_warnings;
    warnings.append(&mut placed.notes);
    let bodies = bodies(&fits, &set, &mut warnings);

    // Spins, one constant vector per sphere and flight phase.
    let ph = flight_phases(
        &placed.obs,
        &placed.views,
        split,
        0.5 * set.period,
        set.g,
        set.min_side,
    );
    let shared_bias = shared_biases(&placed, &fits, &ph, split, &mut warnings);
    let Placed {
        views,
        obs,
        mut calibration,
        ..
    } = placed;
    if let Some(c) = calibration.as_mut() {
        warnings.extend(calibration::check_geometry(c, &obs, &views, &ph, set.g));
    }
    let spins = spins::PhaseSpins::of(
        &obs,
        &views,
        &fits,
        &ph,
        split,
        &set,
        bodies,
        &shared_bias,
        cfg,
        first_pass_spins,
        settle_handedness,
        handedness_doubt.as_ref(),
        &mut warnings,
    );
    let spin_fits = spins.all_four(&mut warnings);
    // From here on the spins move with the impulse they were reconciled with.
    let bodies = Bodies {
        impulse: spins.impulse,
        ..bodies
    };
    let impact_err = |e: ImpactError| AnalysisError::NoImpact {
        source_name: info.name.clone(),
        message: format!("{e:?}"),
    };
    let d = derive(
        &fits,
        spin_fits.map(|f| f.map(|f| f.omega)).as_ref(),
        bodies,
        set.contact_mm,
        set.g,
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
        set.contact_mm,
        split,
        set.g,
        set.masses_known,
    )
    .map_err(impact_err)?;
    let three_d = result_warnings(
        &obs,
        &views,
        &fits,
        &d,
        split,
        &set,
        frames_dropped,
        &mut warnings,
    );
    let beta = beta_where_defined(d.beta.zip(sd.beta), d.psi1.zip(sd.psi1), &mut warnings);
    // The centres as reported: their σ checked against the flights (the second pass and the
    // estimates keep their own).
    let reported = flight_misfit::widened(&obs, &views, &fits, &ph, split, set.g);
    let report = assemble::Parts {
        info,
        views: &views,
        obs: &reported,
        fits: &fits,
        derived: &d,
        sigma: &sd,
        split,
        g: set.g,
        contact_mm: set.contact_mm,
        three_d,
        beta,
        spins: &spins,
        frames_dropped,
        calibration,
        unmeasured,
        warnings,
    }
    .report();
    Ok((
        report,
        Details {
            views,
            obs,
            impact_time_s: split + d.tau_c,
            phases: ph,
            spins: spins.measured,
            handedness: spins.handedness,
        },
    ))
}

/// What the result lacks or where its checks disagree, said as warnings; whether it is 3-D
/// (both views, no axis lost).
#[allow(clippy::too_many_arguments)]
fn result_warnings(
    obs: &[FrameObs],
    views: &[View],
    fits: &Fits,
    d: &super::kinematics::Derived,
    split: f64,
    set: &Setup,
    frames_dropped: u64,
    warnings: &mut Vec<String>,
) -> bool {
    let (period, g, min_side, contact_mm) = (set.period, set.g, set.min_side, set.contact_mm);
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
        .filter(|&i| fits.iter().all(|f: &SideFit| f.axes[i].is_none()))
        .collect();
    let three_d = views.len() == 2 && lost_axes.is_empty();
    if views.len() < 2 {
        warnings.push(format!(
            "only the {} view is configured: results are 2-D (the missing coordinate is taken as constant)",
            views[0].kind.name()
        ));
    }
    for &i in &lost_axes {
        let missing = phases_missing_axis(obs, views, split, 0.5 * period, g, i, min_side);
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
        let missing = phases_missing_axis(obs, views, split, 0.5 * period, g, i, min_side);
        warnings.push(format!(
            "{axis} was not measured for sphere {} the impact (the spheres overlap or hide each other in the one view that sees {axis} there): its {axis} velocity there is taken from momentum conservation (masses from spheres.mass_g) and its {axis} at the impact from its own track in the other phase",
            missing.join(", "),
            axis = ["x", "y", "z"][i],
        ));
    }
    if frames_dropped > 0 {
        warnings.push(format!(
            "{frames_dropped} frame(s) were dropped by the camera (gaps in frame ids)"
        ));
    }
    let dt_check = (d.tau_intersection - d.tau_contact_distance).abs();
    if dt_check > 2.0 * period {
        warnings.push(format!(
            "impact time from contact distance and from the trajectory intersection differ by {:.3} ms: check spheres.diameter_mm and px_per_mm",
            dt_check * 1e3
        ));
    }
    three_d
}
