//! Walton's rough inelastic hard-sphere collision operator (physics.md §1), with the project's
//! conventions: n from a to b, g = (v_b − v_a) + n × (R_a ω_a + R_b ω_b), g_n < 0 on approach.

use crate::V3;
use serde::{Deserialize, Serialize};

/// Collision coefficients of a sphere pair.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct Material {
    /// Normal coefficient of restitution.
    pub e: f64,
    /// Coulomb friction coefficient.
    pub mu: f64,
    /// Tangential restitution of the sticking branch.
    pub beta0: f64,
}

impl Material {
    /// Built-in presets; glass and acetate are the commonly quoted Foerster et al. (1994) values.
    pub fn preset(name: &str) -> Option<Material> {
        Some(match name {
            "glass" => Material {
                e: 0.97,
                mu: 0.092,
                beta0: 0.44,
            },
            "acetate" => Material {
                e: 0.87,
                mu: 0.25,
                beta0: 0.43,
            },
            "teflon" => Material {
                e: 0.90,
                mu: 0.10,
                beta0: 0.30,
            },
            "steel" => Material {
                e: 0.95,
                mu: 0.12,
                beta0: 0.35,
            },
            _ => return None,
        })
    }
    pub const PRESETS: &'static [&'static str] = &["glass", "acetate", "teflon", "steel"];
}

/// A sphere's kinematic state at one instant.
#[derive(Clone, Copy, Debug)]
pub struct Body {
    pub pos_mm: V3,
    pub vel_mm_s: V3,
    pub spin_rad_s: V3,
    pub orientation: nalgebra::UnitQuaternion<f64>,
    pub radius_mm: f64,
    pub mass_g: f64,
}

/// What the operator did, in the report's terms.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Outcome {
    pub normal: [f64; 3],
    pub g_n_mm_s: f64,
    pub g_n_post_mm_s: f64,
    pub g_t_mm_s: [f64; 3],
    pub g_t_post_mm_s: [f64; 3],
    pub e: f64,
    pub beta: f64,
    pub psi1: f64,
    pub psi2: f64,
    pub sliding: bool,
}

/// Moment-of-inertia factor of a solid sphere (I = K m R²).
pub const K_SOLID: f64 = 0.4;

pub fn contact_velocity(n: &V3, a: &Body, b: &Body) -> V3 {
    (b.vel_mm_s - a.vel_mm_s) + n.cross(&(a.spin_rad_s * a.radius_mm + b.spin_rad_s * b.radius_mm))
}

/// Applies the operator at contact; returns the bodies just after impact and the outcome.
pub fn collide(a: &Body, b: &Body, m: &Material) -> (Body, Body, Outcome) {
    let n = (b.pos_mm - a.pos_mm).normalize();
    let g = contact_velocity(&n, a, b);
    let g_n = g.dot(&n);
    let g_t = g - n * g_n;
    let m_star = a.mass_g * b.mass_g / (a.mass_g + b.mass_g);
    let chi = m_star * ((1.0 + 1.0 / K_SOLID) / a.mass_g + (1.0 + 1.0 / K_SOLID) / b.mass_g);
    let j_n = (1.0 + m.e) * m_star * g_n.abs();
    let gt_norm = g_t.norm();
    let (beta, sliding) = if gt_norm < 1e-12 {
        (m.beta0, false)
    } else {
        let beta_star = -1.0 + chi * m.mu * (1.0 + m.e) * g_n.abs() / gt_norm;
        if m.beta0 <= beta_star {
            (m.beta0, false)
        } else {
            (beta_star, true)
        }
    };
    let j_t = -(1.0 + beta) * (m_star / chi) * g_t;
    let j = n * j_n + j_t;
    let mut a2 = *a;
    let mut b2 = *b;
    a2.vel_mm_s = a.vel_mm_s - j / a.mass_g;
    b2.vel_mm_s = b.vel_mm_s + j / b.mass_g;
    let i_a = K_SOLID * a.mass_g * a.radius_mm * a.radius_mm;
    let i_b = K_SOLID * b.mass_g * b.radius_mm * b.radius_mm;
    a2.spin_rad_s = a.spin_rad_s - (a.radius_mm / i_a) * n.cross(&j);
    b2.spin_rad_s = b.spin_rad_s - (b.radius_mm / i_b) * n.cross(&j);
    let g2 = contact_velocity(&n, &a2, &b2);
    let g_n2 = g2.dot(&n);
    let g_t2 = g2 - n * g_n2;
    let (t, psi1, psi2, beta_meas) = if gt_norm < 1e-12 {
        (V3::zeros(), 0.0, 0.0, beta)
    } else {
        let t = g_t / gt_norm;
        (
            t,
            gt_norm / g_n.abs(),
            g_t2.dot(&t) / g_n.abs(),
            -g_t2.dot(&t) / gt_norm,
        )
    };
    let _ = t;
    let out = Outcome {
        normal: n.into(),
        g_n_mm_s: g_n,
        g_n_post_mm_s: g_n2,
        g_t_mm_s: g_t.into(),
        g_t_post_mm_s: g_t2.into(),
        e: -g_n2 / g_n,
        beta: beta_meas,
        psi1,
        psi2,
        sliding,
    };
    (a2, b2, out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn body(pos: V3, vel: V3, spin: V3, r: f64, m: f64) -> Body {
        Body {
            pos_mm: pos,
            vel_mm_s: vel,
            spin_rad_s: spin,
            orientation: nalgebra::UnitQuaternion::identity(),
            radius_mm: r,
            mass_g: m,
        }
    }

    #[test]
    fn glass_reference_points_of_physics_md() {
        // physics.md §3: glass-like (0.97, 0.092, 0.44) gives ψ2 = −0.088, −0.176, −0.034,
        // 0.366, 1.366 for ψ1 = 0.2, 0.4, 0.6, 1.0, 2.0.
        let mat = Material {
            e: 0.97,
            mu: 0.092,
            beta0: 0.44,
        };
        for (psi1, psi2) in [
            (0.2, -0.088),
            (0.4, -0.176),
            (0.6, -0.034),
            (1.0, 0.366),
            (2.0, 1.366),
        ] {
            let a = body(
                V3::zeros(),
                V3::new(1000.0, 1000.0 * psi1, 0.0),
                V3::zeros(),
                3.0,
                1.0,
            );
            let b = body(V3::new(6.0, 0.0, 0.0), V3::zeros(), V3::zeros(), 3.0, 1.0);
            let (_, _, o) = collide(&a, &b, &mat);
            assert!((o.psi1 - psi1).abs() < 1e-9);
            assert!(
                (o.psi2 - psi2).abs() < 6e-4,
                "psi1 {psi1}: psi2 {} vs {psi2}",
                o.psi2
            );
            assert!((o.e - 0.97).abs() < 1e-9);
        }
    }

    #[test]
    fn momentum_conserved_and_energy_not_created() {
        let mut rng = crate::rng::Rng::new(7);
        for _ in 0..500 {
            let mat = Material {
                e: rng.uniform(),
                mu: rng.uniform() * 0.8,
                beta0: rng.uniform() * 2.0 - 1.0,
            };
            let (ra, rb) = (1.0 + 5.0 * rng.uniform(), 1.0 + 5.0 * rng.uniform());
            let (ma, mb) = (0.2 + 5.0 * rng.uniform(), 0.2 + 5.0 * rng.uniform());
            let n = rng.unit_vector();
            let a = body(
                V3::zeros(),
                rng.unit_vector() * 900.0,
                rng.unit_vector() * 200.0,
                ra,
                ma,
            );
            let mut b = body(
                n * (ra + rb),
                rng.unit_vector() * 900.0,
                rng.unit_vector() * 200.0,
                rb,
                mb,
            );
            if (b.vel_mm_s - a.vel_mm_s).dot(&n) > 0.0 {
                b.vel_mm_s = -b.vel_mm_s;
                if (b.vel_mm_s - a.vel_mm_s).dot(&n) > 0.0 {
                    continue;
                }
            }
            let (a2, b2, o) = collide(&a, &b, &mat);
            let p0 = a.vel_mm_s * ma + b.vel_mm_s * mb;
            let p1 = a2.vel_mm_s * ma + b2.vel_mm_s * mb;
            assert!((p0 - p1).norm() <= 1e-9 * p0.norm().max(1.0));
            let ke = |x: &Body| {
                0.5 * x.mass_g * x.vel_mm_s.norm_squared()
                    + 0.5 * K_SOLID * x.mass_g * x.radius_mm.powi(2) * x.spin_rad_s.norm_squared()
            };
            assert!(ke(&a2) + ke(&b2) <= ke(&a) + ke(&b) * (1.0 + 1e-12) + 1e-9);
            assert!((o.e - mat.e).abs() < 1e-9);
        }
    }
}
