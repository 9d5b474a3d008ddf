//! One sphere's measurement in one view: a lone blob refined to a circle with its gates and the
//! dots inside, a disc a static backdrop hid fitted from where its track puts it, and two
//! spheres touching in one silhouette fitted from where each was heading.

use super::{Measurement, ViewLevels};
use crate::analysis::circle::{
    profile_finish, profile_fit_at, profile_plan, refine_plan, CircleFit, DotMask, FirstPassDisc,
    ProfilePlan, Refined,
};
use crate::analysis::detect::Blob;
use crate::analysis::geometry::View;
use crate::analysis::image::GreyImage;
use crate::analysis::markers;
use crate::analysis::stages::{self, Stage};
use crate::config::Config;

/// A blob's circle fit: `refine`, and for a blob cut by the view's border the fit at the known
/// radius over it. What costs the time in measuring a sphere, and a pure function of its
/// arguments — no label, no memory of other frames — so that it can be computed ahead on other
/// threads (`ahead`) and give the same bits as here.
#[derive(Clone, Copy, Debug)]
pub(super) enum BlobFit {
    /// The fit, and whether a static backdrop hid part of the disc's edge
    /// (`circle::refine_plan`).
    Fitted(CircleFit, bool),
    TooFewEdgePoints,
    ClippedNotFitted,
}

///
/// `held`: the second pass's radii (`FirstPassDisc`), of which the one near the blob is held where
/// its edge is blurred.
#[allow(clippy::too_many_arguments)]
pub(super) fn fit_blob(
    img: &GreyImage,
    view: &View,
    b: &Blob,
    radius_px: f64,
    other: Option<([f64; 2], f64)>,
    background: f64,
    dots: &[DotMask],
    held: &[FirstPassDisc],
) -> BlobFit {
    match plan_blob(img, view, b, radius_px, other, background, dots, held) {
        (_, Some(plan)) => finish_blob(img, view, &plan, dots, held),
        (fit, None) => fit,
    }
}

/// `fit_blob` as far as the grey-level fits' box rounds go (`circle::profile_plan`): the fit
/// they give, and what its final round needs (`finish_blob`), None where nothing is left to
/// do (the fit is then final: an edge-point fit, or none).
#[allow(clippy::too_many_arguments)]
pub(super) fn plan_blob(
    img: &GreyImage,
    view: &View,
    b: &Blob,
    radius_px: f64,
    other: Option<([f64; 2], f64)>,
    background: f64,
    dots: &[DotMask],
    held: &[FirstPassDisc],
) -> (BlobFit, Option<BlobPlan>) {
    let near = FirstPassDisc::near(held, b.centroid);
    let refined = stages::timed(Stage::Circles, || {
        refine_plan(
            img, view, b.centroid, radius_px, background, other, dots, near,
        )
    });
    let Some(Refined {
        fit: f,
        hidden,
        edge,
        plan,
    }) = refined
    else {
        return (BlobFit::TooFewEdgePoints, None);
    };
    // A disc cut by the view's border: its radius is known, and held, where the visible arc
    // cannot fix both it and the centre across the cut; an edge-point fit with a free radius
    // there was up to 0.9 px off (as far as 2 px defocused), so without this fit there is no
    // measurement.
    if !b.clipped {
        let plan = plan.map(|plan| BlobPlan {
            plan,
            centroid: b.centroid,
            counts: None,
            hidden,
            unfinished: if hidden {
                BlobFit::TooFewEdgePoints
            } else {
                BlobFit::Fitted(edge, false)
            },
        });
        return (BlobFit::Fitted(f, hidden), plan);
    }
    // The radius the lens gives a disc there, not the view's nominal one: at the top of a
    // 240 × 192 frame through k1 = −0.03 it is 0.08 px smaller, and held at the nominal the
    // centre moved across the cut by as much (calibrate's flights, docs/accuracy.md session 36).
    // (Under perspective the radius changes with the sphere's depth too: not followed here.)
    let radius_px = view
        .lens
        .map_or(radius_px, |lens| radius_px * lens.radius_factor(f.centre));
    match stages::timed(Stage::Circles, || {
        profile_plan(
            img,
            view,
            &f,
            background,
            other,
            dots,
            Some(radius_px),
            None,
        )
    }) {
        Some((k, plan)) => (
            BlobFit::Fitted(with_counts_of(k, &f), hidden),
            Some(BlobPlan {
                plan,
                centroid: b.centroid,
                counts: Some(f),
                hidden,
                unfinished: BlobFit::ClippedNotFitted,
            }),
        ),
        None => (BlobFit::ClippedNotFitted, None),
    }
}

/// The fit `plan_blob` planned, finished with `dots` masked (the first pass's plan, the second
/// pass's dots): its final grey-level round (`circle::profile_finish`), or where that does
/// not settle what `fit_blob` gives when the grey-level fit fails.
pub(super) fn finish_blob(
    img: &GreyImage,
    view: &View,
    plan: &BlobPlan,
    dots: &[DotMask],
    held: &[FirstPassDisc],
) -> BlobFit {
    let near = FirstPassDisc::near(held, plan.centroid);
    match stages::timed(Stage::Circles, || {
        profile_finish(img, view, &plan.plan, dots, near)
    }) {
        Some(k) => BlobFit::Fitted(
            plan.counts.as_ref().map_or(k, |f| with_counts_of(k, f)),
            plan.hidden,
        ),
        None => plan.unfinished,
    }
}

/// A fit at the known radius with the edge points' counts of the fit it started from (its own
/// start is that fit).
fn with_counts_of(k: CircleFit, f: &CircleFit) -> CircleFit {
    CircleFit {
        points_used: f.points_used,
        points_total: f.points_total,
        arc_sectors: f.arc_sectors,
        ..k
    }
}

/// What `finish_blob` needs: the grey-level fit's plan, whether a backdrop hid part of the
/// edge, for a clipped blob the fit whose edge-point counts it keeps, and what the blob's fit
/// is where the final round does not settle.
#[derive(Clone, Debug)]
pub(super) struct BlobPlan {
    plan: ProfilePlan,
    /// The blob's centroid (which of the second pass's radii is this disc's: `FirstPassDisc::near`).
    centroid: [f64; 2],
    counts: Option<CircleFit>,
    hidden: bool,
    unfinished: BlobFit,
}

/// Sphere `s`'s blob in one view and frame, with what fitting it again needs: the other
/// sphere's blob, both spheres' predictions from their tracks in this view, both radii, px.
#[derive(Clone, Copy)]
pub(super) struct Refit<'a> {
    pub img: &'a GreyImage,
    pub view: &'a View,
    pub s: usize,
    pub blob: &'a Blob,
    pub other_blob: Option<&'a Blob>,
    pub predicted: [Option<[f64; 2]>; 2],
    pub radius: [f64; 2],
    pub lv: &'a ViewLevels,
    pub dots: &'a [DotMask],
}

impl Refit<'_> {
    /// Sphere `s`'s disc fitted on the grey levels from where its own track in this view puts it
    /// (`predicted`, both spheres'), for a blob whose edge a static backdrop hid in part or whole
    /// (a tube end, a ruler). Why: the blob the backdrop's subtraction leaves is then only part of
    /// the disc (darker than the backdrop at the limb, brighter inside), its centroid pixels off,
    /// and the few edge points left may trace the bright part alone; spheres passing in front of a
    /// tube end went unmeasured for 20–120 frames of a recording (fits rejected for settling 2 px
    /// from the centroid they began at), and on a synthetic one a fit from the bright part settled
    /// 3.2 px towards the light with the right radius. Also for a blob whose edge points are too
    /// few where the sphere has no track yet, from round the blob's centroid: a side-lit sphere
    /// over a grey ground under a noise of 4 levels (an independent render drawn at random) gave
    /// too few edge points in every frame of one view, and so never a track. Only where the start
    /// (with a track) or the disc found (without) lies on the blob, the blob is not cut by the
    /// view's border, and the other sphere (by its prediction and its blob) is clear of the disc:
    /// two discs in one blob are not one disc.
    pub(super) fn grey_level_fit(&self) -> Option<CircleFit> {
        let Refit {
            img,
            view,
            s,
            blob: b,
            other_blob,
            predicted,
            radius,
            lv,
            dots,
        } = *self;
        let dist = |p: [f64; 2], q: [f64; 2]| (p[0] - q[0]).hypot(p[1] - q[1]);
        if b.clipped || other_blob.is_some_and(|o| std::ptr::eq(o, b)) {
            return None;
        }
        let apart = radius[0] + radius[1] + 1.0;
        let clear = |p: [f64; 2]| {
            dist(p, b.centroid) < radius[s]
                && !predicted[1 - s].is_some_and(|q| dist(p, q) < apart)
                && !other_blob.is_some_and(|o| dist(p, o.centroid) < apart)
        };
        let other = other_blob.map(|o| (o.centroid, radius[1 - s]));
        if let Some(p) = predicted[s] {
            return clear(p)
                .then(|| profile_fit_at(img, view, p, radius[s], lv.background, other, dots))
                .flatten();
        }
        // No track yet (the sphere's first frames in this view). Where the blob holds both sides
        // of a disc whose shading crosses the ground's level (`detect::find_blobs`) its centroid is
        // a start within a pixel or so; where it holds the lit side alone, the centroid lies up to
        // a third of a radius or more towards the light, and a fit from there settles on a smaller
        // disc nearer the light, or on none. So the fit starts also round the centroid, at a
        // quarter and at half a radius in eight directions, and of the discs found the one whose
        // radius is nearest the sphere's is taken: the size is known, where the light is not.
        // (The first of equals, in this fixed order: the same bits every run.)
        let mut starts = vec![b.centroid];
        for reach in [0.25, 0.5] {
            for k in 0..8 {
                let (sin, cos) = (k as f64 * std::f64::consts::FRAC_PI_4).sin_cos();
                let d = reach * radius[s];
                starts.push([b.centroid[0] + d * cos, b.centroid[1] + d * sin]);
            }
        }
        starts
            .into_iter()
            .filter_map(|p| profile_fit_at(img, view, p, radius[s], lv.background, other, dots))
            .filter(|f| clear(f.centre))
            .min_by(|f, g| {
                let stray = |c: &CircleFit| (c.radius - radius[s]).abs();
                stray(f).total_cmp(&stray(g))
            })
    }

    /// A blob's fit made again where the first may be wrong (`fit`, from `fit_blob`), and which of
    /// the two is kept:
    /// - too few edge points: from the track (`Refit::grey_level_fit`), or without one from round
    ///   the blob's centroid;
    /// - an edge a static backdrop hid in part: from the track, and that fit kept. Without a track
    ///   the blob (part of the disc) is no better a start than the first fit's own, and refitted
    ///   from its centroid a side-lit sphere entering a grey-ground view came out 5 px towards the
    ///   light;
    /// - a fit on edge points more than `OFF_TRACK_PX` from where the sphere's own track puts it:
    ///   from there too, and of the two discs the one whose radius is nearer the sphere's
    ///   (`remembered_px` where it is within a tenth of the config's, else the config's) is kept.
    ///   On a grey ground a shaded limb's outer edge and its inner one (where its shading crosses
    ///   the ground's level) are both edges, and a fit on both put one side-lit disc 0.23 px too
    ///   large, 1.5 px off its track and its truth.
    pub(super) fn again(&self, fit: BlobFit, remembered_px: Option<f64>) -> BlobFit {
        let Refit {
            s,
            predicted,
            radius,
            ..
        } = *self;
        let off_track = |f: &CircleFit| {
            predicted[s]
                .is_some_and(|p| (f.centre[0] - p[0]).hypot(f.centre[1] - p[1]) > OFF_TRACK_PX)
        };
        let again = || self.grey_level_fit();
        match fit {
            BlobFit::TooFewEdgePoints => again().map_or(fit, |g| BlobFit::Fitted(g, true)),
            BlobFit::Fitted(_, true) if predicted[s].is_some() => {
                again().map_or(fit, |g| BlobFit::Fitted(g, true))
            }
            BlobFit::Fitted(f, false) if off_track(&f) => {
                let expected = remembered_px
                    .filter(|r| (r - radius[s]).abs() < 0.1 * radius[s])
                    .unwrap_or(radius[s]);
                match again() {
                    Some(g) if (g.radius - expected).abs() < (f.radius - expected).abs() => {
                        BlobFit::Fitted(g, false)
                    }
                    _ => fit,
                }
            }
            _ => fit,
        }
    }
}

/// How far an edge-point fit may lie from its track's prediction before a grey-level fit from
/// the prediction is asked too, px (`Refit::again`). Only when to look twice, not which to keep
/// (the radius decides): in free flight a track predicts within a few hundredths of a pixel,
/// and near the impact, where it can be pixels out, the second fit costs time, not accuracy.
const OFF_TRACK_PX: f64 = 1.0;

/// One sphere's measurement from its blob: the circle fit (`fit`, made ahead or kept from the
/// first pass with the same arguments, else `fit_blob` now), its gates, and the dots inside.
#[allow(clippy::too_many_arguments)]
pub(super) fn measure_blob(
    img: &GreyImage,
    view: &View,
    b: &Blob,
    s: usize,
    radius_px: f64,
    other: Option<([f64; 2], f64)>,
    lv: &ViewLevels,
    cfg: &Config,
    dots: &[DotMask],
    held: &[FirstPassDisc],
    fit: Option<BlobFit>,
) -> Result<(Measurement, CircleFit), String> {
    let name = ["a", "b"][s];
    if b.merged {
        return Err(format!("{name}: silhouettes of a and b merged"));
    }
    let fit =
        fit.unwrap_or_else(|| fit_blob(img, view, b, radius_px, other, lv.background, dots, held));
    let f = match fit {
        BlobFit::Fitted(f, _) => f,
        BlobFit::TooFewEdgePoints => {
            return Err(format!("{name}: too few edge points for a circle fit"))
        }
        BlobFit::ClippedNotFitted => {
            return Err(format!(
                "{name}: sphere clipped by the view border and its visible arc not fitted at the known radius"
            ))
        }
    };
    // A sphere partly beyond the view's border is fitted on its visible arc, and kept if that
    // arc is at least half the circle: fast spheres cross a view in a dozen frames, and the
    // ones at its edges lengthen the trajectory. (Whether the sphere flies freely there is the
    // fits' business: `flight_phases`.)
    if b.clipped && f.arc_sectors < 18 {
        return Err(format!(
            "{name}: sphere clipped by the view border (visible arc {}°, need 180°)",
            f.arc_sectors * 10
        ));
    }
    // A silhouette partly hidden by, or touching, the other sphere is not one circle: its fit
    // is too large or rests on too few of its edge points. Where the grey-level model settled
    // (it fits the whole disc, shading round it included) fewer edge points need agree: on a
    // shiny or side-lit sphere one threshold level does not suit the whole rim, and 40–55 %
    // of the points agreeing rejected lone spheres that were measured well.
    let agree = if f.grey_levels { 0.35 } else { 0.6 };
    if (f.radius - radius_px).abs() > (0.1 * radius_px).max(0.7)
        || (f.points_used as f64) < agree * f.points_total as f64
    {
        return Err(format!(
            "{name}: silhouette is not one circle (fit radius {:.2} px, expected {:.2} px; {} of {} edge points agree)",
            f.radius, radius_px, f.points_used, f.points_total
        ));
    }
    let radius_mm = cfg.spheres.sphere(s).0 / 2.0;
    let m = Measurement {
        centre_px: f.centre,
        blob_centroid_px: b.centroid,
        sigma_px: f.centre_sigma,
        diameter_px: 2.0 * f.radius,
        edge_width_px: f.edge_width_px,
        // Beyond the border the frame shows another view: no dots from a clipped disc.
        markers: if b.clipped {
            Vec::new()
        } else {
            stages::timed(Stage::Markers, || {
                markers::find(
                    img,
                    view,
                    &f,
                    radius_mm,
                    cfg.analysis.marker_diameter_mm,
                    lv.noise_sigma,
                )
            })
        },
        hidden_in_part: None,
        radius_stray_px: 0.0,
        sigma_common_px: 0.0,
    };
    Ok((m, f))
}

/// Both spheres of one silhouette in which they touch, each fitted from its predicted centre
/// with the other's side left out (as for two blobs that nearly touch). None unless both fits
/// land within a pixel of their predictions and no closer together than 95 % of the contact
/// distance: touching spheres do not overlap, so a pair that does was not measured right.
#[allow(clippy::too_many_arguments)]
pub(super) fn measure_touching(
    img: &GreyImage,
    view: &View,
    blob: &Blob,
    predicted: [[f64; 2]; 2],
    radius_px: [f64; 2],
    lv: &ViewLevels,
    cfg: &Config,
    dots: &[DotMask],
) -> Option<[(Measurement, CircleFit); 2]> {
    let part = Blob {
        merged: false,
        ..blob.clone()
    };
    let fit = |s: usize| {
        let b = Blob {
            centroid: predicted[s],
            ..part.clone()
        };
        let other = Some((predicted[1 - s], radius_px[1 - s]));
        measure_blob(
            img,
            view,
            &b,
            s,
            radius_px[s],
            other,
            lv,
            cfg,
            dots,
            &[],
            None,
        )
        .ok()
    };
    let (a, b) = (fit(0)?, fit(1)?);
    for (s, f) in [&a.1, &b.1].iter().enumerate() {
        if (f.centre[0] - predicted[s][0]).hypot(f.centre[1] - predicted[s][1]) > 1.0 {
            return None;
        }
    }
    let apart = (a.1.centre[0] - b.1.centre[0]).hypot(a.1.centre[1] - b.1.centre[1]);
    if apart < 0.95 * (radius_px[0] + radius_px[1]) {
        return None;
    }
    Some([a, b])
}

/// Why a lone circle fitted to sphere `s`'s blob may hold the other sphere too, if it may: the
/// other has no blob of its own in this view (`other`: Some), its track puts its disc over this
/// one by more than a pixel or cannot say where it is (Some(None): not measured in this view
/// lately), and the circle is larger than the sphere by more than `MAY_HOLD_BOTH_PX` (than
/// this view's last radius of it, `remembered_px`, where that is within a tenth of the
/// config's; else the config's). A sphere wholly behind the other leaves the front one's circle
/// its own size; one partly behind makes the silhouette larger.
pub(super) fn may_hold_both(
    s: usize,
    fit: &CircleFit,
    radius_px: [f64; 2],
    other: Option<Option<[f64; 2]>>,
    remembered_px: Option<f64>,
) -> Option<String> {
    let where_other = other?;
    let apart = where_other.map(|p| (fit.centre[0] - p[0]).hypot(fit.centre[1] - p[1]));
    if apart.is_some_and(|d| d > radius_px[0] + radius_px[1] - 1.0) {
        return None;
    }
    let expected = remembered_px
        .filter(|r| (r - radius_px[s]).abs() < 0.1 * radius_px[s])
        .unwrap_or(radius_px[s]);
    let larger = fit.radius - expected;
    (larger > MAY_HOLD_BOTH_PX).then(|| {
        let other_name = ["a", "b"][1 - s];
        let near = apart.map_or(format!("{other_name} not seen apart"), |d| {
            format!("{other_name}'s track {d:.1} px away")
        });
        format!(
            "{}: one silhouette, {near}, and its circle {larger:.2} px larger than the sphere: it may hold both",
            ["a", "b"][s]
        )
    })
}

/// How much larger than its sphere a lone circle over the other sphere's predicted disc may be
/// and still be taken for one sphere, px. A disc's fitted radius strays from its neighbours'
/// by hundredths of a pixel where it is fitted well; seed 105's varied-look recording fitted
/// one circle 0.55 px too large to two discs nearly one behind the other in both views, and its
/// centre came out 3.9 px off (8σ of its σ with the radius's stray in it).
const MAY_HOLD_BOTH_PX: f64 = 0.3;
