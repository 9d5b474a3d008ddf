//! The second pass: every dot found in a sphere's flight is carried with the fitted spins to
//! every other frame of that flight, through the impact too (`carry_orientation`), and
//! projected into each view (`rim_dots`), so the grey-level circle fits can leave out the rim
//! pixels the dots cover.

use super::circle::{self, DotMask};
use super::rotation::SpinFit;
use super::tracking::DotMasks;
use super::Details;
use crate::config::Config;
use nalgebra::Rotation3;

/// Markers a fit of the grey levels near the edge must leave out (`circle::profile_fit`): every
/// marker found in any frame of a sphere's flight, in either view, carried with the fitted
/// spins to each other frame of that flight, and kept where it lies on the rim band of a view.
/// A dot within a pixel of the limb darkens the edge too little to be rejected as an outlier,
/// and moves the centre by a slowly changing few hundredths of a pixel as the sphere turns; the
/// markers finder does not reach there (53°), but the other view sees the same dot near its own
/// centre, and other frames saw it before it reached the limb — before the impact for a dot on
/// the rim after it, since the orientation is continuous through the impact and only ω changes
/// there. A carried dot's mask grows by the drift its spin's uncertainty allows, and a dot is
/// not carried further than `MAX_DRIFT_PX` of drift. Without a spin, only the same frame's
/// other view is used.
pub(super) fn rim_dots(details: &Details, cfg: &Config) -> DotMasks {
    const MAX_DRIFT_PX: f64 = 0.5;
    let dot_r_mm = cfg.analysis.marker_diameter_mm / 2.0;
    let t_c = details.impact_time_s;
    let mut out = DotMasks::new();
    for s in 0..2 {
        let spin = |k: usize| details.spins.get(k).and_then(|m| m.fit.as_ref());
        let (before, after) = (spin(s), spin(s + 2));
        let carry = |t0: f64, t1: f64| carry_orientation(t0, t1, t_c, before, after);
        let radius_mm = cfg.spheres.sphere(s).0 / 2.0;
        let behind_limb = -(dot_r_mm / radius_mm).min(1.0).sin();
        let frames: Vec<usize> = details.phases[s]
            .iter()
            .chain(&details.phases[s + 2])
            .copied()
            .collect();
        for &i in &frames {
            let fi = &details.obs[i];
            for (vi, view) in details.views.iter().enumerate() {
                let Some(m) = &fi.spheres[s][vi] else {
                    continue;
                };
                let dot_px = dot_r_mm * view.px_per_mm;
                let radius_px = radius_mm * view.px_per_mm;
                let inner_px = m.diameter_px / 2.0
                    - circle::PROFILE_BAND_PX
                    - dot_px
                    - DotMask::MARGIN_PX
                    - MAX_DRIFT_PX;
                let mut masks: Vec<DotMask> = Vec::new();
                for &j in &frames {
                    let fj = &details.obs[j];
                    let Some((turn, sigma_rad)) = carry(fj.time_s, fi.time_s) else {
                        continue;
                    };
                    let drift_px = sigma_rad * radius_px;
                    if drift_px > MAX_DRIFT_PX {
                        continue;
                    }
                    for d in fj.spheres[s].iter().flatten().flat_map(|mj| &mj.markers) {
                        let rel = turn * d.rel_mm;
                        if rel.normalize().dot(&view.facing) < behind_limb {
                            continue;
                        }
                        let off = [
                            view.px_per_mm * view.u_axis.dot(&rel),
                            view.px_per_mm * view.v_axis.dot(&rel),
                        ];
                        if off[0].hypot(off[1]) < inner_px {
                            continue;
                        }
                        let c = [m.centre_px[0] + off[0], m.centre_px[1] + off[1]];
                        let seen = masks
                            .iter()
                            .any(|q| (q.centre_px[0] - c[0]).hypot(q.centre_px[1] - c[1]) < 0.3);
                        if !seen {
                            masks.push(DotMask::around(c, dot_px + drift_px));
                        }
                    }
                }
                if !masks.is_empty() {
                    out.entry((fi.index as usize, vi))
                        .or_default()
                        .extend(masks);
                }
            }
        }
    }
    out
}

/// The turn of a sphere from time t0 to t1, s, and its angle's σ, rad: with the spin fitted
/// before the impact (at t_c) on that side of it, after it on the other, and both in turn
/// across it — the orientation is continuous through the impact; only ω changes there. None
/// where a spin the carry needs was not measured.
pub(super) fn carry_orientation(
    t0: f64,
    t1: f64,
    t_c: f64,
    before: Option<&SpinFit>,
    after: Option<&SpinFit>,
) -> Option<(Rotation3<f64>, f64)> {
    let within = |a: f64, b: f64| -> Option<(Rotation3<f64>, f64)> {
        let fit = if a.max(b) <= t_c { before } else { after }?;
        let dt = b - a;
        let sigma = super::spin_tracks::cov_for_carry(fit)
            .trace()
            .max(0.0)
            .sqrt()
            * dt.abs();
        Some((Rotation3::from_scaled_axis(fit.omega * dt), sigma))
    };
    if t0 == t1 {
        return Some((Rotation3::identity(), 0.0));
    }
    if (t0 - t_c) * (t1 - t_c) >= 0.0 {
        return within(t0, t1);
    }
    let (first, e0) = within(t0, t_c)?;
    let (second, e1) = within(t_c, t1)?;
    Some((second * first, e0 + e1))
}
