//! Trajectories and the impact: per-sphere ballistic fits before and after the impact (gravity
//! known, so each axis is a straight-line fit of position minus ½gt²), the impact time and
//! contact point where the pre and post separation lines meet at contact distance (the
//! pre-impact root alone and the lines' intersection are kept as cross-checks), the contact
//! normal there, and e — physics.md §6. Uncertainties are propagated from the fit covariances
//! through a numerical Jacobian of everything derived (`propagate`).

use nalgebra::{Matrix3, Vector3};

pub type V3 = Vector3<f64>;

/// Observations of one coordinate of one sphere: (time s, value mm).
pub type Series = Vec<(f64, f64)>;

pub use super::line_fit::{fit_line, LineFit};

mod propagate;
pub use propagate::uncertainties;

/// Fits of one sphere on one side of the impact; an axis no view measures is None.
#[derive(Clone, Copy, Debug)]
pub struct SideFit {
    pub axes: [Option<LineFit>; 3],
}

impl SideFit {
    pub fn fit(series: &[Series; 3], t_ref: f64, gravity_mm_s2: f64) -> SideFit {
        Self::fit_floored(series, t_ref, gravity_mm_s2, [0.0; 3])
    }

    /// `fit`, each axis's σ floored at `floor_mm`: the scatter the centres' own σ says the
    /// positions have at least (`fit_line`).
    pub fn fit_floored(
        series: &[Series; 3],
        t_ref: f64,
        gravity_mm_s2: f64,
        floor_mm: [f64; 3],
    ) -> SideFit {
        Self::fit_each(series, None, t_ref, gravity_mm_s2, floor_mm)
    }

    /// `fit_floored`, each point weighted (`weights[axis][point]`, 1 for a centre as good as
    /// the phase's usual one; see `fit_line`).
    pub fn fit_weighted(
        series: &[Series; 3],
        weights: &[Vec<f64>; 3],
        t_ref: f64,
        gravity_mm_s2: f64,
        floor_mm: [f64; 3],
    ) -> SideFit {
        Self::fit_each(series, Some(weights), t_ref, gravity_mm_s2, floor_mm)
    }

    /// One `fit_line` per axis, gravity along −y.
    fn fit_each(
        series: &[Series; 3],
        weights: Option<&[Vec<f64>; 3]>,
        t_ref: f64,
        gravity_mm_s2: f64,
        floor_mm: [f64; 3],
    ) -> SideFit {
        let g = [0.0, -gravity_mm_s2, 0.0];
        SideFit {
            axes: [0, 1, 2].map(|i| {
                let w = weights.map(|w| w[i].as_slice());
                fit_line(&series[i], w, t_ref, g[i], floor_mm[i])
            }),
        }
    }
}

/// [a pre, b pre, a post, b post]
pub type Fits = [SideFit; 4];

/// The two spheres as the impact sees them: radii, mm, and, where the four phases' velocities
/// are to be combined under momentum conservation, how (`momentum`).
#[derive(Clone, Copy, Debug)]
pub struct Bodies {
    pub radii: [f64; 2],
    pub momentum: Option<super::momentum::Momentum>,
    /// Where spins came from the contact impulse (`impulse::reconcile`), how they follow it
    /// (`ImpulseCoupling`); None where none did, or with the spins not yet measured.
    pub impulse: Option<ImpulseCoupling>,
}

impl From<[f64; 2]> for Bodies {
    /// Radii alone: the phases' velocities as fitted.
    fn from(radii: [f64; 2]) -> Bodies {
        Bodies {
            radii,
            momentum: None,
            impulse: None,
        }
    }
}

/// How the spins given to `derive` follow the contact impulse they were partly taken from:
/// sphere s's spin of phase p (0 before, 1 after) is its given value plus
/// `weight[s][p]·(Δω_s − delta_omega[s])`, Δω_s = (1/(K r_s)) n_s × Δv_s from the normal and
/// velocities `derive` finds (n_a = n, n_b = −n) and `delta_omega` the impulse's Δω the spins
/// were reconciled with (so at the fits they came from, the spins are as given, to the bit).
/// Why: a spin after the impact taken from the spin before plus the impulse moves with the
/// velocities and the normal, and so do the velocities' and normal's own parts of ψ2 and β;
/// carried as a source of its own, independent of them, those correlations were lost
/// (validation v03: spins after the impact from the impulse alone, the normal 0.002 off, β
/// 4.6σ off; docs/accuracy.md, session 47).
#[derive(Clone, Copy, Debug)]
pub struct ImpulseCoupling {
    pub inertia_factor: f64,
    pub weight: [[Matrix3<f64>; 2]; 2],
    pub delta_omega: [V3; 2],
}

impl ImpulseCoupling {
    /// The spins `derive` uses, given `spins` ([a pre, b pre, a post, b post]) reconciled with
    /// the impulse, the normal and the phases' velocities at the impact.
    fn spins(
        &self,
        spins: &[V3; 4],
        normal: &V3,
        velocities: &[V3; 4],
        radii: [f64; 2],
    ) -> [V3; 4] {
        let mut out = *spins;
        for s in 0..2 {
            let n = if s == 0 { *normal } else { -normal };
            let dv = velocities[2 + s] - velocities[s];
            let now = super::impulse::delta_omega(n, dv, radii[s], self.inertia_factor);
            let change = now - self.delta_omega[s];
            for p in 0..2 {
                out[2 * p + s] += self.weight[s][p] * change;
            }
        }
        out
    }
}

/// Everything derived from the four fits.
#[derive(Clone, Debug)]
pub struct Derived {
    /// Impact time relative to t_ref, s.
    pub tau_c: f64,
    pub e: f64,
    pub normal: V3,
    /// [a pre, b pre, a post, b post] velocities at the impact, mm/s.
    pub velocities: [V3; 4],
    pub tau_intersection: f64,
    /// Where the pre-impact separation alone reaches contact distance, s (for the cross-check).
    pub tau_contact_distance: f64,
    /// Closest approach of the pre-impact trajectories, mm (for the no-impact message).
    pub closest_mm: f64,
    /// With spins: ψ1 = |g_t|/|g_n|, ψ2 = (g_t′·t)/|g_n|, β = −(g_t′·t)/|g_t| (physics.md).
    pub psi1: Option<f64>,
    pub psi2: Option<f64>,
    pub beta: Option<f64>,
}

/// Spins (rad/s) of [a pre, b pre, a post, b post] with their covariances.
#[derive(Clone, Copy, Debug)]
pub struct Spins {
    pub omega: [V3; 4],
    pub cov: [Matrix3<f64>; 4],
}

impl Derived {
    /// The inverse of `to_vec`, with the optional members present where `shape` has them.
    pub fn from_vec(shape: &Derived, v: &[f64]) -> Derived {
        let v3 = |i: usize| V3::new(v[i], v[i + 1], v[i + 2]);
        let mut k = 18;
        let mut next = |present: bool| {
            present.then(|| {
                k += 1;
                v[k - 1]
            })
        };
        Derived {
            tau_c: v[0],
            e: v[1],
            normal: v3(2),
            velocities: [v3(5), v3(8), v3(11), v3(14)],
            tau_intersection: v[17],
            tau_contact_distance: shape.tau_contact_distance,
            closest_mm: shape.closest_mm,
            psi1: next(shape.psi1.is_some()),
            psi2: next(shape.psi2.is_some()),
            beta: next(shape.beta.is_some()),
        }
    }

    /// Flattened for covariance propagation: [tau_c, e, n(3), v(12), tau_x, ψ1?, ψ2?, β?].
    pub fn to_vec(&self) -> Vec<f64> {
        let mut v = vec![
            self.tau_c,
            self.e,
            self.normal.x,
            self.normal.y,
            self.normal.z,
        ];
        for w in &self.velocities {
            v.extend_from_slice(w.as_slice());
        }
        v.push(self.tau_intersection);
        v.extend([self.psi1, self.psi2, self.beta].iter().flatten());
        v
    }
}

/// Position and velocity of a fitted trajectory τ after its reference time.
pub fn pos_vel(f: &SideFit, tau: f64, g: f64) -> (V3, V3) {
    let gv = [0.0, -g, 0.0];
    let mut p = V3::zeros();
    let mut v = V3::zeros();
    for i in 0..3 {
        if let Some(l) = &f.axes[i] {
            p[i] = l.p0 + l.v * tau + 0.5 * gv[i] * tau * tau;
            v[i] = l.v + gv[i] * tau;
        }
    }
    (p, v)
}

#[derive(Debug, Clone, PartialEq)]
pub enum ImpactError {
    /// The pre-impact trajectories never come within contact distance.
    NoContact { closest_mm: f64 },
    /// Spheres are not approaching before the "impact".
    NotApproaching,
}

/// The collision coefficients, physics.md conventions.
#[derive(Clone, Copy, Debug)]
pub struct Collision {
    pub e: f64,
    pub psi1: Option<f64>,
    pub psi2: Option<f64>,
    pub beta: Option<f64>,
}

/// e from the relative velocities (b − a) before and after along n (from a to b); with spins
/// [a pre, b pre, a post, b post] also ψ1 = |g_t|/|g_n|, ψ2 = (g_t′·t)/|g_n| and
/// β = −(g_t′·t)/|g_t|, where g = Δv + n × (R_a ω_a + R_b ω_b). None unless approaching.
pub fn collision(
    normal: &V3,
    rel_pre: &V3,
    rel_post: &V3,
    spins: Option<&[V3; 4]>,
    radii: [f64; 2],
) -> Option<Collision> {
    let g_n = rel_pre.dot(normal);
    if g_n >= 0.0 {
        return None;
    }
    let e = -rel_post.dot(normal) / g_n;
    let (mut psi1, mut psi2, mut beta) = (None, None, None);
    if let Some(w) = spins {
        let contact_pre = rel_pre + normal.cross(&(w[0] * radii[0] + w[1] * radii[1]));
        let contact_post = rel_post + normal.cross(&(w[2] * radii[0] + w[3] * radii[1]));
        let gt = contact_pre - normal * contact_pre.dot(normal);
        let gt_post = contact_post - normal * contact_post.dot(normal);
        if gt.norm() > 1e-9 {
            let t = gt / gt.norm();
            psi1 = Some(gt.norm() / g_n.abs());
            psi2 = Some(gt_post.dot(&t) / g_n.abs());
            beta = Some(-gt_post.dot(&t) / gt.norm());
        }
    }
    Some(Collision {
        e,
        psi1,
        psi2,
        beta,
    })
}

/// Impact time, normal, e and velocities from the four fits (all with the same t_ref); with
/// spins also ψ1, ψ2 and β. `radii` are the spheres' radii in mm.
pub fn derive(
    fits: &Fits,
    spins: Option<&[V3; 4]>,
    bodies: impl Into<Bodies>,
    contact_mm: f64,
    g: f64,
) -> Result<Derived, ImpactError> {
    let Bodies {
        radii,
        momentum,
        impulse,
    } = bodies.into();
    let conserved;
    let fits = match &momentum {
        Some(m) => {
            conserved = super::momentum::conserve(fits, m);
            &conserved
        }
        None => fits,
    };
    let (pa, va) = pos_vel(&fits[0], 0.0, g);
    let (pb, vb) = pos_vel(&fits[1], 0.0, g);
    // Gravity acts on both alike: the separation is a straight line in time.
    let dp = pb - pa;
    let dv = vb - va;
    let a = dv.norm_squared();
    if a < 1e-12 {
        return Err(ImpactError::NotApproaching);
    }
    let b = dp.dot(&dv);
    let c = dp.norm_squared() - contact_mm * contact_mm;
    let tau_closest = -b / a;
    let closest = (dp + dv * tau_closest).norm();
    let disc = b * b - a * c;
    // Fitted trajectories that pass a little wide of contact, where the velocities changed
    // across the split as only a collision changes them: the spheres touched and the fitted
    // positions are biased (a grazing impact on a blurred or side-lit rig misses by a few
    // tenths of a mm). The contact is then sought from where the separation is least
    // (`joint_contact` needs no line to reach contact distance on its own).
    if disc < 0.0 && !velocities_changed(fits) {
        return Err(ImpactError::NoContact {
            closest_mm: closest,
        });
    }
    let tau_contact = if disc < 0.0 {
        tau_closest
    } else {
        (-b - disc.sqrt()) / a
    };
    let rel_pre = dv;
    let (pa2, va2) = pos_vel(&fits[2], 0.0, g);
    let (pb2, vb2) = pos_vel(&fits[3], 0.0, g);
    let rel_post = vb2 - va2;
    let (mut tau_c, mut normal) = joint_contact(fits, g, contact_mm, tau_contact);
    if !turned_back(&normal, &rel_pre, &rel_post) {
        if let Some((tau, n)) =
            physical_contact(fits, g, contact_mm, tau_contact, (&rel_pre, &rel_post))
        {
            (tau_c, normal) = (tau, n);
        }
    }
    let vel = |f: &SideFit| pos_vel(f, tau_c, g).1;
    let velocities = [vel(&fits[0]), vel(&fits[1]), vel(&fits[2]), vel(&fits[3])];
    let coupled = match (spins, &impulse) {
        (Some(w), Some(c)) => Some(c.spins(w, &normal, &velocities, radii)),
        _ => None,
    };
    let spins = coupled.as_ref().or(spins);
    let Some(c) = collision(&normal, &rel_pre, &rel_post, spins, radii) else {
        return Err(ImpactError::NotApproaching);
    };
    let a_off = dp - (pb2 - pa2);
    let b_off = dv - rel_post;
    let tau_x = if b_off.norm_squared() > 1e-12 {
        -a_off.dot(&b_off) / b_off.norm_squared()
    } else {
        tau_c
    };
    let Collision {
        e,
        psi1,
        psi2,
        beta,
    } = c;
    Ok(Derived {
        tau_c,
        e,
        normal,
        velocities,
        tau_intersection: tau_x,
        tau_contact_distance: tau_contact,
        closest_mm: closest,
        psi1,
        psi2,
        beta,
    })
}

/// χ² of the relative velocity's change across the split at which flights that never touched
/// would show it by chance once in 16 000 (4σ), for 1, 2 and 3 axes (`velocities_changed`).
/// Why 4σ and not 5: a grazing impact changes the relative velocity least, and its phases are
/// short — seed 105's (offset 0.97, defocused) changed by 78 ± 19, 204 ± 62 and −7 ± 34 mm/s,
/// χ² 28.5 for 3 axes, 4.7σ.
const CHI2_4SIGMA: [f64; 3] = [16.0, 19.33, 22.06];

/// Whether the spheres' relative velocity changed across the split beyond `CHI2_4SIGMA` (χ²
/// over the axes every phase fitted): flights that never touched keep it, up to noise.
fn velocities_changed(fits: &Fits) -> bool {
    // (b after − a after) − (b before − a before).
    super::momentum::combination_chi2(fits, [1.0, -1.0, -1.0, 1.0])
        .is_some_and(|(chi2, dof)| chi2 > CHI2_4SIGMA[dof - 1])
}

/// Variance of a fitted trajectory's position τ after its reference time, per axis (0 where the
/// axis is not fitted).
fn position_variance(f: &SideFit, tau: f64) -> V3 {
    let mut out = V3::zeros();
    for i in 0..3 {
        if let Some(l) = &f.axes[i] {
            let c = &l.cov;
            out[i] = c[(0, 0)] + 2.0 * tau * c[(0, 1)] + tau * tau * c[(1, 1)];
        }
    }
    out
}

/// The impact time and contact normal that fit both sides at once: the separation lines before
/// (P) and after (Q) the impact must meet at a point r at contact distance, so (τ, r) minimise
/// |P(τ) − r|²_A + |Q(τ) − r|²_B with |r| = D, A and B the inverse covariances of the fitted
/// separations (r is taken as their weighted mean moved radially onto |r| = D, exact when the
/// two lines meet). Why both: in a grazing impact the separation closes at only a quarter of the
/// relative speed, so the contact-distance time alone is four times less certain than the
/// line's tangential error, and a small error in it turns the normal by |g_t|·δτ/D. A bias in
/// D moves the two sides' contact times in opposite directions and mostly cancels here.
fn joint_contact(fits: &Fits, g: f64, contact_mm: f64, tau_start: f64) -> (f64, V3) {
    let (tau, n, _) = ContactCost::new(fits, g, contact_mm, tau_start).descend(tau_start);
    (tau, n)
}

/// `joint_contact`'s cost, the sides' weights taken at `tau_start` (so that the costs of
/// searches from different starts compare: `physical_contact`).
struct ContactCost<'a> {
    fits: &'a Fits,
    g: f64,
    contact_mm: f64,
    w_pre: V3,
    w_post: V3,
}

impl<'a> ContactCost<'a> {
    fn new(fits: &'a Fits, g: f64, contact_mm: f64, tau_start: f64) -> ContactCost<'a> {
        // The noise-free floor keeps exact (simulated, zero-residual) fits finite.
        const FLOOR_MM2: f64 = 1e-12;
        let var_pre =
            position_variance(&fits[0], tau_start) + position_variance(&fits[1], tau_start);
        let var_post =
            position_variance(&fits[2], tau_start) + position_variance(&fits[3], tau_start);
        ContactCost {
            fits,
            g,
            contact_mm,
            w_pre: var_pre.map(|v| 1.0 / v.max(FLOOR_MM2)),
            w_post: var_post.map(|v| 1.0 / v.max(FLOOR_MM2)),
        }
    }

    /// The separation b − a of phase pair `k` (0 before, 2 after) at τ.
    fn sep(&self, k: usize, tau: f64) -> V3 {
        pos_vel(&self.fits[k + 1], tau, self.g).0 - pos_vel(&self.fits[k], tau, self.g).0
    }

    /// The cost at τ and the contact point r it is measured against.
    fn at(&self, tau: f64) -> (f64, V3) {
        let (w_pre, w_post) = (&self.w_pre, &self.w_post);
        let (p, q) = (self.sep(0, tau), self.sep(2, tau));
        let m =
            (w_pre.component_mul(&p) + w_post.component_mul(&q)).component_div(&(w_pre + w_post));
        let r = if m.norm() > 0.0 {
            m * (self.contact_mm / m.norm())
        } else {
            m
        };
        let cost = (p - r).component_mul(&(p - r)).dot(w_pre)
            + (q - r).component_mul(&(q - r)).dot(w_post);
        (cost, r)
    }

    /// The minimum the search from `tau_from` reaches: its τ, normal and cost.
    fn descend(&self, tau_from: f64) -> (f64, V3, f64) {
        let mut tau = tau_from;
        // Newton on a smooth 1-D cost, with derivatives by differences over 0.1 µs (impact-time
        // errors are tens of µs); steps are capped at 1 ms so a flat cost cannot throw τ away.
        let h = 1e-7;
        for _ in 0..30 {
            let (f0, f1, f2) = (self.at(tau - h).0, self.at(tau).0, self.at(tau + h).0);
            let d1 = (f2 - f0) / (2.0 * h);
            let d2 = (f2 - 2.0 * f1 + f0) / (h * h);
            if d2.is_nan() || d2 <= 0.0 || !d1.is_finite() {
                break;
            }
            let step = (d1 / d2).clamp(-1e-3, 1e-3);
            tau -= step;
            if step.abs() < 1e-13 {
                break;
            }
        }
        let (cost, r) = self.at(tau);
        if !tau.is_finite() || r.norm() == 0.0 {
            let n = self.sep(0, tau_from) / self.contact_mm;
            return (tau_from, n, f64::INFINITY);
        }
        (tau, r / r.norm(), cost)
    }
}

/// How far either side of where the first search began `physical_contact` looks for other
/// minima of the contact cost, s: the phases end and begin within a few frames of the
/// impact at 1000 fps and more (2105's two minima were 4 ms apart).
const OTHER_CONTACT_WINDOW_S: f64 = 0.010;
/// The grid `physical_contact` samples that cost on, s: minima about a millisecond wide are
/// each seen.
const OTHER_CONTACT_STEP_S: f64 = 0.000_25;

/// Whether the spheres, with relative velocities `rel_pre` and `rel_post` (b − a), approached
/// along the normal `n` (from a to b) before and did not after: what an impact's contact does.
fn turned_back(n: &V3, rel_pre: &V3, rel_post: &V3) -> bool {
    rel_pre.dot(n) < 0.0 && rel_post.dot(n) >= 0.0
}

/// Where `joint_contact`'s contact gives a normal along which the spheres were not approaching
/// before it or still approach after it (no collision's), the other minima of the same cost within
/// `OTHER_CONTACT_WINDOW_S` are tried, and the lowest-cost one along whose normal they
/// approached before and separate after is taken; None if none is. Why: in a grazing impact
/// both sides' lines run nearly parallel and the cost can have two minima of about the same
/// height; on a defocused one (offset 0.97) whose fitted lines before the impact pass 4.9 mm
/// apart (contact at 6.35 mm), the search from where those lines reach contact distance
/// settled 4.4 ms early on a normal 25° off, e −0.31 — or on the right one, 4 ms later,
/// depending on the last bits of the disc fits (docs/accuracy.md, session 32). The contact an impact
/// gives is the one along which the spheres turned back.
fn physical_contact(
    fits: &Fits,
    g: f64,
    contact_mm: f64,
    tau_start: f64,
    rel: (&V3, &V3),
) -> Option<(f64, V3)> {
    let steps = (OTHER_CONTACT_WINDOW_S / OTHER_CONTACT_STEP_S).round() as i64;
    let cost = ContactCost::new(fits, g, contact_mm, tau_start);
    let grid: Vec<(f64, f64)> = (-steps..=steps)
        .map(|k| {
            let tau = tau_start + k as f64 * OTHER_CONTACT_STEP_S;
            (tau, cost.at(tau).0)
        })
        .collect();
    grid.windows(3)
        .filter(|w| w[1].1 <= w[0].1 && w[1].1 <= w[2].1)
        .map(|w| cost.descend(w[1].0))
        .filter(|(tau, n, cost)| {
            tau.is_finite() && cost.is_finite() && turned_back(n, rel.0, rel.1)
        })
        .min_by(|a, b| a.2.total_cmp(&b.2))
        .map(|(tau, n, _)| (tau, n))
}

#[cfg(test)]
mod tests;
