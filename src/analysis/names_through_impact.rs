//! a and b checked through the impact, view by view: each sphere's image position is
//! continuous there, so its track before the impact and its track after must meet at the
//! impact time. Tracking names the spheres frame by frame; where they overlap in a view for a
//! few frames at the impact (a contact normal out of that view's plane) and pass each other
//! meanwhile, it can come out of the overlap with the names the wrong way round (hw-sim seeds
//! 110 and 3124 of the varied looks: both views swapped, "no impact found"). Here the names
//! after the impact are turned round in a view where that makes the tracks meet far better.

use super::tracking::FrameObs;

/// Frames either side of the impact whose positions are extrapolated to it.
const SIDE_FRAMES: usize = 8;

/// Where sphere `s` is at `t` in view `vi` by a quadratic (a line with fewer than four
/// points) through its image positions in `frames`; None with fewer than three.
fn meet(obs: &[FrameObs], frames: &[usize], s: usize, vi: usize, t: f64) -> Option<[f64; 2]> {
    let pts: Vec<(f64, [f64; 2])> = frames
        .iter()
        .filter_map(|&k| {
            let m = obs[k].spheres[s].get(vi)?.as_ref()?;
            Some((obs[k].time_s - t, m.centre_px))
        })
        .collect();
    if pts.len() < 3 {
        return None;
    }
    let degree = if pts.len() >= 4 { 2 } else { 1 };
    let fit = |axis: usize| -> Option<f64> {
        // Least squares for the value at t (the constant term), centred on t.
        let n = degree + 1;
        let mut ata = nalgebra::DMatrix::<f64>::zeros(n, n);
        let mut atb = nalgebra::DVector::<f64>::zeros(n);
        for (dt, c) in &pts {
            let row: Vec<f64> = (0..n).map(|p| dt.powi(p as i32)).collect();
            for i in 0..n {
                atb[i] += row[i] * c[axis];
                for j in 0..n {
                    ata[(i, j)] += row[i] * row[j];
                }
            }
        }
        let sol = ata.lu().solve(&atb)?;
        Some(sol[0])
    };
    Some([fit(0)?, fit(1)?])
}

/// Turns the names a and b round after `split_s` in each view where the tracks before and
/// after meet at `split_s` far better that way round: the swapped pairing's misses less than
/// half the straight one's, and at least a sphere's radius less. Returns a warning per view
/// turned.
pub(super) fn check(
    obs: &mut [FrameObs],
    view_names: &[&str],
    radii_px: &[f64],
    split_s: f64,
) -> Vec<String> {
    let before: Vec<usize> = (0..obs.len())
        .rev()
        .filter(|&k| obs[k].time_s < split_s)
        .collect();
    let after: Vec<usize> = (0..obs.len())
        .filter(|&k| obs[k].time_s > split_s)
        .collect();
    let mut warnings = Vec::new();
    for (vi, name) in view_names.iter().enumerate() {
        // The last (first) frames before (after) the impact in which this view saw each sphere.
        let side = |frames: &[usize], s: usize| -> Vec<usize> {
            frames
                .iter()
                .copied()
                .filter(|&k| obs[k].spheres[s].get(vi).is_some_and(Option::is_some))
                .take(SIDE_FRAMES)
                .collect()
        };
        let at = |frames: &[usize], s: usize| meet(obs, &side(frames, s), s, vi, split_s);
        let (Some(a0), Some(b0), Some(a1), Some(b1)) =
            (at(&before, 0), at(&before, 1), at(&after, 0), at(&after, 1))
        else {
            continue;
        };
        let d = |p: [f64; 2], q: [f64; 2]| (p[0] - q[0]).hypot(p[1] - q[1]);
        let straight = d(a0, a1) + d(b0, b1);
        let swapped = d(a0, b1) + d(b0, a1);
        let radius = radii_px.get(vi).copied().unwrap_or(0.0);
        if swapped < 0.5 * straight && straight - swapped > radius {
            for &k in &after {
                let [a, b] = &mut obs[k].spheres;
                if let (Some(x), Some(y)) = (a.get_mut(vi), b.get_mut(vi)) {
                    std::mem::swap(x, y);
                }
            }
            warnings.push(format!(
                "{name} view: a and b came out of the impact under each other's names (their tracks meet {straight:.1} px apart at the impact that way, {swapped:.1} px the other); turned round after the impact"
            ));
        }
    }
    warnings
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::tracking::Measurement;

    /// One view of a grazing impact at frame 20 (t = 20 ms): a comes from the left and goes
    /// on to the right past b, which it hid in frames 18–22 (unmeasured); each sphere's image
    /// path is continuous, px per frame. With `swapped`, the frames after the impact carry
    /// each other's names.
    fn passing(swapped: bool) -> Vec<FrameObs> {
        let path = |s: usize, k: f64| -> [f64; 2] {
            let t = k - 20.0;
            match (s, t < 0.0) {
                (0, true) => [120.0 + 0.9 * t, 40.0 + 1.6 * t],
                (0, false) => [120.0 + 0.75 * t, 40.0 + 1.7 * t],
                (_, true) => [124.0 - 0.9 * t, 37.0 + 1.6 * t],
                (_, false) => [124.0 - 0.75 * t, 37.0 + 1.5 * t],
            }
        };
        (0..40)
            .map(|k| {
                let hidden = (18..=22).contains(&k);
                let mut spheres = [0, 1]
                    .map(|s| vec![(!hidden).then(|| Measurement::test_at(path(s, k as f64)))]);
                if swapped && k > 20 {
                    spheres.swap(0, 1);
                }
                FrameObs {
                    index: k as u64,
                    frame_id: k as u64,
                    time_s: k as f64 * 1e-3,
                    spheres,
                    position_mm: [None, None],
                }
            })
            .collect()
    }

    /// Names swapped after the impact are turned round, with a warning; names that were right
    /// are left alone, though the spheres pass within a radius of each other.
    #[test]
    fn names_swapped_through_the_impact_are_turned_round_and_right_ones_kept() {
        let right = passing(false);
        let mut obs = passing(true);
        let w = check(&mut obs, &["direct"], &[6.85], 0.0200);
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(w[0]
            .starts_with("direct view: a and b came out of the impact under each other's names"));
        for (k, (f, g)) in obs.iter().zip(&right).enumerate() {
            for s in 0..2 {
                assert_eq!(
                    f.spheres[s][0].as_ref().map(|m| m.centre_px),
                    g.spheres[s][0].as_ref().map(|m| m.centre_px),
                    "frame {k}, sphere {s}"
                );
            }
        }
        let mut kept = passing(false);
        assert!(check(&mut kept, &["direct"], &[6.85], 0.0200).is_empty());
        for (f, g) in kept.iter().zip(&right) {
            for s in 0..2 {
                assert_eq!(
                    f.spheres[s][0].as_ref().map(|m| m.centre_px),
                    g.spheres[s][0].as_ref().map(|m| m.centre_px)
                );
            }
        }
    }
}
