//! What the analysis's first pass measured of a disc that the second pass's grey-level fit of
//! it uses (`FirstPassDisc`): the radius a blurred disc is held at, its stray, and the disc's
//! smear over the exposure.

use super::dist;
use crate::analysis::circle::CircleFit;

/// What the first pass measured of a disc that the second pass's fit of it uses: the sphere's
/// radius in this view as the frames round it show it, and how far the disc moved while the
/// shutter was open (`smear_px`).
///
/// The radius is what the second pass holds a
/// blurred disc's radius at (`profile_plan`, `profile_fit_pair`). Why: on a defocused sphere
/// the blur, the shading's slope, its harmonic round the disc and the dots the blur spreads
/// over the face all explain the same few pixels, and a free radius lets the fit trade them
/// against the centre: on eight rigs blurred by 1.0–1.2 px the centres were 0.12 px off with
/// their dots and 0.056 without, the fits' radii swinging by tenths of a pixel from frame to
/// frame while the sphere's does not (docs/accuracy.md, session 39). The first pass's radii of the same
/// sphere over the frames round this one fix it far better than one frame's pixels do; their
/// median (`radius_misfit::held_radii`) carries the model's own bias of the radius, which the
/// sphere's known size would not (held at that, the same rigs gave 0.117 px). Held: 0.099 px,
/// and with pairs near contact held too, 0.093.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FirstPassDisc {
    /// Where the first pass put the disc, px.
    pub centre_px: [f64; 2],
    /// The median of the sphere's radii in this view over the frames round this one, px.
    pub radius_px: f64,
    /// This frame's own first-pass radius less that median, px: the misfit a held fit no
    /// longer shows, carried into its centre's σ as `radius_misfit` would have (`held_widened`).
    pub stray_px: f64,
    /// How far the disc moved over the exposure, px (its image velocity from the first pass's
    /// centres times `camera.exposure_us`): the grey-level model is smeared along it
    /// (`PixelModel`). Zero where the exposure is not given or the smear is below
    /// `SMEAR_MIN_PX`.
    pub smear_px: [f64; 2],
}

impl FirstPassDisc {
    /// The one of `held` whose disc lies within a third of its radius of `centre` (the fit's
    /// start), if any.
    pub fn near(held: &[FirstPassDisc], centre: [f64; 2]) -> Option<FirstPassDisc> {
        held.iter()
            .filter(|h| {
                dist(h.centre_px[0] - centre[0], h.centre_px[1] - centre[1]) < h.radius_px / 3.0
            })
            .min_by(|a, b| {
                let d = |h: &FirstPassDisc| {
                    dist(h.centre_px[0] - centre[0], h.centre_px[1] - centre[1])
                };
                d(a).total_cmp(&d(b))
            })
            .copied()
    }
}

/// A fit whose radius was held at `held`'s: its centre's σ carries the first pass's stray of the
/// radius, half its square on each axis (as `radius_misfit::widen` adds it to a free fit's).
pub(super) fn held_widened(fit: CircleFit, held: Option<FirstPassDisc>) -> CircleFit {
    let Some(h) = held else { return fit };
    let add = 0.5 * h.stray_px * h.stray_px;
    CircleFit {
        centre_sigma: fit.centre_sigma.map(|s| (s * s + add).sqrt()),
        ..fit
    }
}
