//! Rotations from marker correspondences (physics.md §4) and spin as one constant vector per
//! flight phase.
//!
//! - `kabsch`: the optimal rotation (weighted Kabsch/Umeyama with determinant correction), the
//!   least-squares and, for isotropic noise, maximum-likelihood solution. Two markers suffice.
//! - `ls9`: the thesis's unconstrained 9-parameter least squares, kept as a baseline
//!   (`--rotation thesis`). It needs three markers and is not orthogonal.
//! - `rotation_vector`: angle and axis through the quaternion (Shepperd), robust at 0° and 180°
//!   — never the thesis's tan formula.
//! - `fit_spin`: ω such that the rotation between frames k and k+j is exp(ω·Δt), fitted over all
//!   usable frame pairs of a flight phase (spin is constant in free flight), with a covariance
//!   clustered by frame.

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

pub type V3 = Vector3<f64>;

pub use crate::config::RotationMethod;

/// R minimising Σ w |q − R p|² over rotations.
pub fn kabsch(p: &[V3], q: &[V3], w: &[f64]) -> Option<Matrix3<f64>> {
    if p.len() < 2 || p.len() != q.len() {
        return None;
    }
    let mut h = Matrix3::zeros();
    for i in 0..p.len() {
        h += w[i] * q[i] * p[i].transpose();
    }
    let svd = h.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let d = (u * vt).determinant().signum();
    let r = u * Matrix3::from_diagonal(&V3::new(1.0, 1.0, d)) * vt;
    r.iter().all(|x| x.is_finite()).then_some(r)
}

/// The thesis's M = (Σ q pᵀ)(Σ p pᵀ)⁻¹ (eqs. 5.32–5.38, with one consistent convention q = M p).
pub fn ls9(p: &[V3], q: &[V3]) -> Option<Matrix3<f64>> {
    if p.len() < 3 || p.len() != q.len() {
        return None;
    }
    let mut a = Matrix3::zeros();
    let mut b = Matrix3::zeros();
    for i in 0..p.len() {
        a += q[i] * p[i].transpose();
        b += p[i] * p[i].transpose();
    }
    Some(a * b.try_inverse()?)
}

/// Rotation vector (axis × angle, rad) of a rotation matrix, through the quaternion. A
/// non-orthogonal matrix (LS9) is first taken to its nearest rotation.
pub fn rotation_vector(m: &Matrix3<f64>) -> V3 {
    // Bounded iterations: a degenerate LS9 matrix must not loop forever.
    let rot = Rotation3::from_matrix_eps(m, 1e-12, 200, Rotation3::identity());
    UnitQuaternion::from_rotation_matrix(&rot).scaled_axis()
}

pub fn estimate(method: RotationMethod, p: &[V3], q: &[V3], w: &[f64]) -> Option<V3> {
    let m = match method {
        RotationMethod::Kabsch => kabsch(p, q, w)?,
        RotationMethod::Thesis => ls9(p, q)?,
    };
    Some(rotation_vector(&m))
}

/// One frame pair's rotation: which frames, the time between them, the rotation vector, and how
/// many markers it rests on.
#[derive(Clone, Copy, Debug)]
pub struct PairRotation {
    pub frame_a: usize,
    pub frame_b: usize,
    pub dt_s: f64,
    pub rotvec: V3,
    pub markers: usize,
}

#[derive(Clone, Debug)]
pub struct SpinFit {
    pub omega: V3,
    pub cov: Matrix3<f64>,
    pub pairs: usize,
    /// Each frame's influence on ω (frame index, rad/s): `cov` is the sum of their outer
    /// products. Kept so that quantities combining spins measured on the same frames (both
    /// spheres, in one phase) get the covariance between them too.
    pub frame_influence: Vec<(usize, V3)>,
}

fn ls_omega(pairs: &[&PairRotation]) -> Option<V3> {
    let (mut num, mut den) = (V3::zeros(), 0.0);
    for p in pairs {
        let w = p.markers as f64;
        num += w * p.rotvec * p.dt_s;
        den += w * p.dt_s * p.dt_s;
    }
    (den > 0.0).then(|| num / den)
}

/// The least-squares ω of frame pairs (rotvec ≈ ω·Δt, weighted by markers), with no covariance
/// and no least number of frames: a start for the whole-track fit (`spin_tracks`).
pub fn ls_omega_of(pairs: &[PairRotation]) -> Option<V3> {
    ls_omega(&pairs.iter().collect::<Vec<_>>())
}

/// The fewest frames a spin is fitted on. Fewer leave the frame-clustered covariance too few
/// degrees of freedom to be believed: on independent frame errors, four or five frames put
/// 2–5 % of their errors beyond 5σ (test `a_fit_on_few_frames_claims_no_more_than_they_show`).
/// A phase with fewer frames takes its spin from the other phase and the contact impulse
/// (`impulse.rs`), whose σ is honest.
pub const MIN_SPIN_FRAMES: usize = 6;

/// Constant ω from all pairs (rotvec ≈ ω·Δt), with a covariance clustered by frame (the
/// infinitesimal jackknife, or sandwich, with frames as the units): pairs that share a frame
/// share its errors, so a plain LS covariance would be too small.
///
/// Why not the leave-one-frame-out jackknife used before: it also counts how the other frames'
/// weights shift when one is dropped (the Efron–Stein excess). On the bench's recordings it
/// was 1.18× this variance on every axis, and it gave β, which adds up four spins, a σ that
/// covered 79–85 % of true values. Both estimators treat frames as independent, which the
/// errors here are not: they drift over several frames (an independent-error model predicts a
/// quarter of the observed variance), and that is what keeps either from being too small.
pub fn fit_spin(pairs: &[PairRotation]) -> Option<SpinFit> {
    if pairs.len() < 2 {
        return None;
    }
    let all: Vec<&PairRotation> = pairs.iter().collect();
    let omega = ls_omega(&all)?;
    let den: f64 = pairs
        .iter()
        .map(|p| p.markers as f64 * p.dt_s * p.dt_s)
        .sum();
    // ∂ω̂/∂(weight of frame f): each pair's weighted residual, credited to both its frames.
    let mut influence: std::collections::BTreeMap<usize, V3> = Default::default();
    for p in pairs {
        let u = p.markers as f64 * (p.rotvec - omega * p.dt_s) * p.dt_s / den;
        for f in [p.frame_a, p.frame_b] {
            *influence.entry(f).or_insert_with(V3::zeros) += u;
        }
    }
    let n = influence.len() as f64;
    // The influences of n frames sum to zero, so their covariance has rank ≤ n − 1 and n − 1
    // degrees of freedom: the error over the estimated σ follows Student's t with ν = n − 1 or
    // worse, whose variance ν/(ν − 2) exists only from four frames on and whose tails are thin
    // only from about six (see MIN_SPIN_FRAMES). Three frames claimed one direction known
    // exactly, and the impulse's combination trusted a wrong post-impact spin along it
    // (docs/accuracy.md, session 22).
    if influence.len() < MIN_SPIN_FRAMES {
        return None;
    }
    // n/(n−1), the usual small-sample factor of a clustered covariance, times the t variance
    // (n−1)/(n−3), so that σ is the error's standard deviation when frames are few.
    let scale = (n / (n - 3.0)).sqrt();
    let frame_influence: Vec<(usize, V3)> =
        influence.into_iter().map(|(f, u)| (f, u * scale)).collect();
    let cov = frame_influence
        .iter()
        .fold(Matrix3::zeros(), |c, (_, d)| c + d * d.transpose());
    Some(SpinFit {
        omega,
        cov,
        pairs: pairs.len(),
        frame_influence,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn points() -> Vec<V3> {
        vec![
            V3::new(1.0, 2.0, 3.0),
            V3::new(-2.0, 1.0, 2.5),
            V3::new(0.5, -3.0, 1.0),
            V3::new(2.5, 0.3, -1.0),
        ]
    }

    #[test]
    fn kabsch_and_ls9_recover_an_exact_rotation() {
        let truth = V3::new(0.19, 0.11, 0.9756).normalize() * 6.5f64.to_radians();
        let r = Rotation3::from_scaled_axis(truth);
        let p = points();
        let q: Vec<V3> = p.iter().map(|x| r * x).collect();
        let w = vec![1.0; p.len()];
        for m in [RotationMethod::Kabsch, RotationMethod::Thesis] {
            let v = estimate(m, &p, &q, &w).unwrap();
            assert!((v - truth).norm() < 1e-9, "{m:?}: {v:?}");
        }
    }

    #[test]
    fn rotation_vector_is_exact_at_180_degrees() {
        let axis = V3::new(1.0, 2.0, -0.5).normalize();
        let r =
            Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), std::f64::consts::PI);
        let v = rotation_vector(r.matrix());
        assert!((v.norm() - std::f64::consts::PI).abs() < 1e-9);
        assert!(v.normalize().dot(&axis).abs() > 1.0 - 1e-9);
    }

    #[test]
    fn kabsch_never_returns_a_reflection() {
        // Points on a plane: H is rank 2 and an unconstrained fit may reflect.
        let p = vec![
            V3::new(1.0, 0.0, 0.0),
            V3::new(0.0, 1.0, 0.0),
            V3::new(-1.0, -1.0, 0.0),
        ];
        let q = vec![
            V3::new(1.0, 0.0, 0.0),
            V3::new(0.0, -1.0, 0.0),
            V3::new(-1.0, 1.0, 0.0),
        ];
        let r = kabsch(&p, &q, &[1.0; 3]).unwrap();
        assert!((r.determinant() - 1.0).abs() < 1e-9);
    }

    #[test]
    fn spin_fit_recovers_constant_omega() {
        let omega = V3::new(10.0, -40.0, 120.0);
        let dt = 1e-3;
        let mut pairs = Vec::new();
        for k in 0..12 {
            for j in 1..4 {
                pairs.push(PairRotation {
                    frame_a: k,
                    frame_b: k + j,
                    dt_s: j as f64 * dt,
                    rotvec: omega * (j as f64 * dt),
                    markers: 4,
                });
            }
        }
        let f = fit_spin(&pairs).unwrap();
        assert!((f.omega - omega).norm() < 1e-9);
        assert!(f.cov.norm() < 1e-12);
    }

    /// Pairs over `frames` frames (gaps 1–4, as `spin::pair_rotations` makes them) of a spin
    /// `omega`, each frame's orientation off by `frame_err(k)` and each pair by `pair_err`.
    fn noisy_pairs(
        frames: usize,
        omega: V3,
        frame_err: &dyn Fn(usize) -> V3,
        pair_err: &mut dyn FnMut() -> V3,
    ) -> Vec<PairRotation> {
        let dt = 1e-3;
        let mut pairs = Vec::new();
        for a in 0..frames {
            for b in a + 1..(a + 5).min(frames) {
                let t = (b - a) as f64 * dt;
                pairs.push(PairRotation {
                    frame_a: a,
                    frame_b: b,
                    dt_s: t,
                    rotvec: omega * t + frame_err(b) - frame_err(a) + pair_err(),
                    markers: 2 + (a * 7 + b * 3) % 5,
                });
            }
        }
        pairs
    }

    /// Three frames' influences sum to zero, so their covariance would claim one direction
    /// known exactly; with four or five, independent frame errors still land beyond 5σ in
    /// 2–5 % of fits (Student's t with few degrees of freedom, and the pairs' leverage): no fit
    /// below six frames. From six on, the tails must stay thin: ≤ 5 % beyond 3σ and ≤ 1.5 %
    /// beyond 5σ (the clustered covariance's n/(n−1) alone gave 6.3 % and 1.6 % at six).
    #[test]
    fn a_fit_on_few_frames_claims_no_more_than_they_show() {
        let omega = V3::new(5.0, -20.0, 150.0);
        for frames in [3, 5] {
            let pairs = noisy_pairs(
                frames,
                omega,
                &|k| V3::new(0.01, 0.0, -0.01) * k as f64,
                &mut || V3::zeros(),
            );
            assert!(
                pairs.len() >= 2 && fit_spin(&pairs).is_none(),
                "{frames} frames"
            );
        }
        let mut rng = hw_sim::Rng::new(5);
        let mut z = Vec::new();
        for _ in 0..3000 {
            let errs: Vec<V3> = (0..MIN_SPIN_FRAMES)
                .map(|_| V3::new(rng.gaussian(), rng.gaussian(), rng.gaussian()) * 0.01)
                .collect();
            let pairs = noisy_pairs(MIN_SPIN_FRAMES, omega, &|k| errs[k], &mut || V3::zeros());
            let fit = fit_spin(&pairs).expect("enough frames");
            z.extend((0..3).map(|i| ((fit.omega[i] - omega[i]) / fit.cov[(i, i)].sqrt()).abs()));
        }
        let beyond = |k: f64| z.iter().filter(|x| **x > k).count() as f64 / z.len() as f64;
        assert!(
            beyond(3.0) <= 0.05 && beyond(5.0) <= 0.015,
            "beyond 3σ {:.3}, beyond 5σ {:.4}",
            beyond(3.0),
            beyond(5.0)
        );
    }

    /// Each frame's influence is how ω moves when that frame weighs a little more (the
    /// infinitesimal jackknife), not how it moves when the frame is dropped.
    #[test]
    fn frame_influence_is_the_derivative_of_omega_by_the_frames_weight() {
        let mut rng = hw_sim::Rng::new(7);
        let errs: Vec<V3> = (0..12)
            .map(|_| V3::new(rng.gaussian(), rng.gaussian(), rng.gaussian()) * 0.01)
            .collect();
        let pairs = noisy_pairs(12, V3::new(5.0, -20.0, 150.0), &|k| errs[k], &mut || {
            V3::zeros()
        });
        let fit = fit_spin(&pairs).unwrap();
        let n = 12.0_f64;
        let h = 1e-6;
        for &(f, influence) in &fit.frame_influence {
            let (mut num, mut den) = (V3::zeros(), 0.0);
            for p in &pairs {
                let w = p.markers as f64
                    * if p.frame_a == f || p.frame_b == f {
                        1.0 + h
                    } else {
                        1.0
                    };
                num += w * p.rotvec * p.dt_s;
                den += w * p.dt_s * p.dt_s;
            }
            let derivative = (num / den - fit.omega) / h;
            let expected = derivative * (n / (n - 3.0)).sqrt();
            assert!(
                (influence - expected).norm() < 1e-4 * expected.norm().max(1e-3),
                "frame {f}: {influence:?} against {expected:?}"
            );
        }
        let sum = fit
            .frame_influence
            .iter()
            .fold(Matrix3::zeros(), |c, (_, d)| c + d * d.transpose());
        assert!((sum - fit.cov).norm() < 1e-12);
    }

    /// Orientation errors that drift over frames (AR(1), correlation 0.9 from one frame to the
    /// next), plus some independent per-pair noise, as the bench's recordings have: ±1σ must
    /// cover the true ω between 55 % and 85 % of the time on each axis. (Errors independent
    /// from frame to frame would be over-covered: both frame-clustered estimators, this one
    /// and the jackknife, then count the pair structure twice; see docs/accuracy.md.)
    #[test]
    fn spin_covariance_covers_drifting_orientation_errors() {
        let omega = V3::new(5.0, -20.0, 150.0);
        let mut rng = hw_sim::Rng::new(11);
        let trials = 600;
        let mut inside = [0usize; 3];
        for _ in 0..trials {
            let mut drift = V3::zeros();
            let errs: Vec<V3> = (0..20)
                .map(|_| {
                    let fresh = V3::new(rng.gaussian(), rng.gaussian(), rng.gaussian());
                    drift = drift * 0.9 + fresh * (1.0f64 - 0.81).sqrt() * 0.01;
                    drift
                })
                .collect();
            let mut pair_rng = hw_sim::Rng::new(rng.next_u64());
            let pairs = noisy_pairs(20, omega, &|k| errs[k], &mut || {
                V3::new(
                    pair_rng.gaussian(),
                    pair_rng.gaussian(),
                    pair_rng.gaussian(),
                ) * 0.005
            });
            let fit = fit_spin(&pairs).unwrap();
            for (i, n) in inside.iter_mut().enumerate() {
                if (fit.omega[i] - omega[i]).abs() <= fit.cov[(i, i)].sqrt() {
                    *n += 1;
                }
            }
        }
        for (i, n) in inside.iter().enumerate() {
            let coverage = *n as f64 / trials as f64;
            assert!(
                (0.55..=0.85).contains(&coverage),
                "axis {i}: coverage {coverage}"
            );
        }
    }
}
