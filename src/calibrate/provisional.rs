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
/// c_mirror = a·c_direct + b, each c the image coordinate along which its view images x (u, or
/// v on a camera turned on its side: `x_index`); matrices and projections are left as given.
pub(super) fn align_mirror(direct: &ViewGeometry, mirror: &mut ViewGeometry, (a, b): (f64, f64)) {
    let (Some(sd), Some(od), Some((kd, sign_d)), Some((km, _))) = (
        direct.px_per_mm,
        direct.origin_px,
        shorthand_x(direct),
        shorthand_x(mirror),
    ) else {
        return;
    };
    let (Some(_), Some(om)) = (mirror.px_per_mm, mirror.origin_px.as_mut()) else {
        return;
    };
    // x = sign_d·(c_d − o_d)/s_d, so c_m = a·c_d + b is the mirror with scale |a|·s_d along
    // x, reversed when a·sign_d < 0, and offset b + a·o_d along its own image of x.
    om[km] = b + a * od[kd];
    mirror.px_per_mm = Some(a.abs() * sd);
    let axis = Some(if a * sign_d < 0.0 { "-x" } else { "+x" }.into());
    if km == 0 {
        mirror.u_axis = axis;
    } else {
        mirror.v_axis = axis;
    }
}

/// The shorthand's image axis along world x (0 for u, 1 for v) and the sign x runs along it.
fn shorthand_x(v: &ViewGeometry) -> Option<(usize, f64)> {
    [&v.u_axis, &v.v_axis]
        .into_iter()
        .enumerate()
        .find_map(|(k, axis)| {
            let axis = axis.as_deref()?;
            axis.ends_with('x')
                .then_some((k, if axis.starts_with('-') { -1.0 } else { 1.0 }))
        })
}

/// The image axis a view images world x nearer (0 for u, 1 for v): u on the thesis's rig, v on
/// a camera turned on its side (the views side by side).
pub(super) fn x_index(view: &View) -> usize {
    usize::from(view.v_axis.x.abs() > view.u_axis.x.abs())
}

/// How the mirror view images the world, from its provisional map: the image axis world x runs
/// along (`x_index`) and its sign there, and the sign world z runs along the other axis (which
/// side of the collision the mirror is on, which spheres alone cannot tell).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct MirrorAxes {
    pub(super) x_along: usize,
    pub(super) sx: f64,
    pub(super) f: f64,
}

impl MirrorAxes {
    /// The thesis's mirror: u along +x, v along +z.
    #[cfg(test)]
    pub(super) const THESIS: MirrorAxes = MirrorAxes {
        x_along: 0,
        sx: 1.0,
        f: 1.0,
    };

    pub(super) fn of(view: &View) -> MirrorAxes {
        let x_along = x_index(view);
        let axes = [view.u_axis, view.v_axis];
        let sign = |x: f64| if x < 0.0 { -1.0 } else { 1.0 };
        MirrorAxes {
            x_along,
            sx: sign(axes[x_along].x),
            f: sign(axes[1 - x_along].z),
        }
    }
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
