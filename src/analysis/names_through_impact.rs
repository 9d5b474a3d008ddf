//! a and b checked through the impact, view by view: each sphere's image position is
//! continuous there, so its track before the impact and its track after must meet at the
//! impact time. Tracking names the spheres frame by frame; where they overlap in a view for a
//! few frames at the impact (a contact normal out of that view's plane) and pass each other
//! meanwhile, it can come out of the overlap with the names the wrong way round (hw-sim seeds
//! 110 and 3124 of the varied looks: both views swapped, "no impact found"). Here the names
//! after the impact are turned round in a view where that makes the tracks meet far better;
//! and once the four phases are fitted in the world, each sphere's flights must meet at the
//! impact, or there is no result (`flights_meet`).

use super::geometry::View;
use super::kinematics::{self, Fits};
use super::phases;
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

/// When to check the names at, s: the spheres' closest approach where both views see both
/// (`phases::closest_approach`), moved into the frames next to it where they did not — after
/// it if the spheres were still coming closer there, before it if they were already leaving
/// each other — to where the separation, at the rate it changed into (out of) the closest
/// frame, reaches `contact_mm` (at most to the far end of those frames). Why: a view that
/// loses the spheres at the impact (one silhouette) has its closest frame at one end of that
/// gap, and the tracks extrapolated to it from the far side then cross the impact's kink (an
/// independent render under side light and cast shadows: closest 2 ms before the impact in one
/// pass and 5 ms after it in the other, and its names turned round wrongly in both). Not the
/// gap's middle: tracks extrapolated past the impact from the near side cross it too (the
/// same renders with dust: a gap of three frames, its middle 1 ms after the impact, swapped).
pub(super) fn check_time(obs: &[FrameObs], views: &[View], contact_mm: f64) -> Option<f64> {
    let seps = phases::separations_mm(obs, views);
    let Some(i) = (0..seps.len()).min_by(|&a, &b| seps[a].1.total_cmp(&seps[b].1)) else {
        return phases::closest_approach(obs, views, 0).map(|(t, _)| t);
    };
    let (t, d) = seps[i];
    // The frame period: the shortest step between frames.
    let period = obs
        .windows(2)
        .map(|w| w[1].time_s - w[0].time_s)
        .filter(|dt| *dt > 0.0)
        .fold(f64::INFINITY, f64::min);
    let before = i.checked_sub(1).map(|j| seps[j]);
    let after = seps.get(i + 1).copied();
    let gap = |a: f64, b: f64| (b - a).abs() > 1.5 * period;
    // From `t` towards `end` at the separation's rate `rate_mm_s` (its magnitude), to contact.
    let to_contact = |end: f64, rate_mm_s: f64| {
        let dt = ((d - contact_mm).max(0.0) / rate_mm_s.max(1e-9)).min((end - t).abs());
        t + dt * (end - t).signum()
    };
    match (before, after) {
        (Some(p), Some(n)) if gap(t, n.0) && p.1 > d => {
            Some(to_contact(n.0, (p.1 - d) / (t - p.0)))
        }
        (Some(p), Some(n)) if gap(p.0, t) && n.1 > d => {
            Some(to_contact(p.0, (n.1 - d) / (n.0 - t)))
        }
        _ => Some(t),
    }
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

/// How far apart, mm, each sphere's flight before the impact and its flight after it are at
/// the impact (the fits' reference time, where `p0` is the position): straight, [a before
/// with a after, b before with b after], and swapped, [a before with b after, b before with a
/// after]; None unless all four fits have every axis. Flights named right meet within a few
/// hundredths of a millimetre (the lab's eight renders: 0.003–0.023 mm, both spheres summed),
/// and swapped ones a contact distance apart.
pub(super) fn meet_in_space(fits: &Fits, g: f64) -> Option<([f64; 2], [f64; 2])> {
    if fits.iter().any(|f| f.axes.iter().any(Option::is_none)) {
        return None;
    }
    let at = |k: usize| kinematics::pos_vel(&fits[k], 0.0, g).0;
    let (a0, b0, a1, b1) = (at(0), at(1), at(2), at(3));
    Some((
        [(a0 - a1).norm(), (b0 - b1).norm()],
        [(a0 - b1).norm(), (b0 - a1).norm()],
    ))
}

/// Each sphere's flights before and after the impact meet there within half the contact
/// distance (`meet_in_space`), or why not. Why: a sphere's position is continuous through the
/// impact whatever happens to its velocity; flights that miss by millimetres hold frames of
/// the other sphere, or of both, under one name (a view that swapped the names a few frames
/// after the impact and the other some frames later). A grazing impact under a grey ground,
/// both views losing the spheres for six frames, gave e −1.58 and a velocity at 400σ without a
/// warning; it gives no result now.
pub(super) fn flights_meet(fits: &Fits, g: f64, contact_mm: f64) -> Result<(), String> {
    let Some((misses, _)) = meet_in_space(fits, g) else {
        return Ok(());
    };
    if misses.iter().all(|m| *m <= 0.5 * contact_mm) {
        return Ok(());
    }
    Err(format!(
        "each sphere's flights before and after the impact must meet there, but a's are {:.1} mm apart and b's {:.1} mm (at most {:.1} mm): most likely frames after the impact carry the other sphere's name in a view",
        misses[0],
        misses[1],
        0.5 * contact_mm
    ))
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

    /// Spheres meeting head-on along x at t = 20 ms (each 1 mm/ms, contact at 6.35 mm), both
    /// views seeing both except in `lost` frames: the names are checked at the contact the
    /// separation's rate next to the gap gives, not at the gap's edge.
    #[test]
    fn the_names_are_checked_where_the_separation_reaches_contact_inside_a_gap() {
        let cfg = crate::config::Config::default_config();
        let views = crate::analysis::geometry::views(&cfg);
        let contact_mm = cfg.spheres.contact_mm();
        let recording = |lost: std::ops::RangeInclusive<usize>| -> Vec<FrameObs> {
            (0..40)
                .map(|k| {
                    let t = k as f64 * 1e-3;
                    let half = 0.5 * contact_mm + (t - 0.020).abs() * 1e3;
                    let at = |x: f64| {
                        let p = crate::analysis::geometry::V3::new(x, 10.0, 0.0);
                        views
                            .iter()
                            .map(|v| Some(Measurement::test_at(v.project(&p))))
                            .collect::<Vec<_>>()
                    };
                    let (a, b) = if lost.contains(&k) {
                        (vec![None, None], vec![None, None])
                    } else {
                        (at(-half), at(half))
                    };
                    FrameObs {
                        index: k as u64,
                        frame_id: k as u64,
                        time_s: t,
                        spheres: [a, b],
                        position_mm: [None, None],
                    }
                })
                .collect()
        };
        // Lost from 19 ms to 22 ms: closest at 18 ms, still coming closer.
        let t = check_time(&recording(19..=22), &views, contact_mm).expect("a time");
        assert!((t - 0.020).abs() < 1e-6, "{t}");
        // Lost from 16 ms to 21 ms: closest at 22 ms, already leaving.
        let t = check_time(&recording(16..=21), &views, contact_mm).expect("a time");
        assert!((t - 0.020).abs() < 1e-6, "{t}");
        // Nothing lost: the closest frame itself.
        let t = check_time(&recording(99..=99), &views, contact_mm).expect("a time");
        assert!((t - 0.020).abs() < 1e-9, "{t}");
    }

    /// A phase's fit through `p0_mm` at the impact (the fits' reference time) at `v_mm_s`.
    fn flight(p0_mm: [f64; 3], v_mm_s: [f64; 3]) -> kinematics::SideFit {
        kinematics::SideFit {
            axes: [0, 1, 2].map(|i| {
                Some(crate::analysis::line_fit::LineFit {
                    p0: p0_mm[i],
                    v: v_mm_s[i],
                    cov: nalgebra::Matrix2::identity() * 1e-4,
                    rms: 0.01,
                    n: 12,
                    rejected: 0,
                })
            }),
        }
    }

    /// a at the origin and b a contact distance (6.35 mm) along x at the impact; after it,
    /// each moving off with velocities of its own.
    fn collision(swapped_after: bool, a_after_mm: [f64; 3]) -> Fits {
        let (a, b) = ([0.0; 3], [6.35, 0.0, 0.0]);
        let (a_after, b_after) = (
            flight(a_after_mm, [-300.0, 20.0, 40.0]),
            flight(b, [350.0, -10.0, -30.0]),
        );
        let (x, y) = if swapped_after {
            (b_after, a_after)
        } else {
            (a_after, b_after)
        };
        [
            flight(a, [500.0, 0.0, 0.0]),
            flight(b, [-480.0, 0.0, 0.0]),
            x,
            y,
        ]
    }

    /// Flights named right meet at the impact; swapped after it (in every view), each
    /// sphere's flights miss by the contact distance, and meet the other way round.
    #[test]
    fn flights_named_right_meet_at_the_impact_and_swapped_ones_do_not() {
        let g = 9810.0;
        let right = collision(false, [0.0; 3]);
        assert!(flights_meet(&right, g, 6.35).is_ok());
        let swapped = collision(true, [0.0; 3]);
        let (straight, other) = meet_in_space(&swapped, g).unwrap();
        assert!((straight[0] - 6.35).abs() < 1e-9 && (straight[1] - 6.35).abs() < 1e-9);
        assert!(other.iter().all(|m| *m < 1e-9), "{other:?}");
        assert!(flights_meet(&swapped, g, 6.35).is_err());
    }

    /// A flight after the impact that holds the other sphere's frames in one view (its depth
    /// 14 mm off where it met the other flight) gives no result, with both spheres' misses.
    #[test]
    fn flights_that_do_not_meet_at_the_impact_give_no_result() {
        let g = 9810.0;
        let mixed = collision(false, [1.3, 1.4, -14.7]);
        let why = flights_meet(&mixed, g, 6.35).unwrap_err();
        assert!(
            why.contains("a's are 14.8 mm apart and b's 0.0 mm (at most 3.2 mm)"),
            "{why}"
        );
    }
}
