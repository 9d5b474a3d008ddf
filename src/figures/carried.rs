//! Markers carried by the fitted spins, for the session viewer's overlay: where a report's spin
//! of each sphere puts, in one frame, the markers found in the nearest other frame of the same
//! flight. Drawn beside the markers found there, they show at a glance whether the spin fits
//! the dots (they land on them) or not.

use crate::analysis::geometry::{View, ViewKind, V3};
use crate::analysis::markers;
use crate::analysis::report::{Report, SphereTrack, TrackFrame, ViewTrack};
use nalgebra::UnitQuaternion;

fn view_track(s: &SphereTrack, kind: ViewKind) -> Option<&ViewTrack> {
    match kind {
        ViewKind::Direct => s.direct.as_ref(),
        ViewKind::Mirror => s.mirror.as_ref(),
    }
}

/// A world centre with the coordinates no view measured taken as 0 (only the map's local
/// scale and line of sight depend on it, and only under perspective).
fn world(c: &[Option<f64>; 3]) -> V3 {
    V3::new(
        c[0].unwrap_or(0.0),
        c[1].unwrap_or(0.0),
        c[2].unwrap_or(0.0),
    )
}

/// In frame `k` (index in the recording), per sphere (a, b) the image positions the fitted
/// spins carry the markers of the nearest other frame of the same flight phase to, in each view
/// where the sphere is measured in both frames; only markers on the hemisphere the view sees.
/// `radii_mm` are the spheres' radii. Empty where a spin was not measured.
pub fn carried(
    report: &Report,
    views: &[View],
    radii_mm: [f64; 2],
    k: usize,
) -> [Vec<[f64; 2]>; 2] {
    let mut out: [Vec<[f64; 2]>; 2] = [Vec::new(), Vec::new()];
    let Some(here) = report.tracks.iter().find(|t| t.frame as usize == k) else {
        return out;
    };
    let t_c = report.impact.time_s.value;
    let before = here.time_s < t_c;
    for (s, sphere) in [&report.spheres.a, &report.spheres.b]
        .into_iter()
        .enumerate()
    {
        let spin = if before {
            &sphere.spin_pre_rad_s
        } else {
            &sphere.spin_post_rad_s
        };
        let Some(spin) = spin else { continue };
        let omega = V3::from(spin.value);
        fn track(t: &TrackFrame, s: usize) -> Option<&SphereTrack> {
            if s == 0 {
                t.a.as_ref()
            } else {
                t.b.as_ref()
            }
        }
        let Some(now) = track(here, s) else { continue };
        for view in views {
            let Some(now_v) = view_track(now, view.kind) else {
                continue;
            };
            // The nearest other frame of the same phase with markers found in this view.
            let reference = report
                .tracks
                .iter()
                .filter(|t| t.frame as usize != k && (t.time_s < t_c) == before)
                .filter_map(|t| {
                    let st = track(t, s)?;
                    let vt = view_track(st, view.kind)?;
                    (!vt.markers_px.is_empty()).then_some((t.time_s, st, vt))
                })
                .min_by(|a, b| {
                    (a.0 - here.time_s)
                        .abs()
                        .total_cmp(&(b.0 - here.time_s).abs())
                });
            let Some((t_ref, st_ref, vt_ref)) = reference else {
                continue;
            };
            let turn = UnitQuaternion::from_scaled_axis(omega * (here.time_s - t_ref));
            let at_ref = world(&st_ref.centre_mm);
            let (jacobian, toward) = view.local_at(&world(&now.centre_mm));
            for m in &vt_ref.markers_px {
                let Some(lifted) =
                    markers::lift_at(view, *m, vt_ref.centre_px, radii_mm[s], &at_ref)
                else {
                    continue;
                };
                let rel = turn * lifted.rel_mm;
                if rel.dot(&toward) <= 0.0 {
                    continue;
                }
                let d = jacobian * rel;
                out[s].push([now_v.centre_px[0] + d[0], now_v.centre_px[1] + d[1]]);
            }
        }
    }
    out
}
