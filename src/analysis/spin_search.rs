//! A spin too fast to follow from rest: where a sphere's markers turn further between frames
//! than the first tracking pass's gate (`spin::measure` links each marker to the nearest one
//! a frame later, as if the sphere stood still), that pass links the wrong markers and the fit
//! settles on a spin near zero with a small σ. Seen at 500 fps: 214 rad/s is 24° a frame, a
//! marker 1.4 mm away a frame later, and the spin came out 2 ± 10 rad/s (20σ off).
//!
//! This module scores a spin by how many markers it carries onto a marker of the next frame
//! (`PhaseMarkers::links`), and searches a grid of rotations per frame for the spin that carries
//! the most (`PhaseMarkers::search`). The rotation per frame is searched up to `MAX_TURN_PER_FRAME_RAD`: beyond that
//! the markers' pattern repeats too soon to be followed at all.

use super::markers::MarkerObs;
use super::rotation::V3;
use super::tracking::FrameObs;
use nalgebra::Rotation3;

/// The largest rotation between consecutive frames searched, rad (46°: with 5–12 dots on a
/// sphere, about half the spacing between neighbouring dots).
const MAX_TURN_PER_FRAME_RAD: f64 = 0.8;
/// The coarse grid's step, rad per frame: a carried marker lands within r·step·√3/2 (0.44 mm
/// on a 6.35 mm sphere) of where the nearest grid point puts it, inside the scoring gate.
const COARSE_STEP_RAD: f64 = 0.16;
/// The fine grid's step, searched within a coarse step round the coarse grid's best.
const FINE_STEP_RAD: f64 = 0.04;
/// Frames of a phase the search looks at (from its start): enough pairs to tell a spin from
/// chance, few enough to keep the grid cheap on long phases.
const SEARCH_FRAMES: usize = 12;

/// A phase's markers as the search sees them: per view, each frame's markers (relative to the
/// centre, mm) with the frame's time, over the phase's first `SEARCH_FRAMES` frames. Gathered
/// once per phase and scored many times.
pub struct PhaseMarkers {
    views: Vec<Vec<(f64, Vec<V3>)>>,
}

impl PhaseMarkers {
    /// Sphere `s`'s markers over the first `SEARCH_FRAMES` of `frames`.
    pub fn of(obs: &[FrameObs], frames: &[usize], s: usize) -> PhaseMarkers {
        let views = frames
            .first()
            .map(|&k| obs[k].spheres[s].len())
            .unwrap_or(0);
        let views = (0..views)
            .map(|vi| {
                frames
                    .iter()
                    .take(SEARCH_FRAMES)
                    .filter_map(|&k| {
                        let m = obs[k].spheres[s].get(vi)?.as_ref()?;
                        let pts: Vec<V3> = m.markers.iter().map(|d: &MarkerObs| d.rel_mm).collect();
                        (!pts.is_empty()).then_some((obs[k].time_s, pts))
                    })
                    .collect()
            })
            .collect();
        PhaseMarkers { views }
    }

    /// How many markers spin `omega` carries from each frame onto a distinct marker of the
    /// next frame the same view saw the sphere in, within `gate_mm`, over the views: each such
    /// link counts 1 − (d/gate)², d how far it lands from that marker, so that of two spins
    /// that link the same markers the one that carries them closer scores more.
    pub fn links(&self, omega: V3, gate_mm: f64) -> f64 {
        let mut n = 0.0;
        for frames in &self.views {
            for w in frames.windows(2) {
                let ((t0, p), (t1, q)) = (&w[0], &w[1]);
                let r = Rotation3::from_scaled_axis(omega * (t1 - t0));
                let mut used = vec![false; q.len()];
                for a in p {
                    let ra = r * a;
                    let nearest = q
                        .iter()
                        .enumerate()
                        .map(|(j, b)| (j, (b - ra).norm()))
                        .min_by(|x, y| x.1.total_cmp(&y.1));
                    if let Some((j, d)) = nearest {
                        if d < gate_mm && !used[j] {
                            used[j] = true;
                            n += 1.0 - (d / gate_mm).powi(2);
                        }
                    }
                }
            }
        }
        n
    }

    /// The most `links` any spin could score: every marker of the sparser frame of each pair
    /// carried exactly onto one of the other's.
    pub fn most_links(&self) -> f64 {
        self.views
            .iter()
            .flat_map(|f| f.windows(2).map(|w| w[0].1.len().min(w[1].1.len())))
            .sum::<usize>() as f64
    }

    /// The spin on a grid of rotations per frame that carries the most markers onto the next
    /// frame's (`links`), with its score; None where no view saw markers in two frames. Ties
    /// go to the smaller rotation.
    pub fn search(&self, gate_mm: f64) -> Option<(V3, f64)> {
        // The typical frame interval: the smallest gap between frames any view saw in turn.
        let dt = self
            .views
            .iter()
            .flat_map(|f| f.windows(2).map(|w| w[1].0 - w[0].0))
            .filter(|d| *d > 0.0)
            .min_by(f64::total_cmp)?;
        // Coarse, then fine round the coarse grid's best.
        let mut best: Option<(V3, f64, f64)> = None;
        let consider = |turn: V3, best: &mut Option<(V3, f64, f64)>| {
            let size = turn.norm();
            if size > MAX_TURN_PER_FRAME_RAD + 1e-9 {
                return;
            }
            let n = self.links(turn / dt, gate_mm);
            let better = match best {
                None => true,
                Some((_, bn, bs)) => n > *bn || (n == *bn && size < *bs),
            };
            if better {
                *best = Some((turn, n, size));
            }
        };
        let grid = |centre: V3, step: f64, steps: i32, best: &mut Option<(V3, f64, f64)>| {
            for i in -steps..=steps {
                for j in -steps..=steps {
                    for k in -steps..=steps {
                        consider(centre + V3::new(i as f64, j as f64, k as f64) * step, best);
                    }
                }
            }
        };
        let coarse = (MAX_TURN_PER_FRAME_RAD / COARSE_STEP_RAD).round() as i32;
        grid(V3::zeros(), COARSE_STEP_RAD, coarse, &mut best);
        let centre = best.as_ref()?.0;
        let fine = (COARSE_STEP_RAD / FINE_STEP_RAD).round() as i32;
        grid(centre, FINE_STEP_RAD, fine, &mut best);
        best.map(|(turn, n, _)| (turn / dt, n))
    }
}

#[cfg(test)]
mod tests {
    use super::super::rotation::RotationMethod;
    use super::super::spin;
    use super::super::tracking::Measurement;
    use super::*;

    /// Frames of one view (looking from +z) of a 6.35 mm sphere spinning at `omega`, its
    /// eight dots seen on the hemisphere facing the view, lifted with `noise_mm` of error.
    fn frames(omega: V3, frames: usize, noise_mm: f64) -> Vec<FrameObs> {
        let dots: Vec<V3> = [
            [0.3, 0.2, 1.0],
            [-0.7, 0.4, 0.6],
            [0.8, -0.5, 0.3],
            [-0.2, -0.9, 0.4],
            [0.1, 0.8, -0.6],
            [-0.6, -0.3, -0.7],
            [0.9, 0.4, -0.2],
            [-0.4, 0.1, -1.0],
        ]
        .iter()
        .map(|d| V3::from(*d).normalize() * 3.175)
        .collect();
        let mut rng = hw_sim::Rng::new(7);
        (0..frames)
            .map(|k| {
                let t = k as f64 * 1e-3;
                let r = Rotation3::from_scaled_axis(omega * t);
                let markers = dots
                    .iter()
                    .map(|p| r * p)
                    .filter(|q| q.z > 0.3)
                    .map(|q| {
                        let e = V3::new(rng.gaussian(), rng.gaussian(), 0.0) * noise_mm;
                        let xy = V3::new(q.x + e.x, q.y + e.y, 0.0);
                        let depth = (3.175f64.powi(2) - xy.norm_squared()).max(0.0).sqrt();
                        MarkerObs {
                            centre_px: [0.0, 0.0],
                            rel_mm: xy + V3::z() * depth,
                            weight: (depth / 3.175).powi(2),
                            toward: V3::z(),
                        }
                    })
                    .collect();
                let m = Measurement {
                    markers,
                    ..Measurement::test_at([50.0, 50.0])
                };
                FrameObs {
                    index: k as u64,
                    frame_id: k as u64,
                    time_s: t,
                    spheres: [vec![Some(m)], vec![None]],
                    position_mm: [None, None],
                }
            })
            .collect()
    }

    /// A spin of 450 rad/s about an axis across the view (26° a frame, as 225 rad/s at 500 fps:
    /// a dot facing the camera moves 1.4 mm a frame) is found by the search and
    /// followed to within its σ; followed from rest it is not found at all.
    #[test]
    fn a_spin_too_fast_to_follow_from_rest_is_found_by_the_search() {
        let omega = V3::new(-450.0, 60.0, 40.0);
        let obs = frames(omega, 14, 0.02);
        let all: Vec<usize> = (0..obs.len()).collect();
        let m = spin::measure(&obs, &all, 0, RotationMethod::Kabsch);
        assert!(m.searched, "the search was not used");
        let fit = m.reportable().expect("a spin");
        let err = fit.omega - omega;
        assert!(err.norm() < 15.0, "ω {:?} for {omega:?}", fit.omega);
        for i in 0..3 {
            let z = err[i] / fit.cov[(i, i)].sqrt();
            assert!(z.abs() < 5.0, "axis {i}: {z:.1}σ");
        }
        // From rest alone the first pass links the wrong dots: what the search is for.
        let seen = PhaseMarkers::of(&obs, &all, 0);
        let rest = seen.links(V3::zeros(), 0.6);
        let found = seen.links(fit.omega, 0.6);
        assert!(found > 1.25 * rest + 2.0, "{found} vs {rest}");
    }

    /// A spin the first pass follows well is left as that pass found it, to the bit.
    #[test]
    fn a_spin_followed_from_rest_is_left_alone() {
        let omega = V3::new(30.0, 20.0, -150.0);
        let obs = frames(omega, 14, 0.02);
        let all: Vec<usize> = (0..obs.len()).collect();
        let m = spin::measure(&obs, &all, 0, RotationMethod::Kabsch);
        assert!(!m.searched);
        let fit = m.reportable().expect("a spin");
        assert!((fit.omega - omega).norm() < 10.0, "{:?}", fit.omega);
        // The search itself finds the same spin to within its grid.
    }
}
