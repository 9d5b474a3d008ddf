//! Flight phases: which frames are free flight on each side of the impact (grown outwards
//! from it while they stay on the ballistic track), the per-axis series built from the views,
//! the ballistic fits of the four phases, and the axes every phase measured.

use super::geometry::{View, ViewKind, V3};
use super::kinematics::{self, Fits, Series, SideFit};
use super::line_fit::LineFit;
use super::markers;
use super::tracking::FrameObs;
use nalgebra::Matrix2;

/// Per-sphere coordinate series (x, y, z) in world mm over the given frames, built from the
/// views: y from the direct view, z from the mirror, x from the direct view where it measured
/// the sphere (the mirror's x is then the calibration check), else from the mirror.
pub(super) fn series(obs: &[FrameObs], views: &[View], s: usize, frames: &[usize]) -> [Series; 3] {
    series_with(obs, views, s, frames, None)
}

/// `series`, per axis the median of the centres' own σ, mm (each centre's σ in px over its
/// view's scale; 0 where there is none): the scatter the positions have at least; and each
/// point's weight in the line fit: 1, but (median/σ)² for a centre the other sphere partly hid
/// whose σ is larger than the median (`overlap`: its σ holds what its own fit cannot see).
/// Why not every centre by its σ: the others' σ come from their own fits and vary with
/// noise more than their errors do; the weights would then follow the noise.
fn series_and_sigma(
    obs: &[FrameObs],
    views: &[View],
    s: usize,
    frames: &[usize],
) -> ([Series; 3], [f64; 3], [Vec<f64>; 3]) {
    let mut points: [Vec<Point>; 3] = [Vec::new(), Vec::new(), Vec::new()];
    let out = series_with(obs, views, s, frames, Some(&mut points));
    let median = |v: &[Point]| {
        let mut finite: Vec<f64> = v.iter().map(|p| p.0).filter(|x| x.is_finite()).collect();
        finite.sort_by(f64::total_cmp);
        finite.get(finite.len() / 2).copied().unwrap_or(0.0)
    };
    let floor = [0, 1, 2].map(|i| median(&points[i]));
    let weights = [0, 1, 2].map(|i| {
        points[i]
            .iter()
            .map(|&(sigma, hidden, _)| {
                if hidden && sigma.is_finite() && sigma > floor[i] && floor[i] > 0.0 {
                    (floor[i] / sigma).powi(2)
                } else {
                    1.0
                }
            })
            .collect()
    });
    (out, floor, weights)
}

/// What `series_with` says of each point besides its value: its centre's σ in mm (NaN where
/// there is none), whether the other sphere partly hid it, and its radius's stray from its
/// neighbours' in mm (`radius_misfit`).
type Point = (f64, bool, f64);

/// `series`, pushing each point's `Point` onto `sigmas` per axis when asked (the growing phases
/// and the leave-one-out refits, which call `series` for every frame, do not ask).
fn series_with(
    obs: &[FrameObs],
    views: &[View],
    s: usize,
    frames: &[usize],
    mut sigmas: Option<&mut [Vec<Point>; 3]>,
) -> [Series; 3] {
    let mut out: [Series; 3] = [Vec::new(), Vec::new(), Vec::new()];
    let has_direct = views.iter().any(|v| v.kind == ViewKind::Direct);
    for f in frames.iter().map(|&k| &obs[k]) {
        // The direct view's x where it measured the sphere in this frame; the mirror's
        // (refined to agree with it) where it did not, and where the other sphere hid part of
        // the direct view's disc but not the mirror's (the hidden fit is the worse of the two).
        let seen = |whole: bool, direct: bool| {
            views.iter().zip(&f.spheres[s]).any(|(v, m)| {
                (v.kind == ViewKind::Direct) == direct
                    && m.as_ref()
                        .is_some_and(|m| !whole || m.hidden_in_part.is_none())
            })
        };
        let (direct_whole, direct_any) = (seen(true, true), seen(false, true));
        let other_whole = seen(true, false);
        for (vi, view) in views.iter().enumerate() {
            let Some(m) = &f.spheres[s][vi] else { continue };
            let skip_x = if view.kind == ViewKind::Direct {
                !direct_whole && other_whole
            } else {
                has_direct && (direct_whole || (direct_any && m.hidden_in_part.is_some()))
            };
            for (axis, val) in view.unproject(m.centre_px, f.position_mm[s].as_ref()) {
                if axis == 0 && skip_x {
                    continue;
                }
                out[axis].push((f.time_s, val));
                if let Some(sigmas) = sigmas.as_deref_mut() {
                    let sigma_mm =
                        m.sigma_px[0].hypot(m.sigma_px[1]) / 2f64.sqrt() / view.px_per_mm;
                    sigmas[axis].push((
                        sigma_mm,
                        m.hidden_in_part.is_some(),
                        m.radius_stray_px / view.px_per_mm,
                    ));
                }
            }
        }
    }
    out
}

/// How far the misfits its centres' radii show could move each axis's velocity of sphere `s`
/// over `frames`, mm/s (`radius_misfit`: a centre is out by about its radius's stray, in a
/// direction its fit does not say). Each point counts with its lever on the line fit's slope,
/// (t − t̄)/Σ(t − t̄)², and only for its stray beyond the strays' own scatter over the phase
/// (1.4826 × their median magnitude: on a disc fitted well the stray is the radius's noise,
/// which the line fit's σ already holds). Within a run of consecutive frames whose strays go
/// beyond that, in full; separate runs, in quadrature. Why in full: the misfits that matter run
/// in groups — a blurred neighbour's edge over the frames before contact, the view's border over
/// the first ones — and one group's centres are out the same way, at one end of the phase, which
/// a line fit takes for velocity; on seed 4112's defocused rig b's y velocity came out 10–17 mm/s
/// off at 3–11σ that way. (In full over the whole phase was too wide: 83 % of the bench's
/// velocities within ±1σ.)
pub(super) fn stray_velocity(
    obs: &[FrameObs],
    views: &[View],
    s: usize,
    frames: &[usize],
) -> [f64; 3] {
    let mut points: [Vec<Point>; 3] = [Vec::new(), Vec::new(), Vec::new()];
    let series = series_with(obs, views, s, frames, Some(&mut points));
    [0, 1, 2].map(|axis| {
        let (ts, pts) = (&series[axis], &points[axis]);
        if ts.len() < 3 || ts.len() != pts.len() {
            return 0.0;
        }
        let mut magnitudes: Vec<f64> = pts.iter().map(|p| p.2.abs()).collect();
        magnitudes.sort_by(f64::total_cmp);
        let scatter = 1.4826 * magnitudes[magnitudes.len() / 2];
        let n = ts.len() as f64;
        let t_mean = ts.iter().map(|p| p.0).sum::<f64>() / n;
        let stt: f64 = ts.iter().map(|p| (p.0 - t_mean).powi(2)).sum();
        if stt <= 0.0 {
            return 0.0;
        }
        // Within a run of consecutive misfits, in full; runs apart, in quadrature.
        let (mut sum_sq, mut run) = (0.0, 0.0);
        for (p, q) in ts.iter().zip(pts) {
            let beyond = (q.2 * q.2 - scatter * scatter).max(0.0).sqrt();
            if beyond > 0.0 {
                run += (p.0 - t_mean).abs() * beyond / std::f64::consts::SQRT_2;
            } else {
                sum_sq += run * run;
                run = 0.0;
            }
        }
        (sum_sq + run * run).sqrt() / stt
    })
}

/// The fewest whole discs of a view in a phase for `diameter_drift_velocity` to fit a line
/// through their diameters.
const MIN_DRIFT_FRAMES: usize = 6;

/// How far a drift of the disc model's misfit along the phase could move each axis's velocity
/// of sphere `s` over `frames`, mm/s. Per view, a line through the phase's diameters, each in
/// mm at the view's local scale where the sphere is (so perspective's own change is not
/// counted), fitted by least squares with its slope's σ from the residuals; the part of the
/// slope beyond twice that σ is a misfit that changes along the phase, and a centre moves by
/// half its diameter's misfit, in a direction the fit does not say: half of it, split over the
/// view's two axes. Why: on seed 4114 of the 190 varied-look recordings (session 40) a blurred
/// disc's held diameter rose 0.08 px over its last 31 frames before the impact while its
/// centre moved 0.05 px with it, smoothly; each centre's σ covered it, the strays from the
/// rolling median (`stray_velocity`) did not see it (the median drifts along), and the line
/// fit took it for velocity: 6σ. Discs cut by the view's border are left out (their radius is
/// held at the nominal), as are those the other sphere partly hides.
pub(super) fn diameter_drift_velocity(
    obs: &[FrameObs],
    views: &[View],
    s: usize,
    frames: &[usize],
) -> [f64; 3] {
    let mut out = [0.0f64; 3];
    for (vi, view) in views.iter().enumerate() {
        let points: Vec<(f64, f64)> = frames
            .iter()
            .map(|&k| &obs[k])
            .filter_map(|f| {
                let m = f.spheres[s].get(vi)?.as_ref()?;
                // Aligned views have no 3-D place and need none: their scale is the same
                // everywhere.
                let p = f.position_mm[s].unwrap_or_else(V3::zeros);
                let r = 0.5 * m.diameter_px;
                let [u, v] = m.centre_px;
                let whole = m.hidden_in_part.is_none()
                    && r.is_finite()
                    && [(u - r, v), (u + r, v), (u, v - r), (u, v + r)]
                        .iter()
                        .all(|&(a, b)| view.contains(a, b));
                let (j, _) = view.local_at(&p);
                // The local scale across the line of sight: the geometric mean of the map's
                // two singular values.
                let det = (j * j.transpose()).determinant();
                (whole && det > 0.0).then(|| (f.time_s, m.diameter_px / det.sqrt().sqrt()))
            })
            .collect();
        if points.len() < MIN_DRIFT_FRAMES {
            continue;
        }
        let n = points.len() as f64;
        let t_mean = points.iter().map(|p| p.0).sum::<f64>() / n;
        let d_mean = points.iter().map(|p| p.1).sum::<f64>() / n;
        let stt: f64 = points.iter().map(|p| (p.0 - t_mean).powi(2)).sum();
        if stt <= 0.0 {
            continue;
        }
        let slope = points
            .iter()
            .map(|p| (p.0 - t_mean) * (p.1 - d_mean))
            .sum::<f64>()
            / stt;
        let rss: f64 = points
            .iter()
            .map(|p| (p.1 - d_mean - slope * (p.0 - t_mean)).powi(2))
            .sum();
        let slope_var = rss / (n - 2.0) / stt;
        let excess = slope * slope - 4.0 * slope_var;
        if excess.is_nan() || excess <= 0.0 {
            continue;
        }
        let per_axis = 0.5 * excess.sqrt() / std::f64::consts::SQRT_2;
        for (axis, o) in out.iter_mut().enumerate() {
            if axis != view.kind.depth_axis() {
                *o = o.max(per_axis);
            }
        }
    }
    out
}

/// The fewest frames both views must have seen a sphere in, in a phase, for their x velocities
/// to be compared (`x_views_disagree`): a line fit's σ from fewer says little.
const MIN_SHARED_X_FRAMES: usize = 6;

/// How far the direct view's x velocity of sphere `s` over `frames` lies from the secondary
/// view's, mm/s, with its σ, and the part of it beyond twice that σ (None where within it, or
/// where fewer than `MIN_SHARED_X_FRAMES` frames have both views' whole discs). Why: both views
/// see x, each on its own hemisphere of the sphere, so what biases one view's centres from frame
/// to frame (faint dots turning under a blurred disc, unmasked because none was found) is not
/// what biases the other's; the phase's fit takes x from the direct view alone and cannot see
/// it. On a defocused look (blur σ 1.2 px, no dot found) a's x before the impact drifted by
/// half a pixel over its last ten frames, and its velocity came out 14 mm/s off at 11.7σ.
pub(super) fn x_views_disagree(
    obs: &[FrameObs],
    views: &[View],
    s: usize,
    frames: &[usize],
    t_ref: f64,
) -> Option<(f64, f64, f64)> {
    let mut x: [Series; 2] = [Vec::new(), Vec::new()];
    for f in frames.iter().map(|&k| &obs[k]) {
        if let Some((direct, mirror)) = super::calibration::x_pair(f, views, s) {
            x[0].push((f.time_s, direct));
            x[1].push((f.time_s, mirror));
        }
    }
    if x.iter().any(|series| series.len() < MIN_SHARED_X_FRAMES) {
        return None;
    }
    let fit = |series: &Series| super::line_fit::fit_line(series, None, t_ref, 0.0, 0.0);
    let (a, b) = (fit(&x[0])?, fit(&x[1])?);
    let d = a.v - b.v;
    let var = a.cov[(1, 1)] + b.cov[(1, 1)];
    let excess = d * d - 4.0 * var;
    (excess > 0.0 && var.is_finite()).then(|| (d, var.sqrt(), excess.sqrt()))
}

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
    for (k, frames) in ph.iter().enumerate() {
        let s = k % 2;
        if fits[k].axes.iter().any(|a| a.is_none()) {
            continue;
        }
        for &i in frames {
            let Some(f) = out.get_mut(i) else { continue };
            let (p, _) = kinematics::pos_vel(&fits[k], f.time_s - split, g);
            for (vi, view) in views.iter().enumerate() {
                let Some(m) = f.spheres[s][vi].as_mut() else {
                    continue;
                };
                let c = view.project(&p);
                if (c[0] - m.centre_px[0]).hypot(c[1] - m.centre_px[1]) > 0.3 {
                    continue;
                }
                m.markers = m
                    .markers
                    .iter()
                    .filter_map(|mk| markers::lift_at(view, mk.centre_px, c, radii[s], &p))
                    .collect();
            }
        }
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
