//! The centres' σ as the report gives them, checked against the flight fitted through them: a
//! sphere's centres in one view and phase that scatter about its fitted trajectory more than
//! their σ say have their σ scaled up by how much more (Birge's ratio, from the median of the
//! squared normalised residuals so that one blunder does not set it), and a centre still beyond
//! `OWN_DISAGREEMENT_SIGMAS` of it carries its own disagreement (as `overlap` does for a hidden
//! disc). The estimates are not touched: their fits already take their σ from the residuals'
//! scatter (`phases::series_and_sigma`'s floor is only a floor).
//!
//! Why: a look can move a disc's fitted centre from frame to frame by more than its fit's
//! residuals show — albedo in low waves fixed on a turning sphere (`scripts/rerender-looks.py`'s
//! `texture`) shifts the shaded edge the model takes for the limb, and the shift turns with
//! the sphere; the model absorbs the wave, so the residuals stay small. There the centres
//! scattered 0.03–0.08 px about their flights at a claimed 0.02–0.04 px, and 14 of 2500 lay
//! beyond 5σ. The flight, fitted over a phase's frames in both views, is several times more
//! precise than one frame's centre, so the scatter about it is the centres' own. With this, on
//! 17 sets of eight such renders (after `radius_misfit::widen_against_the_map`): centres
//! within ±1σ 73.3 → 75.5 %, beyond 3σ 243 → 131, beyond 5σ 20 → 6 of 41 990 (the texture's
//! 14 → 4); on hw-sim's 190 varied-look recordings beyond 5σ 0.06 → 0.05 % (docs/accuracy.md,
//! session 55). Centres in the impact's gap, in no phase, are checked against the flight on
//! their side of it alone (`widened`). What it cannot see: a view's centres out alike in every
//! frame, which the flight's offset takes up (the texture's 0.03–0.1 px per sphere and view;
//! on hw-sim's grey-ground look a sphere half hidden behind the other in the frames round the
//! impact, its v 4–6 px off in a dozen frames, which its flight follows).

use super::geometry::View;
use super::kinematics::{self, Fits};
use super::phases;
use super::tracking::FrameObs;

/// A centre further than this many of its (scaled) σ from its flight carries the disagreement
/// in its σ: beyond 3σ a normal error is rare (0.27 %), and what is left is a misfit the scale
/// does not hold (a shadow or a neighbour's edge taken for the limb in that frame alone).
const OWN_DISAGREEMENT_SIGMAS: f64 = 3.0;

/// The median of a χ² variable of one degree of freedom: a normalised residual's median square
/// when the σ are right.
const CHI2_1_MEDIAN: f64 = 0.454_936;

/// Fewer centres than this in a view and phase, and their scatter is not judged.
const MIN_CENTRES: usize = 6;

/// `obs` with each centre's σ widened by its scatter about the phase's flight (see the module's
/// comment); frames in the impact's gap are checked against the flight on their side of it;
/// other frames outside the phases `ph` (0–3: a before, b before, a after, b after, each
/// referenced at `split`) and phases whose fit lacks an axis keep theirs.
pub(super) fn widened(
    obs: &[FrameObs],
    views: &[View],
    fits: &Fits,
    ph: &[Vec<usize>; 4],
    split: f64,
    g: f64,
) -> Vec<FrameObs> {
    let mut out = obs.to_vec();
    let points = phases::on_flights(obs, views, fits, ph, split, g);
    for k in 0..4 {
        let s = k % 2;
        for vi in 0..views.len() {
            // (frame, residual per axis, its own σ per axis: without the part every frame
            // shares, which the flight's offset takes up, `Measurement::own_sigma_px`)
            let mut seen: Vec<(usize, [f64; 2], [f64; 2])> = Vec::new();
            for q in points.iter().filter(|q| q.phase == k && q.view == vi) {
                let Some(m) = obs[q.frame].spheres[s][vi].as_ref() else {
                    continue;
                };
                let own = m.own_sigma_px();
                let d = [m.centre_px[0] - q.at_px[0], m.centre_px[1] - q.at_px[1]];
                if d.iter().chain(&own).all(|x| x.is_finite()) && own.iter().all(|&x| x > 0.0) {
                    seen.push((q.frame, d, own));
                }
            }
            if seen.len() < MIN_CENTRES {
                continue;
            }
            let mut z2: Vec<f64> = seen
                .iter()
                .flat_map(|(_, d, own)| [(d[0] / own[0]).powi(2), (d[1] / own[1]).powi(2)])
                .collect();
            let half = z2.len() / 2;
            let median = *z2.select_nth_unstable_by(half, f64::total_cmp).1;
            let ratio = (median / CHI2_1_MEDIAN).sqrt().max(1.0);
            for (i, d, own) in seen {
                let Some(m) = out[i].spheres[s][vi].as_mut() else {
                    continue;
                };
                let common_sq = m.sigma_common_px.powi(2);
                for axis in 0..2 {
                    let scaled = ratio * own[axis];
                    let mut var = scaled * scaled + common_sq;
                    if d[axis].abs() > OWN_DISAGREEMENT_SIGMAS * var.sqrt() {
                        var += d[axis] * d[axis];
                    }
                    m.sigma_px[axis] = var.sqrt().max(m.sigma_px[axis]);
                }
            }
        }
    }
    // The frames between a sphere's last before the impact and its first after are in no phase
    // (contact, one silhouette of both, a disc given the other's name): each centre there is
    // checked against its flight on its side of `split` (each flight is free up to the contact)
    // and carries its disagreement where that is beyond `OWN_DISAGREEMENT_SIGMAS` of its σ.
    // Why: on hw-sim's varied looks (seed 4105) the direct view's one disc in the frame after
    // the impact was a's, named b, and reported 13.4 px from b at σ 0.015 px.
    for s in 0..2 {
        let (Some(&last), Some(&first)) = (ph[s].iter().max(), ph[2 + s].iter().min()) else {
            continue;
        };
        let gap = obs.iter().zip(out.iter_mut()).take(first).skip(last + 1);
        for (f, reported) in gap {
            let k = if f.time_s < split { s } else { 2 + s };
            if fits[k].axes.iter().any(Option::is_none) {
                continue;
            }
            let (p, _) = kinematics::pos_vel(&fits[k], f.time_s - split, g);
            for (vi, view) in views.iter().enumerate() {
                let Some(m) = reported.spheres[s].get_mut(vi).and_then(Option::as_mut) else {
                    continue;
                };
                let at = view.project(&p);
                for ((c, a), sigma) in m.centre_px.iter().zip(at).zip(m.sigma_px.iter_mut()) {
                    let d = c - a;
                    if d.is_finite() && d.abs() > OWN_DISAGREEMENT_SIGMAS * *sigma {
                        *sigma = sigma.hypot(d);
                    }
                }
            }
        }
    }
    out
}
