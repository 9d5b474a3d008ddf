//! The provisional geometry calibrate starts from: the config's views with their scale set
//! from the data where needed, and the mirror's x made to agree with the direct view's, so that
//! the spheres are labelled alike in both views before anything is fitted.

use crate::analysis::calibration::fit_line;
use crate::analysis::geometry::View;
use crate::config::ViewGeometry;

/// Least-squares line y = a·x + b through (x, y) pairs, when they span 20 px of x and lie
/// within 1.5 px RMS of it (blobs of clutter paired with spheres do not).
pub(super) fn line_fit(pairs: &[(f64, f64)]) -> Option<(f64, f64)> {
    if pairs.len() < 6 {
        return None;
    }
    let l = fit_line(pairs).filter(|l| l.x_span >= 20.0)?;
    let (a, b) = (l.slope, l.intercept);
    let rms = (pairs
        .iter()
        .map(|p| (p.1 - a * p.0 - b).powi(2))
        .sum::<f64>()
        / pairs.len() as f64)
        .sqrt();
    (rms <= 1.5).then_some((a, b))
}

/// A provisional shorthand mirror made to agree with the direct view on x, from
/// u_mirror = a·u_direct + b (matrices and projections are left as given).
pub(super) fn align_mirror(direct: &ViewGeometry, mirror: &mut ViewGeometry, (a, b): (f64, f64)) {
    let (Some(sd), Some(od), Some(ud)) = (direct.px_per_mm, direct.origin_px, &direct.u_axis)
    else {
        return;
    };
    let (Some(_), Some(om)) = (mirror.px_per_mm, mirror.origin_px.as_mut()) else {
        return;
    };
    // x = sign_d·(u_d − o_d)/s_d, so u_m = a·u_d + b is the mirror with scale |a|·s_d along
    // x, reversed when a·sign_d < 0, and u offset b + a·o_d.
    let sign_d = if ud.starts_with('-') { -1.0 } else { 1.0 };
    om[0] = b + a * od[0];
    mirror.px_per_mm = Some(a.abs() * sd);
    mirror.u_axis = Some(if a * sign_d < 0.0 { "-x" } else { "+x" }.into());
}

/// A view's scale at the world origin, px/mm (the geometric mean of its two image axes').
pub(super) fn local_scale(v: &ViewGeometry) -> Option<f64> {
    let (m, _) = v.local_affine()?;
    let norm = |r: &[f64; 3]| r.iter().map(|x| x * x).sum::<f64>().sqrt();
    Some((norm(&m[0]) * norm(&m[1])).sqrt())
}

/// Sets a provisional view's scale to `px_per_mm` (a projection is left as given).
pub(super) fn set_scale(v: &mut ViewGeometry, px_per_mm: f64) {
    let Some(now) = local_scale(v) else { return };
    let k = px_per_mm / now;
    if !k.is_finite() {
        return;
    }
    if let Some(s) = v.px_per_mm.as_mut() {
        *s *= k;
    }
    if let Some(mm) = v.matrix_px_per_mm.as_mut() {
        *mm = mm.map(|r| r.map(|x| x * k));
    }
}

/// The sign with which world z shows along the mirror's v (from the provisional map: which side
/// of the collision the mirror is on, which spheres alone cannot tell).
pub(super) fn z_sign(view: &View) -> f64 {
    if view.v_axis.z < 0.0 {
        -1.0
    } else {
        1.0
    }
}
