//! Per-frame measurement: every view of every frame is segmented, each candidate sphere gets a
//! sub-pixel circle fit, and the measurements are labelled a or b (a has the smaller world x, as
//! the report contract says). What cannot be measured is listed with the reason.

use super::circle::{profile_fit_pair, rings_meet, CircleFit, DotMask, FirstPassDisc};
use super::detect::{find_blobs, levels, Blob, ViewLevels};
use super::geometry::View;
use super::image::GreyImage;
use super::markers::MarkerObs;
use super::report::Unmeasured;
use super::stages::{self, Stage};
use crate::config::Config;
use std::collections::HashMap;

mod ahead;
mod cross;
mod identity;
mod measure;
mod split;
#[cfg(test)]
mod tests;
mod walk;

pub use ahead::FitMemo;
use identity::{
    assign, assign_by_continuity, assign_by_one_track, assign_by_prediction, assign_by_x,
    extrapolate, x_names_both, ViewMemory,
};
use measure::{may_hold_both, measure_blob, measure_touching, BlobFit, Refit};

#[derive(Clone, Debug)]
pub struct Measurement {
    pub centre_px: [f64; 2],
    /// The segmented blob's centroid before refinement (the thesis baseline rounds it).
    pub blob_centroid_px: [f64; 2],
    pub sigma_px: [f64; 2],
    pub diameter_px: f64,
    /// The grey-level fit's edge width s, px (`CircleFit::edge_width_px`); NaN where the disc
    /// was fitted on edge points or typed in.
    pub edge_width_px: f64,
    pub markers: Vec<MarkerObs>,
    /// Fitted where the other sphere hides part of this disc in this view, and how; None for a
    /// disc seen whole. Such a centre's error is more than its fit's σ says (`overlap`).
    pub hidden_in_part: Option<HiddenInPart>,
    /// How far the fitted radius strays from the same sphere's in the frames round it, px
    /// (`radius_misfit`; 0 until it has looked): a misfit of the disc's model, already in
    /// `sigma_px`, and one that neighbouring frames may share.
    pub radius_stray_px: f64,
    /// The part of each axis's σ, px, that the sphere's centres in this view share from frame
    /// to frame (`radius_misfit::widen_against_the_map`: a misfit the look makes alike in every
    /// frame), already in `sigma_px`. It moves a trajectory as a whole, not its velocity, so the
    /// line fits leave it out (`phases::series`).
    pub sigma_common_px: f64,
}

impl Measurement {
    /// Each axis's σ without the part the sphere's centres in this view share
    /// (`sigma_common_px`), px: what one frame's centre scatters by about its flight.
    pub fn own_sigma_px(&self) -> [f64; 2] {
        self.sigma_px
            .map(|sd| (sd * sd - self.sigma_common_px.powi(2)).max(0.0).sqrt())
    }
}

#[cfg(test)]
impl Measurement {
    /// For tests: a whole disc 13.7 px across (hw-sim's default scale) at `centre_px`, σ
    /// 0.02 px, no markers.
    pub(crate) fn test_at(centre_px: [f64; 2]) -> Measurement {
        Measurement {
            centre_px,
            blob_centroid_px: centre_px,
            sigma_px: [0.02, 0.02],
            diameter_px: 13.7,
            edge_width_px: f64::NAN,
            markers: Vec::new(),
            hidden_in_part: None,
            radius_stray_px: 0.0,
            sigma_common_px: 0.0,
        }
    }
}

/// How a disc the other sphere partly hides was measured (`Measurement::hidden_in_part`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HiddenInPart {
    /// The circle through its part of a split silhouette's outline.
    Outline,
    /// The grey-level fit with the front disc hiding the back one (`profile_fit_behind`).
    Crescent,
}

#[derive(Clone, Debug)]
pub struct FrameObs {
    pub index: u64,
    pub frame_id: u64,
    pub time_s: f64,
    /// [sphere a, sphere b][view index] (views in the order of `geometry::views`).
    pub spheres: [Vec<Option<Measurement>>; 2],
    /// Each sphere's 3-D centre, mm, from both views (or one view and the nearest frames where
    /// both saw it): the coordinate a turned view cannot see (`world::place`). None before
    /// placement, and for aligned views, which do not need it.
    pub position_mm: [Option<super::geometry::V3>; 2],
}

/// World x of an image point in a view (both views see x).
fn world_x(view: &View, px: [f64; 2]) -> f64 {
    view.x_mm(px, None).unwrap_or(px[0])
}

/// Markers expected on the rims, by (frame index, view index): the grey-level circle fits leave
/// those pixels out. Empty on the first pass, which is what finds the markers and spins.
pub type DotMasks = HashMap<(usize, usize), Vec<DotMask>>;

/// Each sphere's radius as the first pass's frames round it show it, by (frame index, view
/// index): a blurred disc's fit holds it (`circle::FirstPassDisc`). Empty on the first pass.
pub type FirstPassDiscs = HashMap<(usize, usize), Vec<FirstPassDisc>>;

/// What the second pass measures with that the first did not know: the dots on each rim and
/// each sphere's radius from the frames round it. Empty (`default`) on the first pass.
#[derive(Clone, Debug, Default)]
pub struct SecondPass {
    pub dots: DotMasks,
    pub radii: FirstPassDiscs,
}

impl SecondPass {
    /// The dots of frame `i`'s view `vi`.
    fn dots(&self, i: usize, vi: usize) -> &[DotMask] {
        self.dots.get(&(i, vi)).map(Vec::as_slice).unwrap_or(&[])
    }

    /// The radii held in frame `i`'s view `vi`.
    fn radii(&self, i: usize, vi: usize) -> &[FirstPassDisc] {
        self.radii.get(&(i, vi)).map(Vec::as_slice).unwrap_or(&[])
    }
}

pub use walk::measure_all;
mod held;

/// One frame being measured: its index and time, its pixels, and what it is measured with.
struct FrameCtx<'a> {
    i: usize,
    t: f64,
    img: &'a GreyImage,
    views: &'a [View],
    cfg: &'a Config,
    pass: &'a SecondPass,
    /// Fits made without dot masks (the first pass's, in the second).
    memo: &'a FitMemo,
    /// What was done for this frame ahead, on other threads.
    ahead: &'a ahead::Ahead,
}

impl FrameCtx<'_> {
    /// A blob's fit: done ahead, or kept from the first pass, or done now (None for a merged
    /// blob, which is not fitted).
    #[allow(clippy::too_many_arguments)]
    fn blob_fit(
        &self,
        vi: usize,
        view: &View,
        b: &Blob,
        radius_px: f64,
        other: Option<([f64; 2], f64)>,
        background: f64,
        dots: &[DotMask],
    ) -> Option<BlobFit> {
        if b.merged {
            return None;
        }
        self.ahead.fit(vi, b, radius_px, other).or_else(|| {
            Some(self.memo.fit_blob(
                self.i,
                vi,
                self.img,
                view,
                b,
                radius_px,
                other,
                background,
                dots,
                self.pass.radii(self.i, vi),
            ))
        })
    }
}

/// Each sphere's measurement in each view of one frame.
type Spheres = [Vec<Option<Measurement>>; 2];

/// What tracking remembers from frame to frame: each view's memory of where a and b were, the
/// primary view's recent x of each, and what could not be measured.
struct Tracker {
    memory: Vec<ViewMemory>,
    /// Per view, a run of frames followed by continuity and not yet named (`held`).
    held: Vec<Option<held::Run>>,
    /// Per view, whether this frame's measurements there belong to its held run.
    holding_now: Vec<bool>,
    /// Whether the secondary view named both spheres this frame by the one it followed from
    /// its last frame (`identity::assign_by_one_track`), which the primary's labels are then
    /// checked against (`check_primary_against_secondary`).
    secondary_by_one_track: bool,
    /// Held runs named since: (frame index, view index, [a, b]), for the walk to put in place.
    released: held::Released,
    /// Primary-view world x of each sphere: (time s, x mm), most recent last.
    x_history: [Vec<(f64, f64)>; 2],
    unmeasured: Vec<Unmeasured>,
    max_gap_s: f64,
    max_gap_x_s: f64,
    recent_s: f64,
}

impl Tracker {
    fn new(views: usize, frame_rate_hz: f64) -> Tracker {
        Tracker {
            memory: vec![ViewMemory::default(); views],
            held: (0..views).map(|_| None).collect(),
            holding_now: vec![false; views],
            secondary_by_one_track: false,
            released: Vec::new(),
            x_history: [Vec::new(), Vec::new()],
            unmeasured: Vec::new(),
            // Free flight is a straight line in x and nearly one in the image over a few frames.
            max_gap_s: 15.0 / frame_rate_hz,
            max_gap_x_s: 60.0 / frame_rate_hz,
            // Only recent evidence labels a sphere inside a silhouette of two: x extrapolated
            // over many frames, or a position predicted across the collision's kink, can swap
            // two spheres that pass each other.
            recent_s: 3.0 / frame_rate_hz,
        }
    }

    /// Both spheres in every view of one frame, then what the frame teaches the memory.
    fn measure_frame(&mut self, cx: &FrameCtx) -> Spheres {
        let mut spheres: Spheres = [vec![None; cx.views.len()], vec![None; cx.views.len()]];
        let mut deferred: Option<(Blob, ViewLevels)> = None;
        let mut primary_lone: Option<(Blob, ViewLevels)> = None;
        for (vi, view) in cx.views.iter().enumerate() {
            self.measure_view(cx, vi, view, &mut spheres, &mut deferred, &mut primary_lone);
        }
        // Held measurements name nothing yet: out of the frame while the views are checked
        // against each other, in it while the memory learns where the spheres went.
        let mut provisional = Vec::new();
        for (vi, holding) in self.holding_now.iter_mut().enumerate() {
            if std::mem::take(holding) {
                provisional.push((vi, [spheres[0][vi].take(), spheres[1][vi].take()]));
            }
        }
        if let Some((blob, lv)) = deferred.take() {
            self.label_by_secondary_x(cx, &blob, &lv, &mut spheres);
        }
        self.check_primary_against_secondary(cx, &mut spheres);
        self.secondary_by_one_track = false;
        if let Some((blob, lv)) = primary_lone {
            self.split_primary_by_secondary(cx, &blob, &lv, &mut spheres);
        }
        for (vi, [a, b]) in &mut provisional {
            spheres[0][*vi] = a.take();
            spheres[1][*vi] = b.take();
        }
        self.remember(cx, &spheres);
        for (vi, _) in provisional {
            let name = cx.views[vi].kind.name();
            match (
                spheres[0][vi].take(),
                spheres[1][vi].take(),
                self.held[vi].as_mut(),
            ) {
                (Some(a), Some(b), Some(run)) => run.push((cx.i, [a, b])),
                _ => {
                    if let Some(run) = self.held[vi].take() {
                        held::drop_run(run, name, &mut self.unmeasured);
                    }
                    self.unmeasured.push(Unmeasured {
                        frame: cx.i as u64,
                        view: name.into(),
                        reason: held::UNNAMED.into(),
                    });
                }
            }
        }
        spheres
    }

    /// After the last frame: a run still held is dropped; the named runs, and the reasons
    /// for what was not measured in frame order.
    fn finish(mut self, views: &[View]) -> (held::Released, Vec<Unmeasured>) {
        for (vi, run) in self.held.iter_mut().enumerate() {
            if let Some(run) = run.take() {
                held::drop_run(run, views[vi].kind.name(), &mut self.unmeasured);
            }
        }
        self.unmeasured.sort_by_key(|u| u.frame);
        (self.released, self.unmeasured)
    }

    /// One view of one frame: blobs, their a/b labels (by x from the primary view, continuity,
    /// or position), sub-pixel fits, and the reasons for what could not be measured. A lone
    /// blob the primary view cannot label yet is left in `deferred` for the secondary's x, and
    /// the primary's one silhouette in `primary_lone` (`split_primary_by_secondary`).
    fn measure_view(
        &mut self,
        cx: &FrameCtx,
        vi: usize,
        view: &View,
        spheres: &mut Spheres,
        deferred: &mut Option<(Blob, ViewLevels)>,
        primary_lone: &mut Option<(Blob, ViewLevels)>,
    ) {
        let dots = cx.pass.dots(cx.i, vi);
        let radius = [0, 1].map(|s| cx.cfg.spheres.sphere(s).0 / 2.0 * view.px_per_mm);
        let r_mean = 0.5 * (radius[0] + radius[1]);
        let (lv, blobs) = match cx.ahead.detected(vi) {
            Some(d) => d.clone(),
            None => stages::timed(Stage::Detect, || {
                cx.memo.detection(cx.i, vi, || {
                    let lv = levels(cx.img, view);
                    let blobs = find_blobs(
                        cx.img,
                        view,
                        &lv,
                        r_mean,
                        cx.cfg.analysis.threshold_fraction,
                    );
                    (lv, blobs)
                })
            }),
        };
        // Views after the first take identity from it through the x both views see.
        // Where the primary view does not measure a sphere in this frame, its x is
        // extrapolated from the primary's recent frames (x has no gravity: a straight line).
        let primary_x: [Option<f64>; 2] = if vi > 0 {
            [0, 1].map(|s| {
                spheres[s][0]
                    .as_ref()
                    .map(|m| world_x(&cx.views[0], m.centre_px))
                    .or_else(|| extrapolate(&self.x_history[s], cx.t, self.max_gap_x_s))
            })
        } else {
            [None, None]
        };
        let contact_mm = cx.cfg.spheres.contact_mm();
        // One silhouette holding both spheres in a secondary view (after a collision they
        // can stay one behind the other in the mirror to the end of the recording): each
        // sphere's visible arc is fitted on its own, and labelled by the x the primary view
        // measured, or by where this view last saw each.
        // A held run goes on only while this view sees the two apart.
        if blobs.len() != 2 || blobs.iter().any(|b| b.merged) {
            if let Some(run) = self.held[vi].take() {
                held::drop_run(run, view.kind.name(), &mut self.unmeasured);
            }
        }
        if vi > 0
            && self.measure_split_silhouette(cx, vi, view, &lv, dots, &blobs, primary_x, spheres)
        {
            return;
        }
        // A secondary view the primary cannot help (the spheres are outside the primary's
        // region) keeps identity through lost frames (a sphere clipped by the view's border,
        // a frame not measured) by where each sphere's own track in this view says it is now,
        // when that is unambiguous; up to `TRACK_GAP_FRAMES` frames.
        let by_track = if vi > 0 && primary_x == [None, None] && blobs.len() == 2 {
            let gap_s = TRACK_GAP_FRAMES * self.recent_s / 3.0;
            assign_by_prediction(&blobs, &self.memory[vi], cx.t, gap_s, r_mean)
        } else {
            None
        };
        // A secondary view that followed one sphere into this frame, where the primary lost
        // both since its last frame: by that one's own track (`assign_by_one_track`).
        let by_one_track =
            if vi > 0 && by_track.is_none() && !self.memory[0].both_in_previous && blobs.len() == 2
            {
                assign_by_one_track(&blobs, &self.memory[vi], cx.t, 0.5 * self.recent_s, r_mean)
            } else {
                None
            };
        self.secondary_by_one_track |= by_one_track.is_some();
        let mut assigned = match primary_x {
            _ if by_track.is_some() => by_track.unwrap_or([None, None]),
            _ if by_one_track.is_some() => by_one_track.unwrap_or([None, None]),
            // Closer in x than a diameter, one may hide the other in this view: a single
            // blob is then both, partly, and neither centre can be trusted.
            [Some(xa), Some(xb)] if (xa - xb).abs() < contact_mm && blobs.len() < 2 => {
                if !blobs.is_empty() {
                    self.unmeasured.push(Unmeasured {
                        frame: cx.i as u64,
                        view: view.kind.name().into(),
                        reason: "a, b: one hides the other in this view".into(),
                    });
                }
                [None, None]
            }
            _ if self.memory[vi].both_in_previous && blobs.len() == 2 => {
                assign_by_continuity(&blobs, &self.memory[vi])
            }
            // A secondary view with nothing from the primary and no continuity of its own
            // cannot tell a from b once they have been seen together: its projection of the
            // contact normal does not keep its sign through a grazing pass.
            // Two apart: followed by continuity from here, held until the primary names them
            // (`held`).
            [None, None]
                if vi > 0
                    && self.memory[vi].a_to_b.is_some()
                    && blobs.len() == 2
                    && !blobs.iter().any(|b| b.merged) =>
            {
                self.held[vi] = Some(Vec::new());
                assign(&blobs, view, &self.memory[vi], cx.t, self.max_gap_s)
            }
            [None, None] if vi > 0 && self.memory[vi].a_to_b.is_some() => {
                if !blobs.is_empty() {
                    self.unmeasured.push(Unmeasured {
                        frame: cx.i as u64,
                        view: view.kind.name().into(),
                        reason:
                            "identity of a and b unknown in this view (the primary view lost both)"
                                .into(),
                    });
                }
                [None, None]
            }
            [None, None] => assign(&blobs, view, &self.memory[vi], cx.t, self.max_gap_s),
            // Two apart in this view where the primary's x cannot tell them (they pass each
            // other in x, out of the primary's plane, and just lost continuity here touching):
            // by the side each was on here, which this view's projection of the contact
            // normal keeps. (x named them by chance, and the primary's labels, set by the
            // side each was on in a view where they overlapped, then went unchecked: a and b
            // swapped after the impact and no impact found.)
            [Some(xa), Some(xb)]
                if vi > 0
                    && self.memory[vi].a_to_b.is_some()
                    && blobs.len() == 2
                    && !blobs.iter().any(|b| b.merged)
                    && !x_names_both(&blobs, view, [xa, xb]) =>
            {
                assign(&blobs, view, &self.memory[vi], cx.t, self.max_gap_s)
            }
            x => assign_by_x(&blobs, view, x, contact_mm),
        };
        // A held run is named by the first frame whose primary x names a sphere; until then
        // this frame's measurements are held too.
        if self.held[vi].is_some() {
            let by_x = if primary_x == [None, None] {
                [None, None]
            } else {
                assign_by_x(&blobs, view, primary_x, contact_mm)
            };
            match held::named_by_x(assigned, by_x) {
                Some(swap) => {
                    if let Some(run) = self.held[vi].take() {
                        held::release(run, vi, swap, &mut self.released);
                    }
                    if swap {
                        held::swap_memory(&mut self.memory[vi]);
                        assigned.swap(0, 1);
                    }
                }
                None => self.holding_now[vi] = true,
            }
        }
        // Two spheres touching in the primary view are one silhouette, in the frames that
        // fix the contact best. Where this view saw both in the last frames, each is fitted
        // from where they were heading, with the other's side left out (then both together,
        // below, where their rings meet).
        let mut touching = false;
        let mut fitted: [Option<CircleFit>; 2] = [None, None];
        if vi == 0 && blobs.len() == 1 && blobs[0].merged && self.memory[vi].both_in_previous {
            let t = cx.t;
            let predicted = [0, 1].map(|s| self.memory[vi].predict(s, t, self.recent_s));
            if let [Some(pa), Some(pb)] = predicted {
                if let Some(pair) =
                    measure_touching(cx.img, view, &blobs[0], [pa, pb], radius, &lv, cx.cfg, dots)
                {
                    for (s, (m, f)) in pair.into_iter().enumerate() {
                        fitted[s] = Some(f);
                        spheres[s][vi] = Some(m);
                        self.memory[vi].last[s] = Some(f.centre);
                        self.memory[vi].radius[s] = Some(f.radius);
                        self.memory[vi].history[s].push((t, f.centre));
                    }
                    touching = true;
                }
            }
        }
        if let [only] = blobs.as_slice() {
            let reason = if touching {
                None
            } else if only.merged {
                Some("a, b: silhouettes merged")
            } else if assigned.iter().all(|a| a.is_none()) && vi > 0 {
                Some("one sphere seen and no earlier frame to tell whether it is a or b")
            } else {
                None
            };
            if let Some(reason) = reason {
                self.unmeasured.push(Unmeasured {
                    frame: cx.i as u64,
                    view: view.kind.name().into(),
                    reason: reason.into(),
                });
            }
        }
        // The primary view's first frames with one sphere only: which one it is, the
        // secondary view (processed next) can tell by x.
        if vi == 0 && blobs.len() == 1 && !blobs[0].merged && assigned.iter().all(|x| x.is_none()) {
            *deferred = Some((blobs[0].clone(), lv));
        }
        if vi == 0 && blobs.len() == 1 && !touching {
            *primary_lone = Some((blobs[0].clone(), lv));
        }
        for (s, blob) in assigned.iter().enumerate() {
            let Some(b) = blob else { continue };
            let other = assigned[1 - s].map(|o| (o.centroid, radius[1 - s]));
            let mut fit = cx.blob_fit(vi, view, b, radius[s], other, lv.background, dots);
            let predicted = [0, 1].map(|k| self.memory[vi].predict(k, cx.t, self.recent_s));
            if let Some(first) = fit {
                let refit = Refit {
                    img: cx.img,
                    view,
                    s,
                    blob: b,
                    other_blob: assigned[1 - s],
                    predicted,
                    radius,
                    lv: &lv,
                    dots,
                };
                let remembered_px = self.memory[vi].radius[s];
                fit = Some(stages::timed(Stage::Circles, || {
                    refit.again(first, remembered_px)
                }));
            }
            let held = cx.pass.radii(cx.i, vi);
            let measured = measure_blob(
                cx.img, view, b, s, radius[s], other, &lv, cx.cfg, dots, held, fit,
            )
            .and_then(|(m, f)| {
                let other = (assigned[1 - s].is_none())
                    .then(|| self.memory[vi].predict(1 - s, cx.t, self.recent_s));
                match may_hold_both(s, &f, radius, other, self.memory[vi].radius[s]) {
                    Some(reason) => Err(reason),
                    None => Ok((m, f)),
                }
            });
            match measured {
                Ok((m, f)) => {
                    fitted[s] = Some(f);
                    spheres[s][vi] = Some(m);
                    self.memory[vi].last[s] = Some(f.centre);
                    self.memory[vi].radius[s] = Some(f.radius);
                    self.memory[vi].history[s].push((cx.t, f.centre));
                }
                Err(reason) => self.unmeasured.push(Unmeasured {
                    frame: cx.i as u64,
                    view: view.kind.name().into(),
                    reason,
                }),
            }
        }
        if let [Some(fa), Some(fb)] = &fitted {
            if rings_meet(fa, fb) {
                let radii = cx.pass.radii(cx.i, vi);
                let held = [fa, fb].map(|f| FirstPassDisc::near(radii, f.centre));
                let pair = stages::timed(Stage::Circles, || {
                    profile_fit_pair(
                        cx.img,
                        view,
                        [fa, fb],
                        lv.background,
                        dots,
                        held,
                        cx.memo.is_final(),
                    )
                });
                if let Some(pair) = pair {
                    for (s, f) in pair.iter().enumerate() {
                        if let Some(m) = spheres[s][vi].as_mut() {
                            m.centre_px = f.centre;
                            m.sigma_px = f.centre_sigma;
                            m.diameter_px = 2.0 * f.radius;
                        }
                        self.memory[vi].last[s] = Some(f.centre);
                        self.memory[vi].radius[s] = Some(f.radius);
                        if let Some(h) = self.memory[vi].history[s].last_mut() {
                            h.1 = f.centre;
                        }
                    }
                }
            }
        }
        if blobs.len() > 2 {
            self.unmeasured.push(Unmeasured {
                frame: cx.i as u64,
                view: view.kind.name().into(),
                reason: format!(
                    "{} bright blobs, expected at most 2; the two largest were used",
                    blobs.len()
                ),
            });
        }
    }

    /// The frame's measurements into the memory: the primary view's x of each sphere, and per
    /// view whether both were seen and the direction from a to b.
    fn remember(&mut self, cx: &FrameCtx, spheres: &Spheres) {
        for (s, hist) in self.x_history.iter_mut().enumerate() {
            if let (Some(m), Some(view)) = (&spheres[s][0], cx.views.first()) {
                hist.push((cx.t, world_x(view, m.centre_px)));
            }
        }
        for (vi, mem) in self.memory.iter_mut().enumerate() {
            mem.both_in_previous = spheres[0][vi].is_some() && spheres[1][vi].is_some();
            if let (Some(a), Some(b)) = (&spheres[0][vi], &spheres[1][vi]) {
                let (du, dv) = (
                    b.centre_px[0] - a.centre_px[0],
                    b.centre_px[1] - a.centre_px[1],
                );
                let n = du.hypot(dv);
                if n > 0.0 {
                    mem.a_to_b = Some([du / n, dv / n]);
                }
            }
        }
    }
}

/// How many frames a secondary view's own tracks carry identity without a measurement
/// (`identity::assign_by_prediction`, which also asks that the labelling be unambiguous).
const TRACK_GAP_FRAMES: f64 = 20.0;
