//! Momentum across the impact: in the instant of contact only the spheres act on each other, so
//! m_a·Δv_a + m_b·Δv_b = 0 on every axis (gravity changes both alike per unit mass, so the sum
//! is the same at any reference time). The four phases' velocities are fitted apart; this checks
//! them against that (a χ² over the axes) and, where they agree, combines them under it, so that
//! a phase measured poorly (a sphere the other half hides in the mirror after the impact) takes
//! its velocity from the others (physics.md §6).

use super::kinematics::{Fits, SideFit};

/// χ² for 3 degrees of freedom at 3σ (two-sided 99.73 %), and for 2 and 1 (a 2-D result).
const CHI2_3SIGMA: [f64; 3] = [9.0, 11.83, 14.16];

/// Per axis measured in all four phases: Σ A_k·v_k over (a before, b before, a after, b after)
/// and its variance from the fits'. Momentum's residual is A = (−m_a, −m_b, m_a, m_b); the
/// change of the relative velocity across the split (`kinematics`) is A = (1, −1, −1, 1). An
/// axis one phase took from the others' momentum (`phases::keep_common_axes`; no frame, n = 0)
/// is not measured in all four: it holds momentum by construction.
pub(super) fn combination(fits: &Fits, a: [f64; 4]) -> Vec<(usize, f64, f64)> {
    (0..3)
        .filter_map(|i| {
            let lines: Vec<_> = fits.iter().map(|f| f.axes[i]).collect::<Option<_>>()?;
            if lines
                .iter()
                .any(|l: &crate::analysis::line_fit::LineFit| l.n == 0)
            {
                return None;
            }
            let r: f64 = lines.iter().zip(&a).map(|(l, a)| a * l.v).sum();
            let var: f64 = lines
                .iter()
                .zip(&a)
                .map(|(l, a)| a * a * l.cov[(1, 1)])
                .sum();
            (var > 0.0 && var.is_finite()).then_some((i, r, var))
        })
        .collect()
}

/// χ² of `combination` over its axes, and their number; None without an axis.
pub(super) fn combination_chi2(fits: &Fits, a: [f64; 4]) -> Option<(f64, usize)> {
    let res = combination(fits, a);
    (!res.is_empty()).then(|| (res.iter().map(|(_, r, var)| r * r / var).sum(), res.len()))
}

/// The momentum residual's coefficients (`combination`).
fn momentum_coefficients(masses: [f64; 2]) -> [f64; 4] {
    [-masses[0], -masses[1], masses[0], masses[1]]
}

/// The check: χ² of the measured velocities against momentum conservation and its degrees of
/// freedom (the axes measured in all four phases), and whether it passes at 3σ. None without an
/// axis to check.
pub(super) fn check(fits: &Fits, masses: [f64; 2]) -> Option<(f64, usize, bool)> {
    let (chi2, dof) = combination_chi2(fits, momentum_coefficients(masses))?;
    Some((chi2, dof, chi2 <= CHI2_3SIGMA[dof - 1]))
}

/// How the velocities are combined: the masses, and each phase's (p0, v) covariance per axis
/// from the fits that passed the check, held fixed (`conserve`).
#[derive(Clone, Copy, Debug)]
pub struct Momentum {
    masses: [f64; 2],
    /// [phase][axis]: (var v, cov(p0, v)); None where the axis is not in all four phases.
    weights: [[Option<(f64, f64)>; 3]; 4],
}

impl Momentum {
    /// The combination the fits `fits` call for.
    pub(super) fn of(fits: &Fits, masses: [f64; 2]) -> Momentum {
        let mut weights = [[None; 3]; 4];
        for (i, _, _) in combination(fits, momentum_coefficients(masses)) {
            for k in 0..4 {
                weights[k][i] = fits[k].axes[i].map(|l| (l.cov[(1, 1)], l.cov[(0, 1)]));
            }
        }
        Momentum { masses, weights }
    }
}

/// The fits with their velocities combined under momentum conservation: each phase's velocity
/// moved by its share of the residual (weighted least squares under the constraint, each
/// phase's variance its weight), and its position by the part of that move its fit ties to it.
/// The weights are `m`'s, held fixed, so this is a linear function of the fits' values:
/// propagating their covariances through it, and a jackknife re-running it on refits, give its
/// σ. (With each refit's own weights, a refit that lost one of a phase's two frames moved the
/// weights, not the data, and the jackknife doubled σ.)
pub(super) fn conserve(fits: &Fits, m: &Momentum) -> Fits {
    let a = [-m.masses[0], -m.masses[1], m.masses[0], m.masses[1]];
    let mut out: Fits = *fits;
    for i in 0..3 {
        let Some(w): Option<Vec<(f64, f64)>> = m.weights.iter().map(|w| w[i]).collect() else {
            continue;
        };
        let Some(v): Option<Vec<f64>> = fits.iter().map(|f| f.axes[i].map(|l| l.v)).collect()
        else {
            continue;
        };
        let r: f64 = v.iter().zip(&a).map(|(v, a)| a * v).sum();
        let var: f64 = w.iter().zip(&a).map(|((c, _), a)| a * a * c).sum();
        if var <= 0.0 {
            continue;
        }
        for (k, f) in out.iter_mut().enumerate() {
            let SideFit { axes } = f;
            let Some(l) = axes[i].as_mut() else { continue };
            let (c, c01) = w[k];
            let dv = -c * a[k] * r / var;
            if c > 0.0 {
                l.p0 += c01 / c * dv;
            }
            l.v += dv;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::line_fit::LineFit;
    use nalgebra::Matrix2;

    fn line(v: f64, sigma_v: f64) -> Option<LineFit> {
        Some(LineFit {
            p0: 0.0,
            v,
            cov: Matrix2::new(1e-6, 0.0, 0.0, sigma_v * sigma_v),
            rms: 0.0,
            n: 10,
            rejected: 0,
        })
    }

    fn fits(v: [f64; 4], sigma: [f64; 4]) -> Fits {
        [0, 1, 2, 3].map(|k| SideFit {
            axes: [line(v[k], sigma[k]), None, None],
        })
    }

    /// Equal masses, a before 300, b before −300, b after +250 well measured, a after measured
    /// at −230 ± 30 (truth −250): combined, a's velocity after is −250 to within what the three
    /// good phases allow, and its σ (propagated by moving each fit by its own) is theirs.
    #[test]
    fn a_poorly_measured_phase_takes_its_velocity_from_the_others() {
        let sigma = [0.5, 0.5, 30.0, 0.5];
        let f = fits([300.0, -300.0, -230.0, 250.0], sigma);
        let (chi2, dof, ok) = check(&f, [1.0, 1.0]).expect("checked");
        assert_eq!(dof, 1);
        assert!(ok && chi2 < 1.0, "χ² {chi2}");
        let m = Momentum::of(&f, [1.0, 1.0]);
        let c = conserve(&f, &m);
        let v = c[2].axes[0].expect("axis").v;
        assert!((v + 250.0).abs() < 1.0, "a after: {v}");
        // σ by propagation: the combined a-after velocity moves with each input by ∂/∂v_k.
        let mut var = 0.0;
        for k in 0..4 {
            let mut moved = [300.0, -300.0, -230.0, 250.0];
            moved[k] += 1e-3;
            let d = (conserve(&fits(moved, sigma), &m)[2].axes[0]
                .expect("axis")
                .v
                - v)
                / 1e-3;
            var += (d * sigma[k]).powi(2);
        }
        assert!(var.sqrt() < 1.0, "σ {}", var.sqrt());
        // The momentum is conserved exactly afterwards.
        let p: f64 = [-1.0, -1.0, 1.0, 1.0]
            .iter()
            .zip(&c)
            .map(|(a, f)| a * f.axes[0].expect("axis").v)
            .sum();
        assert!(p.abs() < 1e-9, "residual {p}");
    }

    /// Velocities that break momentum conservation by 9.5σ (15 against σ 1.58) fail the check.
    #[test]
    fn velocities_that_break_momentum_fail_the_check() {
        let f = fits([300.0, -300.0, -250.0, 265.0], [0.5, 0.5, 1.0, 1.0]);
        let (chi2, _, ok) = check(&f, [1.0, 1.0]).expect("checked");
        assert!(!ok && (chi2 - 90.0).abs() < 1e-6, "χ² {chi2}");
    }
}
