//! The provisional geometry calibrate starts from: the config's views with their scale set
//! from the data where needed, and the mirror's x made to agree with the direct view's, so that
//! the spheres are labelled alike in both views before anything is fitted; and the first
//! recording measured under the first such geometry that shows flights (`first_flights`).

use super::flights::{flights, FlightViews};
use super::whole_discs_only;
use crate::analysis::calibration::fit_line;
use crate::analysis::geometry::{View, ViewKind};
use crate::analysis::tracking::FrameObs;
use crate::analysis::BlobSurvey;
use crate::analysis::{self, FrameSource};
use crate::config::{Config, ViewGeometry};

/// `first_flights`: the provisional config, its views, the measurements, the split frame and
/// the four flights' frames.
pub(super) type FirstFlights = (Config, (Vec<View>, Vec<FrameObs>, usize, [Vec<usize>; 4]));

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

/// The views `flights` reads, from the provisional ones: the direct view at `di` and the
/// mirror's, each with the image axis x runs along.
pub(super) fn flight_views(views: &[View], di: usize) -> FlightViews {
    FlightViews {
        direct: (di, x_index(&views[di])),
        mirror: views
            .iter()
            .position(|v| v.kind == ViewKind::Mirror)
            .map(|mi| (mi, x_index(&views[mi]))),
    }
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

/// What the first recording shows under the first provisional geometry that gives flights in
/// the direct view: that config, its views, the frames' measurements (whole discs only), the
/// frame the flights split at and the four flights' frames. The direct view's scale is tried
/// in turn (`calibrate`'s provisional geometry), the mirror set from `mirror_line` (its x
/// against the direct view's) or kept at its ratio to the direct view; Err says each scale
/// tried and why it gave no flights.
pub(super) fn first_flights(
    src: &mut dyn FrameSource,
    cfg: &Config,
    direct_cfg: &ViewGeometry,
    survey: &BlobSurvey,
    di: usize,
    mirror_line: Option<(f64, f64)>,
) -> Result<FirstFlights, String> {
    // The direct view's scale must be within 10 % for its discs to be taken for spheres. Tried
    // in turn: the config's, then the blobs' median size (which the light biases: a highlight
    // raises the threshold and shrinks the blob) and 15 % either side of it.
    let mean_diameter_mm = 0.5 * (cfg.spheres.sphere(0).0 + cfg.spheres.sphere(1).0);
    let config_scale = local_scale(direct_cfg).unwrap_or(1.0);
    let mut scales = vec![config_scale];
    let mut sizes: Vec<f64> = survey
        .iter()
        .flat_map(|f| f[di].iter().map(|b| b.1))
        .collect();
    if sizes.len() >= 3 {
        sizes.sort_by(f64::total_cmp);
        let blob = sizes[sizes.len() / 2] / mean_diameter_mm;
        for k in [1.0, 1.15, 1.0 / 1.15] {
            let c = blob * k;
            if scales.iter().all(|x| (c / x - 1.0).abs() > 0.05) {
                scales.push(c);
            }
        }
    }
    let mut tried = Vec::new();
    for s_d in scales {
        let mut trial = cfg.clone();
        if let Some(v) = trial.geometry.direct.as_mut() {
            set_scale(v, s_d);
        }
        let direct_now = trial.geometry.direct.clone();
        if let (Some(m), Some(d)) = (trial.geometry.mirror.as_mut(), direct_now.as_ref()) {
            match mirror_line {
                Some(line) => align_mirror(d, m, line),
                None => {
                    let ratio = local_scale(m).unwrap_or(config_scale) / config_scale;
                    set_scale(m, s_d * ratio);
                }
            }
        }
        let attempt = analysis::measure(src, &trial)
            .map_err(|e| e.to_string())
            .map(|(views, obs)| (views, whole_discs_only(obs)))
            .and_then(|(views, obs)| {
                let (split, phases) = flights(&obs, flight_views(&views, di))?;
                Ok((views, obs, split, phases))
            });
        match attempt {
            Ok(ok) => return Ok((trial, ok)),
            Err(e) => tried.push(format!("at {s_d:.3} px/mm: {e}")),
        }
    }
    Err(format!(
        "no provisional scale gives flights in the direct view ({})",
        tried.join("; ")
    ))
}
