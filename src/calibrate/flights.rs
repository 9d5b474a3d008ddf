//! The flights in the image: which frames of each sphere are free flight on each side of the
//! impact (found in the direct view alone, before any geometry is trusted), the parabolas
//! through them, and the spheres' imaged size.

use super::bundle::cut_by_border;
use super::sigma::scatter_ratio;
use super::Fitted;
use crate::analysis::geometry::View;
use crate::analysis::geometry::V3;
use crate::analysis::tracking::{FrameObs, Measurement};
use nalgebra::{DMatrix, DVector};

/// The views `flights` reads: the direct one's index and the image axis world x runs along in
/// it (`provisional::x_index`), and the mirror's, where there is one.
#[derive(Clone, Copy, Debug)]
pub(super) struct FlightViews {
    pub(super) direct: (usize, usize),
    pub(super) mirror: Option<(usize, usize)>,
}

/// Frames with both spheres measured in both views, at least, for `flights` to split where
/// their separation seen by both views is least; fewer, and the direct view's alone decides.
const SPLIT_FRAMES_BOTH_VIEWS: usize = 4;

/// The frame the flights split at: where spheres a and b are closest. Seen by both views
/// (`SPLIT_FRAMES_BOTH_VIEWS` frames or more with both spheres in each), their separation is
/// taken as the direct view's (x, y) and the mirror's (x, z) put together, the x both share
/// counted once (the mean of its squares in the two images); else the direct view's alone.
/// Why: spheres that part along the direct camera's line of sight overlap in its image for
/// the rest of the recording, a few pixels apart where it measures them whole; split there,
/// 5–14 frames after the impact, the flights before it ran through the impact and calibrate
/// wrote a direct view rolled by 72° (a render of the lab's v03 seen from 542 mm).
fn split_frame(obs: &[FrameObs], views: FlightViews) -> Option<usize> {
    let pair = |i: usize, v: usize| {
        let c = |s: usize| obs[i].spheres[s].get(v)?.as_ref().map(|m| m.centre_px);
        let (a, b) = (c(0)?, c(1)?);
        Some([a[0] - b[0], a[1] - b[1]])
    };
    let (di, kd) = views.direct;
    let both = |i: usize| {
        let (mi, km) = views.mirror?;
        let (d, m) = (pair(i, di)?, pair(i, mi)?);
        let sq = |p: [f64; 2]| p[0] * p[0] + p[1] * p[1];
        Some(sq(d) + sq(m) - 0.5 * (d[kd] * d[kd] + m[km] * m[km]))
    };
    let closest = |sep: &dyn Fn(usize) -> Option<f64>| {
        (0..obs.len())
            .filter_map(|i| Some((i, sep(i)?)))
            .min_by(|x, y| x.1.total_cmp(&y.1))
            .map(|(i, _)| i)
    };
    if (0..obs.len()).filter(|&i| both(i).is_some()).count() >= SPLIT_FRAMES_BOTH_VIEWS {
        return closest(&both);
    }
    closest(&|i| pair(i, di).map(|d| d[0] * d[0] + d[1] * d[1]))
}

/// The flights in the direct view, in its image alone: split at the frame where a and b are
/// closest (`split_frame`), then for each sphere and side a parabola per image coordinate
/// seeded on the 8 frames nearest the split and grown outwards while each next frame lies
/// within 5σ of it (a sphere still rolling in its tube leaves the parabola). Returns the split
/// frame and the frames of [a before, b before, a after, b after].
pub(super) fn flights(
    obs: &[FrameObs],
    views: FlightViews,
) -> Result<(usize, [Vec<usize>; 4]), String> {
    let di = views.direct.0;
    let centre = |i: usize, s: usize| obs[i].spheres[s][di].as_ref().map(|m| m.centre_px);
    let split = split_frame(obs, views)
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

/// How far the disc's model can put a sharp edge from where it is, px on the radius, whatever
/// the look: a lamp off the camera's axis, a shiny surface, dots at the limb. The largest mean
/// radius error measured (docs/accuracy.md, session 32): 0.027 px on hw-sim's varied looks
/// (a specular family's rig), 0.016 px on the independent renders with sharp edges.
pub(super) const EDGE_SYSTEMATIC_PX: f64 = 0.03;

/// Median imaged diameter over the true one, px/mm. Its σ is the median's own (from the
/// spread) and what the look can do to every disc alike, which no number of frames averages
/// away: `EDGE_SYSTEMATIC_PX`, and defocus's σ_b²/R, where σ_b = π·s/√3 is the fitted edge's
/// blur (`Measurement::edge_width_px`, the median over the view). Why σ_b²/R: blurring a disc
/// moves its half-level contour in by σ_b²/2R, and the disc's model follows that only in
/// part; on hw-sim's defocused looks the diameter came out 0.5–2.6 % small at σ_b 1–1.5 px
/// (R ≈ 7 px: σ_b²/R is 2–5 %), on a render blurred by 0.5 px 0.6 % large.
///
/// Discs the grey-level model fitted (a finite edge width) are taken alone where there are
/// three or more: a disc fitted on its edge points (where the model's fit failed) is only the
/// model's start, and its edge is where the profile crosses a level, not where the disc ends.
/// Why: on a render lit along the axis over a ground brighter than the spheres' limbs, with
/// markers at the rim, sphere a's direct discs all fell back to edge points, 11.1–11.5 px
/// across for 12.5; the median of both spheres' put the scale 8 % low at a σ of 1.2 %.
pub(super) fn diameter_scale(obs: &[FrameObs], vi: usize, diam_mm: [f64; 2]) -> Option<Fitted> {
    let measured = |m: &Measurement| m.diameter_px.is_finite() && m.diameter_px > 0.0;
    let modelled = obs
        .iter()
        .flat_map(|f| (0..2).filter_map(move |s| f.spheres[s][vi].as_ref()))
        .filter(|m| measured(m) && m.edge_width_px.is_finite())
        .count();
    let modelled_only = modelled >= 3;
    let discs = || {
        obs.iter().flat_map(move |f| {
            (0..2).filter_map(move |s| {
                let m = f.spheres[s][vi].as_ref()?;
                (measured(m) && (!modelled_only || m.edge_width_px.is_finite())).then_some((s, m))
            })
        })
    };
    let mut r: Vec<f64> = discs().map(|(s, m)| m.diameter_px / diam_mm[s]).collect();
    if r.len() < 3 {
        return None;
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let med = median(&mut r);
    let mut dev: Vec<f64> = r.iter().map(|x| (x - med).abs()).collect();
    let spread = 1.4826 * median(&mut dev) * (std::f64::consts::PI / 2.0 / r.len() as f64).sqrt();
    let radius_px = median(&mut discs().map(|(_, m)| m.diameter_px / 2.0).collect());
    let mut widths: Vec<f64> = discs()
        .map(|(_, m)| m.edge_width_px)
        .filter(|w| w.is_finite())
        .collect();
    let blur_px = if widths.is_empty() {
        0.0
    } else {
        std::f64::consts::PI / 3f64.sqrt() * median(&mut widths)
    };
    let systematic_px = EDGE_SYSTEMATIC_PX.hypot(blur_px * blur_px / radius_px);
    Some(Fitted {
        value: med,
        sigma: spread.hypot(med * systematic_px / radius_px),
    })
}

/// The direct view's free fall, pooled over the flights (`free_fall`).
pub(super) struct FreeFall {
    /// px/mm, from the acceleration's size (g known).
    pub scale: Fitted,
    /// The image direction of gravity: the camera's roll, deg.
    pub roll_deg: Fitted,
    /// How much more the flights' accelerations scatter than their σ say (`scatter_ratio`),
    /// already in both σ; every scale from the flights' curvature carries it.
    pub scatter: f64,
}

/// The direct view's free fall: each flight's image acceleration (`parabola_acceleration`,
/// whole discs only, as the bundle takes them: `cut_by_border`), weighed by its σ. None where
/// no flight has six frames.
pub(super) fn free_fall(
    obs: &[FrameObs],
    views: &[View],
    phases: &[Vec<usize>],
    di: usize,
    g: f64,
) -> Option<FreeFall> {
    let mut acc = Vec::new();
    for (k, frames) in phases.iter().enumerate() {
        let pts: Vec<(f64, [f64; 2])> = frames
            .iter()
            .filter_map(|&i| {
                let m = obs[i].spheres[k % 2][di].as_ref()?;
                (!cut_by_border(&views[di], m)).then_some((obs[i].time_s, m.centre_px))
            })
            .collect();
        if let Some(a) = parabola_acceleration(&pts) {
            acc.push(a);
        }
    }
    if acc.is_empty() {
        return None;
    }
    let (mut w, mut au, mut av) = (0.0, 0.0, 0.0);
    for (a, s) in &acc {
        let wk = 1.0 / (s * s);
        w += wk;
        au += wk * a[0];
        av += wk * a[1];
    }
    let (au, av, sa) = (au / w, av / w, w.recip().sqrt());
    let a_norm = au.hypot(av);
    // How much more the flights' accelerations scatter than their σ say (Birge's ratio, at
    // least 1): a disc's centre errs alike from frame to frame as it crosses the light and the
    // pixel grid, which a fit that takes its residuals for independent cannot see, and every
    // scale from the flights' curvature carries it. On 72 hw-sim rigs drawn at random and
    // calibrated (docs/accuracy.md, session 48) the flights' scale was within its σ on 50 %
    // and beyond 3σ on 9, up to 6σ; the diameter's within its σ on 93 %, none beyond 2σ.
    let scatter = scatter_ratio(&acc, [au, av]);
    Some(FreeFall {
        scale: Fitted {
            value: a_norm / g,
            sigma: sa / g * scatter,
        },
        roll_deg: Fitted {
            value: au.atan2(av).to_degrees(),
            sigma: (sa / a_norm).to_degrees() * scatter,
        },
        scatter,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A disc measured at `centre_px`, `diameter_px` across, fitted with edge width
    /// `edge_width_px` (NaN: on edge points).
    fn disc(centre_px: [f64; 2], diameter_px: f64, edge_width_px: f64) -> Option<Measurement> {
        Some(Measurement {
            centre_px,
            blob_centroid_px: centre_px,
            sigma_px: [0.02; 2],
            diameter_px,
            edge_width_px,
            markers: Vec::new(),
            hidden_in_part: None,
            radius_stray_px: 0.0,
            sigma_common_px: 0.0,
        })
    }

    /// 30 frames of both spheres seen whole in one view, diameters 13.7 px ± 0.02 px.
    fn discs(edge_width_px: f64) -> Vec<FrameObs> {
        (0..30)
            .map(|k| {
                let m = |d: f64| disc([50.0, 40.0], d, edge_width_px);
                let d = 13.7 + 0.02 * ((k % 5) as f64 - 2.0);
                FrameObs {
                    index: k,
                    frame_id: k,
                    time_s: k as f64 / 1000.0,
                    spheres: [vec![m(d)], vec![m(d + 0.01)]],
                    position_mm: [None, None],
                }
            })
            .collect()
    }

    /// The diameter's scale is known no better than the disc's model places an edge, however
    /// many frames agree, and worse where the edge is blurred.
    #[test]
    fn the_diameters_scale_carries_what_the_look_can_do_to_every_disc() {
        let diam = [6.35, 6.35];
        let sharp = diameter_scale(&discs(0.05), 0, diam).unwrap();
        let blurred = diameter_scale(&discs(0.6), 0, diam).unwrap();
        let typed_in = diameter_scale(&discs(f64::NAN), 0, diam).unwrap();
        assert!((sharp.value - 13.7 / 6.35).abs() < 0.01, "{}", sharp.value);
        // The median of 60 discs scattered by 0.02 px alone would claim 0.02 %.
        let floor = EDGE_SYSTEMATIC_PX / 6.85;
        let rel = |f: Fitted| f.sigma / f.value;
        assert!(rel(sharp) >= floor, "sharp: {} against {floor}", rel(sharp));
        assert!(rel(sharp) < 1.1 * floor, "sharp: {}", rel(sharp));
        assert!(rel(typed_in) >= floor, "{}", rel(typed_in));
        // s = 0.6: σ_b = 1.09 px, σ_b²/R = 0.17 px, 2.5 % of R.
        assert!(rel(blurred) > 0.02, "blurred: {}", rel(blurred));
    }

    /// Spheres that part along the direct camera's line of sight after they meet: in its image
    /// they stay a few pixels apart for the rest of the recording (measured whole in some
    /// frames), closer than in any frame before the impact; the mirror sees them part. The
    /// flights split at the impact, not in those frames.
    #[test]
    fn the_flights_split_where_both_views_see_the_spheres_closest() {
        let impact = 20;
        let obs: Vec<FrameObs> = (0..40)
            .map(|k| {
                let t = k as f64 - impact as f64;
                // Before: closing along x at 2 px a frame, 14 px apart at the last frame
                // before contact; after: 8 px apart in the direct image, parting along z.
                let (dx, dz) = if t < 0.0 {
                    (12.0 - 2.0 * t, 0.0)
                } else {
                    (8.0, 12.0 + 3.0 * t)
                };
                let (cd, cm) = ([100.0, 40.0], [100.0, 140.0]);
                let direct = [
                    disc([cd[0] - dx / 2.0, cd[1]], 13.0, 0.05),
                    disc([cd[0] + dx / 2.0, cd[1]], 13.0, 0.05),
                ];
                let mirror = [
                    disc([cm[0] - dx / 2.0, cm[1] - dz / 2.0], 13.0, 0.05),
                    disc([cm[0] + dx / 2.0, cm[1] + dz / 2.0], 13.0, 0.05),
                ];
                // The spheres touch over the impact's frames and are not measured whole; after
                // it the direct view measures them only now and then, overlapping.
                let touching = (impact - 1..=impact + 1).contains(&k);
                let direct_seen = !touching && (t < 0.0 || k % 5 == 0);
                let [da, db] = direct;
                let [ma, mb] = mirror;
                let keep = |m: Option<Measurement>, seen: bool| if seen { m } else { None };
                FrameObs {
                    index: k as u64,
                    frame_id: k as u64,
                    time_s: k as f64 / 1000.0,
                    spheres: [
                        vec![keep(da, direct_seen), keep(ma, !touching)],
                        vec![keep(db, direct_seen), keep(mb, !touching)],
                    ],
                    position_mm: [None, None],
                }
            })
            .collect();
        let both = FlightViews {
            direct: (0, 0),
            mirror: Some((1, 0)),
        };
        let split = split_frame(&obs, both).unwrap();
        assert!(split.abs_diff(impact) <= 2, "split at frame {split}");
        // The direct view alone splits after the impact (the test's premise).
        let direct_only = FlightViews {
            direct: (0, 0),
            mirror: None,
        };
        let alone = split_frame(&obs, direct_only).unwrap();
        assert!(alone > impact + 2, "the direct view alone split at {alone}");
    }

    /// Discs fitted on their edge points (the model's fit failed), small as such discs can
    /// be, do not set the scale where the model fitted others.
    #[test]
    fn the_diameters_scale_comes_from_discs_the_model_fitted() {
        let mut obs = discs(0.05);
        for (k, f) in obs.iter_mut().enumerate() {
            // Sphere a on edge points, 10 % small, in every frame, and b in every other one:
            // most of the discs.
            f.spheres[0][0] = disc([50.0, 40.0], 12.33, f64::NAN);
            if k % 2 == 0 {
                f.spheres[1][0] = disc([50.0, 40.0], 12.34, f64::NAN);
            }
        }
        let scale = diameter_scale(&obs, 0, [6.35, 6.35]).unwrap();
        let truth = 13.71 / 6.35;
        assert!(
            (scale.value / truth - 1.0).abs() < 0.005,
            "{} px/mm against {truth}",
            scale.value
        );
    }
}
