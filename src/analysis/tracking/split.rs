//! One silhouette holding both spheres in one view while the other view tells them apart: split
//! into two circles on the outline, labelled by the x the other view measured (or this view's
//! own memory), and refitted on the grey levels with the front disc hiding the back one where
//! the other view says which of them is nearer this view's camera.
//!
//! In a secondary view this is the mirror after an oblique impact. In the primary view it is an
//! impact whose normal lies along the direct camera's axis: after it the spheres separate
//! towards and away from the camera, one partly hiding the other in the direct view for the
//! rest of the recording, while the mirror sees them apart. Only the direct view measures y, so
//! without the split that whole phase had no y, and the spins could not be checked (an
//! independent render, validation v03, gave 2-D results and no spin).

use super::identity::{extrapolate, label_split};
use super::{world_x, FrameCtx, HiddenInPart, Measurement, Spheres, Tracker};
use crate::analysis::circle::{
    profile_fit_behind, split_pair, CircleFit, DotMask, BEHIND_REACH_PX,
};
use crate::analysis::detect::{Blob, ViewLevels};
use crate::analysis::geometry::{View, V3};
use crate::analysis::image::GreyImage;
use crate::analysis::markers;
use crate::analysis::report::Unmeasured;
use crate::analysis::stages::{self, Stage};

/// What the other view says about the two spheres in this frame: each one's world x (to label
/// the split circles) and its depth along this view's line of sight, larger nearer this view's
/// camera (to say which disc is in front).
struct FromOtherView {
    x_mm: [Option<f64>; 2],
    depth_mm: [Option<f64>; 2],
    /// Each sphere's world point as the other view places it (the coordinate that view cannot
    /// see taken as 0), mm: where this view's scale is taken for its image radius.
    at_mm: [Option<V3>; 2],
}

impl Tracker {
    /// A secondary view whose one silhouette holds both spheres: split, labelled by the primary
    /// view's x or this view's memory, the front disc as the primary places them along this
    /// view's line of sight. Whether it handled the view (else the view is measured blob by
    /// blob).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn measure_split_silhouette(
        &mut self,
        cx: &FrameCtx,
        vi: usize,
        view: &View,
        lv: &ViewLevels,
        dots: &[DotMask],
        blobs: &[Blob],
        primary_x: [Option<f64>; 2],
        spheres: &mut Spheres,
    ) -> bool {
        let [blob] = blobs else { return false };
        if vi == 0 || blob.clipped {
            return false;
        }
        let contact_mm = cx.cfg.spheres.contact_mm();
        let close = matches!(primary_x, [Some(xa), Some(xb)] if (xa - xb).abs() < contact_mm);
        if !(blob.merged || close) {
            return false;
        }
        let other = FromOtherView {
            x_mm: [0, 1].map(|s| {
                spheres[s][0]
                    .as_ref()
                    .map(|m| world_x(&cx.views[0], m.centre_px))
                    .or_else(|| extrapolate(&self.x_history[s], cx.t, self.recent_s))
            }),
            depth_mm: depths(cx, spheres, 0, view),
            at_mm: placed(cx, spheres, 0),
        };
        self.split_silhouette(cx, vi, view, lv, dots, blob, &other, spheres)
    }

    /// The primary view's one silhouette, after the secondary views were measured, where the
    /// primary measured neither sphere in it (it was merged, or a circle fitted to it was
    /// dropped as maybe holding both: `check_primary_against_secondary`) and the secondary
    /// measured both, closer in x than they are wide or with the silhouette merged. The
    /// reasons given for not measuring the primary in this frame are withdrawn where the split
    /// names a sphere.
    pub(super) fn split_primary_by_secondary(
        &mut self,
        cx: &FrameCtx,
        blob: &Blob,
        lv: &ViewLevels,
        spheres: &mut Spheres,
    ) {
        let Some(oi) = (1..cx.views.len()).find(|&vj| spheres.iter().all(|s| s[vj].is_some()))
        else {
            return;
        };
        if blob.clipped || spheres.iter().any(|s| s[0].is_some()) {
            return;
        }
        let view = &cx.views[0];
        let x_mm = [0, 1].map(|s| {
            spheres[s][oi]
                .as_ref()
                .map(|m| world_x(&cx.views[oi], m.centre_px))
        });
        let contact_mm = cx.cfg.spheres.contact_mm();
        let close = matches!(x_mm, [Some(xa), Some(xb)] if (xa - xb).abs() < contact_mm);
        if !(blob.merged || close) {
            return;
        }
        let other = FromOtherView {
            x_mm,
            depth_mm: depths(cx, spheres, oi, view),
            at_mm: placed(cx, spheres, oi),
        };
        let dots = cx.pass.dots(cx.i, 0);
        let before = self.unmeasured.len();
        if self.split_silhouette(cx, 0, view, lv, dots, blob, &other, spheres) {
            let own = self.unmeasured.split_off(before);
            let (frame, name) = (cx.i as u64, view.kind.name());
            self.unmeasured
                .retain(|u| !(u.frame == frame && u.view == name));
            self.unmeasured.extend(own);
        }
    }

    /// Splits view `vi`'s one silhouette into two circles and labels them with what the other
    /// view says; each labelled circle is measured (the front one with its dots), the other
    /// listed as hidden. Whether any circle was labelled.
    #[allow(clippy::too_many_arguments)]
    fn split_silhouette(
        &mut self,
        cx: &FrameCtx,
        vi: usize,
        view: &View,
        lv: &ViewLevels,
        dots: &[DotMask],
        blob: &Blob,
        other: &FromOtherView,
        spheres: &mut Spheres,
    ) -> bool {
        let t = cx.t;
        let contact_mm = cx.cfg.spheres.contact_mm();
        // Each sphere's image radius where the other view places it: under a pinhole the one
        // nearer the camera images larger, and the crescent's fit holds the radii's ratio (an
        // independent render seen from 300 mm, its spheres 37 mm apart in depth: the back disc
        // held at the front one's radius, 13.3 px for 11.8, came out 0.8 px off, at 2.9σ).
        let radius = match other.at_mm {
            [Some(pa), Some(pb)] => [(0, pa), (1, pb)]
                .map(|(s, p)| cx.cfg.spheres.sphere(s).0 / 2.0 * view.px_per_mm_at(&p)),
            _ => [0, 1].map(|s| cx.cfg.spheres.sphere(s).0 / 2.0 * view.px_per_mm),
        };
        let r_mean = 0.5 * (radius[0] + radius[1]);
        let r_seen: Vec<f64> = self.memory[vi].radius.iter().flatten().copied().collect();
        let r_fit = if r_seen.is_empty() {
            r_mean
        } else {
            r_seen.iter().sum::<f64>() / r_seen.len() as f64
        };
        let fits = stages::timed(Stage::Circles, || {
            split_pair(cx.img, view, blob.centroid, r_fit, lv.background, lv.peak)
        });
        let predicted = [0, 1].map(|s| self.memory[vi].predict(s, t, self.recent_s));
        let labels = label_split(&fits, view, other.x_mm, predicted, r_mean);
        // The sphere nearer this view's camera: all of its disc is its own, so its dots are its
        // own too. The other's dots near the overlap may be either.
        let front = match other.depth_mm {
            [Some(da), Some(db)] if (da - db).abs() > 0.5 * contact_mm => {
                Some(if da > db { 0 } else { 1 })
            }
            _ => None,
        };
        // Starts for the grey-level refit, tried in turn until one holds: the split's circles;
        // then, in the primary view only, where the view's own tracks put the discs (if those
        // agree with the other view's x on which is which), and where the other view's x and
        // the silhouette's own extent put them (`starts_from_x`). Why the primary: there the
        // frames without a split have no y at all; on a side-lit sphere the outline misses the
        // dark limb, so the split gives no two circles (every other frame of a side-lit hw-sim
        // recording) or circles 1.3 px towards the lamp, beyond what the refit may move (a
        // synthetic pair lit from 30°, `tracking::tests`). In a secondary view the frames it
        // misses cost only some of its z, and fits from tracks there (the mirror, before and
        // after oblique impacts) put velocities off by up to 6 % at 5σ on the bench's varied
        // looks.
        let mut starts: Vec<[CircleFit; 2]> = Vec::new();
        if let [Some(fa), Some(fb)] = labels {
            starts.push([*fa, *fb]);
        }
        if vi == 0 && front.is_some() {
            let r = [0, 1].map(|k| self.memory[vi].radius[k].unwrap_or(r_fit));
            if let [Some(pa), Some(pb)] = predicted {
                let from_tracks = [CircleFit::start_at(pa, r[0]), CircleFit::start_at(pb, r[1])];
                let named = label_split(&from_tracks, view, other.x_mm, [None, None], r_mean);
                if matches!(named, [Some(a), Some(b)]
                    if std::ptr::eq(a, &from_tracks[0]) && std::ptr::eq(b, &from_tracks[1]))
                {
                    starts.push(from_tracks);
                }
            }
            if let [Some(xa), Some(xb)] = other.x_mm {
                starts.extend(starts_from_x(cx.img, view, blob, lv, [xa, xb], r));
            }
        }
        // With the front one known, both discs are refitted on the grey levels, the front disc
        // hiding the back one. A refit that moves a disc by more than a pixel from its start
        // is kept only where a fit tried again from there stays (`MAX_REFIT_MOVE_PX`).
        let behind = front.and_then(|fr| {
            starts.iter().find_map(|[fa, fb]| {
                stages::timed(Stage::Circles, || {
                    profile_fit_behind(cx.img, view, [fa, fb], fr, radius, lv.background, dots)
                })
                .filter(|pair| {
                    pair.iter().zip([fa, fb]).all(|(n, o)| {
                        (n.centre[0] - o.centre[0]).hypot(n.centre[1] - o.centre[1])
                            < MAX_REFIT_MOVE_PX
                    })
                })
            })
        });
        if labels.iter().all(|l| l.is_none()) && behind.is_none() {
            return false;
        }
        let labels: [Option<&CircleFit>; 2] = match &behind {
            Some(pair) => [Some(&pair[0]), Some(&pair[1])],
            None => labels,
        };
        for (s, f) in labels.iter().enumerate() {
            match f {
                Some(f) => {
                    let dots = if front == Some(s) {
                        stages::timed(Stage::Markers, || {
                            markers::find(
                                cx.img,
                                view,
                                f,
                                cx.cfg.spheres.sphere(s).0 / 2.0,
                                cx.cfg.analysis.marker_diameter_mm,
                                lv.noise_sigma,
                            )
                        })
                    } else {
                        Vec::new()
                    };
                    spheres[s][vi] = Some(Measurement {
                        centre_px: f.centre,
                        // The thesis baseline would click this disc's centre, not the merged
                        // silhouette's.
                        blob_centroid_px: f.centre,
                        sigma_px: f.centre_sigma,
                        diameter_px: 2.0 * f.radius,
                        edge_width_px: f.edge_width_px,
                        markers: dots,
                        hidden_in_part: Some(if behind.is_some() {
                            HiddenInPart::Crescent
                        } else {
                            HiddenInPart::Outline
                        }),
                        radius_stray_px: 0.0,
                        sigma_common_px: 0.0,
                    });
                    self.memory[vi].last[s] = Some(f.centre);
                    self.memory[vi].history[s].push((t, f.centre));
                }
                None => self.unmeasured.push(Unmeasured {
                    frame: cx.i as u64,
                    view: view.kind.name().into(),
                    reason: format!("{}: hidden by the other sphere in this view", ["a", "b"][s]),
                }),
            }
        }
        true
    }
}

/// Starts for the two discs of `view`'s one silhouette from the world x the other view measured:
/// each disc's place along x where its x images in this view, and across x the middle of the
/// silhouette's run over the lines on its far side from the other disc (0.3–0.75 radii out),
/// which the other disc does not reach while they are at least 0.7 radii apart
/// (`profile_fit_behind` needs three quarters). The lines are the image's columns where x
/// images nearer u, its rows where nearer v (a camera mounted on its side, or views side by
/// side: read down the columns, such a view's discs were never apart across them, and an
/// independent render turned by 90° lost the direct view's y for the whole phase after its
/// impact). Each line's run is where it is brighter than halfway between the background and its
/// own brightest pixel, so a lamp's shading or a highlight moves it little. None where the discs
/// are less than 0.7 radii apart along that axis (their lines shared: on a hw-sim rig such
/// starts gave crescents 2.5–8 px off), or a disc has fewer than two such lines whose run is at
/// least a radius long.
pub(super) fn starts_from_x(
    img: &GreyImage,
    view: &View,
    blob: &Blob,
    lv: &ViewLevels,
    x_mm: [f64; 2],
    radius_px: [f64; 2],
) -> Option<[CircleFit; 2]> {
    let base = view.solve(blob.centroid, None);
    let at_x = |x: f64| {
        let mut p = base;
        p.x = x;
        view.project(&p)
    };
    let centres = [at_x(x_mm[0]), at_x(x_mm[1])];
    // The image axis x runs nearer (`along`: 0 for u, 1 for v); the lines run across it.
    let gap = [0, 1].map(|k| centres[1][k] - centres[0][k]);
    let along = if gap[0].abs() >= gap[1].abs() { 0 } else { 1 };
    let across = 1 - along;
    let size = [img.width, img.height];
    // Discs less than 0.7 radii apart along it share their lines: no far side to read.
    if gap[along].abs() < 0.7 * radius_px[0].max(radius_px[1]) {
        return None;
    }
    // `extent_px` is [u0, v0, u1, v1].
    let (first_px, last_px) = (blob.extent_px[across], blob.extent_px[across + 2]);
    let span = first_px.saturating_sub(2)..(last_px + 3).min(size[across]);
    // The pixel at `a` along and `c` across.
    let pixel = |a: usize, c: usize| {
        if along == 0 {
            img.at(a, c)
        } else {
            img.at(c, a)
        }
    };
    let mid_of = |s: usize| -> Option<f64> {
        let (a_s, r) = (centres[s][along], radius_px[s]);
        let away = if a_s < centres[1 - s][along] {
            -1.0
        } else {
            1.0
        };
        let mut mids: Vec<f64> = Vec::new();
        for k in 1..=4 {
            let a = (a_s + away * r * (0.15 + 0.15 * k as f64)).round();
            let mut probe = blob.centroid;
            probe[along] = a;
            if a < 0.0 || a >= size[along] as f64 || !view.contains(probe[0], probe[1]) {
                continue;
            }
            let line: Vec<(usize, f64)> = span
                .clone()
                .map(|c| (c, pixel(a as usize, c) as f64))
                .collect();
            let top = line.iter().map(|c| c.1).fold(f64::MIN, f64::max);
            let level = lv.background + 0.5 * (top - lv.background);
            if top <= lv.background + 3.0 * lv.noise_sigma {
                continue;
            }
            // The run's ends, each interpolated between the pixels either side of `level`.
            let first = line.iter().position(|c| c.1 >= level)?;
            let last = line.len() - 1 - line.iter().rev().position(|c| c.1 >= level)?;
            let cross = |i: usize, j: usize| {
                let (a, b) = (line[i], line[j]);
                a.0 as f64 + (level - a.1) / (b.1 - a.1) * (b.0 as f64 - a.0 as f64)
            };
            let start = if first > 0 {
                cross(first - 1, first)
            } else {
                line[0].0 as f64
            };
            let end = if last + 1 < line.len() {
                cross(last, last + 1)
            } else {
                line[last].0 as f64
            };
            if end - start >= r {
                mids.push(0.5 * (start + end));
            }
        }
        if mids.len() < 2 {
            return None;
        }
        mids.sort_by(f64::total_cmp);
        Some(0.5 * (mids[(mids.len() - 1) / 2] + mids[mids.len() / 2]))
    };
    let at = |s: usize, mid: f64| {
        let mut c = centres[s];
        c[across] = mid;
        CircleFit::start_at(c, radius_px[s])
    };
    let (mid_a, mid_b) = (mid_of(0)?, mid_of(1)?);
    Some([at(0, mid_a), at(1, mid_b)])
}

/// Each sphere's world point as view `oi` measured it in this frame, mm, the coordinate that view
/// cannot see taken as 0.
fn placed(cx: &FrameCtx, spheres: &Spheres, oi: usize) -> [Option<V3>; 2] {
    [0, 1].map(|s| {
        let m = spheres[s][oi].as_ref()?;
        Some(cx.views[oi].solve(m.centre_px, None))
    })
}

/// Each sphere's depth along `view`'s line of sight as view `oi` measured it in this frame,
/// larger nearer `view`'s camera; None where `oi` did not measure it or does not see that axis.
fn depths(cx: &FrameCtx, spheres: &Spheres, oi: usize, view: &View) -> [Option<f64>; 2] {
    let fi = view.facing.iamax();
    [0, 1].map(|s| {
        let m = spheres[s][oi].as_ref()?;
        cx.views[oi]
            .unproject(m.centre_px, None)
            .iter()
            .find(|(axis, _)| *axis == fi)
            .map(|(_, x)| x * view.facing[fi])
    })
}

/// How far the grey-level refit of a split silhouette may move a disc from the split's own
/// circle and still be taken, px (`circle::profile_fit_behind`): a pixel, as for any grey-level
/// fit from its start. It was a fifth, on the belief that the outline split is right to
/// hundredths; under a side light or shading it is 0.4–0.7 px off, so the refit that corrects
/// it was thrown away. Same 38 varied-look recordings, 0.2 → 1 px: centre RMS 0.0759 → 0.0703
/// px (paint 0.039 → 0.029), e's p95 0.034 → 0.019, ψ2's p95 0.075 → 0.039; the independent
/// renders unchanged. Beyond a pixel, where the fit tried again from where it went stays there
/// (`circle::BEHIND_REACH_PX`, session 53: a silhouette's extent under a lamp 35° off the axis
/// put the starts 0.8–1.3 px off).
const MAX_REFIT_MOVE_PX: f64 = BEHIND_REACH_PX;
