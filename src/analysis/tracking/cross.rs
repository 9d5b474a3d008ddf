//! The views checked against each other within a frame: both measure world x, so the
//! secondary view names the primary's lone sphere, drops a primary circle that may hold both
//! spheres (unless the other sphere's track has taken it beyond the primary view's border),
//! and turns the primary's labels round where they came out crossed.

use super::identity::assign_by_x;
use super::measure::measure_blob;
use super::{world_x, FrameCtx, Spheres, Tracker, TRACK_GAP_FRAMES};
use crate::analysis::detect::{Blob, ViewLevels};
use crate::analysis::report::Unmeasured;

impl Tracker {
    /// Both views measure world x. Where the primary view labelled a and b without continuity
    /// (after frames where their silhouettes merged: a contact normal out of its plane) and the
    /// secondary view carried both through those frames, the secondary is right: if swapping
    /// the primary's labels makes the two views' x agree several times better, they are
    /// swapped. Spheres that graze past each other in one view were otherwise labelled by the
    /// side each was on before, and the trajectories came out crossed. And in any frame, one
    /// circle in the primary view where the secondary sees both closer in x than they are wide
    /// is dropped (it may hold both: an independent render's frame at contact put it 6.6 px
    /// from either sphere).
    pub(super) fn check_primary_against_secondary(&mut self, cx: &FrameCtx, spheres: &mut Spheres) {
        if cx.views.len() < 2 {
            return;
        }
        let x = |vi: usize, s: usize| {
            spheres[s][vi]
                .as_ref()
                .map(|m| world_x(&cx.views[vi], m.centre_px))
        };
        let (Some(sa), Some(sb)) = (x(1, 0), x(1, 1)) else {
            return;
        };
        // One circle in the primary view where the secondary sees both closer in x than they
        // are wide: the primary's silhouette may hold both, one partly hiding the other, and a
        // circle fitted to it sits between them. It is not a measurement of either.
        let contact_mm = cx.cfg.spheres.contact_mm();
        if x(0, 0).is_some() != x(0, 1).is_some() {
            // Unless the other sphere's own track in the primary view has taken it wholly
            // beyond the view's border: then the circle holds one sphere. Why: spheres one above
            // the other in the direct view, the lower leaving its region, lost the upper's
            // circles for a dozen frames because the mirror view saw both close in x. (Only
            // beyond the border: a track extrapolated across the impact that merely put the
            // other sphere a few radii away was wrong on an independent render, and that
            // recording lost its result.)
            let gap_s = TRACK_GAP_FRAMES * self.recent_s / 3.0;
            let primary = &cx.views[0];
            let gone = |s: usize| {
                let r = primary.px_per_mm * cx.cfg.spheres.sphere(s).0 / 2.0;
                self.memory[0].predict(s, cx.t, gap_s).is_some_and(|q| {
                    [(-r, 0.0), (r, 0.0), (0.0, -r), (0.0, r)]
                        .iter()
                        .all(|(du, dv)| !primary.contains(q[0] + du, q[1] + dv))
                        && !primary.contains(q[0], q[1])
                })
            };
            let one_sphere = (0..2).any(|s| spheres[s][0].is_some() && gone(1 - s));
            if (sa - sb).abs() < contact_mm && !one_sphere {
                for s in 0..2 {
                    if spheres[s][0].take().is_some() {
                        // Nor is it where this sphere was.
                        let mem = &mut self.memory[0];
                        if mem.history[s].last().is_some_and(|e| e.0 == cx.t) {
                            mem.history[s].pop();
                        }
                        mem.last[s] = mem.history[s].last().map(|e| e.1);
                        self.unmeasured.push(Unmeasured {
                            frame: cx.i as u64,
                            view: cx.views[0].kind.name().into(),
                            reason: format!(
                                "{}: one silhouette where the {} view sees both {:.2} mm apart in x: they may overlap here",
                                ["a", "b"][s],
                                cx.views[1].kind.name(),
                                (sa - sb).abs()
                            ),
                        });
                    }
                }
            }
            return;
        }
        if self.memory[0].both_in_previous
            || !(self.memory[1].both_in_previous || self.secondary_by_one_track)
        {
            return;
        }
        let (Some(pa), Some(pb)) = (x(0, 0), x(0, 1)) else {
            return;
        };
        let straight = (pa - sa).abs() + (pb - sb).abs();
        let swapped = (pa - sb).abs() + (pb - sa).abs();
        if swapped * 3.0 >= straight {
            return;
        }
        let (first, rest) = spheres.split_at_mut(1);
        std::mem::swap(&mut first[0][0], &mut rest[0][0]);
        let mem = &mut self.memory[0];
        mem.last.swap(0, 1);
        mem.radius.swap(0, 1);
        let t = cx.t;
        let (h0, h1) = mem.history.split_at_mut(1);
        if let (Some(e0), Some(e1)) = (h0[0].last_mut(), h1[0].last_mut()) {
            if e0.0 == t && e1.0 == t {
                std::mem::swap(e0, e1);
            }
        }
    }

    /// The primary view's lone sphere, labelled by the x the secondary view measured in the
    /// same frame.
    pub(super) fn label_by_secondary_x(
        &mut self,
        cx: &FrameCtx,
        blob: &Blob,
        lv: &ViewLevels,
        spheres: &mut Spheres,
    ) {
        let view = &cx.views[0];
        let dots0 = cx.pass.dots(cx.i, 0);
        let radius = [0, 1].map(|s| cx.cfg.spheres.sphere(s).0 / 2.0 * view.px_per_mm);
        let contact_mm = cx.cfg.spheres.contact_mm();
        // x of a and b as the secondary view measured them in this frame; a sphere it
        // did not measure matches nothing.
        let x = [0, 1].map(|s| {
            (1..cx.views.len()).find_map(|vj| {
                spheres[s][vj]
                    .as_ref()
                    .map(|m| world_x(&cx.views[vj], m.centre_px))
            })
        });
        let both = x[0]
            .zip(x[1])
            .is_some_and(|(xa, xb)| (xa - xb).abs() > contact_mm);
        let labels = if both {
            assign_by_x(std::slice::from_ref(blob), view, x, contact_mm)
        } else {
            [None, None]
        };
        match labels.iter().position(|l| l.is_some()) {
            Some(s) => match measure_blob(
                cx.img,
                view,
                blob,
                s,
                radius[s],
                None,
                lv,
                cx.cfg,
                dots0,
                cx.pass.radii(cx.i, 0),
                cx.blob_fit(0, view, blob, radius[s], None, lv.background, dots0),
            ) {
                Ok((m, f)) => {
                    spheres[s][0] = Some(m);
                    self.memory[0].last[s] = Some(f.centre);
                    self.memory[0].radius[s] = Some(f.radius);
                    self.memory[0].history[s].push((cx.t, f.centre));
                }
                Err(reason) => self.unmeasured.push(Unmeasured {
                    frame: cx.i as u64,
                    view: view.kind.name().into(),
                    reason,
                }),
            },
            None => self.unmeasured.push(Unmeasured {
                frame: cx.i as u64,
                view: view.kind.name().into(),
                reason: "one sphere seen and no earlier frame, nor the other view, tells whether it is a or b".into(),
            }),
        }
    }
}
