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
//!   usable frame pairs of a flight phase (spin is constant in free flight), with a jackknife
//!   over frames for its covariance.

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

pub type V3 = Vector3<f64>;

#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RotationMethod {
    /// Optimal rotation (Kabsch with determinant correction).
    Kabsch,
    /// The thesis's 9-parameter least squares.
    Thesis,
}

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

#[derive(Clone, Copy, Debug)]
pub struct SpinFit {
    pub omega: V3,
    pub cov: Matrix3<f64>,
    pub pairs: usize,
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

/// Constant ω from all pairs (rotvec ≈ ω·Δt), with a leave-one-frame-out jackknife covariance:
/// pairs that share a frame share its errors, so a plain LS covariance would be too small.
pub fn fit_spin(pairs: &[PairRotation]) -> Option<SpinFit> {
    if pairs.len() < 2 {
        return None;
    }
    let all: Vec<&PairRotation> = pairs.iter().collect();
    let omega = ls_omega(&all)?;
    let mut frames: Vec<usize> = pairs.iter().flat_map(|p| [p.frame_a, p.frame_b]).collect();
    frames.sort_unstable();
    frames.dedup();
    let mut reps = Vec::new();
    for &f in &frames {
        let rest: Vec<&PairRotation> = pairs
            .iter()
            .filter(|p| p.frame_a != f && p.frame_b != f)
            .collect();
        if let Some(o) = ls_omega(&rest) {
            reps.push(o);
        }
    }
    let n = reps.len() as f64;
    if n < 3.0 {
        return None;
    }
    let mean = reps.iter().fold(V3::zeros(), |a, r| a + r) / n;
    let mut cov = Matrix3::zeros();
    for r in &reps {
        let d = r - mean;
        cov += d * d.transpose();
    }
    cov *= (n - 1.0) / n;
    Some(SpinFit {
        omega,
        cov,
        pairs: pairs.len(),
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
}
