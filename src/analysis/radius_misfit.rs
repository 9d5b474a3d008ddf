//! A centre whose fitted radius strays from the radius the same sphere shows in the frames
//! round it: the stray is a misfit of the disc's model, and it is carried into the centre's σ.
//! After the first pass, the same medians are the radii the second holds blurred discs at
//! (`held_radii`), beside each disc's smear over the exposure (`smear_px`).
//!
//! Why: a sphere's imaged radius changes only slowly along its flight (perspective, the mirror's
//! longer path), so where one frame's fit finds it a few tenths of a pixel larger or smaller than
//! its neighbours do, part of that disc's edge was put where it is not — by a blurred neighbour
//! whose edge runs into it, a dot turning past the limb, a highlight, a lamp the shading model
//! does not follow. Moving one side of a circle's edge by δ moves its radius by δ/2 and its
//! centre by δ/2 towards that side, so the centre is out by about the radius's stray, in a
//! direction the fit does not say. The fit's own σ does not see it: its residuals are small,
//! the model found a disc, only not the sphere's. On 190 varied-look recordings the centres
//! whose radius strayed 0.1–0.2 px from their neighbours' were 0.12 px off (RMS per axis)
//! against a claimed 0.06 px, and on a defocused rig (seed 4112, `tests/looks.rs`) fits of two
//! blurred discs near contact came out with radii 0.4–0.6 px too large and centres 0.7–1 px off
//! against a claimed 0.1 px; 28 % of that rig's centres were within ±1σ.
//!
//! So every centre's σ on each axis gets the stray over √2 added in quadrature (the stray's
//! direction is unknown, split between the axes). The radius's own noise is in the stray too:
//! a well-fitted disc's σ grows by a little (its radius scatters about as its centre does).
//! Same 190 recordings, every centre and axis: 58.5 % → 69.5 % within ±1σ, 0.72 % → 0.20 %
//! beyond 5σ (defocused looks 40 % → 61 %); the centres themselves are unchanged.

use super::circle::FirstPassDisc;
use super::geometry::{View, V3};
use super::tracking::{FirstPassDiscs, FrameObs};

/// Frames of the same sphere in the same view on each side of a frame whose radii give the
/// radius it is compared with: enough that a run of misfits near the impact (a few frames)
/// does not move their median, few enough that perspective changes it by far less than the
/// strays this is for.
const NEIGHBOURS: usize = 10;

/// Widens every measured centre's σ by its radius's stray from the median of its neighbours'
/// (see the module's comment). Centres fitted where the other sphere hides part of the disc
/// are left to `overlap`, which checks them against the other view; diameters not measured
/// (centres digitised elsewhere) are left as they are.
pub(super) fn widen(obs: &mut [FrameObs]) {
    for (k, s, vi, _, stray_px) in strays(obs) {
        if let Some(m) = obs[k].spheres[s][vi].as_mut() {
            m.radius_stray_px = stray_px;
            let add = 0.5 * stray_px * stray_px;
            for sigma in m.sigma_px.iter_mut() {
                *sigma = (*sigma * *sigma + add).sqrt();
            }
        }
    }
}

/// Widens every measured centre's σ, as `widen` does, by how far the radius its sphere shows
/// in that view over the frames round it (the median `widen` compares with) strays from the
/// radius the configured diameter has there through the view's map (`View::px_per_mm_at`).
/// Called once the mirror's map is refined and the spheres placed. Why: a misfit the look
/// makes in every frame alike — a limb shaded down to the ground's level on the side away
/// from the lamp, which the model puts inside the disc — moves every frame's radius and its
/// neighbours' together, so `widen` sees none of it, while the centres are out by about as
/// much towards the lit side (one side's edge moved by δ: radius and centre by δ/2). On the
/// mixed look of `scripts/rerender-looks.py` (ground 60, gamma 0.8, mottled paint) the mirror
/// view's discs came out 0.3–0.6 px small in diameter and their centres 0.15–0.27 px off
/// towards the lamp, at a claimed 0.05–0.09 px; under gamma 0.6, 0.06 px large and 0.03 px
/// off at a claimed 0.015. With this, on 17 sets of eight such renders, centres beyond 5σ
/// 150 → 20 and beyond 3σ 888 → 243 (mixed 47.6 → 62.0 % within ±1σ, gamma 42.5 → 72.2 %);
/// on hw-sim's 190 varied-look recordings 73.1 → 79.7 % (docs/accuracy.md, session 55).
/// The widening is shared by the sphere's centres in the view (`sigma_common_px`), which
/// the line fits leave out: it moves a trajectory, not its slope. Its limit: a view whose
/// configured scale is wrong by 1 % widens its centres by about 0.05 px for 13 px discs,
/// which the centres in pixels do not need (the config's disagreement with the frames is
/// real, and the free fall and `calibration::diameter_against_depth` warn of it).
pub(super) fn widen_against_the_map(obs: &mut [FrameObs], views: &[View], diameters_mm: [f64; 2]) {
    for (k, s, vi, median_px, _) in strays(obs) {
        let Some(view) = views.get(vi) else { continue };
        let f = &mut obs[k];
        let at = f.position_mm[s].unwrap_or_else(V3::zeros);
        let nominal_px = diameters_mm[s] * view.px_per_mm_at(&at);
        let off_px = 0.5 * (median_px - nominal_px);
        if !off_px.is_finite() {
            continue;
        }
        if let Some(m) = f.spheres[s][vi].as_mut() {
            let add = 0.5 * off_px * off_px;
            for sigma in m.sigma_px.iter_mut() {
                *sigma = (*sigma * *sigma + add).sqrt();
            }
            m.sigma_common_px = add.sqrt();
        }
    }
}

/// The first pass's discs as the second fits them (`circle::FirstPassDisc`): for each measured
/// disc seen whole, the median of its sphere's radii in that view over the frames round it (the
/// radius a blurred disc is held at), its own stray from that — what `widen` compares it with —
/// and its smear over `exposure_s` (`smear_px`; 0 s: none).
pub(super) fn held_radii(obs: &[FrameObs], exposure_s: f64) -> FirstPassDiscs {
    let mut out = FirstPassDiscs::new();
    for (k, s, vi, median_px, stray_px) in strays(obs) {
        let Some(m) = obs[k].spheres[s][vi].as_ref() else {
            continue;
        };
        out.entry((obs[k].index as usize, vi))
            .or_default()
            .push(FirstPassDisc {
                centre_px: m.centre_px,
                radius_px: 0.5 * median_px,
                stray_px,
                smear_px: smear_px(obs, k, s, vi, exposure_s, median_px),
            });
    }
    out
}

/// A smear shorter than this is not modelled, px: the pixel's own width spreads the edge as
/// much (a box of 1 px and a smear of 0.5 px widen it by 12 %, which the edge's fitted width
/// takes up); and 0.1 ms at the rig's 0.3–3 px per millisecond, hw-sim's default and the
/// independent renders' exposure, stays below it.
const SMEAR_MIN_PX: f64 = 0.5;

/// How far sphere `s`'s disc in view `vi` moved over `exposure_s` at frame `k`, px: its image
/// velocity from the first pass's centres in the frames next to it. Where the velocities to the
/// frame before and to the frame after differ by more than a fifth, the motion changed there
/// (an impact, a bounce): the side whose own neighbour agrees with it is taken, so that a
/// frame just before an impact is not smeared with the velocity after it. Zero where neither
/// neighbour was measured, or the smear is below `SMEAR_MIN_PX` or longer than the disc's
/// `diameter_px`: on the rig at 1 ms the fastest sphere moves 3 px, under half its diameter, and
/// a longer smear comes from a first-pass centre put on something else (a name swapped, two
/// discs taken for one), which the fit would be dragged along.
fn smear_px(
    obs: &[FrameObs],
    k: usize,
    s: usize,
    vi: usize,
    exposure_s: f64,
    diameter_px: f64,
) -> [f64; 2] {
    if exposure_s <= 0.0 {
        return [0.0; 2];
    }
    let at = |i: usize| -> Option<([f64; 2], f64)> {
        let m = obs.get(i)?.spheres[s].get(vi)?.as_ref()?;
        Some((m.centre_px, obs[i].time_s))
    };
    // Velocity from frame i to frame j, px/s.
    let vel = |i: usize, j: usize| -> Option<[f64; 2]> {
        let ((a, ta), (b, tb)) = (at(i)?, at(j)?);
        let dt = tb - ta;
        (dt > 0.0).then(|| [(b[0] - a[0]) / dt, (b[1] - a[1]) / dt])
    };
    let back = k.checked_sub(1).and_then(|i| vel(i, k));
    let fwd = vel(k, k + 1);
    let norm = |v: [f64; 2]| v[0].hypot(v[1]);
    let differ = |a: [f64; 2], b: [f64; 2]| norm([a[0] - b[0], a[1] - b[1]]);
    let v = match (back, fwd) {
        (Some(b), Some(f)) if differ(b, f) <= 0.2 * norm(b).max(norm(f)) => {
            [0.5 * (b[0] + f[0]), 0.5 * (b[1] + f[1])]
        }
        (Some(b), Some(f)) => {
            let back2 = k.checked_sub(2).and_then(|i| vel(i, k - 1));
            let fwd2 = vel(k + 1, k + 2);
            let steady =
                |v: [f64; 2], w: Option<[f64; 2]>| w.map_or(f64::INFINITY, |w| differ(v, w));
            if steady(b, back2) <= steady(f, fwd2) {
                b
            } else {
                f
            }
        }
        (Some(v), None) | (None, Some(v)) => v,
        (None, None) => return [0.0; 2],
    };
    let smear = [v[0] * exposure_s, v[1] * exposure_s];
    let length = norm(smear);
    // (A NaN length, from a NaN diameter or centre, is not modelled either.)
    if !(SMEAR_MIN_PX..=diameter_px).contains(&length) {
        [0.0; 2]
    } else {
        smear
    }
}

/// Per measured disc seen whole (`obs` index, sphere, view): the median of its sphere's
/// diameters in that view over `NEIGHBOURS` frames on each side, px, and its radius's stray
/// from that median, px. Discs the other sphere hides in part and diameters not measured are
/// left out, of the medians too.
fn strays(obs: &[FrameObs]) -> Vec<(usize, usize, usize, f64, f64)> {
    let n_views = obs.iter().map(|f| f.spheres[0].len()).max().unwrap_or(0);
    let mut out = Vec::new();
    for s in 0..2 {
        for vi in 0..n_views {
            let seen: Vec<(usize, f64)> = obs
                .iter()
                .enumerate()
                .filter_map(|(k, f)| {
                    let m = f.spheres[s].get(vi)?.as_ref()?;
                    (m.hidden_in_part.is_none() && m.diameter_px.is_finite())
                        .then_some((k, m.diameter_px))
                })
                .collect();
            if seen.len() < 3 {
                continue;
            }
            for i in 0..seen.len() {
                let lo = i.saturating_sub(NEIGHBOURS);
                let hi = (i + NEIGHBOURS + 1).min(seen.len());
                let mut window: Vec<f64> = seen[lo..hi].iter().map(|x| x.1).collect();
                let median = median(&mut window);
                out.push((seen[i].0, s, vi, median, 0.5 * (seen[i].1 - median)));
            }
        }
    }
    out
}

/// The median of `values` (reordered), the mean of the middle two for an even count.
fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n % 2 == 1 {
        values[n / 2]
    } else {
        0.5 * (values[n / 2 - 1] + values[n / 2])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::tracking::Measurement;

    fn frame(k: u64, diameter_px: f64) -> FrameObs {
        let m = Measurement {
            sigma_px: [0.03, 0.04],
            diameter_px,
            ..Measurement::test_at([10.0, 10.0])
        };
        FrameObs {
            index: k,
            frame_id: k,
            time_s: k as f64 * 1e-3,
            spheres: [vec![Some(m.clone())], vec![Some(m)]],
            position_mm: [None, None],
        }
    }

    #[test]
    fn a_radius_that_strays_from_its_neighbours_widens_that_centre_alone() {
        let mut obs: Vec<FrameObs> = (0..30).map(|k| frame(k, 13.4)).collect();
        obs[15].spheres[1][0].as_mut().unwrap().diameter_px = 14.6;
        widen(&mut obs);
        // 0.6 px too large a radius: 0.6/√2 = 0.42 px on each axis, in quadrature.
        let sigma = obs[15].spheres[1][0].as_ref().unwrap().sigma_px;
        assert!(
            (sigma[0] - (0.03f64.powi(2) + 0.18).sqrt()).abs() < 1e-12,
            "{sigma:?}"
        );
        assert!(
            (sigma[1] - (0.04f64.powi(2) + 0.18).sqrt()).abs() < 1e-12,
            "{sigma:?}"
        );
        // Its neighbours and the other sphere keep their σ.
        assert_eq!(
            obs[14].spheres[1][0].as_ref().unwrap().sigma_px,
            [0.03, 0.04]
        );
        assert_eq!(
            obs[15].spheres[0][0].as_ref().unwrap().sigma_px,
            [0.03, 0.04]
        );
    }

    #[test]
    fn a_radius_that_changes_slowly_along_the_flight_widens_nothing() {
        // Perspective: the disc grows by 0.01 px a frame as the sphere comes nearer.
        let mut obs: Vec<FrameObs> = (0..40).map(|k| frame(k, 13.0 + 0.02 * k as f64)).collect();
        widen(&mut obs);
        for f in &obs[NEIGHBOURS..40 - NEIGHBOURS] {
            let sigma = f.spheres[0][0].as_ref().unwrap().sigma_px;
            assert!((sigma[0] - 0.03).abs() < 1e-12, "{sigma:?}");
        }
    }

    /// A look that images every disc of one sphere small alike (its shaded limb taken for
    /// ground, in every frame) widens each of that sphere's centres by the stray from the map's
    /// radius, and marks it as shared, which `widen` alone does not see.
    #[test]
    fn radii_small_in_every_frame_widen_the_centres_by_their_stray_from_the_map() {
        // 2 px per mm, 6.35 mm spheres: 12.7 px across. Sphere a images 12.1 px in every
        // frame, b as the map says.
        let g =
            crate::config::ViewGeometry::shorthand([0, 0, 240, 96], 2.0, [0.0, 0.0], "+x", "-y");
        let views = [View::from_config(
            crate::analysis::geometry::ViewKind::Direct,
            &g,
        )];
        let mut obs: Vec<FrameObs> = (0..30).map(|k| frame(k, 12.7)).collect();
        for f in obs.iter_mut() {
            f.spheres[0][0].as_mut().unwrap().diameter_px = 12.1;
        }
        widen(&mut obs);
        assert_eq!(
            obs[15].spheres[0][0].as_ref().unwrap().sigma_px,
            [0.03, 0.04]
        );
        widen_against_the_map(&mut obs, &views, [6.35, 6.35]);
        // 0.3 px too small a radius: 0.3/√2 on each axis, in quadrature, and shared.
        for f in &obs {
            let a = f.spheres[0][0].as_ref().unwrap();
            assert!(
                (a.sigma_px[0] - (0.03f64.powi(2) + 0.045).sqrt()).abs() < 1e-12,
                "{:?}",
                a.sigma_px
            );
            assert!(
                (a.sigma_px[1] - (0.04f64.powi(2) + 0.045).sqrt()).abs() < 1e-12,
                "{:?}",
                a.sigma_px
            );
            assert!((a.sigma_common_px - 0.045f64.sqrt()).abs() < 1e-12);
            let b = f.spheres[1][0].as_ref().unwrap();
            assert!((b.sigma_px[0] - 0.03).abs() < 1e-12, "{:?}", b.sigma_px);
            assert!(b.sigma_common_px.abs() < 1e-12);
        }
    }

    /// A disc's smear is its velocity times the exposure, from the frames next to it, and at an
    /// impact from the side whose motion it shares: sphere a moves +2 px a frame until halfway
    /// between frames 20 and 21, and −1 px a frame after.
    #[test]
    fn a_discs_smear_is_its_velocity_over_the_exposure_on_its_side_of_an_impact() {
        let mut obs: Vec<FrameObs> = (0..40).map(|k| frame(k, 13.4)).collect();
        for (k, f) in obs.iter_mut().enumerate() {
            let x = if k <= 20 {
                2.0 * k as f64
            } else {
                40.5 - (k - 21) as f64
            };
            f.spheres[0][0].as_mut().unwrap().centre_px = [x, 10.0];
        }
        // 1 ms frames, 0.6 ms exposure: 1.2 px of smear before, 0.6 px after.
        let discs = held_radii(&obs, 0.6e-3);
        // Sphere a's disc first (the same order as the spheres).
        let smear_u = |k: usize| {
            let s = discs[&(k, 0)][0].smear_px;
            assert!(s[1].abs() < 1e-9, "frame {k}: {s:?}");
            s[0]
        };
        let near = |a: f64, b: f64| (a - b).abs() < 1e-9;
        assert!(near(smear_u(10), 1.2), "{}", smear_u(10));
        assert!(
            near(smear_u(20), 1.2),
            "the last frame before the impact: {}",
            smear_u(20)
        );
        assert!(
            near(smear_u(21), -0.6),
            "the first after it: {}",
            smear_u(21)
        );
        assert!(near(smear_u(30), -0.6), "{}", smear_u(30));
        // Sphere b stands still, and without an exposure nothing is smeared.
        assert_eq!(discs[&(10, 0)][1].smear_px, [0.0, 0.0]);
        assert!(held_radii(&obs, 0.0)
            .values()
            .flatten()
            .all(|d| d.smear_px == [0.0, 0.0]));
        // A first-pass centre 40 px off (another disc's): its own frame is not smeared (both
        // sides give 25 px, longer than the disc), and its neighbours take their steady sides.
        let mut blunder = obs.clone();
        blunder[10].spheres[0][0].as_mut().unwrap().centre_px = [60.0, 10.0];
        let d = held_radii(&blunder, 0.6e-3);
        assert_eq!(d[&(10, 0)][0].smear_px, [0.0, 0.0]);
        for k in [9, 11] {
            let s = d[&(k, 0)][0].smear_px;
            assert!(near(s[0], 1.2) && s[1].abs() < 1e-9, "frame {k}: {s:?}");
        }
        // Below half a pixel a smear is not modelled.
        assert!(held_radii(&obs, 0.24e-3)
            .values()
            .flatten()
            .all(|d| d.smear_px == [0.0, 0.0]));
    }
}
