//! Flight phases: which frames are free flight on each side of the impact (grown outwards
//! from it while they stay on the ballistic track), the ballistic fits of the four phases on
//! the per-axis series the views give (`series`), and the axes every phase measured.

use super::geometry::{View, V3};
use super::kinematics::{self, Fits, SideFit};
use super::line_fit::LineFit;
use super::markers;
use super::tracking::FrameObs;
use nalgebra::Matrix2;

mod series;

pub(super) use series::{
    diameter_drift_velocity, series, series_and_sigma, stray_velocity, x_views_disagree,
};

/// Fewer frames than this of a phase in the primary view, and the phase is the span any view
/// saw the sphere in.
const MIN_PRIMARY_FRAMES: usize = 3;

/// Frames of one flight phase of sphere `s` (before or after `split`, more than `guard` away):
/// only the time span in which the primary view (direct, when configured) saw it, because the
/// other view may still see the sphere rolling in its tube, where free flight does not hold;
/// unless the primary view saw it in fewer than `MIN_PRIMARY_FRAMES` frames there, or, after
/// the impact (where no tube holds it), in fewer than `min_side` (the frames a phase needs):
/// a sphere the other one hides in the direct view after an impact whose normal leans towards
/// the camera is seen there in 3–4 frames, and its phase, cut to that span, was too short to
/// analyse while the mirror saw it fly for a dozen more.
pub(super) fn side_frames(
    obs: &[FrameObs],
    s: usize,
    pre: bool,
    split: f64,
    guard: f64,
    min_side: usize,
) -> Vec<usize> {
    let on_side = |t: f64| {
        if pre {
            t < split - guard
        } else {
            t > split + guard
        }
    };
    // Where the primary view hardly sees the sphere on this side (two spheres passing at
    // different depths can overlap in it for the whole phase), the span any view saw it in.
    let primary_frames = obs
        .iter()
        .filter(|f| on_side(f.time_s) && f.spheres[s][0].is_some())
        .count();
    let any_view = primary_frames < MIN_PRIMARY_FRAMES || (!pre && primary_frames < min_side);
    let seen = || {
        obs.iter()
            .filter(move |f| {
                on_side(f.time_s)
                    && if any_view {
                        f.spheres[s].iter().any(Option::is_some)
                    } else {
                        f.spheres[s][0].is_some()
                    }
            })
            .map(|f| f.time_s)
    };
    let lo = seen().fold(f64::INFINITY, f64::min);
    let hi = seen().fold(f64::NEG_INFINITY, f64::max);
    (0..obs.len())
        .filter(|&k| on_side(obs[k].time_s) && obs[k].time_s >= lo && obs[k].time_s <= hi)
        .collect()
}

/// The first guess of the impact: (time, separation) of the frame where a and b are closest
/// together in 3-D, from both views where both see both spheres (spheres passing at different
/// depths overlap in one view long before and after they touch); else where they are seen
/// closest in the primary view (separation in px). None if they are never seen together.
pub(super) fn closest_approach(
    obs: &[FrameObs],
    views: &[View],
    primary: usize,
) -> Option<(f64, f64)> {
    let closest_3d = separations_mm(obs, views)
        .into_iter()
        .min_by(|a, b| a.1.total_cmp(&b.1));
    if closest_3d.is_some() {
        return closest_3d;
    }
    let mut closest: Option<(f64, f64)> = None;
    for f in obs {
        if let (Some(a), Some(b)) = (&f.spheres[0][primary], &f.spheres[1][primary]) {
            let d = (a.centre_px[0] - b.centre_px[0]).hypot(a.centre_px[1] - b.centre_px[1]);
            if closest.is_none_or(|(_, dd)| d < dd) {
                closest = Some((f.time_s, d));
            }
        }
    }
    closest
}

/// (time, separation of the centres, mm) of every frame where both views see both spheres, in
/// the frames' order.
pub(super) fn separations_mm(obs: &[FrameObs], views: &[View]) -> Vec<(f64, f64)> {
    let separation_mm = |f: &FrameObs| -> Option<f64> {
        if views.len() < 2 {
            return None;
        }
        let mut d = [None::<f64>; 3];
        for (vi, v) in views.iter().enumerate() {
            let (a, b) = (f.spheres[0][vi].as_ref()?, f.spheres[1][vi].as_ref()?);
            for ((axis, xa), (_, xb)) in v
                .unproject(a.centre_px, f.position_mm[0].as_ref())
                .into_iter()
                .zip(v.unproject(b.centre_px, f.position_mm[1].as_ref()))
            {
                d[axis].get_or_insert(xa - xb);
            }
        }
        Some(
            d.iter()
                .map(|x| x.map(|x| x * x))
                .sum::<Option<f64>>()?
                .sqrt(),
        )
    };
    obs.iter()
        .filter_map(|f| Some((f.time_s, separation_mm(f)?)))
        .collect()
}

/// Whether the primary view saw a sphere in fewer than `MIN_PRIMARY_FRAMES` frames of one of
/// its phases, so that phase was taken from any view (`side_frames`).
pub(super) fn primary_view_lost(obs: &[FrameObs], split: f64, guard: f64) -> bool {
    [(0, true), (1, true), (0, false), (1, false)]
        .iter()
        .any(|&(s, pre)| {
            obs.iter()
                .filter(|f| {
                    if pre {
                        f.time_s < split - guard
                    } else {
                        f.time_s > split + guard
                    }
                })
                .filter(|f| f.spheres[s][0].is_some())
                .count()
                < MIN_PRIMARY_FRAMES
        })
}

/// [a pre, b pre, a post, b post]
pub(super) fn phases(obs: &[FrameObs], split: f64, guard: f64, min_side: usize) -> [Vec<usize>; 4] {
    [(0, true), (1, true), (0, false), (1, false)]
        .map(|(s, pre)| side_frames(obs, s, pre, split, guard, min_side))
}

/// The frames of each phase in which the sphere flies freely: starting from the 15 frames next
/// to the impact, frames further away are taken one by one while they lie on the ballistic
/// trajectory fitted so far (within 4σ of its prediction, σ from the residuals and the
/// extrapolation); three misses in a row end the phase. Before that, a sphere seen still
/// rolling in its tube (its vertical acceleration there is a fraction of g) bent the fit.
pub(super) fn flight_phases(
    obs: &[FrameObs],
    views: &[View],
    split: f64,
    guard: f64,
    g: f64,
    min_side: usize,
) -> [Vec<usize>; 4] {
    let ph = phases(obs, split, guard, min_side);
    [0, 1, 2, 3].map(|k| free_flight(obs, views, k % 2, &ph[k], k < 2, g))
}

pub(super) fn free_flight(
    obs: &[FrameObs],
    views: &[View],
    s: usize,
    frames: &[usize],
    pre: bool,
    g: f64,
) -> Vec<usize> {
    const SEED: usize = 15;
    if frames.len() <= SEED + 2 {
        return frames.to_vec();
    }
    let order: Vec<usize> = if pre {
        frames.iter().rev().copied().collect()
    } else {
        frames.to_vec()
    };
    let t_ref = obs[order[0]].time_s;
    let gravity = [0.0, -g, 0.0];
    let mut kept: Vec<usize> = order[..SEED].to_vec();
    let mut fit = SideFit::fit(&series(obs, views, s, &kept), t_ref, g);
    let mut misses = 0;
    for &k in &order[SEED..] {
        let one = series(obs, views, s, &[k]);
        let tau = obs[k].time_s - t_ref;
        let on_track = (0..3).all(|axis| {
            let Some(l) = &fit.axes[axis] else {
                return true;
            };
            one[axis].iter().all(|&(_, x)| {
                let predicted = l.p0 + l.v * tau + 0.5 * gravity[axis] * tau * tau;
                let extrapolation =
                    l.cov[(0, 0)] + 2.0 * tau * l.cov[(0, 1)] + tau * tau * l.cov[(1, 1)];
                let sigma = (l.rms * l.rms + extrapolation.max(0.0)).sqrt().max(0.005);
                (x - predicted).abs() <= 4.0 * sigma
            })
        });
        if on_track {
            kept.push(k);
            misses = 0;
            fit = SideFit::fit(&series(obs, views, s, &kept), t_ref, g);
        } else {
            misses += 1;
            if misses >= 3 {
                break;
            }
        }
    }
    kept.sort_unstable();
    kept
}

/// The four ballistic fits for a given split, referenced at it (an axis one phase lacks taken
/// from the others' momentum where `masses` are known, `keep_common_axes`).
pub(super) fn fit_all(
    obs: &[FrameObs],
    views: &[View],
    split: f64,
    guard: f64,
    g: f64,
    min_side: usize,
    masses: Option<[f64; 2]>,
) -> Fits {
    let ph = flight_phases(obs, views, split, guard, g, min_side);
    // The final fits' σ floored at the centres' own (`fit_line`); while a phase grows (above)
    // it is not, so which frames a phase holds does not change.
    let mut fits = [0, 1, 2, 3].map(|k| {
        let (series, floor, weights) = series_and_sigma(obs, views, k % 2, &ph[k]);
        SideFit::fit_weighted(&series, &weights, split, g, floor)
    });
    keep_common_axes(&mut fits, masses);
    fits
}

/// A centre measured in a phase (`on_flights`) and where that phase's fit puts its sphere at
/// the frame.
pub(super) struct OnFlight {
    /// The phase, 0–3: a before, b before, a after, b after (the sphere is `phase % 2`).
    pub(super) phase: usize,
    /// Index into the observations.
    pub(super) frame: usize,
    /// Index into the views.
    pub(super) view: usize,
    /// The fit's point at the frame's time, world mm, and its image in the view, px.
    pub(super) at_mm: V3,
    pub(super) at_px: [f64; 2],
}

/// Every centre measured in the frames of a phase `ph` whose fit has every axis, with where
/// that fit (referenced at `split`) puts its sphere: phase by phase, frame by frame, view by
/// view. What the markers are lifted about (`relift_on_trajectories`) and what the reported
/// centres' σ are checked against (`flight_misfit`).
pub(super) fn on_flights(
    obs: &[FrameObs],
    views: &[View],
    fits: &Fits,
    ph: &[Vec<usize>; 4],
    split: f64,
    g: f64,
) -> Vec<OnFlight> {
    let mut out = Vec::new();
    for (k, frames) in ph.iter().enumerate() {
        if fits[k].axes.iter().any(|a| a.is_none()) {
            continue;
        }
        for &i in frames {
            let Some(f) = obs.get(i) else { continue };
            let (p, _) = kinematics::pos_vel(&fits[k], f.time_s - split, g);
            for (vi, view) in views.iter().enumerate() {
                if f.spheres[k % 2].get(vi).is_some_and(Option::is_some) {
                    out.push(OnFlight {
                        phase: k,
                        frame: i,
                        view: vi,
                        at_mm: p,
                        at_px: view.project(&p),
                    });
                }
            }
        }
    }
    out
}

/// Markers lifted again about the sphere's centre on its fitted trajectory instead of the
/// frame's own circle fit: the trajectory, fitted over every frame of the phase, is several
/// times more precise than one frame's circle, and an error of the centre moves every marker of
/// the frame alike, which the rotation between two frames takes for a turn. Frames where the
/// trajectory and the circle disagree by more than 0.3 px keep their own centre.
pub(super) fn relift_on_trajectories(
    obs: &[FrameObs],
    views: &[View],
    fits: &Fits,
    ph: &[Vec<usize>; 4],
    split: f64,
    g: f64,
    radii: [f64; 2],
) -> Vec<FrameObs> {
    let mut out = obs.to_vec();
    for q in on_flights(obs, views, fits, ph, split, g) {
        let (s, view) = (q.phase % 2, &views[q.view]);
        let Some(m) = out[q.frame].spheres[s][q.view].as_mut() else {
            continue;
        };
        let c = q.at_px;
        if (c[0] - m.centre_px[0]).hypot(c[1] - m.centre_px[1]) > 0.3 {
            continue;
        }
        m.markers = m
            .markers
            .iter()
            .filter_map(|mk| markers::lift_at(view, mk.centre_px, c, radii[s], &q.at_mm))
            .collect();
    }
    out
}

/// Drops a world axis from all four fits unless every one of them measured it, and says which
/// axes went. A coordinate that no view saw for one sphere in one phase (in the mirror the two
/// spheres can hide each other from the impact to the end of the recording) must not enter the
/// collision as a zero velocity: the collision is then analysed in the axes all four share —
/// unless that phase alone lacks it and the masses are known (`masses`): then it is taken from
/// the other three (`from_momentum`), and the axis stays.
pub(super) fn keep_common_axes(fits: &mut Fits, masses: Option<[f64; 2]>) -> Vec<usize> {
    let mut dropped = Vec::new();
    for i in 0..3 {
        let missing: Vec<usize> = (0..4).filter(|&k| fits[k].axes[i].is_none()).collect();
        if missing.len() == 1 && i != 0 {
            if let Some(line) = masses.and_then(|m| from_momentum(fits, i, missing[0], m)) {
                fits[missing[0]].axes[i] = Some(line);
                continue;
            }
        }
        if !missing.is_empty() && missing.len() < fits.len() {
            for f in fits.iter_mut() {
                f.axes[i] = None;
            }
            dropped.push(i);
        }
    }
    dropped
}

/// Phase `k`'s motion along axis `i`, which no view measured, from the other three phases: its
/// velocity from momentum across the impact (m_a·Δv_a + m_b·Δv_b = 0, `momentum`), its
/// position at the impact (the fits' reference time) the same sphere's in its other phase (a
/// sphere does not jump), each with the variance those give it. Why: the mirror view alone
/// sees z, and after an impact the spheres often hide each other there for the rest of the
/// recording; dropping z then left a 2-D result whose e, ψ and β were those of the motion's
/// projection — e 0.10–0.13 off a true 0.90 on a bench rig whose normal leans 12° out of the
/// view's plane, at up to 9σ (docs/accuracy.md, session 38). Marked by `n` = 0 (no frame): the
/// momentum check and combination leave the axis out (`momentum::combination`), as it holds
/// there by construction. None where the masses or the other fits do not give it.
fn from_momentum(fits: &Fits, i: usize, k: usize, masses: [f64; 2]) -> Option<LineFit> {
    let a = [-masses[0], -masses[1], masses[0], masses[1]];
    if !a.iter().all(|x| x.is_finite() && *x != 0.0) {
        return None;
    }
    let (mut sum, mut var) = (0.0, 0.0);
    for j in (0..4).filter(|&j| j != k) {
        let l = fits[j].axes[i]?;
        sum += a[j] * l.v;
        var += a[j] * a[j] * l.cov[(1, 1)];
    }
    let twin = fits[k ^ 2].axes[i]?;
    let v = -sum / a[k];
    let var_v = var / (a[k] * a[k]);
    (v.is_finite() && var_v.is_finite()).then(|| LineFit {
        p0: twin.p0,
        v,
        cov: Matrix2::new(twin.cov[(0, 0)], 0.0, 0.0, var_v),
        rms: 0.0,
        n: 0,
        rejected: 0,
    })
}

/// Which of [a pre, b pre, a post, b post] measured no position along world axis `i`.
pub(super) fn phases_missing_axis(
    obs: &[FrameObs],
    views: &[View],
    split: f64,
    guard: f64,
    g: f64,
    i: usize,
    min_side: usize,
) -> Vec<&'static str> {
    let ph = flight_phases(obs, views, split, guard, g, min_side);
    let names = ["a before", "b before", "a after", "b after"];
    (0..4)
        .filter(|&k| series(obs, views, k % 2, &ph[k])[i].is_empty())
        .map(|k| names[k])
        .collect()
}
