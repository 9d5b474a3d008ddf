//! Mirror calibration: the mirror view's scale and offset refined from the x coordinate both
//! views see, and the residuals of that shared coordinate.

use super::geometry::{View, ViewKind};
use super::report::Calibration;
use super::tracking::FrameObs;

/// Pairs (direct x, mirror x) in mm of every sphere measured in both views of a frame.
pub(super) fn x_pairs(obs: &[FrameObs], views: &[View]) -> Option<Vec<(f64, f64)>> {
    let di = views.iter().position(|v| v.kind == ViewKind::Direct)?;
    let mi = views.iter().position(|v| v.kind == ViewKind::Mirror)?;
    let x = |vi: usize, px: [f64; 2]| {
        views[vi]
            .unproject(px)
            .iter()
            .find(|(a, _)| *a == 0)
            .map(|(_, x)| *x)
    };
    Some(
        obs.iter()
            .flat_map(|f| {
                (0..2).filter_map(move |s| {
                    Some((f.spheres[s][di].as_ref()?, f.spheres[s][mi].as_ref()?))
                })
            })
            .filter_map(|(d, m)| Some((x(di, d.centre_px)?, x(mi, m.centre_px)?)))
            .collect(),
    )
}

pub(super) fn residual_stats(pairs: &[(f64, f64)]) -> (f64, f64) {
    let n = pairs.len().max(1) as f64;
    let mean = pairs.iter().map(|(d, m)| m - d).sum::<f64>() / n;
    let rms = (pairs.iter().map(|(d, m)| (m - d).powi(2)).sum::<f64>() / n).sqrt();
    (mean, rms)
}

/// Refines the mirror view's scale and u-offset from the x coordinate both views see
/// (physics.md §5, minimum calibration): x_mirror = a·x_direct + b over the whole recording.
/// With the config's scale s and offset u0, the true ones are a·s and u0 + sign·b·s. Applied
/// only when the fit is well conditioned (≥ 10 pairs over ≥ 3 mm of x); always reported.
pub(super) fn calibrate_mirror(obs: &[FrameObs], views: &mut [View]) -> Option<Calibration> {
    let pairs = x_pairs(obs, views)?;
    if pairs.is_empty() {
        return None;
    }
    let (mean_before, rms_before) = residual_stats(&pairs);
    let mi = views.iter().position(|v| v.kind == ViewKind::Mirror)?;
    let config_scale = views[mi].px_per_mm;
    let config_origin_u = views[mi].origin_px[0];
    let n = pairs.len() as f64;
    let (mx, my) = (
        pairs.iter().map(|p| p.0).sum::<f64>() / n,
        pairs.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxx: f64 = pairs.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = pairs.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let lo = pairs.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
    let hi = pairs.iter().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max);
    let refined = pairs.len() >= 10 && hi - lo >= 3.0 && sxx > 0.0;
    let (mut mean_after, mut rms_after) = (mean_before, rms_before);
    if refined {
        let a = sxy / sxx;
        let b = my - a * mx;
        let sign = views[mi].u_axis.x.signum();
        views[mi].px_per_mm = a * config_scale;
        views[mi].origin_px[0] = config_origin_u + sign * b * config_scale;
        let after = x_pairs(obs, views)?;
        (mean_after, rms_after) = residual_stats(&after);
    }
    Some(Calibration {
        frames: pairs.len() as u64,
        mirror_minus_direct_x_mean_mm: mean_before,
        mirror_minus_direct_x_rms_mm: rms_before,
        refined,
        mirror_px_per_mm_config: config_scale,
        mirror_px_per_mm_refined: views[mi].px_per_mm,
        mirror_origin_u_px_config: config_origin_u,
        mirror_origin_u_px_refined: views[mi].origin_px[0],
        residual_mean_mm_after: mean_after,
        residual_rms_mm_after: rms_after,
    })
}
