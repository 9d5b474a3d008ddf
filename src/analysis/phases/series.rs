//! The per-axis series a phase's fit takes from the views (y from the direct view, z from the
//! mirror, x from whichever saw the sphere), and what the views' centres add to its σ beyond
//! their own: a misfit of the disc's radius, a drift of its diameter, the two views' x velocities
//! disagreeing.

use super::super::geometry::{View, ViewKind, V3};
use super::super::kinematics::Series;
use super::super::tracking::FrameObs;
use super::super::{calibration, line_fit};

/// Per-sphere coordinate series (x, y, z) in world mm over the given frames, built from the
/// views: y from the direct view, z from the mirror, x from the direct view where it measured
/// the sphere (the mirror's x is then the calibration check), else from the mirror.
pub(in crate::analysis) fn series(
    obs: &[FrameObs],
    views: &[View],
    s: usize,
    frames: &[usize],
) -> [Series; 3] {
    series_with(obs, views, s, frames, None)
}

/// `series`, per axis the median of the centres' own σ, mm (each centre's σ in px over its
/// view's scale; 0 where there is none): the scatter the positions have at least; and each
/// point's weight in the line fit: 1, but (median/σ)² for a centre the other sphere partly hid
/// whose σ is larger than the median (`overlap`: its σ holds what its own fit cannot see).
/// Why not every centre by its σ: the others' σ come from their own fits and vary with
/// noise more than their errors do; the weights would then follow the noise.
pub(in crate::analysis) fn series_and_sigma(
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
                    // (Without the part every frame shares, which moves the line, not its
                    // slope: `Measurement::sigma_common_px`.)
                    let all_px = m.sigma_px[0].hypot(m.sigma_px[1]) / 2f64.sqrt();
                    let own_px = if m.sigma_common_px > 0.0 {
                        (all_px * all_px - m.sigma_common_px.powi(2))
                            .max(0.0)
                            .sqrt()
                    } else {
                        all_px
                    };
                    let sigma_mm = own_px / view.px_per_mm;
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
pub(in crate::analysis) fn stray_velocity(
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
pub(in crate::analysis) fn diameter_drift_velocity(
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
pub(in crate::analysis) fn x_views_disagree(
    obs: &[FrameObs],
    views: &[View],
    s: usize,
    frames: &[usize],
    t_ref: f64,
) -> Option<(f64, f64, f64)> {
    let mut x: [Series; 2] = [Vec::new(), Vec::new()];
    for f in frames.iter().map(|&k| &obs[k]) {
        if let Some((direct, mirror)) = calibration::x_pair(f, views, s) {
            x[0].push((f.time_s, direct));
            x[1].push((f.time_s, mirror));
        }
    }
    if x.iter().any(|series| series.len() < MIN_SHARED_X_FRAMES) {
        return None;
    }
    let fit = |series: &Series| line_fit::fit_line(series, None, t_ref, 0.0, 0.0);
    let (a, b) = (fit(&x[0])?, fit(&x[1])?);
    let d = a.v - b.v;
    let var = a.cov[(1, 1)] + b.cov[(1, 1)];
    let excess = d * d - 4.0 * var;
    (excess > 0.0 && var.is_finite()).then(|| (d, var.sqrt(), excess.sqrt()))
}
