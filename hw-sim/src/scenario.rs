//! The staged experiment: where each sphere is, how fast it moves and spins, at any time after
//! the solenoids release it. Computed once from the config and seed; rendering and ground truth
//! both read it, so what is drawn and what is claimed true cannot disagree.
//!
//! Time τ counts from release. Before τ = 0 the spheres rest at the top of their tubes; they roll
//! without slipping down the tubes (a = g sin θ / (1 + K)), fly ballistically, meet at the world
//! origin at τ_c = τ_exit + flight time, collide per Walton, and fly on.

use crate::config::{LabConfig, SphereSpec};
use crate::physics::{collide, Body, Material, Outcome, K_SOLID};
use crate::rng::Rng;
use crate::{GRAVITY_MM_S2, V3};
use nalgebra::UnitQuaternion;

#[derive(Clone, Debug)]
pub struct Scenario {
    pub material: Material,
    /// Tube exit time after release, s.
    pub exit_tau_s: f64,
    /// First contact after release, s.
    pub impact_tau_s: f64,
    tube_top: [V3; 2],
    tube_dir: [V3; 2],
    roll_axis: [V3; 2],
    tube_accel_mm_s2: f64,
    start_orientation: [UnitQuaternion<f64>; 2],
    /// States just after leaving the tubes (flight starts here).
    pub exit: [Body; 2],
    /// States at contact, before and after the operator.
    pub pre: [Body; 2],
    pub post: [Body; 2],
    /// None when the spheres are staged to miss each other (impact parameter ≥ 1).
    pub outcome: Option<Outcome>,
    /// Marker directions in each sphere's body frame (unit vectors).
    pub markers: [Vec<V3>; 2],
}

fn gravity() -> V3 {
    V3::new(0.0, -GRAVITY_MM_S2, 0.0)
}

fn ballistic(b: &Body, dt: f64) -> Body {
    let mut out = *b;
    out.pos_mm = b.pos_mm + b.vel_mm_s * dt + 0.5 * gravity() * dt * dt;
    out.vel_mm_s = b.vel_mm_s + gravity() * dt;
    out.orientation = UnitQuaternion::from_scaled_axis(b.spin_rad_s * dt) * b.orientation;
    out
}

impl Scenario {
    pub fn new(cfg: &LabConfig, spheres: &[SphereSpec; 2]) -> Result<Scenario, String> {
        cfg.validate()?;
        let material = cfg.material()?;
        let mut rng = Rng::new(cfg.seed);
        let th = cfg.tube_angle_deg.to_radians();
        let radius = [spheres[0].diameter_mm / 2.0, spheres[1].diameter_mm / 2.0];
        let mass = [spheres[0].mass_g, spheres[1].mass_g];
        let tube_dir = [
            V3::new(th.cos(), -th.sin(), 0.0),
            V3::new(-th.cos(), -th.sin(), 0.0),
        ];
        // Upward wall normal of each tube: the sphere rolls on the tube's lower wall.
        let wall_up = [
            V3::new(th.sin(), th.cos(), 0.0),
            V3::new(-th.sin(), th.cos(), 0.0),
        ];
        let accel = GRAVITY_MM_S2 * th.sin() / (1.0 + K_SOLID);
        let exit_tau = (2.0 * cfg.tube_length_mm / accel).sqrt();
        let v_exit = accel * exit_tau;
        let roll_axis = [
            wall_up[0].cross(&tube_dir[0]),
            wall_up[1].cross(&tube_dir[1]),
        ];
        let start_orientation = [random_orientation(&mut rng), random_orientation(&mut rng)];
        let mut markers = [
            random_markers(
                &mut rng,
                cfg.markers_per_sphere,
                cfg.marker_diameter_mm / radius[0],
            ),
            random_markers(
                &mut rng,
                cfg.markers_per_sphere,
                cfg.marker_diameter_mm / radius[1],
            ),
        ];

        let mut exit_vel = [tube_dir[0] * v_exit, tube_dir[1] * v_exit];
        let mut exit_spin = [
            roll_axis[0] * v_exit / radius[0],
            roll_axis[1] * v_exit / radius[1],
        ];
        for i in 0..2 {
            let sign = if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
            exit_vel[i].z += sign * cfg.out_of_plane_velocity_mm_s * (0.5 + 0.5 * rng.uniform());
            exit_spin[i] += rng.unit_vector() * cfg.spin_jitter_rad_s;
        }

        // Contact geometry: n leans away from the approach direction by the impact parameter.
        let approach = -(exit_vel[1] - exit_vel[0]).normalize();
        let side = V3::z().cross(&approach).normalize();
        let up = approach.cross(&side);
        let (b1, b2) = (cfg.impact_offset, cfg.impact_offset_z);
        let miss = b1 * b1 + b2 * b2 >= 1.0;
        // A miss puts the closest approach, at the same instant, |b| contact distances apart.
        let n = if miss {
            side * b1 + up * b2
        } else {
            approach * (1.0 - b1 * b1 - b2 * b2).sqrt() + side * b1 + up * b2
        };
        let t_f = cfg.flight_time_ms / 1000.0;
        let contact = [-n * radius[0], n * radius[1]];

        let mut exit = [Body {
            pos_mm: V3::zeros(),
            vel_mm_s: V3::zeros(),
            spin_rad_s: V3::zeros(),
            orientation: UnitQuaternion::identity(),
            radius_mm: 0.0,
            mass_g: 0.0,
        }; 2];
        let mut tube_top = [V3::zeros(); 2];
        for i in 0..2 {
            let pos_exit = contact[i] - exit_vel[i] * t_f - 0.5 * gravity() * t_f * t_f;
            tube_top[i] = pos_exit - tube_dir[i] * cfg.tube_length_mm;
            let rolled =
                UnitQuaternion::from_scaled_axis(roll_axis[i] * (cfg.tube_length_mm / radius[i]));
            exit[i] = Body {
                pos_mm: pos_exit,
                vel_mm_s: exit_vel[i],
                spin_rad_s: exit_spin[i],
                orientation: rolled * start_orientation[i],
                radius_mm: radius[i],
                mass_g: mass[i],
            };
        }
        if cfg.look.as_ref().is_some_and(|l| l.markers_one_hemisphere) {
            // Painted on the side the direct camera (world +z) sees as the sphere leaves its
            // tube: each marker on the far side is reflected through the x–y plane.
            for i in 0..2 {
                let q = exit[i].orientation;
                for m in markers[i].iter_mut() {
                    let mut w = q * *m;
                    w.z = w.z.abs();
                    *m = q.inverse() * w;
                }
            }
        }
        let pre = [ballistic(&exit[0], t_f), ballistic(&exit[1], t_f)];
        let (post, outcome) = if miss {
            (pre, None)
        } else {
            let (pa, pb, outcome) = collide(&pre[0], &pre[1], &material);
            if outcome.g_n_mm_s >= 0.0 {
                return Err("sim: the configured tubes do not bring the spheres together".into());
            }
            ([pa, pb], Some(outcome))
        };
        Ok(Scenario {
            material,
            exit_tau_s: exit_tau,
            impact_tau_s: if miss { f64::INFINITY } else { exit_tau + t_f },
            tube_top,
            tube_dir,
            roll_axis,
            tube_accel_mm_s2: accel,
            start_orientation,
            exit,
            pre,
            post,
            outcome,
            markers,
        })
    }

    /// Both spheres at τ seconds after release (τ < 0: still held at the top of the tubes).
    pub fn state_at(&self, tau: f64) -> [Body; 2] {
        [self.sphere_at(0, tau), self.sphere_at(1, tau)]
    }

    fn sphere_at(&self, i: usize, tau: f64) -> Body {
        if tau < self.exit_tau_s {
            let t = tau.max(0.0);
            let s = 0.5 * self.tube_accel_mm_s2 * t * t;
            let v = self.tube_accel_mm_s2 * t;
            let r = self.exit[i].radius_mm;
            Body {
                pos_mm: self.tube_top[i] + self.tube_dir[i] * s,
                vel_mm_s: self.tube_dir[i] * v,
                spin_rad_s: self.roll_axis[i] * (v / r),
                orientation: UnitQuaternion::from_scaled_axis(self.roll_axis[i] * (s / r))
                    * self.start_orientation[i],
                radius_mm: r,
                mass_g: self.exit[i].mass_g,
            }
        } else if tau < self.impact_tau_s {
            ballistic(&self.exit[i], tau - self.exit_tau_s)
        } else {
            ballistic(&self.post[i], tau - self.impact_tau_s)
        }
    }

    /// Both spheres held still where they fly shortly before impact, about three contact
    /// distances apart, where both views see them: what the camera's preview shows to set the
    /// rig up (focus, exposure, geometry). The tube exits themselves are above the direct view in
    /// most rigs. Never part of an experiment.
    pub fn at_rest_in_view(&self) -> [Body; 2] {
        let contact = self.exit[0].radius_mm + self.exit[1].radius_mm;
        let closing = (self.exit[0].vel_mm_s - self.exit[1].vel_mm_s).norm();
        let flight = (self.impact_tau_s - self.exit_tau_s).max(0.0);
        let before = if closing > 0.0 {
            (2.0 * contact / closing).min(flight)
        } else {
            0.5 * flight
        };
        let tau = self.impact_tau_s - before;
        let bodies = self.state_at(tau);
        bodies.map(|b| Body {
            vel_mm_s: V3::zeros(),
            spin_rad_s: V3::zeros(),
            ..b
        })
    }

    /// Where sphere i leaves its tube (its centre at the exit, mm) and the tube's direction
    /// (unit, downhill): what a look's tube ends are drawn from.
    pub fn tube_exit(&self, i: usize) -> (V3, V3) {
        (self.exit[i].pos_mm, self.tube_dir[i])
    }

    /// World positions of sphere i's markers (on its surface) at τ.
    pub fn marker_positions(&self, i: usize, body: &Body) -> Vec<V3> {
        self.markers[i]
            .iter()
            .map(|m| body.pos_mm + body.orientation * m * body.radius_mm)
            .collect()
    }
}

fn random_orientation(rng: &mut Rng) -> UnitQuaternion<f64> {
    let axis = rng.unit_vector();
    UnitQuaternion::from_scaled_axis(axis * (rng.uniform() * std::f64::consts::PI))
}

/// Marker directions, at least three marker diameters apart so dots never merge.
fn random_markers(rng: &mut Rng, count: u32, angular_diameter: f64) -> Vec<V3> {
    let mut out: Vec<V3> = Vec::new();
    let min_cos = (3.0 * angular_diameter)
        .min(std::f64::consts::PI / 2.0)
        .cos();
    let mut tries = 0;
    while (out.len() as u32) < count && tries < 10_000 {
        tries += 1;
        let m = rng.unit_vector();
        if out.iter().all(|o| o.dot(&m) < min_cos) {
            out.push(m);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spheres() -> [SphereSpec; 2] {
        [
            SphereSpec {
                diameter_mm: 6.35,
                mass_g: 0.29,
            },
            SphereSpec {
                diameter_mm: 6.35,
                mass_g: 0.29,
            },
        ]
    }

    #[test]
    fn spheres_touch_exactly_at_impact_and_not_before() {
        let s = Scenario::new(&LabConfig::default(), &spheres()).unwrap();
        let at = s.state_at(s.impact_tau_s - 1e-9);
        let d = (at[1].pos_mm - at[0].pos_mm).norm();
        assert!((d - 6.35).abs() < 1e-3, "contact distance {d}");
        for k in 1..200 {
            let tau = s.impact_tau_s * k as f64 / 200.0;
            let st = s.state_at(tau);
            assert!((st[1].pos_mm - st[0].pos_mm).norm() >= 6.35 - 1e-6);
        }
        let after = s.state_at(s.impact_tau_s + 0.01);
        assert!((after[1].pos_mm - after[0].pos_mm).norm() > 6.35);
        assert!((s.outcome.unwrap().e - s.material.e).abs() < 1e-9);
    }

    #[test]
    fn an_impact_parameter_of_one_or_more_is_a_miss() {
        let cfg = LabConfig {
            impact_offset: 1.5,
            ..LabConfig::default()
        };
        let s = Scenario::new(&cfg, &spheres()).unwrap();
        assert!(s.outcome.is_none());
        let closest = (0..2000)
            .map(|k| {
                let st = s.state_at(s.exit_tau_s + k as f64 * 1e-4);
                (st[1].pos_mm - st[0].pos_mm).norm()
            })
            .fold(f64::INFINITY, f64::min);
        assert!(
            (closest - 1.5 * 6.35).abs() < 0.05,
            "closest approach {closest}"
        );
    }

    #[test]
    fn nothing_moves_before_release() {
        let s = Scenario::new(&LabConfig::default(), &spheres()).unwrap();
        let a = s.state_at(-1.0);
        let b = s.state_at(0.0);
        assert_eq!(a[0].pos_mm, b[0].pos_mm);
        assert_eq!(a[0].vel_mm_s, V3::zeros());
    }
}
