//! The flights in the image: which frames of each sphere are free flight on each side of the
//! impact (found in the direct view alone, before any geometry is trusted), the parabolas
//! through them, and the spheres' imaged size.

use super::Fitted;
use crate::analysis::geometry::V3;
use crate::analysis::tracking::FrameObs;
use nalgebra::{DMatrix, DVector};

/// The flights in the direct view, in its image alone: split at the frame where a and b are
/// closest, then for each sphere and side a parabola per image coordinate seeded on the 8
/// frames nearest the split and grown outwards while each next frame lies within 5σ of it (a
/// sphere still rolling in its tube leaves the parabola). Returns the split frame and the frames
/// of [a before, b before, a after, b after].
pub(super) fn flights(obs: &[FrameObs], di: usize) -> Result<(usize, [Vec<usize>; 4]), String> {
    let centre = |i: usize, s: usize| obs[i].spheres[s][di].as_ref().map(|m| m.centre_px);
    let split = (0..obs.len())
        .filter_map(|i| {
            let (a, b) = (centre(i, 0)?, centre(i, 1)?);
            Some((i, (a[0] - b[0]).hypot(a[1] - b[1])))
        })
        .min_by(|x, y| x.1.total_cmp(&y.1))
        .map(|(i, _)| i)
        .ok_or("spheres a and b are never both measured in the direct view")?;
    const SEED: usize = 8;
    let mut out: [Vec<usize>; 4] = Default::default();
    for (k, slot) in out.iter_mut().enumerate() {
        let (s, pre) = (k % 2, k < 2);
        // Outwards from the split, a frame's gap from it left for the contact itself.
        let order: Vec<usize> = if pre {
            (0..split.saturating_sub(1)).rev().collect()
        } else {
            (split + 2..obs.len()).collect()
        };
        let order: Vec<usize> = order
            .into_iter()
            .filter(|&i| centre(i, s).is_some())
            .collect();
        if order.len() < SEED {
            continue;
        }
        let mut kept: Vec<usize> = order[..SEED].to_vec();
        let mut misses = 0;
        for &i in &order[SEED..] {
            let pts: Vec<(f64, [f64; 2])> = kept
                .iter()
                .filter_map(|&j| Some((obs[j].time_s, centre(j, s)?)))
                .collect();
            let Some((c, rms)) = parabola(&pts) else {
                break;
            };
            let (t, q) = (obs[i].time_s, centre(i, s).unwrap_or([f64::NAN; 2]));
            let off = (0..2)
                .map(|a| (q[a] - (c[a][0] + c[a][1] * t + c[a][2] * t * t)).abs())
                .fold(0.0, f64::max);
            if off <= 5.0 * rms.max(0.05) {
                kept.push(i);
                misses = 0;
            } else {
                misses += 1;
                if misses >= 3 {
                    break;
                }
            }
        }
        kept.sort_unstable();
        *slot = kept;
    }
    Ok((split, out))
}

/// Coefficients (c0, c1, c2) of u(t) and v(t) = c0 + c1·t + c2·t², and the RMS residual, px.
pub(super) fn parabola(pts: &[(f64, [f64; 2])]) -> Option<([[f64; 3]; 2], f64)> {
    if pts.len() < 4 {
        return None;
    }
    let a = DMatrix::from_fn(pts.len(), 3, |r, j| pts[r].0.powi(j as i32));
    let svd = a.clone().svd(true, true);
    let mut coef = [[0.0; 3]; 2];
    let mut ss = 0.0;
    for (c, co) in coef.iter_mut().enumerate() {
        let b = DVector::from_fn(pts.len(), |r, _| pts[r].1[c]);
        let x = svd.solve(&b, 1e-12).ok()?;
        ss += (b - &a * &x).norm_squared();
        *co = [x[0], x[1], x[2]];
    }
    Some((coef, (ss / (2 * pts.len()) as f64).sqrt()))
}

/// Acceleration (u, v) of a parabola through image points over time, px/s², and its σ per
/// component; None under 6 points.
pub(super) fn parabola_acceleration(pts: &[(f64, [f64; 2])]) -> Option<([f64; 2], f64)> {
    if pts.len() < 6 {
        return None;
    }
    let t0 = pts.iter().map(|p| p.0).sum::<f64>() / pts.len() as f64;
    let mut ata = nalgebra::Matrix3::<f64>::zeros();
    let mut atb = [V3::zeros(); 2];
    for (t, q) in pts {
        let a = V3::new(1.0, t - t0, (t - t0).powi(2));
        ata += a * a.transpose();
        for c in 0..2 {
            atb[c] += a * q[c];
        }
    }
    let inv = ata.try_inverse()?;
    let coef = atb.map(|b| inv * b);
    let mut ss = 0.0;
    for (t, q) in pts {
        let a = V3::new(1.0, t - t0, (t - t0).powi(2));
        for c in 0..2 {
            ss += (q[c] - coef[c].dot(&a)).powi(2);
        }
    }
    let var = ss / (2.0 * pts.len() as f64 - 6.0);
    Some((
        [2.0 * coef[0][2], 2.0 * coef[1][2]],
        2.0 * (var * inv[(2, 2)]).max(0.0).sqrt(),
    ))
}

/// Median imaged diameter over the true one, px/mm, with σ from the spread.
pub(super) fn diameter_scale(obs: &[FrameObs], vi: usize, diam_mm: [f64; 2]) -> Option<Fitted> {
    let mut r: Vec<f64> = obs
        .iter()
        .flat_map(|f| {
            (0..2).filter_map(move |s| Some(f.spheres[s][vi].as_ref()?.diameter_px / diam_mm[s]))
        })
        .filter(|x| x.is_finite() && *x > 0.0)
        .collect();
    if r.len() < 3 {
        return None;
    }
    r.sort_by(f64::total_cmp);
    let med = r[r.len() / 2];
    let mut dev: Vec<f64> = r.iter().map(|x| (x - med).abs()).collect();
    dev.sort_by(f64::total_cmp);
    Some(Fitted {
        value: med,
        sigma: 1.4826 * dev[dev.len() / 2] * (std::f64::consts::PI / 2.0 / r.len() as f64).sqrt(),
    })
}
