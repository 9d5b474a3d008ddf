//! The 1992 thesis's methods, kept as a measured baseline (never used for a report): integer
//! (one-pixel) sphere centres and marker positions, velocities as two-frame differences next to
//! the impact, the contact normal from the centres in the frame nearest the impact, and spin
//! from the unconstrained 9-parameter rotation between two frames. `impactcam bench accuracy`
//! runs it beside impactcam's methods on the same frames.

use super::geometry::View;
use super::kinematics::{collision, Collision, V3};
use super::markers::MarkerObs;
use super::rotation::RotationMethod;
use super::spin;
use super::tracking::FrameObs;
use crate::config::Config;

#[derive(Clone, Debug)]
pub struct ThesisResult {
    pub collision: Option<Collision>,
    /// [a pre, b pre, a post, b post], mm/s.
    pub velocities: Option<[V3; 4]>,
    /// [a pre, b pre, a post, b post], rad/s.
    pub spins: Option<[V3; 4]>,
}

/// The observations with every centre and marker rounded to whole pixels, markers re-lifted
/// from the rounded positions.
pub fn rounded(obs: &[FrameObs], views: &[View], cfg: &Config) -> Vec<FrameObs> {
    obs.iter()
        .map(|f| {
            let mut f = f.clone();
            for (s, per_view) in f.spheres.iter_mut().enumerate() {
                let radius_mm = cfg.spheres.sphere(s).0 / 2.0;
                for (vi, m) in per_view.iter_mut().enumerate() {
                    let Some(m) = m else { continue };
                    let view = &views[vi];
                    m.centre_px = m.blob_centroid_px.map(f64::round);
                    let c = m.centre_px;
                    m.markers = m
                        .markers
                        .iter()
                        .filter_map(|k| {
                            let p = k.centre_px.map(f64::round);
                            let (du, dv) = (
                                (p[0] - c[0]) / view.px_per_mm,
                                (p[1] - c[1]) / view.px_per_mm,
                            );
                            let rho2 = du * du + dv * dv;
                            let depth = (radius_mm * radius_mm - rho2).max(0.0).sqrt();
                            (rho2 < radius_mm * radius_mm).then(|| MarkerObs {
                                centre_px: p,
                                rel_mm: view.u_axis * du + view.v_axis * dv + view.facing * depth,
                                weight: 1.0,
                                toward: view.facing,
                            })
                        })
                        .collect();
                }
            }
            f
        })
        .collect()
}

/// World centre of sphere s in frame f: x and y from the direct view, z from the mirror.
fn centre(f: &FrameObs, views: &[View], s: usize) -> Option<V3> {
    let mut c = [None; 3];
    for (vi, view) in views.iter().enumerate().rev() {
        let m = f.spheres[s][vi].as_ref()?;
        for (axis, val) in view.unproject(m.centre_px, f.position_mm[s].as_ref()) {
            c[axis] = Some(val);
        }
    }
    Some(V3::new(c[0]?, c[1].unwrap_or(0.0), c[2].unwrap_or(0.0)))
}

pub fn estimate(
    obs: &[FrameObs],
    views: &[View],
    cfg: &Config,
    impact_time_s: f64,
) -> ThesisResult {
    let obs = rounded(obs, views, cfg);
    let both = |k: usize| Some((centre(&obs[k], views, 0)?, centre(&obs[k], views, 1)?));
    let measured: Vec<usize> = (0..obs.len()).filter(|&k| both(k).is_some()).collect();
    let pre: Vec<usize> = measured
        .iter()
        .copied()
        .filter(|&k| obs[k].time_s < impact_time_s)
        .collect();
    let post: Vec<usize> = measured
        .iter()
        .copied()
        .filter(|&k| obs[k].time_s > impact_time_s)
        .collect();
    if pre.len() < 2 || post.len() < 2 {
        return ThesisResult {
            collision: None,
            velocities: None,
            spins: None,
        };
    }
    let (p1, p2) = (pre[pre.len() - 2], pre[pre.len() - 1]);
    let (q1, q2) = (post[0], post[1]);
    let diff = |k1: usize, k2: usize, s: usize| -> Option<V3> {
        let (a, b) = (centre(&obs[k1], views, s)?, centre(&obs[k2], views, s)?);
        Some((b - a) / (obs[k2].time_s - obs[k1].time_s))
    };
    let velocities = (|| {
        Some([
            diff(p1, p2, 0)?,
            diff(p1, p2, 1)?,
            diff(q1, q2, 0)?,
            diff(q1, q2, 1)?,
        ])
    })();
    // The normal from the centres in the measured frame nearest the impact.
    let nearest = if impact_time_s - obs[p2].time_s <= obs[q1].time_s - impact_time_s {
        p2
    } else {
        q1
    };
    let normal = both(nearest).map(|(a, b)| (b - a).normalize());
    // Spin from the 9-parameter fit between the two frames used for the velocity.
    let spin_of = |k1: usize, k2: usize, s: usize| -> Option<V3> {
        let (pairs, _) = spin::pairs(&obs, &[k1, k2], s, RotationMethod::Thesis, V3::zeros(), 1.3);
        let p = pairs.first()?;
        Some(p.rotvec / p.dt_s)
    };
    let spins = (|| {
        Some([
            spin_of(p1, p2, 0)?,
            spin_of(p1, p2, 1)?,
            spin_of(q1, q2, 0)?,
            spin_of(q1, q2, 1)?,
        ])
    })();
    let radii = [cfg.spheres.sphere(0).0 / 2.0, cfg.spheres.sphere(1).0 / 2.0];
    let collision = match (velocities, normal) {
        (Some(v), Some(n)) => collision(&n, &(v[1] - v[0]), &(v[3] - v[2]), spins.as_ref(), radii),
        _ => None,
    };
    ThesisResult {
        collision,
        velocities,
        spins,
    }
}
