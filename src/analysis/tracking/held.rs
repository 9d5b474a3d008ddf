//! A secondary view's measurements held back until the spheres can be named. Where the primary
//! view has lost both (spheres just out of their tubes, still at its border) and this view
//! last saw them both long ago, it follows the two by continuity from frame to frame, and the
//! first frame in which the primary view's x names them names the whole run, turned round if
//! need be. A run that breaks first (a frame without both) is dropped, as such frames were
//! before: names taken from the order the spheres were in long ago could be swapped, since
//! spheres that graze pass each other.

use super::identity::ViewMemory;
use super::Measurement;
use crate::analysis::detect::Blob;
use crate::analysis::report::Unmeasured;

/// Why a held run's frames are not measured in a view when it is dropped.
pub(super) const UNNAMED: &str =
    "identity of a and b unknown in this view (the primary view lost both)";

/// One view's run: per frame (index), the two spheres under the run's provisional names.
pub(super) type Run = Vec<(usize, [Measurement; 2])>;

/// Named runs' frames: (frame index, view index, [a, b]).
pub(super) type Released = Vec<(usize, usize, [Measurement; 2])>;

/// How a frame's labels by continuity compare with the labels the primary view's x gives:
/// None where x names neither, or the two disagree about one and agree about the other;
/// Some(false) where they agree, Some(true) where x names them the other way round.
pub(super) fn named_by_x(
    by_continuity: [Option<&Blob>; 2],
    by_x: [Option<&Blob>; 2],
) -> Option<bool> {
    let mut verdict = None;
    for s in 0..2 {
        let Some(x) = by_x[s] else { continue };
        let same = by_continuity[s].is_some_and(|c| std::ptr::eq(c, x));
        let swapped = by_continuity[1 - s].is_some_and(|c| std::ptr::eq(c, x));
        let this = match (same, swapped) {
            (true, false) => false,
            (false, true) => true,
            _ => return None,
        };
        if verdict.is_some_and(|v| v != this) {
            return None;
        }
        verdict = Some(this);
    }
    verdict
}

/// Turns a view's memory of a and b round (a held run named the other way).
pub(super) fn swap_memory(mem: &mut ViewMemory) {
    mem.last.swap(0, 1);
    mem.radius.swap(0, 1);
    mem.history.swap(0, 1);
    mem.a_to_b = mem.a_to_b.map(|d| [-d[0], -d[1]]);
}

/// A named run's frames, into (frame index, view index, [a, b]).
pub(super) fn release(run: Run, vi: usize, swap: bool, out: &mut Released) {
    for (i, [p, q]) in run {
        out.push((i, vi, if swap { [q, p] } else { [p, q] }));
    }
}

/// A run that could not be named: each of its frames is unmeasured in the view.
pub(super) fn drop_run(run: Run, view: &str, unmeasured: &mut Vec<Unmeasured>) {
    for (i, _) in run {
        unmeasured.push(Unmeasured {
            frame: i as u64,
            view: view.into(),
            reason: UNNAMED.into(),
        });
    }
}
