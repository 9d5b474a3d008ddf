//! Which sphere is a and which b in a view: by the x the primary view measured, by continuity
//! with the last frames, by position, and inside a split silhouette; and each view's memory of
//! where a and b were.

use super::world_x;
use crate::analysis::circle::CircleFit;
use crate::analysis::detect::Blob;
use crate::analysis::geometry::View;

/// Labels the circles found in one silhouette holding both spheres: by the positions this view
/// predicts from its own last frames, when those tell them apart by more than half a radius;
/// else by world x against the x the primary view measured for a and b, when that tells them
/// apart by more than 0.3 mm (fifteen times the x error of either). Otherwise neither.
pub(super) fn label_split<'a>(
    fits: &'a [CircleFit],
    view: &View,
    x: [Option<f64>; 2],
    predicted: [Option<[f64; 2]>; 2],
    radius_px: f64,
) -> [Option<&'a CircleFit>; 2] {
    let by_x = |f: &CircleFit, s: usize| x[s].map(|xs| (world_x(view, f.centre) - xs).abs());
    let by_px = |f: &CircleFit, s: usize| {
        predicted[s].map(|p| (f.centre[0] - p[0]).hypot(f.centre[1] - p[1]))
    };
    let decide =
        |straight: Option<f64>, swapped: Option<f64>, margin: f64| match (straight, swapped) {
            (Some(a), Some(b)) if (a - b).abs() > margin => Some(a < b),
            _ => None,
        };
    match fits {
        [p, q] => {
            let sum = |c: &dyn Fn(&CircleFit, usize) -> Option<f64>,
                       f0: &CircleFit,
                       f1: &CircleFit| { Some(c(f0, 0)? + c(f1, 1)?) };
            let straight_first = decide(sum(&by_px, p, q), sum(&by_px, q, p), 0.5 * radius_px)
                .or_else(|| decide(sum(&by_x, p, q), sum(&by_x, q, p), X_MARGIN_MM));
            match straight_first {
                Some(true) => [Some(p), Some(q)],
                Some(false) => [Some(q), Some(p)],
                None => [None, None],
            }
        }
        [p] => {
            let is_a = decide(by_px(p, 0), by_px(p, 1), 0.5 * radius_px)
                .or_else(|| decide(by_x(p, 0), by_x(p, 1), X_MARGIN_MM));
            match is_a {
                Some(true) => [Some(p), None],
                Some(false) => [None, Some(p)],
                None => [None, None],
            }
        }
        _ => [None, None],
    }
}

/// x at time t on the line through the last (up to) three points, if the last is recent.
pub(super) fn extrapolate(history: &[(f64, f64)], t: f64, max_gap_s: f64) -> Option<f64> {
    let recent = &history[history.len().saturating_sub(3)..];
    let &(t_last, x_last) = recent.last()?;
    if t - t_last > max_gap_s {
        return None;
    }
    if recent.len() < 2 {
        return Some(x_last);
    }
    let n = recent.len() as f64;
    let (mt, mx) = (
        recent.iter().map(|p| p.0).sum::<f64>() / n,
        recent.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let (sxy, sxx) = recent.iter().fold((0.0, 0.0), |a, p| {
        (a.0 + (p.0 - mt) * (p.1 - mx), a.1 + (p.0 - mt).powi(2))
    });
    let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    Some(mx + slope * (t - mt))
}

/// Whether the x the primary view gives a and b (`x`, measured or extrapolated) names two
/// blobs of a secondary view: the blobs lie more than `X_MARGIN_MM` apart in x, and the two
/// labellings' total x misfits differ by more than that too. Spheres passing each other in x
/// (a grazing impact whose normal leaves the primary's plane) are at nearly one x there, and
/// x then names them by chance.
pub(super) fn x_names_both(blobs: &[Blob], view: &View, x: [f64; 2]) -> bool {
    let [p, q] = blobs else { return true };
    let (xp, xq) = (world_x(view, p.centroid), world_x(view, q.centroid));
    let straight = (xp - x[0]).abs() + (xq - x[1]).abs();
    let swapped = (xq - x[0]).abs() + (xp - x[1]).abs();
    (xp - xq).abs() > X_MARGIN_MM && (straight - swapped).abs() > X_MARGIN_MM
}

/// How far apart two labellings' x misfits must be for x to choose between them, mm (fifteen
/// times the x error of either sphere).
const X_MARGIN_MM: f64 = 0.3;

/// Labels blobs of a secondary view by matching their world x to where the primary view
/// measured a and/or b in the same frame (a sphere the primary view did not measure is "the
/// other one").
pub(super) fn assign_by_x<'a>(
    blobs: &'a [Blob],
    view: &View,
    x: [Option<f64>; 2],
    contact_mm: f64,
) -> [Option<&'a Blob>; 2] {
    let mut sorted: Vec<&Blob> = blobs.iter().filter(|b| !b.merged).collect();
    sorted.sort_by_key(|b| std::cmp::Reverse(b.area_px));
    sorted.truncate(2);
    // Distance of a blob from a sphere's primary x; a sphere not measured there matches nothing.
    let cost = |b: &Blob, s: usize| x[s].map(|xs| (world_x(view, b.centroid) - xs).abs());
    match sorted.as_slice() {
        [p, q] => {
            let straight = cost(p, 0).unwrap_or(0.0) + cost(q, 1).unwrap_or(0.0);
            let swapped = cost(q, 0).unwrap_or(0.0) + cost(p, 1).unwrap_or(0.0);
            if straight <= swapped {
                [Some(p), Some(q)]
            } else {
                [Some(q), Some(p)]
            }
        }
        [p] => match (cost(p, 0), cost(p, 1)) {
            (Some(da), Some(db)) if da <= db => [Some(p), None],
            (Some(_), Some(_)) => [None, Some(p)],
            (Some(da), None) if da < contact_mm => [Some(p), None],
            (None, Some(db)) if db < contact_mm => [None, Some(p)],
            _ => [None, None],
        },
        _ => [None, None],
    }
}

/// Labels two blobs by least total movement from the previous frame, where both were measured:
/// a sphere moves a few pixels per frame, far less than the diameter that separates the two.
pub(super) fn assign_by_continuity<'a>(
    blobs: &'a [Blob],
    memory: &ViewMemory,
) -> [Option<&'a Blob>; 2] {
    let (p, q) = (&blobs[0], &blobs[1]);
    let d = |b: &Blob, s: usize| {
        memory.last[s]
            .map(|c| (c[0] - b.centroid[0]).hypot(c[1] - b.centroid[1]))
            .unwrap_or(0.0)
    };
    if d(p, 0) + d(q, 1) <= d(q, 0) + d(p, 1) {
        [Some(p), Some(q)]
    } else {
        [Some(q), Some(p)]
    }
}

/// Labels two blobs by each sphere's own recent track in this view (`ViewMemory::predict`),
/// when both tracks are recent, each blob lies within `radius_px` of its prediction, and the
/// other labelling would be at least three times as far off; None otherwise.
pub(super) fn assign_by_prediction<'a>(
    blobs: &'a [Blob],
    memory: &ViewMemory,
    t: f64,
    max_gap_s: f64,
    radius_px: f64,
) -> Option<[Option<&'a Blob>; 2]> {
    let [Some(pa), Some(pb)] = [0, 1].map(|s| memory.predict(s, t, max_gap_s)) else {
        return None;
    };
    let [p, q] = blobs else { return None };
    let d = |b: &Blob, c: [f64; 2]| (b.centroid[0] - c[0]).hypot(b.centroid[1] - c[1]);
    let (straight, swapped) = (d(p, pa) + d(q, pb), d(q, pa) + d(p, pb));
    let (best, worst, labels) = if straight <= swapped {
        (straight, swapped, [Some(p), Some(q)])
    } else {
        (swapped, straight, [Some(q), Some(p)])
    };
    let each_close = if straight <= swapped {
        d(p, pa).max(d(q, pb))
    } else {
        d(q, pa).max(d(p, pb))
    };
    (each_close < radius_px && worst > 3.0 * best).then_some(labels)
}

/// Labels two blobs by the one sphere this view saw in its last frame, where it did not see
/// the other (`ViewMemory::predict` within `max_gap_s` for that sphere alone): the blob within
/// `radius_px` of where that sphere's own track puts it now is that sphere, the other blob the
/// other sphere, when the other blob is at least three times as far from it; None otherwise.
/// Why: after an impact whose normal leans out of the primary view's plane, the primary can
/// lose both spheres for a few frames and name them again by tracks that cross the impact's
/// kink, while this view followed one of them through (an independent render under side light
/// and cast shadows: both views swapped from the frame after, and no impact found).
pub(super) fn assign_by_one_track<'a>(
    blobs: &'a [Blob],
    memory: &ViewMemory,
    t: f64,
    max_gap_s: f64,
    radius_px: f64,
) -> Option<[Option<&'a Blob>; 2]> {
    let (s, c) = match [0, 1].map(|s| memory.predict(s, t, max_gap_s)) {
        [Some(c), None] => (0, c),
        [None, Some(c)] => (1, c),
        _ => return None,
    };
    let [p, q] = blobs else { return None };
    let d = |b: &Blob| (b.centroid[0] - c[0]).hypot(b.centroid[1] - c[1]);
    let (near, far) = if d(p) <= d(q) { (p, q) } else { (q, p) };
    if d(near) >= radius_px || d(far) <= 3.0 * d(near) || p.merged || q.merged {
        return None;
    }
    let mut out = [None, None];
    out[s] = Some(near);
    out[1 - s] = Some(far);
    Some(out)
}

/// What the labelling remembers per view.
#[derive(Clone, Default)]
pub(super) struct ViewMemory {
    pub(super) last: [Option<[f64; 2]>; 2],
    /// Radius of the last single-sphere fit of each sphere in this view, px: the edge level
    /// makes it a little smaller than the known diameter says, and a split silhouette is fitted
    /// with this one.
    pub(super) radius: [Option<f64>; 2],
    /// Image direction from a to b the last time both were seen.
    pub(super) a_to_b: Option<[f64; 2]>,
    /// Whether both were measured in this view in the previous frame.
    pub(super) both_in_previous: bool,
    /// Recent image positions of each sphere in this view: (time s, centre px).
    pub(super) history: [Vec<(f64, [f64; 2])>; 2],
}

impl ViewMemory {
    /// Where sphere s should be at time t: a straight line through its last three positions in
    /// this view, if the last is at most `max_gap_s` old.
    pub(super) fn predict(&self, s: usize, t: f64, max_gap_s: f64) -> Option<[f64; 2]> {
        let h = &self.history[s];
        let u: Vec<(f64, f64)> = h.iter().map(|(t, c)| (*t, c[0])).collect();
        let v: Vec<(f64, f64)> = h.iter().map(|(t, c)| (*t, c[1])).collect();
        Some([
            extrapolate(&u, t, max_gap_s)?,
            extrapolate(&v, t, max_gap_s)?,
        ])
    }
}

/// Labels up to two blobs a/b. The first time both are seen, a is the one with the smaller world
/// x (the report contract). After that identity is kept, not re-derived from x: spheres that
/// graze each other pass, and x order flips. Through a collision the separation along the
/// contact normal keeps its sign (they approach and leave along it), so b stays on the side a→b
/// pointed to when both were last seen. A single blob goes to the sphere last seen nearest; a
/// single merged blob belongs to neither.
pub(super) fn assign<'a>(
    blobs: &'a [Blob],
    view: &View,
    memory: &ViewMemory,
    t: f64,
    max_gap_s: f64,
) -> [Option<&'a Blob>; 2] {
    let mut sorted: Vec<&Blob> = blobs.iter().collect();
    sorted.sort_by_key(|b| std::cmp::Reverse(b.area_px));
    sorted.truncate(2);
    match sorted.as_slice() {
        [p, q] => {
            let p_is_a = match memory.a_to_b {
                Some(dir) => {
                    (q.centroid[0] - p.centroid[0]) * dir[0]
                        + (q.centroid[1] - p.centroid[1]) * dir[1]
                        > 0.0
                }
                None => world_x(view, p.centroid) <= world_x(view, q.centroid),
            };
            if p_is_a {
                [Some(p), Some(q)]
            } else {
                [Some(q), Some(p)]
            }
        }
        [p] if !p.merged => {
            let d = |s: usize| {
                memory
                    .predict(s, t, max_gap_s)
                    .map(|c| (c[0] - p.centroid[0]).hypot(c[1] - p.centroid[1]))
            };
            match (d(0), d(1)) {
                (Some(da), Some(db)) if da <= db => [Some(p), None],
                (Some(_), Some(_)) => [None, Some(p)],
                (Some(_), None) => [Some(p), None],
                (None, Some(_)) => [None, Some(p)],
                (None, None) => [None, None],
            }
        }
        _ => [None, None],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;

    fn blob(u: f64, v: f64) -> Blob {
        Blob {
            centroid: [u, v],
            area_px: 140,
            extent_px: [0, 0, 0, 0],
            clipped: false,
            merged: false,
        }
    }

    /// x names two blobs only where the two labellings' x misfits differ by more than 0.3 mm:
    /// two spheres one above the other at nearly one x (passing each other in x) are not named
    /// by it, two a diameter apart are.
    #[test]
    fn x_names_two_blobs_only_where_they_lie_apart_in_x() {
        let cfg = Config::default_config();
        let views = crate::analysis::geometry::views(&cfg);
        let mirror = &views[1];
        let x = |u: f64| world_x(mirror, [u, 140.0]);
        // Blobs 0.4 px (0.19 mm) apart in x; a and b's x from the primary 0.6 mm apart.
        let passing = [blob(120.8, 137.0), blob(121.2, 151.0)];
        assert!(!x_names_both(&passing, mirror, [x(121.6), x(120.3)]));
        // A diameter apart.
        let apart = [blob(114.0, 137.0), blob(128.0, 151.0)];
        assert!(x_names_both(&apart, mirror, [x(114.2), x(127.9)]));
    }

    /// Two blobs where this view saw only a in its last frames (b hidden since before the
    /// impact): the blob on a's own track is a, the other b — whichever side of it b comes out
    /// on; not where the blob on a's track is a radius off it, nor where the other is nearly as
    /// close, nor where b's track is recent too (then both tracks decide).
    #[test]
    fn one_sphere_followed_into_the_frame_names_both() {
        let dt = 1e-3;
        let mut memory = ViewMemory::default();
        // a at frames 19–21 moving down the view 1.5 px a frame; b last seen at frame 14.
        memory.history[0] = (19..=21)
            .map(|k| (k as f64 * dt, [114.5, 150.0 + 1.5 * (k - 19) as f64]))
            .collect();
        memory.history[1] = vec![(14.0 * dt, [130.0, 142.0])];
        let (t, gap, radius) = (22.0 * dt, 1.5e-3, 6.2);
        for other in [blob(122.4, 136.3), blob(106.0, 150.0)] {
            let on_track = blob(114.4, 154.5);
            let pair = [other.clone(), on_track.clone()];
            let named = assign_by_one_track(&pair, &memory, t, gap, radius).expect("named");
            assert_eq!(named[0].map(|b| b.centroid), Some(on_track.centroid));
            assert_eq!(named[1].map(|b| b.centroid), Some(other.centroid));
        }
        // The blob on a's track 7 px off it (beyond the radius): nothing.
        let off = [blob(122.4, 136.3), blob(114.4, 161.5)];
        assert!(assign_by_one_track(&off, &memory, t, gap, radius).is_none());
        // The other blob less than three times as far from a's track: nothing.
        let near = [blob(114.4, 155.0), blob(115.4, 155.2)];
        assert!(assign_by_one_track(&near, &memory, t, gap, radius).is_none());
        // b seen in the last frame too: not this rule's to decide.
        memory.history[1].push((21.0 * dt, [121.2, 138.6]));
        let pair = [blob(122.4, 136.3), blob(114.4, 154.5)];
        assert!(assign_by_one_track(&pair, &memory, t, gap, radius).is_none());
    }
}
