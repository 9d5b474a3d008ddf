//! Each sphere's 3-D centre per frame, from both views where both see it, and from one view and
//! the nearest frames where both did where one alone does. A turned view (a rolled camera, a
//! tilted mirror, a camera not square to the plane of collision) mixes the coordinate it cannot
//! see into the two it measures; this is where that coordinate comes from. Aligned views (the
//! shorthand) measure their two coordinates alone and are left as they are.

use super::geometry::{triangulate, View, V3};
use super::tracking::FrameObs;

/// Fills `position_mm` of every frame in which a turned view sees a sphere.
pub(super) fn place(obs: &mut [FrameObs], views: &[View]) {
    if views.iter().all(|v| v.aligned) {
        return;
    }
    for s in 0..2 {
        for f in obs.iter_mut() {
            let seen: Vec<(&View, [f64; 2])> = views
                .iter()
                .zip(&f.spheres[s])
                .filter_map(|(v, m)| Some((v, m.as_ref()?.centre_px)))
                .collect();
            // A pinhole's rows are weighted by the depth at the point: a second round uses the
            // first round's point.
            let first = triangulate(&seen, &V3::zeros());
            f.position_mm[s] = first.and_then(|p| triangulate(&seen, &p)).or(first);
        }
        let known: Vec<(f64, V3)> = obs
            .iter()
            .filter_map(|f| Some((f.time_s, f.position_mm[s]?)))
            .collect();
        for f in obs.iter_mut().filter(|f| f.position_mm[s].is_none()) {
            let Some((view, m)) = views
                .iter()
                .zip(&f.spheres[s])
                .find_map(|(v, m)| Some((v, m.as_ref()?)))
            else {
                continue;
            };
            let near = interpolate(&known, f.time_s);
            f.position_mm[s] = Some(view.solve(m.centre_px, near.as_ref()));
        }
    }
}

/// The position at `t`, linear between the nearest known frames on either side (the nearest
/// one beyond the ends). `known` is in time order.
fn interpolate(known: &[(f64, V3)], t: f64) -> Option<V3> {
    let i = known.partition_point(|(tk, _)| *tk < t);
    match (i.checked_sub(1).map(|j| known[j]), known.get(i).copied()) {
        (Some((t0, p0)), Some((t1, p1))) if t1 > t0 => {
            Some(p0 + (p1 - p0) * ((t - t0) / (t1 - t0)))
        }
        (Some((_, p)), _) | (None, Some((_, p))) => Some(p),
        (None, None) => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolation_is_linear_inside_and_held_outside() {
        let known = [
            (0.0, V3::new(0.0, 0.0, 0.0)),
            (1.0, V3::new(2.0, 4.0, -2.0)),
        ];
        assert_eq!(interpolate(&known, 0.25), Some(V3::new(0.5, 1.0, -0.5)));
        assert_eq!(interpolate(&known, -1.0), Some(known[0].1));
        assert_eq!(interpolate(&known, 3.0), Some(known[1].1));
        assert_eq!(interpolate(&[], 3.0), None);
    }
}
