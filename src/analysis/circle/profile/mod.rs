//! Grey-level fits: the disc's edge modelled over every pixel within `PROFILE_BAND_PX` of it
//! (further inside where the edge is blurred), integrated over each pixel's area where the edge
//! crosses it; one disc, two discs whose rings meet fitted together, or the front disc hiding
//! the back one. `ring` gathers the pixels, `model` holds the disc's shading averaged over a
//! box, `pixel` the model at one pixel, `fit` the Levenberg–Marquardt fit of it, and
//! `dark_patches` the dots a blur has spread, which that fit leaves out; `shadow` the sectors
//! a cast shadow lies against, which it leaves out too; `first_pass` what the analysis's first
//! pass gives the second's fit of a disc.

mod dark_patches;
mod first_pass;
mod fit;
mod model;
mod pixel;
mod ring;
mod shadow;

use super::edge::sectors_covered;
use super::{CircleFit, DotMask, GreyImage, View};
use first_pass::held_widened;
pub use first_pass::FirstPassDisc;
use fit::{fit_grey_levels, Kept, Layering, Rounds};
use ring::{ring_pixels, RingPixel};
use shadow::Shadowed;

/// Half-width of the band round the edge whose pixels the profile fit uses, px.
pub const PROFILE_BAND_PX: f64 = 2.5;

/// The disc's centre and radius from the grey levels of every pixel near its edge, not from
/// edge points: a model I = background + L((R − d)/s)·S (L a logistic step of width s, S the
/// sphere's shading inside the edge, see `fit_grey_levels`), integrated over each pixel's
/// area, is fitted by
/// Levenberg–Marquardt, starting from the edge-point fit. Why: a threshold crossing
/// uses two samples per ray, and the edge-point fit's centre scatters about three times the
/// Cramér–Rao bound (physics.md §6), most of it pixel locking; the model fit uses all of the
/// edge's pixels. Pixels far off the model (dots on the rim) and their neighbours are dropped,
/// and so are pixels near the other sphere's disc or beyond the view's border, as long as 20 of
/// the ring's 36 sectors stay. Where the fit finds the edge blurred, it is fitted again from
/// there on a ring reaching further inside (`INNER_BAND_PER_EDGE_WIDTH`). A fit that settles
/// more than a pixel from the start is tried again from there (`profile_plan`). None when the
/// fit does not settle near the start or, tried again, where it went.
pub fn profile_fit(
    img: &GreyImage,
    view: &View,
    start: &CircleFit,
    background: f64,
    other: Option<([f64; 2], f64)>,
    dots: &[DotMask],
) -> Option<CircleFit> {
    let (_, plan) = profile_plan(img, view, start, background, other, dots, None, None)?;
    profile_finish(img, view, &plan, dots, None)
}

/// `profile_fit` with the disc's radius held at `radius_px`: for a disc cut by the view's
/// border, where the radius and the centre across the cut trade off (a free radius 0.5 px too
/// small put such centres 0.9 px off).
pub fn profile_fit_known_radius(
    img: &GreyImage,
    view: &View,
    start: &CircleFit,
    background: f64,
    other: Option<([f64; 2], f64)>,
    dots: &[DotMask],
    radius_px: f64,
) -> Option<CircleFit> {
    let (_, plan) = profile_plan(
        img,
        view,
        start,
        background,
        other,
        dots,
        Some(radius_px),
        None,
    )?;
    profile_finish(img, view, &plan, dots, None)
}

/// A lone disc's grey-level fit as far as its box rounds go (`profile_fit`, its radius held at
/// `radius_px` where given): the disc as they leave it (centres within about 0.01 px of the
/// final round's; enough to track it and find its dots), and the plan of its final round over
/// each pixel's area, which `profile_finish` carries out — with the same dots masked, or with
/// more. Why split: the analysis's first pass needs the discs only to find dots and spins, and
/// its second pass fits every disc again with the dots those put on its rim masked; the final
/// round started from where the first pass's box rounds stopped costs a third of a fit from
/// the edge points (docs/performance.md, session 38).
///
/// `held`: where the edge is found blurred, the refit holds the radius at it (`FirstPassDisc`).
#[allow(clippy::too_many_arguments)]
pub fn profile_plan(
    img: &GreyImage,
    view: &View,
    start: &CircleFit,
    background: f64,
    other: Option<([f64; 2], f64)>,
    dots: &[DotMask],
    radius_px: Option<f64>,
    held: Option<FirstPassDisc>,
) -> Option<(CircleFit, ProfilePlan)> {
    plan_with(
        img, view, start, background, other, dots, radius_px, held, None,
    )
}

/// `profile_plan`, with the shadowed sectors already found from this `start` where given (a
/// plan made again from its start finds the same ones: `profile_finish`).
#[allow(clippy::too_many_arguments)]
fn plan_with(
    img: &GreyImage,
    view: &View,
    start: &CircleFit,
    background: f64,
    other: Option<([f64; 2], f64)>,
    dots: &[DotMask],
    radius_px: Option<f64>,
    held: Option<FirstPassDisc>,
    shadowed: Option<Shadowed>,
) -> Option<(CircleFit, ProfilePlan)> {
    let near_other = |u: f64, v: f64| {
        other.is_some_and(|(oc, or)| dist(u - oc[0], v - oc[1]) < or + PROFILE_BAND_PX + 1.0)
    };
    let shadowed =
        shadowed.unwrap_or_else(|| Shadowed::find(img, view, start, background, &near_other));
    let left_out = |u: f64, v: f64| near_other(u, v) || shadowed.covers(u, v);
    let chain_start = *start;
    let start = CircleFit {
        radius: radius_px.unwrap_or(start.radius),
        ..*start
    };
    let min_sectors = min_sectors(radius_px);
    let smear_px = held.map_or([0.0; 2], |h| h.smear_px);
    // `tie`: the radius the fit holds (`radius_px`, or on the blurred refit `held`'s).
    let fit = |disc: &CircleFit, inner_px: f64, max_move_px: f64, tie: Option<f64>| {
        let pixels = ring_pixels(img, view, &[disc], dots, left_out, min_sectors, inner_px)?;
        // The refit on the ring reaching past a blurred edge models the shading's rise
        // under it as blurred (`model::blurred_rise`); the first, on the usual band, as
        // the step times the shading, which a sharp edge makes exact and which only has
        // to find how blurred the edge is.
        let convolved = inner_px > PROFILE_BAND_PX;
        let f = fit_grey_levels::<11, 1>(
            &pixels,
            [disc],
            background,
            Layering::Apart,
            [tie],
            [smear_px],
            max_move_px,
            convolved,
            Rounds::Box,
        )?;
        let held = held.filter(|_| radius_px.is_none() && tie.is_some());
        let plan = ProfilePlan {
            start: chain_start,
            disc: *disc,
            inner_px,
            max_move_px,
            radius_px,
            held,
            smear_px,
            other,
            shadowed,
            background,
            kept: f.kept?,
            fallback: None,
        };
        Some((held_widened(f.discs[0], held), f.widths, plan))
    };
    // A fit that settled more than a pixel from its start may still have found the disc: an
    // edge-point start on a blurred sphere lit from one side lies up to 1.5 px towards the lamp
    // (the threshold crosses the dark limb's blur well inside it). It is kept only if a fit
    // started from there, on the ring round it, stays within `RESTART_AGREE_PX`: then it is
    // the model's minimum round the disc, not a slide along something else. Why: those frames
    // fell back to the edge-point fit, 1 px off with a claimed 0.02 px, in runs of 2–4 frames
    // as a dot turned past the dark limb (seed 112: 28 of b's 282 mirror centres).
    // Not for a disc cut by the view's border (its radius held): along the cut such a fit can
    // slide, and that is what the pixel rule is there to stop.
    let reach_px = if radius_px.is_some() {
        1.0
    } else {
        RESTART_REACH_PX
    };
    let reached = fit(&start, PROFILE_BAND_PX, reach_px, radius_px)?;
    let moved = dist(
        reached.0.centre[0] - start.centre[0],
        reached.0.centre[1] - start.centre[1],
    );
    let first = if moved <= 1.0 {
        reached
    } else {
        let from_there = CircleFit {
            centre: reached.0.centre,
            radius: reached.0.radius,
            ..start
        };
        fit(&from_there, PROFILE_BAND_PX, RESTART_AGREE_PX, radius_px)?
    };
    let Some(inner_px) = blurred_inner_band(&first.1) else {
        return Some((first.0, first.2));
    };
    // The refit holds the radius the frames round it show (`FirstPassDisc`), where it is given.
    let tie = radius_px.or(held.map(|h| h.radius_px));
    let again = CircleFit {
        centre: first.0.centre,
        radius: tie.unwrap_or(first.0.radius),
        ..start
    };
    // Where the refit fails, in its box rounds here or in its final round (`profile_finish`),
    // the first fit stands.
    Some(match fit(&again, inner_px, 1.0, tie) {
        Some((disc, _, plan)) => (
            disc,
            ProfilePlan {
                fallback: Some(Box::new(first.2)),
                ..plan
            },
        ),
        None => (first.0, first.2),
    })
}

/// The final round of a lone disc's grey-level fit (`profile_plan`), over each pixel's area,
/// with `dots` masked: from where the plan's box rounds stopped where none of `dots` falls on
/// the plan's ring (the fit `profile_fit` would give with these dots, to the bit); else the
/// box rounds again on the masked ring from where they stopped, with the first round's scale
/// the plan's (`finish_masked`), then the final round; where that does not settle, the whole
/// fit again from the plan's start with them masked. Why not the final round from the plan
/// wherever: started where a fit of the unmasked ring settled, the rounds that find the dots
/// take their scale from smaller residuals and drop other pixels; tried in session 38, it put
/// the centres of the side-lit and cluttered looks 17 % further off (docs/performance.md).
/// None where the fit does not settle within the plan's reach of its start, or too little of
/// the ring is left.
///
/// `held`: as for `profile_plan`; where the plan's last fit is a blurred refit that did not
/// hold it, the whole fit again.
pub fn profile_finish(
    img: &GreyImage,
    view: &View,
    plan: &ProfilePlan,
    dots: &[DotMask],
    held: Option<FirstPassDisc>,
) -> Option<CircleFit> {
    let held = held.filter(|_| plan.radius_px.is_none());
    let hold_anew = held.is_some() && plan.inner_px > PROFILE_BAND_PX && plan.held != held;
    // A disc smeared over the exposure is modelled so from its first round on.
    let smear_anew = held.map_or([0.0; 2], |h| h.smear_px) != plan.smear_px;
    if !hold_anew && !smear_anew {
        if let Some(fit) = finish_unchanged(img, view, plan, dots) {
            return fit;
        }
        if let Some(fit) = finish_masked(img, view, plan, dots) {
            return Some(fit);
        }
    }
    let (_, again) = plan_with(
        img,
        view,
        &plan.start,
        plan.background,
        plan.other,
        dots,
        plan.radius_px,
        held,
        Some(plan.shadowed),
    )?;
    // Its ring has these dots masked already.
    finish_unchanged(img, view, &again, dots).flatten()
}

/// The plan's box rounds again on its ring with `dots` masked, from where they stopped
/// (`Rounds::BoxFrom`), then its final round; None where either does not settle (the whole
/// fit is then made again from the plan's start). Why: most second-pass rings have a dot the
/// markers found on them (77 % of the independent renders' discs, docs/performance.md session
/// 50), and the box rounds from the edge points were as costly as the first pass's.
fn finish_masked(
    img: &GreyImage,
    view: &View,
    plan: &ProfilePlan,
    dots: &[DotMask],
) -> Option<CircleFit> {
    let pixels = plan.ring(img, view, dots)?;
    let kept = plan.fit(&pixels, Rounds::BoxFrom(&plan.kept))?.kept?;
    let f = plan.fit(&pixels, Rounds::AreaFrom(&kept))?;
    Some(held_widened(f.discs[0], plan.held))
}

/// The plan's final round where none of `dots` falls on its ring (Some: the fit, or None where
/// it does not settle); None where some do.
fn finish_unchanged(
    img: &GreyImage,
    view: &View,
    plan: &ProfilePlan,
    dots: &[DotMask],
) -> Option<Option<CircleFit>> {
    let pixels = plan
        .ring(img, view, dots)
        .filter(|pixels| pixels.len() == plan.kept.ring_len)?;
    match (
        plan.fit(&pixels, Rounds::AreaFrom(&plan.kept)),
        &plan.fallback,
    ) {
        (Some(f), _) => Some(Some(held_widened(f.discs[0], plan.held))),
        (None, Some(first)) => finish_unchanged(img, view, first, dots),
        (None, None) => Some(None),
    }
}

/// What `profile_finish` needs of a lone disc's fit: where the whole fit started, the disc
/// its last fit started from (the ring is gathered round it, and it must settle near it), the ring's reach inside the edge, the
/// radius held if any, the other sphere's disc, the background, where its box rounds
/// stopped, and what stands if its final round fails.
#[derive(Clone, Debug)]
pub struct ProfilePlan {
    /// Where the whole fit started (`profile_plan`'s `start`).
    start: CircleFit,
    disc: CircleFit,
    inner_px: f64,
    max_move_px: f64,
    radius_px: Option<f64>,
    /// The radius a blurred refit held (`FirstPassDisc`).
    held: Option<FirstPassDisc>,
    /// The smear the fit modelled (`FirstPassDisc::smear_px`).
    smear_px: [f64; 2],
    other: Option<([f64; 2], f64)>,
    /// The sectors a shadow lies against, left out (`shadow`).
    shadowed: Shadowed,
    background: f64,
    kept: Kept,
    /// For a blurred disc's refit, the first fit's plan: what stands where the refit's final
    /// round does not settle.
    fallback: Option<Box<ProfilePlan>>,
}

impl ProfilePlan {
    /// The ring round the disc the plan's last fit started from, with `dots` masked, and
    /// without what the plan leaves out: pixels near the other sphere's disc, or in a sector
    /// a shadow lies against.
    fn ring(&self, img: &GreyImage, view: &View, dots: &[DotMask]) -> Option<Vec<RingPixel>> {
        let leaves_out = |u: f64, v: f64| {
            self.other
                .is_some_and(|(oc, or)| dist(u - oc[0], v - oc[1]) < or + PROFILE_BAND_PX + 1.0)
                || self.shadowed.covers(u, v)
        };
        ring_pixels(
            img,
            view,
            &[&self.disc],
            dots,
            leaves_out,
            min_sectors(self.radius_px),
            self.inner_px,
        )
    }

    /// The plan's disc fitted on `pixels` (its `ring`) as its last fit was: the same start,
    /// reach, held radius, smear and band, running `rounds`.
    fn fit(&self, pixels: &[RingPixel], rounds: Rounds<'_>) -> Option<fit::Fitted<1>> {
        fit_grey_levels::<11, 1>(
            pixels,
            [&self.disc],
            self.background,
            Layering::Apart,
            [self.radius_px.or(self.held.map(|h| h.radius_px))],
            [self.smear_px],
            self.max_move_px,
            self.inner_px > PROFILE_BAND_PX,
            rounds,
        )
    }
}

/// How many of its ring's 36 sectors a lone disc's fit needs: 20, or 12 with its radius held
/// (the radius no longer needs the ring to go round).
fn min_sectors(radius_px: Option<f64>) -> usize {
    if radius_px.is_some() {
        12
    } else {
        20
    }
}

/// How far from its start a lone disc's grey-level fit may settle and be tried again from
/// there (`fit_one`), px: within the ring's outer band, so the disc's edge was in the pixels
/// it was fitted on.
const RESTART_REACH_PX: f64 = PROFILE_BAND_PX;

/// How close to where it began the second fit of a restarted one (`fit_one`) must settle, px.
const RESTART_AGREE_PX: f64 = 0.25;

/// How far inside a disc's edge the ring reaches once the fit has found the edge blurred, in
/// edge widths s of the logistic step beyond `PROFILE_BAND_PX`: the blurred edge itself
/// reaches about 2s in (where the step is within 12 % of its plateau), and the band must go
/// past it to see the shading on its own. Why: on a defocused sphere the edge's blur, the
/// shading's slope and its harmonic round the disc all explain the same few pixels, and the
/// centre trades off with them — a lone sphere blurred by 1.1 px scattered 0.20 px (σ = 2)
/// where its fit claimed 0.11, and lit from 30° to one side came out 0.05–0.06 px towards the
/// lamp. With the ring reaching past the blur: 0.10 px against a claimed 0.085, and within
/// 0.01 px (`circle::tests::lone::a_defocused_sphere_is_measured_as_well_as_its_fit_claims`).
const INNER_BAND_PER_EDGE_WIDTH: f64 = 2.0;

/// The inner band a second fit should use after a first one (on `PROFILE_BAND_PX`) found the
/// edge widths `widths`, px; None where the edges are sharp enough that it would add less
/// than a quarter of a pixel (a sharp render's fit is left exactly as it was).
fn blurred_inner_band(widths: &[f64]) -> Option<f64> {
    let s = widths.iter().copied().fold(0.0, f64::max);
    edge_is_blurred(s).then_some(PROFILE_BAND_PX + INNER_BAND_PER_EDGE_WIDTH * s)
}

/// Whether an edge of width `s` px is blurred enough that the ring reaches further inside
/// (`blurred_inner_band`).
pub(crate) fn edge_is_blurred(s: f64) -> bool {
    INNER_BAND_PER_EDGE_WIDTH * s >= 0.25
}

/// Two discs side by side whose rings come close, fitted together: the model is the background
/// plus both discs' terms of `profile_fit`'s model, so the pixels between them, where both
/// edges' blur adds up, are explained instead of left out. Why: fitted one at a time, each disc
/// loses the part of its ring that faces the other — the part that fixes its centre along the
/// line between them — just in the frames next to the impact that fix the contact normal; on
/// the bench the centres there scattered 1.5–2 times as much along that line as far from it.
/// Only for discs that do not overlap in the view (one partly behind the other hides, and
/// hiding does not add up); None there and where the fit does not settle.
///
/// `held`: each disc's, as for `profile_plan`: held where the edges are found blurred.
/// `final_round`: false for the box rounds only (the first pass's, enough for dots and spins,
/// as its lone discs'; the final round over each pixel's area was a twentieth of the fits'
/// work on the independent renders, docs/performance.md session 54).
pub fn profile_fit_pair(
    img: &GreyImage,
    view: &View,
    starts: [&CircleFit; 2],
    background: f64,
    dots: &[DotMask],
    held: [Option<FirstPassDisc>; 2],
    final_round: bool,
) -> Option<[CircleFit; 2]> {
    let [a, b] = starts;
    let apart = (a.centre[0] - b.centre[0]).hypot(a.centre[1] - b.centre[1]);
    if apart < a.radius + b.radius - PAIR_OVERLAP_PX {
        return None;
    }
    let smears = held.map(|h| h.map_or([0.0; 2], |h| h.smear_px));
    let fit = |discs: [&CircleFit; 2], inner_px: f64, ties: [Option<f64>; 2]| {
        let pixels = ring_pixels(img, view, &discs, dots, |_, _| false, 20, inner_px)?;
        fit_grey_levels::<21, 2>(
            &pixels,
            discs,
            background,
            Layering::Apart,
            ties,
            smears,
            1.0,
            false,
            if final_round {
                Rounds::All
            } else {
                Rounds::Box
            },
        )
        .map(|f| (f.discs, f.widths))
    };
    let (first, widths) = fit(starts, PROFILE_BAND_PX, [None; 2])?;
    let Some(inner_px) = blurred_inner_band(&widths) else {
        return Some(first);
    };
    let ties = held.map(|h| h.map(|h| h.radius_px));
    let again = [0, 1].map(|k| CircleFit {
        centre: first[k].centre,
        radius: ties[k].unwrap_or(first[k].radius),
        ..*starts[k]
    });
    Some(
        fit([&again[0], &again[1]], inner_px, ties)
            .map_or(first, |(f, _)| [0, 1].map(|k| held_widened(f[k], held[k]))),
    )
}

/// Two discs of one silhouette, one partly hiding the other (the mirror after an oblique
/// impact), fitted together on the grey levels: the model is the front disc's term of
/// `profile_fit`'s model over the back disc's, which shows only where the front one does not
/// (and through the front's blurred edge), and the two radii keep the ratio of the spheres'
/// sizes `radii_px` (each start is given its sphere's: the starts' own radii, from an outline
/// split or a view's memory, held a crescent 9 % too large and 0.6 px off on a cluttered
/// varied-look recording, seed 130). The disc behind is lit by the front one's lamp.
/// Why: the split into circles rests on outline points, and where the outlines meet they are
/// neither circle's; as the spheres slide behind each other over a few frames the split circles
/// drifted by 0.1 px, which a line fit took for a z velocity several σ off. `front` is the
/// index (0 or 1) of the disc nearer the camera. None unless the discs are three quarters of
/// the back one's radius apart or more and the back one shows at least a third of its edge, and
/// where the fit does not settle.
pub fn profile_fit_behind(
    img: &GreyImage,
    view: &View,
    starts: [&CircleFit; 2],
    front: usize,
    radii_px: [f64; 2],
    background: f64,
    dots: &[DotMask],
) -> Option<[CircleFit; 2]> {
    let sized = [0, 1].map(|k| CircleFit {
        radius: radii_px[k],
        ..*starts[k]
    });
    let starts = [&sized[0], &sized[1]];
    let (f, b) = (starts[front], starts[1 - front]);
    // A crescent narrower than three quarters of the radius let the back disc slide along it by
    // a tenth of a pixel in renders; the split's circles are better there.
    if (f.centre[0] - b.centre[0]).hypot(f.centre[1] - b.centre[1]) < MIN_CRESCENT_RADII * b.radius
    {
        return None;
    }
    let fit = |starts: [&CircleFit; 2], max_move_px: f64| {
        let (f, b) = (starts[front], starts[1 - front]);
        // (Only the ring's usual band: a crescent's inside is mostly the front disc's.)
        let pixels = ring_pixels(img, view, &starts, dots, |_, _| false, 20, PROFILE_BAND_PX)?;
        let shown: Vec<[f64; 2]> = pixels
            .iter()
            .filter(|q| {
                ((q.u - b.centre[0]).hypot(q.v - b.centre[1]) - b.radius).abs() < 1.0
                    && (q.u - f.centre[0]).hypot(q.v - f.centre[1]) > f.radius + 1.0
            })
            .map(|q| [q.u, q.v])
            .collect();
        if sectors_covered(&shown, b.centre) < 12 {
            return None;
        }
        fit_grey_levels::<21, 2>(
            &pixels,
            starts,
            background,
            Layering::InFront(front),
            [None; 2],
            // (Not smeared: a crescent's frames are those round the impact, where the motion
            // changes within the exposure.)
            [[0.0; 2]; 2],
            max_move_px,
            false,
            Rounds::All,
        )
        .map(|f| f.discs)
    };
    // As for a lone disc (`plan_with`): a pair that settles more than a pixel from its starts
    // is kept only if a fit started from there stays within `RESTART_AGREE_PX` of it. Why:
    // under a lamp 35° off the axis over a ground the shaded limb matches, a silhouette's extent
    // put the starts 0.8–1.3 px off across the line between the spheres, and the direct view
    // lost both spheres for the rest of an independent-renderer recording after its impact
    // (docs/accuracy.md, session 53).
    let first = fit(starts, RESTART_REACH_PX)?;
    let moved = (0..2)
        .map(|k| {
            dist(
                first[k].centre[0] - starts[k].centre[0],
                first[k].centre[1] - starts[k].centre[1],
            )
        })
        .fold(0.0, f64::max);
    if moved <= 1.0 {
        return Some(first);
    }
    let again = [0, 1].map(|k| CircleFit {
        centre: first[k].centre,
        ..sized[k]
    });
    fit([&again[0], &again[1]], RESTART_AGREE_PX)
}

/// How far from its starts `profile_fit_behind` may put a disc, px: a pixel, or the reach of a
/// fit tried again from where the first went (`RESTART_REACH_PX`).
pub const BEHIND_REACH_PX: f64 = RESTART_REACH_PX + RESTART_AGREE_PX;

/// The narrowest crescent `profile_fit_behind` fits, in radii of the back disc.
const MIN_CRESCENT_RADII: f64 = 0.75;

/// How far two discs may overlap in a view and still be fitted as a sum (`profile_fit_pair`),
/// px: touching spheres whose contact normal leans a few degrees out of the view's plane.
pub const PAIR_OVERLAP_PX: f64 = 0.3;

/// Whether two discs' rings are close enough that fitting each alone leaves part of it out
/// (`profile_fit` drops the pixels near the other disc).
pub fn rings_meet(a: &CircleFit, b: &CircleFit) -> bool {
    let apart = (a.centre[0] - b.centre[0]).hypot(a.centre[1] - b.centre[1]);
    apart < a.radius + b.radius + 2.0 * PROFILE_BAND_PX + 1.0
}

/// √(dx² + dy²): at pixel scale nothing overflows, and `hypot`'s care costs several times a
/// √ on every pixel of every ring.
fn dist(dx: f64, dy: f64) -> f64 {
    (dx * dx + dy * dy).sqrt()
}

#[cfg(test)]
mod tests {
    use super::super::fit_edges;
    use super::super::tests::{dotless_direct_view, render_pair};
    use super::*;
    use nalgebra::Vector3;

    /// The analysis's first pass stops its grey-level fits after the box rounds and its second
    /// finishes them (`profile_plan`, `profile_finish`): where the second pass masks no new
    /// dot, the final round from the kept state is the whole fit to the bit, for the final
    /// round's work alone; where it masks some, the box rounds run again from where they
    /// stopped, with them masked.
    #[test]
    fn a_planned_fit_finishes_as_the_whole_fit_would() {
        let (view, r_px, cfg) = dotless_direct_view(64, 64, [31.3, 31.6]);
        let far = Vector3::new(40.0, 40.0, 0.0);
        let (img, truth) = render_pair(&view, 64, 64, [Vector3::zeros(), far], &cfg, 11);
        let t = truth[0];
        let e = fit_edges(&img, &view, [t[0] + 0.3, t[1] - 0.2], r_px, 30.0, None)
            .expect("edge fit")
            .0;
        let pixels = ring_pixels(&img, &view, &[&e], &[], |_, _| false, 20, PROFILE_BAND_PX)
            .expect("the ring");
        let fit = |rounds| {
            fit_grey_levels::<11, 1>(
                &pixels,
                [&e],
                30.0,
                Layering::Apart,
                [None],
                [[0.0; 2]],
                2.5,
                false,
                rounds,
            )
            .expect("the disc is fitted")
        };
        crate::analysis::stages::take_model_samples();
        let whole = fit(Rounds::All);
        let whole_work = crate::analysis::stages::take_model_samples();
        let boxed = fit(Rounds::Box);
        let kept = boxed.kept.expect("the box rounds keep their state");
        crate::analysis::stages::take_model_samples();
        let finished = fit(Rounds::AreaFrom(&kept));
        let finish_work = crate::analysis::stages::take_model_samples();
        let (w, f) = (whole.discs[0], finished.discs[0]);
        assert_eq!(
            (w.centre, w.radius, w.centre_sigma),
            (f.centre, f.radius, f.centre_sigma),
            "finished from the box rounds, not the whole fit"
        );
        assert!(
            finish_work < whole_work,
            "the final round alone cost {finish_work} of the whole fit's {whole_work} evaluations"
        );
        // Through the public pair: no dot masked in either pass.
        let (_, plan) =
            profile_plan(&img, &view, &e, 30.0, None, &[], None, None).expect("planned");
        let done = profile_finish(&img, &view, &plan, &[], None).expect("finished");
        assert_eq!(
            done.centre,
            profile_fit(&img, &view, &e, 30.0, None, &[])
                .unwrap()
                .centre
        );
        // A dot masked on the rim in the second pass: its box rounds again from where the
        // plan's stopped, with it masked, then the final round: where a whole fit with it
        // masked from the start settles, for less work.
        let dot = [DotMask::around([t[0] + r_px, t[1]], 1.0)];
        crate::analysis::stages::take_model_samples();
        let again = profile_finish(&img, &view, &plan, &dot, None).expect("finished with a dot");
        let again_work = crate::analysis::stages::take_model_samples();
        let direct = profile_fit(&img, &view, &e, 30.0, None, &dot).expect("fitted with a dot");
        let direct_work = crate::analysis::stages::take_model_samples();
        let apart = dist(
            again.centre[0] - direct.centre[0],
            again.centre[1] - direct.centre[1],
        );
        // (The box rounds after the first settle to 1e-3 px: 1.0e-4 px apart here, where the
        // centre's σ is 0.007 px; 1266 evaluations against 2070, linear starts counted. On
        // hw-sim's default look, an in-distribution look: what this checks is the mechanism.)
        assert!(
            apart < 1e-3,
            "{apart} px from the whole fit with the dot masked"
        );
        assert!(
            again_work < direct_work,
            "the second pass cost {again_work} evaluations, the whole fit {direct_work}"
        );
        assert_ne!(
            again.centre, done.centre,
            "the mask changed nothing: a vacuous test"
        );
    }
}
