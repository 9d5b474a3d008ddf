//! Edge-point fits: level crossings along rays, Taubin's algebraic circle, the geometric
//! (Gauss–Newton) fit with asymmetric outlier rejection, and the fits built on them.

use super::{gauss_newton, CircleFit, GreyImage, View};
use nalgebra::{Matrix3, Vector3};

/// Algebraic circle fit with Taubin's constraint (Chernov's Newton-based implementation).
pub fn taubin(points: &[[f64; 2]]) -> Option<([f64; 2], f64)> {
    let n = points.len();
    if n < 3 {
        return None;
    }
    let nf = n as f64;
    let mx = points.iter().map(|p| p[0]).sum::<f64>() / nf;
    let my = points.iter().map(|p| p[1]).sum::<f64>() / nf;
    let (mut mxx, mut myy, mut mxy, mut mxz, mut myz, mut mzz) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for p in points {
        let (xi, yi) = (p[0] - mx, p[1] - my);
        let zi = xi * xi + yi * yi;
        mxy += xi * yi;
        mxx += xi * xi;
        myy += yi * yi;
        mxz += xi * zi;
        myz += yi * zi;
        mzz += zi * zi;
    }
    let (mxx, myy, mxy, mxz, myz, mzz) =
        (mxx / nf, myy / nf, mxy / nf, mxz / nf, myz / nf, mzz / nf);
    let mz = mxx + myy;
    let cov_xy = mxx * myy - mxy * mxy;
    let var_z = mzz - mz * mz;
    let a3 = 4.0 * mz;
    let a2 = -3.0 * mz * mz - mzz;
    let a1 = var_z * mz + 4.0 * cov_xy * mz - mxz * mxz - myz * myz;
    let a0 = mxz * (mxz * myy - myz * mxy) + myz * (myz * mxx - mxz * mxy) - var_z * cov_xy;
    let (a22, a33) = (a2 + a2, a3 + a3 + a3);
    let (mut x, mut y) = (0.0f64, a0);
    for _ in 0..99 {
        let dy = a1 + x * (a22 + a33 * x);
        let xnew = x - y / dy;
        if xnew == x || !xnew.is_finite() {
            break;
        }
        let ynew = a0 + xnew * (a1 + xnew * (a2 + xnew * a3));
        if ynew.abs() >= y.abs() {
            break;
        }
        x = xnew;
        y = ynew;
    }
    let det = x * x - x * mz + cov_xy;
    if det.abs() < 1e-300 {
        return None;
    }
    let xc = (mxz * (myy - x) - myz * mxy) / det / 2.0;
    let yc = (myz * (mxx - x) - mxz * mxy) / det / 2.0;
    let r = (xc * xc + yc * yc + mz).sqrt();
    (r.is_finite()).then_some(([xc + mx, yc + my], r))
}

/// What `geometric` returns: centre, radius, each point's residual and (JᵀJ)⁻¹.
type GeometricFit = ([f64; 2], f64, Vec<f64>, Matrix3<f64>);

/// Geometric least squares: minimise Σ(|p − c| − R)².
fn geometric(points: &[[f64; 2]], start: ([f64; 2], f64)) -> Option<GeometricFit> {
    let mut q = Vector3::new(start.0[0], start.0[1], start.1);
    gauss_newton(&mut q, 30, |q| {
        let mut jtj = Matrix3::<f64>::zeros();
        let mut jtr = Vector3::<f64>::zeros();
        for p in points {
            let (dx, dy) = (p[0] - q[0], p[1] - q[1]);
            let d = (dx * dx + dy * dy).sqrt().max(1e-12);
            let j = Vector3::new(-dx / d, -dy / d, -1.0);
            jtj += j * j.transpose();
            jtr += j * (d - q[2]);
        }
        (jtj, jtr, 0.0)
    })?;
    let (c, r) = ([q[0], q[1]], q[2]);
    let mut jtj = Matrix3::<f64>::zeros();
    let mut res = Vec::with_capacity(points.len());
    for p in points {
        let (dx, dy) = (p[0] - c[0], p[1] - c[1]);
        let d = (dx * dx + dy * dy).sqrt().max(1e-12);
        let j = Vector3::new(-dx / d, -dy / d, -1.0);
        jtj += j * j.transpose();
        res.push(d - r);
    }
    let inv = jtj.try_inverse()?;
    (c[0].is_finite() && c[1].is_finite() && r > 0.0).then_some((c, r, res, inv))
}

/// Robust circle fit: Taubin start, geometric refinement, rejection of points further than
/// max(3σ, 0.3 px) from the circle, repeated until stable.
pub fn robust_fit(points: &[[f64; 2]], oversampling: f64) -> Option<CircleFit> {
    let mut keep: Vec<[f64; 2]> = points.to_vec();
    let mut start = taubin(&keep)?;
    for _ in 0..4 {
        let (c, r, res, _) = geometric(&keep, start)?;
        let mut abs: Vec<f64> = res.iter().map(|x| x.abs()).collect();
        abs.sort_by(f64::total_cmp);
        let sigma = 1.4826 * abs[abs.len() / 2];
        // Asymmetric: a marker near the limb darkens the rim and moves edge points inwards
        // only, by a few tenths of a pixel; noise moves them both ways. Cutting the inner tail
        // harder removes the markers' bias of the centre, and for noise costs only a slightly
        // larger radius (the centre of a symmetric cut stays put).
        let (limit_in, limit_out) = ((1.5 * sigma).max(0.05), (3.0 * sigma).max(0.1));
        let before = keep.len();
        keep = keep
            .iter()
            .zip(res.iter())
            .filter(|(_, e)| **e >= -limit_in && **e <= limit_out)
            .map(|(p, _)| *p)
            .collect();
        start = (c, r);
        if keep.len() == before || keep.len() < 8 {
            break;
        }
    }
    if keep.len() < 8 {
        return None;
    }
    let (c, r, res, inv) = geometric(&keep, start)?;
    let n = keep.len() as f64;
    let s2 = res.iter().map(|e| e * e).sum::<f64>() / (n - 3.0).max(1.0);
    // Neighbouring rays share pixels; their errors are not independent when rays are closer than
    // a pixel along the edge.
    let cov_scale = s2 * oversampling.max(1.0);
    Some(CircleFit {
        centre: c,
        radius: r,
        centre_sigma: [
            (cov_scale * inv[(0, 0)]).sqrt(),
            (cov_scale * inv[(1, 1)]).sqrt(),
        ],
        radius_sigma: (cov_scale * inv[(2, 2)]).sqrt(),
        rms_px: s2.sqrt(),
        points_used: keep.len(),
        points_total: points.len(),
        arc_sectors: sectors_covered(&keep, c),
        grey_levels: false,
        edge_width_px: f64::NAN,
    })
}

/// Where one ray's edge lies (`edge_points`): the grey `level` its profile crosses there, and
/// how far it may `dip` and rise again inside before the ray is taken to cross a marker;
/// `dark`: the disc is darker than the ground on this side.
#[derive(Clone, Copy, Debug)]
pub struct RayLevel {
    pub level: f64,
    pub dip: f64,
    pub dark: bool,
}

impl RayLevel {
    /// A ray that gives no edge.
    const NONE: RayLevel = RayLevel {
        level: f64::INFINITY,
        dip: 0.0,
        dark: false,
    };
}

/// The ground round a disc (`edge_points`): its level, how far below it a profile must
/// sink beyond its crossing to show a limb darker than the ground there (`trough`), and how far
/// the subtracted backdrop may differ along a ray by its own noise alone (`still_noise`).
#[derive(Clone, Copy, Debug)]
pub struct Ground {
    pub level: f64,
    pub trough: f64,
    pub still_noise: f64,
}

/// Edge points of the disc around `centre`: along ray k (of `ray_levels.len()`, evenly spaced
/// in angle), the first fall through its level outward from inside the disc, interpolated
/// linearly between samples.
///
/// A ray that crosses a marker is not used: its profile dips and rises again inside the disc
/// (by more than `dip`), or rises back above `level` just after the "edge". Dark markers near
/// the limb, passing through the rim as the sphere spins, would otherwise move the edge inwards
/// on a few rays and bias the centre by a slowly varying few hundredths of a pixel — errors that
/// do not average out along a trajectory.
///
/// Nor is a ray whose samples up to its crossing read a static backdrop that differs by more
/// than `dip` (and than the backdrop's own noise, `Ground::still_noise`) from what it is where
/// the ray starts (`GreyImage::ground`: a tube end's or a
/// ruler's edge): the sphere hides it, so there the normalised edge is the sphere's shading
/// less the backdrop, and its crossing lies anywhere. (A backdrop lifted alike along the whole
/// ray, as a grey ground's vignetting lifts it, only shifts the levels the ray's own rim set.) The grey-level fit models that; the edge points are only its start.
///
/// A sphere lit from the side over a grey ground can be darker than the ground at its limb
/// while brighter inside: its shading falls through the ground's level before the limb, and
/// then rises to it at the limb. So where a ray's profile sinks more than `ground.trough`
/// below the ground beyond its crossing, the edge is where it rises again, halfway from its
/// lowest to the ground; and a ray `dark` all the way (the disc below the ground on that side)
/// is read reflected about the ground, so that the same rules find its rise.
///
/// Nor is a ray that reads anything darker than the ground within a few pixels beyond the
/// known radius (`SHADOW_READ_PX`) and off the `other` sphere's disc (whose limb may be darker
/// than the ground too): a shadow against the limb, which the rules above would read as the
/// limb.
/// Returns the points and the number of rays left out for such a backdrop or a shadow.
pub fn edge_points(
    img: &GreyImage,
    view: &View,
    centre: [f64; 2],
    radius_px: f64,
    ray_levels: &[RayLevel],
    ground: Ground,
    other: Option<([f64; 2], f64)>,
) -> (Vec<[f64; 2]>, usize) {
    let rays = ray_levels.len();
    let mut pts = Vec::with_capacity(rays);
    let mut hidden = 0;
    let step = 0.2;
    let r_start = (radius_px - 3.0).max(radius_px * 0.4);
    let r_end = radius_px + 3.0;
    for (k, ray) in ray_levels.iter().enumerate() {
        let (level, dip) = (ray.level, ray.dip);
        // The profile the right way up: bright inside, whichever side of the ground.
        let upright = |val: f64| {
            if ray.dark {
                2.0 * ground.level - val
            } else {
                val
            }
        };
        let a = std::f64::consts::TAU * k as f64 / rays as f64;
        let (dx, dy) = (a.cos(), a.sin());
        let at = |r: f64| {
            img.sample(centre[0] + r * dx, centre[1] + r * dy)
                .map(upright)
        };
        // Something darker than the ground just beyond where the limb must be (the sphere's
        // radius is known): a shadow the sphere casts on a backdrop close behind. Its dark
        // would be read as the limb (`limb_beyond`), or, reflected on a side darker than the
        // ground, as the disc itself: a disc lit from 30° to one side, its shadow against its
        // dark limb, came out 1.4 px towards the shadow. The ray is left out as one over a
        // tube end's edge is: the edge there does not stand against the ground.
        let shadowed = SHADOW_READ_PX.iter().any(|&d| {
            let (u, v) = (
                centre[0] + (radius_px + d) * dx,
                centre[1] + (radius_px + d) * dy,
            );
            view.contains(u, v)
                && !by_the_other([u, v], other)
                && img
                    .sample(u, v)
                    .is_some_and(|b| b < ground.level - ground.trough)
        });
        if shadowed {
            hidden += 1;
            continue;
        }
        let mut prev: Option<(f64, f64)> = None;
        let mut was_inside = false;
        let mut lowest_inside = f64::INFINITY;
        let mut r = r_start;
        // What the backdrop is where the ray starts, inside the disc: a ray is hidden where
        // the backdrop changes along it (a tube end's or a ruler's edge), not where the whole
        // ground is lifted (a grey ground's vignetting, 20 levels across a view).
        let (u0, v0) = (centre[0] + r * dx, centre[1] + r * dy);
        let reference = if u0 >= 0.0 && v0 >= 0.0 && u0 < img.width as f64 && v0 < img.height as f64
        {
            img.ground_at(u0.round() as usize, v0.round() as usize) as f64
        } else {
            0.0
        };
        while r <= r_end {
            let (u, v) = (centre[0] + r * dx, centre[1] + r * dy);
            if !view.contains(u, v) {
                break;
            }
            let Some(val) = at(r) else {
                break;
            };
            if img.ground_off(u, v, reference) > dip.max(ground.still_noise) {
                hidden += 1;
                break;
            }
            if val >= level {
                if val > lowest_inside + dip {
                    break;
                }
                lowest_inside = lowest_inside.min(val);
                was_inside = true;
            } else if was_inside {
                if let Some((pr, pv)) = prev {
                    let f = (pv - level) / (pv - val);
                    let re = pr + f * (r - pr);
                    // The profile just past the crossing, read once for both checks below.
                    // (Built in place: an array filled with None first was a call to memset
                    // at every crossing, 2.6 % of a recording's analysis.)
                    let past: [Option<f64>; PAST_SAMPLES] =
                        std::array::from_fn(|j| at(r + j as f64 * step));
                    let rises_again = past[1..=8].iter().any(|w| w.is_some_and(|w| w >= level));
                    let limb = if rises_again || ray.dark {
                        Some(re)
                    } else {
                        let inside = |j: usize| {
                            let rr = r + j as f64 * step;
                            rr <= r_end && view.contains(centre[0] + rr * dx, centre[1] + rr * dy)
                        };
                        let profile = |j: usize| {
                            if !inside(j) {
                                None
                            } else if j < PAST_SAMPLES {
                                past[j]
                            } else {
                                at(r + j as f64 * step)
                            }
                        };
                        limb_beyond(&profile, r, step, ground).unwrap_or(Some(re))
                    };
                    if let (false, Some(re)) = (rises_again, limb) {
                        pts.push([centre[0] + re * dx, centre[1] + re * dy]);
                    }
                }
                break;
            }
            prev = Some((r, val));
            r += step;
        }
    }
    (pts, hidden)
}

/// Where beyond the sphere's known radius a ray reads the ground for a shadow against the limb
/// (`edge_points`), px: past a sharp edge's blur, within a shadow that touches the limb. Any
/// one reading below the ground by `Ground::trough` leaves the ray out: a shadow's thin end
/// darkens only the nearest. (A blurred disc's light there only lifts the readings; a limb
/// darker than the ground, or a start pixels off, can lower them, and then the ray is left out
/// with a disc whose edge was partly hidden, which the grey-level fit must confirm.)
const SHADOW_READ_PX: [f64; 4] = [1.5, 2.5, 3.5, 4.5];

/// Samples of a ray's profile read past its crossing (`edge_points`): the crossing's, and 2 px
/// beyond it, as far as a limb darker than the ground is looked for (`limb_beyond`).
const PAST_SAMPLES: usize = 11;

/// Beyond a ray's crossing at `r`, its profile's j-th sample `profile(j)` at r + j·`step`
/// (None past the ray's end or the view's): None where it does not sink more than
/// `ground.trough` below the ground within the first `PAST_SAMPLES` (the crossing is the
/// edge); else the radius where it rises again halfway from its lowest to the ground
/// (Some(None) if it does not before the ray ends).
fn limb_beyond(
    profile: &dyn Fn(usize) -> Option<f64>,
    r: f64,
    step: f64,
    ground: Ground,
) -> Option<Option<f64>> {
    let sunk = |w: f64| w < ground.level - ground.trough;
    let (mut low, mut lowest) = (0, f64::INFINITY);
    let mut j = 0;
    while let Some(w) = profile(j) {
        if w < lowest {
            (low, lowest) = (j, w);
        }
        j += 1;
        if j >= PAST_SAMPLES && !sunk(lowest) {
            break;
        }
    }
    if !sunk(lowest) {
        return None;
    }
    // Past the lowest sample, the first rise through halfway to the ground.
    let half = 0.5 * (lowest + ground.level);
    let mut prev = lowest;
    let mut k = low + 1;
    while let Some(w) = profile(k) {
        if prev < half && w >= half {
            let r0 = r + (k - 1) as f64 * step;
            return Some(Some(r0 + (half - prev) / (w - prev) * step));
        }
        prev = w;
        k += 1;
    }
    Some(None)
}

/// How much of a circle its edge points go round: the number of 10° sectors (of 36) that hold
/// at least one. A partial arc fixes the centre well only across its chord.
pub fn sectors_covered(points: &[[f64; 2]], centre: [f64; 2]) -> usize {
    let mut sectors = [false; 36];
    for x in points {
        let a = (x[1] - centre[1]).atan2(x[0] - centre[0]);
        let k = ((a + std::f64::consts::PI) / std::f64::consts::TAU * 36.0) as usize;
        sectors[k.min(35)] = true;
    }
    sectors.iter().filter(|s| **s).count()
}

/// Fewer 10° sectors than this (of 36) holding edge points, where rays were left out over a
/// static backdrop: the edge-point fit holds the radius at the known one (half a circle and a
/// little more fixes both; less trades the radius against the centre across the chord).
const PARTIAL_ARC_SECTORS: usize = 20;

/// Edge points closer than this to the other sphere's disc are not used: in the narrow gap
/// between two spheres the background never reaches its level (both rims' blur and the motion
/// smear add up), so the edge there moves outwards and pulls the centre towards the other
/// sphere — a bias that grows as they approach and tilts the last frames before the impact.
pub const NEIGHBOUR_MARGIN_PX: f64 = 3.0;

/// Whether point `p` lies within `NEIGHBOUR_MARGIN_PX` of the `other` sphere's disc (centre,
/// radius, px): there the ground is not the ground.
fn by_the_other(p: [f64; 2], other: Option<([f64; 2], f64)>) -> bool {
    // (Squared distances: libm's hypot, called for every shadow reading of every ray, was
    // 1.3 % of a recording's analysis.)
    other.is_some_and(|(oc, or)| {
        let (du, dv) = (p[0] - oc[0], p[1] - oc[1]);
        let reach = (or + NEIGHBOUR_MARGIN_PX).max(0.0);
        du * du + dv * dv <= reach * reach
    })
}

/// How many of the ground's noise σ a profile must sink below the ground beyond its crossing
/// to show a limb darker than the ground (`edge_points`): noise alone, over the eleven
/// samples a ray reads beyond it, reaches 2–3σ.
const LIMB_TROUGH_NOISE: f64 = 6.0;

/// How many of the subtracted backdrop's noise σ (`GreyImage::ground_noise`) it must change by
/// along a ray before the ray is taken to cross a static backdrop's edge (`edge_points`). The
/// backdrop is a quantile of a few dozen sampled frames and keeps about a quarter of their
/// noise; a disc's rays compare some two thousand of its pixels with the ones where they start
/// (differences of √2σ), which noise alone takes to 4–5 of those, 6–7σ. Why a floor at all: on
/// the side of a disc whose shading is close to the ground's (a side-lit sphere over a grey
/// ground), a tenth of the contrast (`dip`) is below a grey level, and the backdrop's noise
/// marked such rays as crossing a tube end — the disc then taken as partly hidden, and
/// unmeasured where its grey-level fit did not settle from the edge points (an independent
/// render over a ground of 80: one sphere in 8 of a view's first 10 frames, the other view's
/// names swapped after the impact, e off by 1.9 at 680σ; docs/accuracy.md, session 51).
const STILL_STEP_NOISE: f64 = 8.0;

/// The ground's noise σ just outside the disc: the median absolute deviation of samples 2.5 px
/// beyond its edge (what else stands there, the other sphere or a backdrop's edge, is a minority).
fn ground_noise(
    img: &GreyImage,
    view: &View,
    centre: [f64; 2],
    radius_px: f64,
    rays: usize,
) -> f64 {
    let mut ring: Vec<f64> = (0..rays)
        .filter_map(|k| {
            let a = std::f64::consts::TAU * k as f64 / rays as f64;
            let (u, v) = (
                centre[0] + (radius_px + 2.5) * a.cos(),
                centre[1] + (radius_px + 2.5) * a.sin(),
            );
            view.contains(u, v).then(|| img.sample(u, v)).flatten()
        })
        .collect();
    if ring.len() < 8 {
        return f64::INFINITY;
    }
    ring.sort_by(f64::total_cmp);
    let median = ring[ring.len() / 2];
    // The deviations in place of the samples: one allocation per fit, not two.
    for x in ring.iter_mut() {
        *x = (*x - median).abs();
    }
    let mid = ring.len() / 2;
    1.4826 * *ring.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// A circle through edge points on rays from a rough centre, where the grey level crosses
/// halfway between `background` and the shading just inside the edge on that side; and whether
/// a static backdrop hid part of the edge or the view's border cut it (rays left out there):
/// then the fit is only a start, which the grey-level fit must confirm.
///
/// Why per side: a sphere lit from one side is bright at its rim there and at the ambient
/// floor on the other; one level for the whole rim crosses the dark side's edge far inside
/// it, or not at all, and such a disc was rejected as "not one circle".
pub fn fit_edges(
    img: &GreyImage,
    view: &View,
    rough: [f64; 2],
    radius_px: f64,
    background: f64,
    other: Option<([f64; 2], f64)>,
) -> Option<(CircleFit, bool)> {
    let rays = ((std::f64::consts::TAU * radius_px * 1.5).round() as usize).clamp(24, 720);
    let oversampling = rays as f64 / (std::f64::consts::TAU * radius_px);
    let mut centre = rough;
    let mut fit = None;
    for _ in 0..2 {
        // The shading 1.5 px inside the edge on each ray; beyond the view's border the frame
        // shows another view.
        let rim: Vec<Option<f64>> = (0..rays)
            .map(|k| {
                let a = std::f64::consts::TAU * k as f64 / rays as f64;
                let (u, v) = (
                    centre[0] + (radius_px - 1.5) * a.cos(),
                    centre[1] + (radius_px - 1.5) * a.sin(),
                );
                view.contains(u, v).then(|| img.sample(u, v)).flatten()
            })
            .collect();
        if rim.iter().filter(|r| r.is_some()).count() < rays / 4 {
            return fit;
        }
        // Per ray, the upper part of its neighbourhood's rim (a quarter turn's worth, which
        // dots, darker, pull down only at the bottom), so that a dot does not lower a level.
        let half = (rays / 16).max(2);
        let mut window: Vec<f64> = Vec::with_capacity(2 * half + 1);
        let ray_levels: Vec<RayLevel> = (0..rays)
            .map(|k| {
                window.clear();
                window.extend((0..=2 * half).filter_map(|j| rim[(k + rays + j - half) % rays]));
                if window.is_empty() {
                    return RayLevel::NONE;
                }
                window.sort_by(f64::total_cmp);
                let interior = window[window.len() * 3 / 4];
                if interior == background {
                    return RayLevel::NONE;
                }
                // Below the ground on this side: the same levels about the ground reflected
                // (dots, darker still, sit at the bottom of the rim either way).
                let contrast = (interior - background).abs();
                RayLevel {
                    level: background + 0.5 * contrast,
                    dip: 0.1 * contrast,
                    dark: interior < background,
                }
            })
            .collect();
        let ground = Ground {
            level: background,
            // (At least a grey level: a render without noise shows none.)
            trough: (LIMB_TROUGH_NOISE * ground_noise(img, view, centre, radius_px, rays)).max(1.0),
            still_noise: STILL_STEP_NOISE * img.ground_noise as f64,
        };
        let (mut pts, over_backdrop) =
            edge_points(img, view, centre, radius_px, &ray_levels, ground, other);
        // Rays whose rim lies beyond the view's border are left out too: the disc is cut
        // there, and the arc left is fitted at the known radius like one a backdrop hid (a
        // free radius on it put such centres 1–2 px off while claiming 0.25). Said outright:
        // before the floor on the backdrop's noise (`Ground::still_noise`), that noise left
        // such rays out by chance (their rim reads the ground: no contrast, no `dip`).
        let hidden = over_backdrop + rim.iter().filter(|r| r.is_none()).count();
        pts.retain(|&p| !by_the_other(p, other));
        // Rays over a static backdrop (a tube end the sphere is leaving, a ruler) tell nothing
        // here: a third of the others must give a point.
        if pts.len() < (rays - hidden) / 3 || pts.len() < 8 {
            // Most of the edge in front of a backdrop (a sphere leaving its tube): the rough
            // centre at the known radius is all the grey-level fit gets to start from.
            if fit.is_none() && 2 * hidden > rays {
                return Some((
                    CircleFit {
                        points_used: pts.len(),
                        points_total: pts.len(),
                        arc_sectors: sectors_covered(&pts, centre),
                        ..CircleFit::start_at(centre, radius_px)
                    },
                    true,
                ));
            }
            return fit;
        }
        // Where the backdrop hid much of the edge, the arc left may not fix the radius: the
        // centre at the known radius is the grey-level fit's start.
        let f = if hidden > 0 && sectors_covered(&pts, centre) < PARTIAL_ARC_SECTORS {
            fit_fixed_radius(&pts, centre, radius_px, oversampling)?
        } else {
            robust_fit(&pts, oversampling)?
        };
        centre = f.centre;
        fit = Some((f, hidden > 0));
    }
    fit
}

/// Centre of a circle of known radius through `points` (Gauss–Newton from `start`), dropping
/// points further than max(3σ, 0.1 px) from it and refitting.
pub fn fit_fixed_radius(
    points: &[[f64; 2]],
    start: [f64; 2],
    radius: f64,
    oversampling: f64,
) -> Option<CircleFit> {
    let mut keep: Vec<[f64; 2]> = points.to_vec();
    let mut c = start;
    let mut result = None;
    for _ in 0..3 {
        if keep.len() < 8 {
            return result;
        }
        let mut q = nalgebra::Vector2::new(c[0], c[1]);
        gauss_newton(&mut q, 20, |q| {
            let mut jtj = nalgebra::Matrix2::<f64>::zeros();
            let mut jtr = nalgebra::Vector2::<f64>::zeros();
            for p in &keep {
                let (dx, dy) = (p[0] - q[0], p[1] - q[1]);
                let d = dx.hypot(dy).max(1e-12);
                let j = nalgebra::Vector2::new(-dx / d, -dy / d);
                jtj += j * j.transpose();
                jtr += j * (d - radius);
            }
            (jtj, jtr, 0.0)
        })?;
        c = [q[0], q[1]];
        let mut jtj = nalgebra::Matrix2::<f64>::zeros();
        let res: Vec<f64> = keep
            .iter()
            .map(|p| {
                let (dx, dy) = (p[0] - c[0], p[1] - c[1]);
                let d = dx.hypot(dy).max(1e-12);
                let j = nalgebra::Vector2::new(-dx / d, -dy / d);
                jtj += j * j.transpose();
                d - radius
            })
            .collect();
        let n = keep.len() as f64;
        let s2 = res.iter().map(|e| e * e).sum::<f64>() / (n - 2.0).max(1.0);
        let inv = jtj.try_inverse()?;
        let cov_scale = s2 * oversampling.max(1.0);
        result = Some(CircleFit {
            centre: c,
            radius,
            centre_sigma: [
                (cov_scale * inv[(0, 0)]).sqrt(),
                (cov_scale * inv[(1, 1)]).sqrt(),
            ],
            radius_sigma: 0.0,
            rms_px: s2.sqrt(),
            points_used: keep.len(),
            points_total: points.len(),
            arc_sectors: sectors_covered(&keep, c),
            grey_levels: false,
            edge_width_px: f64::NAN,
        });
        let limit = (3.0 * s2.sqrt()).max(0.1);
        let before = keep.len();
        keep = keep
            .iter()
            .zip(&res)
            .filter(|(_, r)| r.abs() <= limit)
            .map(|(p, _)| *p)
            .collect();
        if keep.len() == before {
            break;
        }
    }
    result
}
