//! Radial lens distortion, one term: where a lens puts the image point an ideal (distortion-free)
//! view would show, the inverse, and the local Jacobian. The convention is the config's
//! (`lens_k1`, `lens_centre_px`, `lens_radius_px`) and hw-sim's: an ideal image point p is
//! recorded at c + (p − c)·(1 + k1·|p − c|²/R²), so k1 is the fractional displacement at
//! distance R from the centre (R = the frame's half-diagonal makes it the corners'; negative:
//! barrel). The views' maps give ideal points; the frames hold recorded ones.

use nalgebra::Matrix2;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lens {
    pub k1: f64,
    pub centre_px: [f64; 2],
    pub radius_px: f64,
}

impl Lens {
    /// The lens from a view's config keys; None when it has none (or k1 is exactly 0).
    pub fn from_config(g: &crate::config::ViewGeometry) -> Option<Lens> {
        let (k1, centre_px, radius_px) = (g.lens_k1?, g.lens_centre_px?, g.lens_radius_px?);
        (k1 != 0.0).then_some(Lens {
            k1,
            centre_px,
            radius_px,
        })
    }

    /// How much larger than the ideal view's the circle this lens records for a small disc at
    /// recorded point `p` is, as fitted: the lens stretches a disc by 1 + k1·r²/R² across the
    /// line to its centre and by 1 + 3·k1·r²/R² along it, and a circle fitted to that outline
    /// takes their mean, 1 + 2·k1·r²/R², r the ideal point's distance from the lens's centre
    /// (to first order in k1; a 13.7 px disc through k1 = −0.03 or +0.02, fitted: within 5e-4
    /// of it out to a corner of a 240 × 192 frame).
    pub fn radius_factor(&self, p: [f64; 2]) -> f64 {
        // r is the ideal point's distance (the recorded point's is 2 % shorter near a corner).
        let ideal = self.undistort(p);
        let (du, dv) = (ideal[0] - self.centre_px[0], ideal[1] - self.centre_px[1]);
        1.0 + 2.0 * self.k1 * (du * du + dv * dv) / (self.radius_px * self.radius_px)
    }

    /// Where the lens records the ideal image point `p`.
    pub fn distort(&self, p: [f64; 2]) -> [f64; 2] {
        let c = self.centre_px;
        let (du, dv) = (p[0] - c[0], p[1] - c[1]);
        let f = 1.0 + self.k1 * (du * du + dv * dv) / (self.radius_px * self.radius_px);
        [c[0] + du * f, c[1] + dv * f]
    }

    /// The ideal image point recorded at `p`: the radial distance t (over R) that satisfies
    /// t·(1 + k1·t²) = s, by Newton's method from t = s. The map is monotone while
    /// 1 + 3·k1·t² > 0, which holds inside any frame for the config's |k1| ≤ 0.2 with R the
    /// half-diagonal; beyond it the last monotone t is kept (a point no lens of this k1 records).
    pub fn undistort(&self, p: [f64; 2]) -> [f64; 2] {
        let c = self.centre_px;
        let (du, dv) = (p[0] - c[0], p[1] - c[1]);
        let s = du.hypot(dv) / self.radius_px;
        if s == 0.0 || !s.is_finite() {
            return p;
        }
        let k = self.k1;
        let mut t = s;
        for _ in 0..30 {
            let slope = 1.0 + 3.0 * k * t * t;
            if slope <= 1e-6 {
                break;
            }
            let step = (t + k * t * t * t - s) / slope;
            t -= step;
            if step.abs() < 1e-15 * (1.0 + s) {
                break;
            }
        }
        let ratio = t / s;
        [c[0] + du * ratio, c[1] + dv * ratio]
    }

    /// ∂(recorded)/∂(ideal) at the ideal point `p`: f·I + (2·k1/R²)·d·dᵀ, d = p − c. Along the
    /// line to the centre it stretches by 1 + 3·k1·t², across it by 1 + k1·t².
    pub fn jacobian(&self, p: [f64; 2]) -> Matrix2<f64> {
        let c = self.centre_px;
        let (du, dv) = (p[0] - c[0], p[1] - c[1]);
        let r2 = self.radius_px * self.radius_px;
        let f = 1.0 + self.k1 * (du * du + dv * dv) / r2;
        let g = 2.0 * self.k1 / r2;
        Matrix2::new(f + g * du * du, g * du * dv, g * du * dv, f + g * dv * dv)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lens(k1: f64) -> Lens {
        Lens {
            k1,
            centre_px: [119.5, 95.5],
            radius_px: 0.5 * 240f64.hypot(192.0),
        }
    }

    /// Undistorting undoes distorting everywhere in a 240×192 frame, for barrel and pincushion
    /// lenses up to the config's bound; and the Jacobian is the distortion's derivative.
    #[test]
    fn undistort_inverts_distort_and_the_jacobian_is_its_derivative() {
        for k1 in [-0.2, -0.03, 0.01, 0.2] {
            let l = lens(k1);
            for p in [
                [0.0, 0.0],
                [239.0, 191.0],
                [119.5, 95.5],
                [30.0, 170.0],
                [200.0, 5.0],
            ] {
                let q = l.undistort(l.distort(p));
                assert!(
                    (q[0] - p[0]).abs() < 1e-9 && (q[1] - p[1]).abs() < 1e-9,
                    "{k1} {p:?} {q:?}"
                );
                let j = l.jacobian(p);
                let h = 1e-5;
                for k in 0..2 {
                    let (mut a, mut b) = (p, p);
                    a[k] += h;
                    b[k] -= h;
                    let (da, db) = (l.distort(a), l.distort(b));
                    for i in 0..2 {
                        let fd = (da[i] - db[i]) / (2.0 * h);
                        assert!((fd - j[(i, k)]).abs() < 1e-7, "{k1} {p:?} ∂{i}/∂{k}");
                    }
                }
            }
            // A point at distance d from the centre moves by k1·d³/R² along the line to it.
            let corner = l.distort([239.0, 191.0]);
            let moved = (corner[0] - 239.0).hypot(corner[1] - 191.0);
            let d = 119.5f64.hypot(95.5);
            assert!((moved - k1.abs() * d.powi(3) / l.radius_px.powi(2)).abs() < 1e-9);
        }
    }

    /// The radius a circle fitted to a small disc's recorded outline has is the ideal radius
    /// times `radius_factor` there (a 13.7 px disc through k1 = −0.03 and +0.02, at the frame's
    /// centre, half-way out and near a corner), to 5e-4 of it (Taubin's algebraic fit); the
    /// tangential factor alone (1 + k1·r²/R²) would be up to 2.3 % off near the corner.
    #[test]
    fn a_recorded_discs_fitted_radius_follows_radius_factor() {
        for k1 in [-0.03, 0.02] {
            let l = lens(k1);
            for centre in [[119.5, 95.5], [60.0, 50.0], [15.0, 10.0]] {
                let rho = 6.85;
                let outline: Vec<[f64; 2]> = (0..720)
                    .map(|i| {
                        let a = i as f64 * std::f64::consts::PI / 360.0;
                        l.distort([centre[0] + rho * a.cos(), centre[1] + rho * a.sin()])
                    })
                    .collect();
                let (fitted_centre, r) =
                    crate::analysis::circle::taubin(&outline).expect("a circle");
                let want = rho * l.radius_factor(fitted_centre);
                assert!(
                    (r - want).abs() < 5e-4 * rho,
                    "k1 {k1} at {centre:?}: fitted {r:.5} px, radius_factor says {want:.5}"
                );
            }
        }
    }
}
