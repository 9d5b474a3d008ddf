//! Tests of the analysis's steps after per-frame measurement: phases, fits, spins and their
//! uncertainties, the impulse check.

use super::kinematics::{Fits, Series, SideFit};
use super::observations::widen_by_first_pass;
use super::phases::{free_flight, keep_common_axes};
use super::rotation::SpinFit;
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
            sigma_common_px: 0.0,
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

/// The part of the centres' σ every frame shares (`radius_misfit::widen_against_the_map`)
/// moves a phase's line, not its slope: the σ floor its fit takes from the centres leaves it
/// out, while the same σ not marked as shared is taken in.
#[test]
fn a_shared_misfit_widens_the_centres_but_not_their_lines_slope() {
    let cfg = Config::default_config();
    let views = geometry::views(&cfg);
    let frames: Vec<usize> = (0..30).collect();
    let widened = |shared: bool| {
        let mut obs = steady_phase_of_a(&views, &|_| 0.0);
        for m in obs
            .iter_mut()
            .flat_map(|f| f.spheres[0].iter_mut().flatten())
        {
            m.sigma_px = m.sigma_px.map(|s| (s * s + 0.01).sqrt());
            m.sigma_common_px = if shared { 0.1 } else { 0.0 };
        }
        phases::series_and_sigma(&obs, &views, 0, &frames).1
    };
    let plain =
        phases::series_and_sigma(&steady_phase_of_a(&views, &|_| 0.0), &views, 0, &frames).1;
    let shared = widened(true);
    let own = widened(false);
    for axis in 0..3 {
        assert!(
            (shared[axis] - plain[axis]).abs() < 1e-12 * plain[axis],
            "axis {axis}: {} against {} mm",
            shared[axis],
            plain[axis]
        );
        assert!(
            own[axis] > 5.0 * plain[axis],
            "axis {axis}: {} mm",
            own[axis]
        );
    }
}

/// The centres the report gives carry their scatter about the flight fitted through them: a
/// view whose centres scatter three times their σ about it has its σ scaled by the scatter
/// (from the median, so one blunder does not set it), a blunder beyond 3σ of that carries
/// its own disagreement, and centres on their flight keep their σ.
#[test]
fn centres_that_scatter_about_their_flight_beyond_their_sigma_say_so_in_the_report() {
    let cfg = Config::default_config();
    let views = geometry::views(&cfg);
    let frames: Vec<usize> = (0..30).collect();
    let mut obs = steady_phase_of_a(&views, &|_| 0.0);
    // The direct view's centres ±0.06 px off their flight in u, alternating (σ 0.02 px); frame
    // 20's 1 px off in v.
    for (k, f) in obs.iter_mut().enumerate() {
        let m = f.spheres[0][0].as_mut().unwrap();
        m.centre_px[0] += if k.is_multiple_of(2) { 0.06 } else { -0.06 };
        if k == 20 {
            m.centre_px[1] += 1.0;
        }
    }
    let (series, floor, weights) = phases::series_and_sigma(&obs, &views, 0, &frames);
    let fit = SideFit::fit_weighted(&series, &weights, 0.0, 0.0, floor);
    let fits: Fits = [fit; 4];
    let ph = [frames.clone(), Vec::new(), Vec::new(), Vec::new()];
    let reported = flight_misfit::widened(&obs, &views, &fits, &ph, 0.0, 0.0);
    // What each centre's error is, about the flight actually fitted (the alternation leaves it
    // a few thousandths of a pixel off the true one).
    let errors: Vec<[f64; 2]> = frames
        .iter()
        .map(|&k| {
            let (p, _) = kinematics::pos_vel(&fit, obs[k].time_s, 0.0);
            let c = views[0].project(&p);
            let m = obs[k].spheres[0][0].as_ref().unwrap();
            [m.centre_px[0] - c[0], m.centre_px[1] - c[1]]
        })
        .collect();
    let direct = |k: usize| reported[k].spheres[0][0].as_ref().unwrap().sigma_px;
    let within = frames
        .iter()
        .filter(|&&k| k != 20)
        .filter(|&&k| errors[k][0].abs() <= direct(k)[0])
        .count();
    assert_eq!(
        within, 29,
        "u: every centre but the blunder within its σ now"
    );
    assert!(
        errors[20][1].abs() < 1.5 * direct(20)[1] && direct(20)[1] > 0.9,
        "the blunder's v σ {:.3} px for an error of {:.3}",
        direct(20)[1],
        errors[20][1]
    );
    // The mirror view's centres lie on the flight: their σ as they were.
    for &k in &frames {
        assert_eq!(
            reported[k].spheres[0][1].as_ref().unwrap().sigma_px,
            obs[k].spheres[0][1].as_ref().unwrap().sigma_px
        );
    }
    // Without the scatter, nothing changes in the direct view either.
    let clean = steady_phase_of_a(&views, &|_| 0.0);
    let (series, floor, weights) = phases::series_and_sigma(&clean, &views, 0, &frames);
    let fit = SideFit::fit_weighted(&series, &weights, 0.0, 0.0, floor);
    let kept = flight_misfit::widened(&clean, &views, &[fit; 4], &ph, 0.0, 0.0);
    for &k in &frames {
        assert_eq!(
            kept[k].spheres[0][0].as_ref().unwrap().sigma_px,
            [0.02, 0.02]
        );
    }
}

/// A centre in the impact's gap (in no phase: the frames between a sphere's last before the
/// impact and its first after) that lies off its flight carries its disagreement: the disc
/// after an impact was the other sphere's, 13 px away, and reported at σ 0.015 px. Centres in
/// the gap that lie on their flight, and frames outside the gap, keep their σ.
#[test]
fn a_centre_in_the_impacts_gap_off_its_flight_says_so_in_the_report() {
    let cfg = Config::default_config();
    let views = geometry::views(&cfg);
    let mut obs = steady_phase_of_a(&views, &|_| 0.0);
    let before: Vec<usize> = (0..20).collect();
    let after: Vec<usize> = (25..30).collect();
    let all: Vec<usize> = (0..30).collect();
    // The flight referenced at the impact (`split`), as the phases' fits are.
    let split = obs[22].time_s;
    let mut at_split = obs.clone();
    for f in &mut at_split {
        f.time_s -= split;
    }
    let (series, floor, weights) = phases::series_and_sigma(&at_split, &views, 0, &all);
    let fit = SideFit::fit_weighted(&series, &weights, 0.0, 0.0, floor);
    let fits: Fits = [fit; 4];
    let ph = [before, Vec::new(), after, Vec::new()];
    for k in [2, 23] {
        if let Some(m) = obs[k].spheres[0][0].as_mut() {
            m.centre_px[1] += 13.0;
        }
    }
    let reported = flight_misfit::widened(&obs, &views, &fits, &ph, split, 0.0);
    let sigma = |k: usize, vi: usize| {
        reported[k].spheres[0][vi]
            .as_ref()
            .map_or([f64::NAN; 2], |m| m.sigma_px)
    };
    assert!(sigma(23, 0)[1] > 12.0, "frame 23: {:?}", sigma(23, 0));
    assert_eq!(sigma(23, 0)[0], 0.02, "its u lies on the flight");
    for k in [20, 21, 22, 24] {
        assert_eq!(sigma(k, 0), [0.02, 0.02], "frame {k}, on its flight");
    }
    for k in 20..25 {
        assert_eq!(sigma(k, 1), [0.02, 0.02], "frame {k}'s mirror view");
    }
    // Frame 2 is in a phase: its blunder is the phase's business (the median keeps one
    // blunder from setting the scale), not the gap's, and a scatter check that sees it as
    // beyond 3σ widens it as before.
    assert!(sigma(2, 0)[1] > 12.0, "frame 2: {:?}", sigma(2, 0));
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

/// A spin after the impact taken from the spin before plus the impulse (no dots after it)
/// follows the velocities and the normal it comes from (`kinematics::ImpulseCoupling`), so ψ2's
/// and β's σ take in the correlation between that spin and the contact velocities they are
/// computed with. Over 400 noisy realisations of one oblique impact with friction (centres
/// 0.01 mm off, 14 frames a phase; the spins before known), β's errors in units of its coupled
/// σ have an RMS of 1.00; carried as an independent source, as before, 1.50 (validation v03:
/// 4.6σ; docs/accuracy.md, session 47). At the fits the spins came from, the
/// coupled derivation gives them to the bit.
#[test]
fn a_spin_from_the_impulse_moves_with_the_velocities_in_its_sigma() {
    use super::impulse;
    use super::kinematics::{derive, uncertainties, Bodies, ImpulseCoupling, Spins};
    let g = 9806.65;
    let (r, k_inertia) = (3.175, 0.4);
    let d = 2.0 * r;
    // Truth: a meets b at n (mostly x, a little z), slipping along y; a tangential impulse a
    // third of the normal one (sliding friction), spins changed by it.
    let n = V3::new(0.95, 0.0, 0.3122).normalize();
    let (va, vb) = (V3::new(800.0, 150.0, 20.0), V3::new(-700.0, -100.0, -30.0));
    let (wa, wb) = (V3::new(5.0, -20.0, 40.0), V3::new(-10.0, 15.0, -35.0));
    let g_n = (vb - va).dot(&n);
    let jn = -0.5 * (1.0 + 0.9) * g_n; // per unit mass, equal masses
    let contact = vb - va + n.cross(&(wa * r + wb * r));
    let gt = contact - n * contact.dot(&n);
    let t = gt / gt.norm();
    let j = n * jn + t * (0.3 * jn);
    let (va2, vb2) = (va - j, vb + j);
    let (wa2, wb2) = (
        wa + impulse::delta_omega(n, va2 - va, r, k_inertia),
        wb + impulse::delta_omega(-n, vb2 - vb, r, k_inertia),
    );
    let truth = super::kinematics::collision(
        &n,
        &(vb - va),
        &(vb2 - va2),
        Some(&[wa, wb, wa2, wb2]),
        [r; 2],
    )
    .expect("approaching");
    let beta = truth.beta.unwrap();
    let (pa, pb) = (-n * r, n * r);
    let mut rng = hw_sim::Rng::new(47);
    let noise = 0.01;
    let mut side = |p0: V3, v: V3, sign: f64| {
        let ts: Vec<f64> = (1..15).map(|k| sign * k as f64 * 1e-3).collect();
        let line = |i: usize, rng: &mut hw_sim::Rng| -> Series {
            let gi = if i == 1 { -g } else { 0.0 };
            ts.iter()
                .map(|&t| {
                    (
                        t,
                        p0[i] + v[i] * t + 0.5 * gi * t * t + noise * rng.gaussian(),
                    )
                })
                .collect()
        };
        let s = [line(0, &mut rng), line(1, &mut rng), line(2, &mut rng)];
        SideFit::fit(&s, 0.0, g)
    };
    let known = |w: V3| SpinFit {
        omega: w,
        cov: nalgebra::Matrix3::zeros(),
        pairs: 10,
        frame_influence: Vec::new(),
    };
    let (mut coupled_z, mut independent_z) = (Vec::new(), Vec::new());
    for _ in 0..400 {
        let fits: Fits = [
            side(pa, va, -1.0),
            side(pb, vb, -1.0),
            side(pa, va2, 1.0),
            side(pb, vb2, 1.0),
        ];
        let plain: Bodies = [r; 2].into();
        let d0 = derive(&fits, None, plain, d, g).unwrap();
        let s0 = uncertainties(&fits, None, plain, d, g).unwrap();
        let mut coupling = ImpulseCoupling {
            inertia_factor: k_inertia,
            weight: [[nalgebra::Matrix3::zeros(); 2]; 2],
            delta_omega: [V3::zeros(); 2],
        };
        let mut spins = [known(wa), known(wb), known(wa), known(wb)];
        for s in 0..2 {
            let ns = if s == 0 { d0.normal } else { -d0.normal };
            let dv = d0.velocities[2 + s] - d0.velocities[s];
            let dv_sigma = (s0.velocities[s].component_mul(&s0.velocities[s])
                + s0.velocities[2 + s].component_mul(&s0.velocities[2 + s]))
            .map(f64::sqrt);
            let imp = impulse::predicted(ns, s0.normal, dv, dv_sigma, r, k_inertia);
            let (_, post, _, _, weights) =
                impulse::reconcile_weighted(s, Some(&spins[s]), None, &imp);
            spins[2 + s] = post.unwrap();
            coupling.weight[s] = weights;
            coupling.delta_omega[s] = imp.delta_omega;
        }
        let omega = [0, 1, 2, 3].map(|k| spins[k].omega);
        let coupled = Bodies {
            impulse: Some(coupling),
            ..plain
        };
        let dc = derive(&fits, Some(&omega), coupled, d, g).unwrap();
        let du = derive(&fits, Some(&omega), plain, d, g).unwrap();
        assert_eq!(
            (dc.psi2, dc.beta),
            (du.psi2, du.beta),
            "at its own fits the coupled derivation gives the reconciled spins' ψ2, β"
        );
        let held = Spins {
            omega,
            cov: [nalgebra::Matrix3::zeros(); 4],
        };
        let sigma_beta = |bodies: Bodies| {
            let kin = uncertainties(&fits, Some(&held), bodies, d, g).unwrap();
            let measured = [&spins[0], &spins[1], &spins[2], &spins[3]];
            let spin = spin_variance(&fits, &omega, measured, bodies, d, g).unwrap();
            (kin.beta.unwrap().powi(2) + spin[spin.len() - 1]).sqrt()
        };
        let err = dc.beta.unwrap() - beta;
        coupled_z.push(err / sigma_beta(coupled));
        independent_z.push(err / sigma_beta(plain));
    }
    let rms = |z: &[f64]| (z.iter().map(|x| x * x).sum::<f64>() / z.len() as f64).sqrt();
    let (c, i) = (rms(&coupled_z), rms(&independent_z));
    assert!(
        (0.8..1.25).contains(&c),
        "β's errors in units of its coupled σ: RMS {c:.2} (independent source: {i:.2})"
    );
    assert!(
        !(0.8..1.25).contains(&i),
        "the independent source's σ should not fit here (RMS {i:.2}), or the test shows nothing"
    );
}
