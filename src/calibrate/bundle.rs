//! Both views fitted to the flights at once (a small bundle adjustment): every flight a
//! ballistic trajectory with g known, seen through the direct view's and the mirror's maps;
//! Levenberg–Marquardt with weak priors on what the flights cannot tell apart, outliers left out.

use super::maps::{direct_matrix, facing_of, mirror_matrix, x_sign};
use super::provisional::MirrorAxes;
use super::{Fitted, MirrorFit};
use crate::analysis::calibration::fit_line;
use crate::analysis::geometry::{View, V3};
use crate::analysis::tracking::FrameObs;
use nalgebra::{DMatrix, DVector};

/// One image point of a sphere in free flight: flight index, time from the flight's mean,
/// view (0 direct, 1 mirror) and the point.
pub(super) struct FlightPoint {
    flight: usize,
    dt: f64,
    view: usize,
    q: [f64; 2],
}

/// What the joint fit found: the direct view's scale and roll, the mirror's scale, roll, tilt
/// and u offset, the lens's k1, with σ, and the residuals per view.
pub(super) struct Bundle {
    pub(super) direct_scale: Fitted,
    pub(super) direct_roll: Fitted,
    /// Inverse camera distance of [direct, mirror], 1/mm.
    pub(super) kappa: [Fitted; 2],
    /// The lens's radial distortion (`analysis::lens`, about `LensFrame`'s centre and radius);
    /// σ 0 when it was held at 0.
    pub(super) lens_k1: Fitted,
    pub(super) mirror: Option<MirrorFit>,
    pub(super) residual_rms_px: [f64; 2],
    /// The mean depth of the spheres' centres towards each view's camera, mm, over the points
    /// fitted (facing·w): where perspective was found, the imaged diameter is the scale there.
    pub(super) mean_depth_mm: [f64; 2],
}

/// (parameter, σ) of the bundle's priors: the mirror's turns about x, y, z (rad), the two
/// cameras' 1/distance (1/mm) and the lens's k1 (a lens that moves the frame's corners by 5 %
/// is far beyond any a measuring rig uses).
pub(super) const PRIORS: [(usize, f64); 6] = [
    (3, 0.0873),
    (4, 0.0873),
    (5, 0.0873),
    (7, 0.01),
    (8, 0.01),
    (9, 0.05),
];

/// Where the one lens both views are seen through has its centre, and the distance at which its
/// k1 is the fractional displacement: the frame's centre and half-diagonal, px.
#[derive(Clone, Copy, Debug)]
pub(super) struct LensFrame {
    pub(super) centre_px: [f64; 2],
    pub(super) radius_px: f64,
}

impl LensFrame {
    pub(super) fn of_frame(width: u32, height: u32) -> LensFrame {
        let (w, h) = (f64::from(width), f64::from(height));
        LensFrame {
            centre_px: [(w - 1.0) / 2.0, (h - 1.0) / 2.0],
            radius_px: 0.5 * w.hypot(h),
        }
    }

    pub(super) fn lens(&self, k1: f64) -> crate::analysis::lens::Lens {
        crate::analysis::lens::Lens {
            k1,
            centre_px: self.centre_px,
            radius_px: self.radius_px,
        }
    }
}

/// Both views fitted together (a small bundle adjustment): every flight is a ballistic
/// trajectory with g known (x, z straight lines, y a parabola), seen by the direct view through
/// (s_d, φ_d) and by the mirror through its scale, its turn about x, y and z, and its offset
/// along its image of x (u, or v on a camera turned on its side); both through one lens of
/// radial distortion k1 (held at 0 unless `lens` is given, and at `lens_k1_held` where that is
/// given: a dot grid's). Held: the direct view's origin and the mirror's offset along its image
/// of z (the world origin, a choice), the mirror's flips, and each camera's 1/distance at 0
/// where `perspective` says so (a camera the flights show no perspective of: `calibrate`).
#[allow(clippy::too_many_arguments)]
pub(super) fn fit_bundle(
    obs: &[FrameObs],
    phases: &[Vec<usize>],
    g: f64,
    di: usize,
    mi: Option<usize>,
    origin_direct: [f64; 2],
    start: (f64, f64),
    provisional_mirror: Option<&View>,
    lens: Option<LensFrame>,
    lens_k1_held: Option<f64>,
    perspective: [bool; 2],
    views: &[View],
) -> Result<Bundle, String> {
    let mut pts = Vec::new();
    for (k, frames) in phases.iter().enumerate() {
        let s = k % 2;
        let mean_t =
            frames.iter().map(|&i| obs[i].time_s).sum::<f64>() / frames.len().max(1) as f64;
        for &i in frames {
            let f = &obs[i];
            for (view, vi) in [(0, Some(di)), (1, mi)] {
                let Some(vi) = vi else { continue };
                if let Some(m) = &f.spheres[s][vi] {
                    // Whole discs only (`cut_by_border`): on a recording through a lens of
                    // k1 = −0.03 the cut discs at the top of the direct view, fitted at the
                    // nominal radius 0.08 px too large there, put the flights' scale 3.7 % low
                    // with the true k1 held (a dot grid's) and a perspective 300 mm away that
                    // the rig does not have; without them, 0.04 % (docs/accuracy.md, session 36).
                    if cut_by_border(&views[vi], m) {
                        continue;
                    }
                    pts.push(FlightPoint {
                        flight: k,
                        dt: f.time_s - mean_t,
                        view,
                        q: m.centre_px,
                    });
                }
            }
        }
    }
    let flights: Vec<usize> = (0..phases.len())
        .filter(|k| pts.iter().filter(|p| p.flight == *k && p.view == 0).count() >= 6)
        .collect();
    pts.retain(|p| flights.contains(&p.flight));
    let mirror_points = pts.iter().filter(|p| p.view == 1).count();
    let with_mirror = mi.is_some() && provisional_mirror.is_some();
    if flights.len() < 2 || (with_mirror && mirror_points < 12) {
        return Err(format!(
            "{} flight(s) of 6 frames or more in the direct view and {mirror_points} mirror centres: calibrate needs 2 flights (a collision gives 4) and 12 mirror centres",
            flights.len()
        ));
    }
    // How the mirror images x and z (the thesis's way, or turned on its side), and its offset
    // along the image axis of z, held (the world origin's z, a choice).
    let axes = provisional_mirror
        .map(MirrorAxes::of)
        .unwrap_or(MirrorAxes {
            x_along: 0,
            sx: 1.0,
            f: 1.0,
        });
    let (kx, kz, f) = (axes.x_along, 1 - axes.x_along, axes.f);
    // Which side of the mirror view its camera is on (`View::mirrored`): it sets the sign of
    // the camera's 1/distance.
    let mirror_mirrored = provisional_mirror.is_none_or(|v| v.mirrored);
    let ov = provisional_mirror.map_or(0.0, |v| v.origin_px[kz]);
    // Parameters: s_d, φ_d, s_m, the mirror's turn about x, y, z, its offset along x, the direct and the
    // mirror camera's inverse distance κ (1/mm; 0 is orthographic), the lens's k1, then
    // (x0, vx, y0, vy, z0, vz) per flight.
    let nv = 10;
    let frame = lens.unwrap_or(LensFrame {
        centre_px: [0.0, 0.0],
        radius_px: 1.0,
    });
    let np = nv + 6 * flights.len();
    let mut th = DVector::zeros(np);
    th[0] = start.0;
    th[1] = start.1;
    if let Some(v) = provisional_mirror {
        th[2] = v.px_per_mm;
        th[6] = v.origin_px[kx];
    }
    let slot = |k: usize| flights.iter().position(|&x| x == k).unwrap_or(0);
    // Starting trajectories: the direct view inverted with the starting map; z from the
    // provisional mirror, each a straight line per flight.
    let sd = x_sign(&views[di]);
    let m0 = direct_matrix(start.0, start.1, sd);
    let inv = nalgebra::Matrix2::new(m0[0][0], m0[0][1], m0[1][0], m0[1][1])
        .try_inverse()
        .ok_or("the direct view's starting map is singular")?;
    for (j, &k) in flights.iter().enumerate() {
        // (intercept, slope); a constant (their mean) where the times do not spread.
        let line = |vals: &[(f64, f64)]| -> (f64, f64) {
            fit_line(vals)
                .map(|l| (l.intercept, l.slope))
                .unwrap_or_else(|| {
                    let mean = vals.iter().map(|x| x.1).sum::<f64>() / vals.len().max(1) as f64;
                    (mean, 0.0)
                })
        };
        let xy: Vec<(f64, nalgebra::Vector2<f64>)> = pts
            .iter()
            .filter(|p| p.flight == k && p.view == 0)
            .map(|p| {
                let d =
                    nalgebra::Vector2::new(p.q[0] - origin_direct[0], p.q[1] - origin_direct[1]);
                (p.dt, inv * d)
            })
            .collect();
        let xs: Vec<(f64, f64)> = xy.iter().map(|(t, p)| (*t, p[0])).collect();
        let ys: Vec<(f64, f64)> = xy
            .iter()
            .map(|(t, p)| (*t, p[1] + 0.5 * g * t * t))
            .collect();
        let (x0, vx) = line(&xs);
        let (y0, vy) = line(&ys);
        let zs: Vec<(f64, f64)> = pts
            .iter()
            .filter(|p| p.flight == k && p.view == 1)
            .map(|p| (p.dt, f * (p.q[kz] - ov) / th[2].max(1e-9)))
            .collect();
        let (z0, vz) = line(&zs);
        for (c, v) in [x0, vx, y0, vy, z0, vz].into_iter().enumerate() {
            th[nv + 6 * j + c] = v;
        }
    }
    // Points left out as outliers (a frame still in contact, a sphere still in its tube at
    // a flight's end) weigh 0.
    let weights = std::cell::RefCell::new(vec![1.0; pts.len()]);
    let residuals = |th: &DVector<f64>| -> DVector<f64> {
        let weights = weights.borrow();
        let md = direct_matrix(th[0], th[1], sd);
        let mm = mirror_matrix(th[2], [th[3], th[4], th[5]], axes);
        let (fd, fm) = (
            facing_of(&md, views[di].mirrored),
            facing_of(&mm, mirror_mirrored),
        );
        let mut r = DVector::zeros(2 * pts.len() + PRIORS.len());
        // Weak priors keep what the flights cannot tell apart sane (and its σ honest): each
        // of the mirror's turns 0 ± 5°, each camera's 1/distance 0 ± 0.01 /mm; a row weighs as
        // an image residual of 0.03 px does.
        for (j, &(c, sigma)) in PRIORS.iter().enumerate() {
            r[2 * pts.len() + j] = th[c] / sigma * 0.03;
        }
        for (i, p) in pts.iter().enumerate() {
            let b = nv + 6 * slot(p.flight);
            let t = p.dt;
            let w = [
                th[b] + th[b + 1] * t,
                th[b + 2] + th[b + 3] * t - 0.5 * g * t * t,
                th[b + 4] + th[b + 5] * t,
            ];
            let (m, o, facing, kappa) = if p.view == 0 {
                (&md, origin_direct, fd, th[7])
            } else {
                let mut o = [0.0; 2];
                (o[kx], o[kz]) = (th[6], ov);
                (&mm, o, fm, th[8])
            };
            let k = 1.0 / (1.0 - kappa * facing.dot(&V3::from(w)));
            let ideal =
                [0, 1].map(|c| k * (m[c][0] * w[0] + m[c][1] * w[1] + m[c][2] * w[2]) + o[c]);
            let seen = if th[9] != 0.0 {
                frame.lens(th[9]).distort(ideal)
            } else {
                ideal
            };
            for c in 0..2 {
                r[2 * i + c] = weights[i] * (p.q[c] - seen[c]);
            }
        }
        r
    };
    // Without a mirror its parameters are held (their columns left out); without a lens, k1.
    // A held k1 (a grid's) is first fitted free like the rest, and held only once the flights
    // are fitted: held from the start, the descent and the outliers it leaves out have ended in
    // a minimum with every scale 3 % off (a recording through a lens of k1 = −0.03).
    // A camera held orthographic (`perspective` false) keeps its κ at 0.
    let free_of = |k1_free: bool| -> Vec<usize> {
        (0..np)
            .filter(|&c| c != 9 || (lens.is_some() && k1_free))
            .filter(|&c| !(c == 7 || c == 8) || perspective[c - 7])
            .filter(|&c| with_mirror || !(2..nv - 1).contains(&c))
            .filter(|&c| with_mirror || (c < nv || (c - nv) % 6 < 4))
            .collect()
    };
    let first = free_of(true);
    let free = free_of(lens_k1_held.is_none());
    // Levenberg–Marquardt: Gauss–Newton steps, damped where they would not lower the cost.
    let descend = |th: &mut DVector<f64>, free: &[usize]| {
        let mut jac = DMatrix::zeros(2 * pts.len() + PRIORS.len(), free.len());
        let mut lambda = 1e-3;
        for _ in 0..60 {
            let r0 = residuals(th);
            let cost0 = r0.norm_squared();
            for (jc, &c) in free.iter().enumerate() {
                let h = 1e-6 * th[c].abs().max(1e-4);
                let mut t2 = th.clone();
                t2[c] += h;
                jac.set_column(jc, &((residuals(&t2) - &r0) / h));
            }
            let a = jac.transpose() * &jac;
            let grad = jac.transpose() * &r0;
            let mut moved = None;
            while lambda < 1e12 {
                let mut damped = a.clone();
                for d in 0..damped.nrows() {
                    damped[(d, d)] += lambda * a[(d, d)].max(1e-12);
                }
                let Some(step) = damped.try_inverse().map(|inv| -(inv * &grad)) else {
                    lambda *= 10.0;
                    continue;
                };
                let mut trial = th.clone();
                for (jc, &c) in free.iter().enumerate() {
                    trial[c] += step[jc];
                }
                if residuals(&trial).norm_squared() <= cost0 {
                    *th = trial;
                    lambda = (lambda / 10.0).max(1e-9);
                    moved = Some(step.amax());
                    break;
                }
                lambda *= 10.0;
            }
            match moved {
                Some(m) if m > 1e-10 => {}
                _ => break,
            }
        }
    };
    for _round in 0..4 {
        descend(&mut th, &first);
        // Robust: points beyond 6σ (σ from the median residual, at least 0.02 px) are left out
        // and the fit repeated, until none is.
        let r = residuals(&th);
        let norms: Vec<f64> = (0..pts.len())
            .map(|i| r[2 * i].hypot(r[2 * i + 1]))
            .collect();
        let mut kept: Vec<f64> = norms
            .iter()
            .zip(weights.borrow().iter())
            .filter(|(_, w)| **w > 0.0)
            .map(|(n, _)| *n)
            .collect();
        kept.sort_by(f64::total_cmp);
        // The median of a 2-D residual's length is 1.1774σ for Gaussian errors.
        let sigma = (kept.get(kept.len() / 2).copied().unwrap_or(0.0) / 1.1774).max(0.02);
        let mut changed = false;
        for (w, n) in weights.borrow_mut().iter_mut().zip(&norms) {
            if *w > 0.0 && *n > 6.0 * sigma {
                *w = 0.0;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    if let Some(k1) = lens_k1_held.filter(|_| lens.is_some()) {
        th[9] = k1;
        descend(&mut th, &free);
    }
    let mut jac = DMatrix::zeros(2 * pts.len() + PRIORS.len(), free.len());
    let r0 = residuals(&th);
    for (jc, &c) in free.iter().enumerate() {
        let h = 1e-6 * th[c].abs().max(1e-4);
        let mut t2 = th.clone();
        t2[c] += h;
        jac.set_column(jc, &((residuals(&t2) - &r0) / h));
    }
    let r = residuals(&th);
    let used = 2 * weights.borrow().iter().filter(|w| **w > 0.0).count();
    let dof = (used as f64 - free.len() as f64).max(1.0);
    let cov = (jac.transpose() * &jac)
        .try_inverse()
        .ok_or("the fit is degenerate")?
        * (r.norm_squared() / dof);
    let fitted = |c: usize, k: f64| {
        let jc = free.iter().position(|&x| x == c);
        Fitted {
            value: th[c] * k,
            sigma: jc
                .map(|j| cov[(j, j)].max(0.0).sqrt() * k.abs())
                .unwrap_or(0.0),
        }
    };
    let rms = |view: usize| {
        let (ss, n) = pts
            .iter()
            .enumerate()
            .filter(|(i, p)| p.view == view && weights.borrow()[*i] > 0.0)
            .fold((0.0, 0usize), |(ss, n), (i, _)| {
                (ss + r[2 * i].powi(2) + r[2 * i + 1].powi(2), n + 2)
            });
        if n == 0 {
            f64::NAN
        } else {
            (ss / n as f64).sqrt()
        }
    };
    let mean_depth = |view: usize| {
        let md = direct_matrix(th[0], th[1], sd);
        let mm = mirror_matrix(th[2], [th[3], th[4], th[5]], axes);
        let facing = if view == 0 {
            facing_of(&md, views[di].mirrored)
        } else {
            facing_of(&mm, mirror_mirrored)
        };
        let (sum, n) = pts
            .iter()
            .enumerate()
            .filter(|(i, p)| p.view == view && weights.borrow()[*i] > 0.0)
            .fold((0.0, 0usize), |(sum, n), (_, p)| {
                let (b, t) = (nv + 6 * slot(p.flight), p.dt);
                let w = V3::new(
                    th[b] + th[b + 1] * t,
                    th[b + 2] + th[b + 3] * t - 0.5 * g * t * t,
                    th[b + 4] + th[b + 5] * t,
                );
                (sum + facing.dot(&w), n + 1)
            });
        if n == 0 {
            0.0
        } else {
            sum / n as f64
        }
    };
    let deg = 180.0 / std::f64::consts::PI;
    Ok(Bundle {
        mean_depth_mm: [mean_depth(0), mean_depth(1)],
        direct_scale: fitted(0, 1.0),
        direct_roll: fitted(1, deg),
        kappa: [fitted(7, 1.0), fitted(8, 1.0)],
        lens_k1: fitted(9, 1.0),
        mirror: with_mirror.then(|| MirrorFit {
            scale: fitted(2, 1.0),
            scale_from_diameter: Fitted {
                value: f64::NAN,
                sigma: f64::NAN,
            },
            tilt_deg: fitted(3, deg),
            roll_deg: fitted(4, deg),
            yaw_deg: fitted(5, deg),
            origin_x_px: fitted(6, 1.0),
            x_along_v: kx == 1,
            x_reversed: axes.sx < 0.0,
            residual_rms_px: rms(1),
            points: mirror_points,
            camera_distance_mm: None,
        }),
        residual_rms_px: [rms(0), rms(1)],
    })
}

/// Whether a measured disc reaches a view's border: such a disc is fitted at a known radius
/// (`tracking::measure::fit_blob`), here the provisional map's, with no lens yet (calibrate is
/// fitting it) and no perspective, which makes it wrong there; its centre moves across the cut
/// with that error.
pub(super) fn cut_by_border(view: &View, m: &crate::analysis::tracking::Measurement) -> bool {
    let r = 0.5 * m.diameter_px + 1.0;
    let [c0, c1] = m.centre_px;
    !(view.contains(c0 - r, c1)
        && view.contains(c0 + r, c1)
        && view.contains(c0, c1 - r)
        && view.contains(c0, c1 + r))
}

#[cfg(test)]
mod tests;
