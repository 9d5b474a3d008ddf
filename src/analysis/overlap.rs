//! Centres measured where the other sphere hides part of the disc in a secondary view (a split
//! silhouette's outline, or the grey-level fit of a crescent): what such a centre's own fit
//! cannot know about its error, measured on the coordinate both views share, and carried into
//! its σ and into its weight in the trajectory fits.
//!
//! Why: these fits rest on part of the disc, and the part left is where the lighting biases
//! an edge most. On 190 varied-look recordings the outline split's centres were 0.26–0.40 px
//! off (RMS) with a claimed σ of 0.026 px, and the crescent fits 0.12 px off with 43 % within
//! ±1σ; two such frames at the start of a phase put a velocity 7σ from the truth (seed 3124,
//! a's z after the impact: +60 ± 8.6 mm/s). Neither fit's residuals show it: the outline is a
//! good circle, only not the sphere's.
//!
//! The shared coordinate shows it: x is measured by both views, and where the direct view sees
//! the sphere whole in the same frame, the secondary view's x of the hidden fit is checked
//! against it. The mean square of those disagreements, over the recording's hidden fits of that
//! view and kind, is the error a hidden fit there has beyond its own σ; it is added to both of
//! its axes (the part of the disc the other hides is round the line between them, which in
//! that view is mostly along x, so z is the better-known axis and the widening is on the safe
//! side for it). Hidden fits with nothing to check them against are not used.

use super::geometry::{View, ViewKind};
use super::tracking::{FrameObs, HiddenInPart};

/// Fewer checks than this of a kind in a view, and its hidden fits are not used: the mean of
/// one or two squares is too likely to be small by chance to stand for the rest.
const MIN_CHECKS: usize = 3;

/// Widens the σ of every centre fitted where the other sphere hid part of its disc by the
/// disagreement such centres show on the shared x (see the module's comment), and drops those
/// that nothing checks. Returns, per secondary view and kind, the widening, px, and how many
/// hidden centres were dropped, for the report's warnings.
pub(super) fn widen_hidden(obs: &mut [FrameObs], views: &[View]) -> Vec<String> {
    let Some(direct) = views.iter().position(|v| v.kind == ViewKind::Direct) else {
        return Vec::new();
    };
    let mut notes = Vec::new();
    for (vi, view) in views.iter().enumerate() {
        if vi == direct {
            continue;
        }
        for kind in [HiddenInPart::Outline, HiddenInPart::Crescent] {
            let mut sum_sq = 0.0;
            let mut checks = 0usize;
            let mut hidden = 0usize;
            for f in obs.iter() {
                for s in 0..2 {
                    let Some(m) = f.spheres[s][vi].as_ref() else {
                        continue;
                    };
                    if m.hidden_in_part != Some(kind) {
                        continue;
                    }
                    hidden += 1;
                    let Some(d) = f.spheres[s][direct]
                        .as_ref()
                        .filter(|d| d.hidden_in_part.is_none())
                    else {
                        continue;
                    };
                    let near = f.position_mm[s].as_ref();
                    if let (Some(xh), Some(xd)) = (
                        view.x_mm(m.centre_px, near),
                        views[direct].x_mm(d.centre_px, near),
                    ) {
                        // In the hidden view's pixels; what the direct view's own σ explains
                        // is left in (it is small beside what this measures).
                        sum_sq += ((xh - xd) * view.px_per_mm).powi(2);
                        checks += 1;
                    }
                }
            }
            if hidden == 0 {
                continue;
            }
            let what = match kind {
                HiddenInPart::Outline => "split silhouette's outline",
                HiddenInPart::Crescent => "crescent fit",
            };
            if checks < MIN_CHECKS {
                for f in obs.iter_mut() {
                    for s in 0..2 {
                        if f.spheres[s][vi]
                            .as_ref()
                            .is_some_and(|m| m.hidden_in_part == Some(kind))
                        {
                            f.spheres[s][vi] = None;
                        }
                    }
                }
                notes.push(format!(
                    "{} view: {hidden} centre(s) from a {what} (the other sphere hiding part of the disc) not used: only {checks} of them could be checked against the direct view's x, need {MIN_CHECKS}",
                    view.kind.name()
                ));
                continue;
            }
            let extra_sq = sum_sq / checks as f64;
            for f in obs.iter_mut() {
                for s in 0..2 {
                    if let Some(m) = f.spheres[s][vi]
                        .as_mut()
                        .filter(|m| m.hidden_in_part == Some(kind))
                    {
                        m.sigma_px = m.sigma_px.map(|sd| (sd * sd + extra_sq).sqrt());
                    }
                }
            }
            notes.push(format!(
                "{} view: {hidden} centre(s) from a {what} (the other sphere hiding part of the disc): their x disagrees with the direct view's by {:.3} px RMS over {checks} frames; that is added to their σ",
                view.kind.name(),
                extra_sq.sqrt()
            ));
        }
    }
    notes
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::geometry::views;
    use crate::analysis::tracking::Measurement;

    fn frame(k: u64, direct: [f64; 2], mirror: [f64; 2], kind: Option<HiddenInPart>) -> FrameObs {
        let m = |c: [f64; 2], h: Option<HiddenInPart>| Measurement {
            centre_px: c,
            blob_centroid_px: c,
            sigma_px: [0.02, 0.02],
            diameter_px: 13.7,
            markers: Vec::new(),
            hidden_in_part: h,
            radius_stray_px: 0.0,
        };
        FrameObs {
            index: k,
            frame_id: k,
            time_s: k as f64 * 1e-3,
            spheres: [
                vec![Some(m(direct, None)), Some(m(mirror, kind))],
                vec![None, None],
            ],
            position_mm: [None, None],
        }
    }

    /// Hidden fits whose x is 0.3 px off the direct view's get a σ of about 0.3 px; the
    /// others keep theirs; with fewer than three checks the hidden fits are dropped.
    #[test]
    fn hidden_fits_get_the_disagreement_on_x_as_their_sigma() {
        let cfg = crate::config::Config::default_config();
        let vs = views(&cfg);
        let (d, m) = (&vs[0], &vs[1]);
        let p = crate::analysis::geometry::V3::new(1.0, 2.0, 0.5);
        let (pd, pm) = (d.project(&p), m.project(&p));
        let mut obs: Vec<FrameObs> = (0..6)
            .map(|k| {
                let off = if k % 2 == 0 { 0.3 } else { -0.3 };
                let kind = (k >= 2).then_some(HiddenInPart::Outline);
                let shift = if kind.is_some() { off } else { 0.0 };
                frame(k, pd, [pm[0] + shift, pm[1]], kind)
            })
            .collect();
        let notes = widen_hidden(&mut obs, &vs);
        assert_eq!(notes.len(), 1, "{notes:?}");
        for (k, f) in obs.iter().enumerate() {
            let s = f.spheres[0][1].as_ref().expect("kept").sigma_px;
            if k >= 2 {
                assert!((s[0] - 0.3f64.hypot(0.02)).abs() < 1e-9, "frame {k}: {s:?}");
                assert!((s[1] - 0.3f64.hypot(0.02)).abs() < 1e-9, "frame {k}: {s:?}");
            } else {
                assert_eq!(s, [0.02, 0.02], "frame {k}");
            }
        }
        // Two checks only: not enough to stand for the others.
        let mut few: Vec<FrameObs> = (0..4)
            .map(|k| {
                let kind = (k >= 2).then_some(HiddenInPart::Crescent);
                frame(k, pd, pm, kind)
            })
            .collect();
        let notes = widen_hidden(&mut few, &vs);
        assert!(notes[0].contains("not used"), "{notes:?}");
        assert!(few[2].spheres[0][1].is_none() && few[3].spheres[0][1].is_none());
        assert!(few[1].spheres[0][1].is_some());
    }
}
