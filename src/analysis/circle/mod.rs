//! Sub-pixel sphere centres, three techniques:
//! - `edge`: edge points found as level crossings along rays from a rough centre, a Taubin
//!   algebraic circle fit, then a geometric (Gauss–Newton) fit with outlier rejection —
//!   physics.md §6: Taubin + LM is unbiased on partial arcs, where Kåsa is not, and edge fits
//!   come within ~1.3× of the Cramér–Rao bound. Markers at the limb and a touching neighbour
//!   produce outlying edge points; those are rejected, not averaged in.
//! - `profile`: the disc's centre and radius from the grey levels of every pixel near its
//!   edge, integrated over each pixel's area (one disc, two whose rings meet, or one hiding
//!   the other).
//! - `split`: a silhouette holding both spheres in one view split into two circles.
//!
//! `refine` chains the first two for one disc.

mod edge;
mod profile;
mod split;
#[cfg(test)]
mod tests;

use super::geometry::View;
use super::image::GreyImage;
pub use edge::*;
use nalgebra::{SMatrix, SVector};
pub use profile::*;
pub use split::*;

#[derive(Clone, Copy, Debug)]
pub struct CircleFit {
    pub centre: [f64; 2],
    pub radius: f64,
    /// One-sigma uncertainty of each centre coordinate, px.
    pub centre_sigma: [f64; 2],
    pub radius_sigma: f64,
    pub rms_px: f64,
    pub points_used: usize,
    pub points_total: usize,
    /// 10° sectors (of 36) the points used go round (`sectors_covered`).
    pub arc_sectors: usize,
    /// Fitted on the grey levels (`profile`), not on edge points alone: a fit of the disc's
    /// whole model, whose own residuals say whether it is one circle (a shiny or side-lit
    /// sphere's edge points agree less, because one level does not suit its whole rim).
    pub grey_levels: bool,
    /// The grey-level fit's edge width s, px (the logistic step L((R − d)/s) of `profile`: a
    /// blur of standard deviation π·s/√3 across the edge beyond the pixel's own, which the
    /// model averages over separately); NaN for a fit on edge points. Calibrate reads from it
    /// how far defocus can move the edge.
    pub edge_width_px: f64,
}

impl CircleFit {
    /// A start for a fit and nothing measured yet: the disc at `centre` with radius `radius_px`,
    /// its σ infinite and no edge points behind it.
    pub fn start_at(centre: [f64; 2], radius_px: f64) -> CircleFit {
        CircleFit {
            centre,
            radius: radius_px,
            centre_sigma: [f64::INFINITY; 2],
            radius_sigma: f64::INFINITY,
            rms_px: f64::INFINITY,
            points_used: 0,
            points_total: 0,
            arc_sectors: 0,
            grey_levels: false,
            edge_width_px: f64::NAN,
        }
    }
}

/// Refines a rough centre to a sub-pixel circle fit: edge points first (`fit_edges`), then the
/// grey levels near the edge (`profile_fit`) where it settles. `other` is the other sphere's
/// disc (centre, radius px) in the same view, when it is there. Where a static backdrop hid
/// part of the edge, only the grey-level fit (which models what the disc hides) measures:
/// without it, None.
pub fn refine(
    img: &GreyImage,
    view: &View,
    rough: [f64; 2],
    radius_px: f64,
    background: f64,
    other: Option<([f64; 2], f64)>,
    dots: &[DotMask],
) -> Option<CircleFit> {
    let r = refine_plan(img, view, rough, radius_px, background, other, dots, None)?;
    let Some(plan) = r.plan else {
        return Some(r.fit);
    };
    match profile_finish(img, view, &plan, dots, None) {
        Some(f) => Some(f),
        None if r.hidden => None,
        None => Some(r.edge),
    }
}

/// `refine` as far as the grey-level fit's box rounds go (`profile_plan`): what it gives now,
/// whether a static backdrop hid part of the edge (then the edge points the fit started from
/// are few and may belong to the part of the disc brighter than the backdrop, so a start from
/// elsewhere, the sphere's track, is worth a try: `tracking`), and what the fit's final round
/// needs (`profile_finish`). None where `refine` gives none. `held`: see `profile_plan`.
#[allow(clippy::too_many_arguments)]
pub fn refine_plan(
    img: &GreyImage,
    view: &View,
    rough: [f64; 2],
    radius_px: f64,
    background: f64,
    other: Option<([f64; 2], f64)>,
    dots: &[DotMask],
    held: Option<FirstPassDisc>,
) -> Option<Refined> {
    let (edge, hidden) = fit_edges(img, view, rough, radius_px, background, other)?;
    match profile_plan(img, view, &edge, background, other, dots, None, held) {
        Some((fit, plan)) => Some(Refined {
            fit,
            hidden,
            edge,
            plan: Some(plan),
        }),
        None if hidden => None,
        None => Some(Refined {
            fit: edge,
            hidden: false,
            edge,
            plan: None,
        }),
    }
}

/// What `refine_plan` gives: the fit as far as it went, whether a static backdrop hid part of
/// the edge, the edge-point fit (what `refine` falls back to where the grey-level fit fails
/// unhidden), and the grey-level fit's final round if it is still to do.
#[derive(Clone, Debug)]
pub struct Refined {
    pub fit: CircleFit,
    pub hidden: bool,
    pub edge: CircleFit,
    pub plan: Option<ProfilePlan>,
}

/// The grey-level fit alone, started at `centre` with the known radius: for a disc whose edge
/// a static backdrop hid, where the sphere's own track says it is (`tracking`). The edge-point
/// fit is left out: on the few rays the backdrop leaves it may move a good start by a pixel
/// the wrong way, and the grey-level fit must then settle a pixel from where it began.
pub fn profile_fit_at(
    img: &GreyImage,
    view: &View,
    centre: [f64; 2],
    radius_px: f64,
    background: f64,
    other: Option<([f64; 2], f64)>,
    dots: &[DotMask],
) -> Option<CircleFit> {
    profile_fit(
        img,
        view,
        &CircleFit::start_at(centre, radius_px),
        background,
        other,
        dots,
    )
}

/// Where a marker is expected on a sphere's rim in one frame, px: the grey-level fit leaves out
/// the pixels within `radius_px` of `centre_px`. A dot within a pixel of the limb darkens the
/// edge only a little and is not rejected as an outlier; the spin and the other view say
/// where it is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DotMask {
    pub centre_px: [f64; 2],
    pub radius_px: f64,
}

impl DotMask {
    /// Beyond the dot's own radius: anti-aliasing, the predicted position's error and the
    /// grey-level fit's pixel support.
    pub const MARGIN_PX: f64 = 0.8;

    /// The mask of a dot of image radius `dot_radius_px` centred at `centre_px`.
    pub fn around(centre_px: [f64; 2], dot_radius_px: f64) -> DotMask {
        DotMask {
            centre_px,
            radius_px: dot_radius_px + Self::MARGIN_PX,
        }
    }
}

/// Normal equations at some parameters: (JᵀJ, Jᵀr, Σr²).
pub(crate) type Normal<const N: usize> = (SMatrix<f64, N, N>, SVector<f64, N>, f64);

/// Gauss–Newton on the parameters `p`, shared by the geometric circle fits: each iteration
/// solves (JᵀJ) δ = −Jᵀr from the sums `normal(p)` gives, adds δ, and stops once |δ| < 1e-9 or
/// after `max_iter` steps. Returns the sums of the last iteration (at the parameters before
/// its step), or None where JᵀJ is singular. (The grey-level fits damp their steps, LM, in
/// `profile`.)
pub(crate) fn gauss_newton<const N: usize>(
    p: &mut SVector<f64, N>,
    max_iter: usize,
    normal: impl Fn(&SVector<f64, N>) -> Normal<N>,
) -> Option<Normal<N>>
where
    nalgebra::Const<N>: nalgebra::DimMin<nalgebra::Const<N>, Output = nalgebra::Const<N>>,
{
    let mut last = None;
    for _ in 0..max_iter {
        let (jtj, jtr, ss) = normal(p);
        let step = jtj.lu().solve(&(-jtr))?;
        *p += step;
        last = Some((jtj, jtr, ss));
        if step.norm() < 1e-9 {
            break;
        }
    }
    last
}
