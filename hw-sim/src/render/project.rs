//! Where a view sees the spheres: a world point's image (through the view's map and its lens),
//! a sphere's imaged radius, and where a line of sight meets a sphere's surface.

use super::Pose;
use crate::config::ViewSpec;
use crate::V3;

/// Projected centre and radius, px, of every sphere in every sub-exposure pose.
pub(super) fn discs_in(view: &ViewSpec, poses: &[[Pose; 2]]) -> Vec<(f64, f64, f64)> {
    poses
        .iter()
        .flat_map(|p| p.iter())
        .map(|s| {
            let (u, v) = project(view, &s.centre_mm);
            (u, v, radius_px(view, &s.centre_mm, s.radius_mm))
        })
        .collect()
}

/// Image position of a world point in a view, px (full-frame coordinates).
pub fn project(view: &ViewSpec, p: &V3) -> (f64, f64) {
    let ideal = project_ideal(view, p);
    match &view.lens {
        Some(lens) => lens.distort(ideal.0, ideal.1),
        None => ideal,
    }
}

/// Image position of a world point before the lens's distortion, px.
fn project_ideal(view: &ViewSpec, p: &V3) -> (f64, f64) {
    let ua = V3::from(view.u_axis);
    let va = V3::from(view.v_axis);
    match view.distance_mm {
        None => (
            view.origin_px[0] + view.px_per_mm * ua.dot(p),
            view.origin_px[1] + view.px_per_mm * va.dot(p),
        ),
        Some(d) => {
            let k = view.px_per_mm * d / (d - V3::from(view.facing).dot(p));
            (
                view.origin_px[0] + k * ua.dot(p),
                view.origin_px[1] + k * va.dot(p),
            )
        }
    }
}

/// Radius in px of a sphere's image centred at world point `c` (under perspective, that of
/// the disc at its depth; its outline is an ellipse a little larger, by the square of the angle
/// off the axis).
pub fn radius_px(view: &ViewSpec, c: &V3, radius_mm: f64) -> f64 {
    let ideal = match view.distance_mm {
        None => radius_mm * view.px_per_mm,
        Some(d) => radius_mm * view.px_per_mm * d / (d - V3::from(view.facing).dot(c)),
    };
    // Under distortion, the scale across the line to the lens's centre there (along it the
    // image is stretched by 1 + 3·k1·r² instead: the outline is no longer a circle).
    match &view.lens {
        Some(lens) => {
            let (u, v) = project_ideal(view, c);
            ideal * lens.factor(u, v)
        }
        None => ideal,
    }
}

/// Where the line of sight through image point (su, sv) meets a sphere: (depth towards the
/// camera, larger is nearer; the unit normal there; its cosine to the line of sight back to the
/// camera), or None where it misses. Orthographic views keep the original arithmetic.
pub(crate) fn hit(
    view: &ViewSpec,
    c: &V3,
    radius_mm: f64,
    su: f64,
    sv: f64,
) -> Option<(f64, V3, f64)> {
    let ua = V3::from(view.u_axis);
    let va = V3::from(view.v_axis);
    let facing = V3::from(view.facing);
    // A distorted view records at (su, sv) what the ideal one shows at its undistorted point.
    let (su, sv) = match &view.lens {
        Some(lens) => lens.undistort(su, sv),
        None => (su, sv),
    };
    let Some(d) = view.distance_mm else {
        let (cu, cv) = project_ideal(view, c);
        let r_px = radius_mm * view.px_per_mm;
        let (du, dv) = (su - cu, sv - cv);
        let rho2 = (du * du + dv * dv) / (r_px * r_px);
        if rho2 >= 1.0 {
            return None;
        }
        let nz = (1.0 - rho2).sqrt();
        let depth = c.dot(&facing) + radius_mm * nz;
        let normal = (ua * du + va * dv) / r_px + facing * nz;
        return Some((depth, normal, nz));
    };
    // The ray from the pinhole through the image point's spot on the plane through the origin.
    let cam = facing * d;
    let spot = ua * ((su - view.origin_px[0]) / view.px_per_mm)
        + va * ((sv - view.origin_px[1]) / view.px_per_mm);
    let dir = (spot - cam).normalize();
    let oc = cam - c;
    let b = dir.dot(&oc);
    let disc = b * b - (oc.norm_squared() - radius_mm * radius_mm);
    if disc <= 0.0 {
        return None;
    }
    let t = -b - disc.sqrt();
    let normal = (cam + dir * t - c) / radius_mm;
    Some((-t, normal, -normal.dot(&dir)))
}
