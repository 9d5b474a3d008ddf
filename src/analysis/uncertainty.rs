//! Uncertainty combination: the Jacobian of the fit covariances, the jackknife over frames,
//! and each frame's influence on the four spin fits together (both spheres are measured on one
//! frame, so their spins move together); and where a σ so propagated does not hold (β where
//! ψ1 is near zero).

use super::geometry::View;
use super::kinematics::{
    self, derive, uncertainties, Bodies, Fits, ImpactError, SideFit, Spins, V3,
};
use super::phases::{keep_common_axes, series};
use super::report::{Estimate, Scalar, Vector};
use super::rotation::SpinFit;
use super::tracking::FrameObs;

/// One-sigma uncertainties of everything derived. Propagating the fit covariances assumes each
/// frame's error is independent and alike; a frame that pulls a fit (a centre biased by the
/// neighbouring sphere just before contact, say) breaks that. So the kinematic variance is the
/// mean of the propagated one and a leave-one-frame-out jackknife of the whole derivation; the
/// spin part is added from the spin fits' per-frame influences (`spin_variance`), and each
/// phase's velocity bias its frames may share (`shared_bias`, mm/s per phase and axis: the
/// views' disagreement on x, the misfits the centres' radii show) is moved through the
/// derivation, in full: neither the fit nor the jackknife over frames sees a bias the frames
/// share.
#[allow(clippy::too_many_arguments)]
pub(super) fn combined_uncertainties(
    obs: &[FrameObs],
    views: &[View],
    ph: &[Vec<usize>; 4],
    fits: &Fits,
    spins: Option<[&SpinFit; 4]>,
    bodies: Bodies,
    shared_bias: &[[f64; 3]; 4],
    contact_mm: f64,
    split: f64,
    g: f64,
    masses: Option<[f64; 2]>,
) -> Result<kinematics::Derived, ImpactError> {
    let omega = spins.map(|f| f.map(|f| f.omega));
    // The trajectories' part, with the spins held at their estimates.
    let spins_held = omega.map(|omega| Spins {
        omega,
        cov: [nalgebra::Matrix3::zeros(); 4],
    });
    let kin = uncertainties(fits, spins_held.as_ref(), bodies, contact_mm, g)?;
    let omega = omega.as_ref();
    let mut frames: Vec<usize> = ph.iter().flatten().copied().collect();
    frames.sort_unstable();
    frames.dedup();
    let mut reps: Vec<Vec<f64>> = Vec::new();
    for &k in &frames {
        let without: [Vec<usize>; 4] =
            [0, 1, 2, 3].map(|j| ph[j].iter().copied().filter(|&f| f != k).collect());
        let fk: Fits =
            [0, 1, 2, 3].map(|j| SideFit::fit(&series(obs, views, j % 2, &without[j]), split, g));
        let mut fk = fk;
        keep_common_axes(&mut fk, masses);
        if let Ok(d) = derive(&fk, omega, bodies, contact_mm, g) {
            reps.push(d.to_vec());
        }
    }
    let vk = kin.to_vec();
    let spin_var = match (spins, omega) {
        (Some(measured), Some(omega)) => {
            spin_variance(fits, omega, measured, bodies, contact_mm, g)?
        }
        _ => vec![0.0; vk.len()],
    };
    // Each phase's shared velocity bias, per axis, moved through the derivation.
    let base = derive(fits, omega, bodies, contact_mm, g)?.to_vec();
    let mut view_var = vec![0.0; vk.len()];
    for (k, axis, shift) in (0..4).flat_map(|k| (0..3).map(move |i| (k, i, shared_bias[k][i]))) {
        if !(shift > 0.0 && shift.is_finite()) {
            continue;
        }
        let mut moved = *fits;
        let Some(line) = moved[k].axes[axis].as_mut() else {
            continue;
        };
        line.v += shift;
        if let Ok(d) = derive(&moved, omega, bodies, contact_mm, g) {
            for (v, (a, b)) in view_var.iter_mut().zip(d.to_vec().iter().zip(&base)) {
                *v += (a - b).powi(2);
            }
        }
    }
    let n = reps.len() as f64;
    let mut out = vk.clone();
    for i in 0..vk.len() {
        let jk = (n >= 3.0 && reps.iter().all(|r| r.len() == vk.len())).then(|| {
            let mean = reps.iter().map(|r| r[i]).sum::<f64>() / n;
            ((n - 1.0) / n * reps.iter().map(|r| (r[i] - mean).powi(2)).sum::<f64>()).sqrt()
        });
        // Two estimates of one variance, the fits' covariance and the jackknife over frames:
        // their mean. The larger of the two, as before, is biased high by the choosing, and
        // once the rim dots were masked it covered e 79–87 % of the time in the bench.
        let kinematic = match jk {
            Some(jk) => (vk[i].powi(2) + jk.powi(2)) / 2.0,
            None => vk[i].powi(2),
        };
        out[i] = (kinematic + spin_var[i] + view_var[i]).sqrt();
    }
    Ok(kinematics::Derived::from_vec(&kin, &out))
}

/// The variance the spins give each derived quantity, from the spin fits' influences of each
/// frame taken together: one frame's errors move both spheres' spins of that phase at once,
/// and β and ψ combine the two. Propagating each spin's covariance on its own would leave
/// that covariance out (on the bench it changed β's σ by a few per cent either way).
pub(super) fn spin_variance(
    fits: &Fits,
    omega: &[V3; 4],
    measured: [&SpinFit; 4],
    bodies: Bodies,
    contact_mm: f64,
    g: f64,
) -> Result<Vec<f64>, ImpactError> {
    // Where the spins follow the impulse in `derive`, its own error terms are the velocities'
    // and the normal's, which the fits' part carries with their correlations: not again here.
    let coupled = bodies.impulse.is_some();
    let mut frames: Vec<usize> = measured
        .iter()
        .flat_map(|m| m.frame_influence.iter().map(|(f, _)| *f))
        .filter(|&f| !(coupled && (0..2).any(|s| super::impulse::is_impulse_term(f, s))))
        .collect();
    frames.sort_unstable();
    frames.dedup();
    let base = derive(fits, Some(omega), bodies, contact_mm, g)?.to_vec();
    let len = base.len();
    let mut var = vec![0.0; len];
    for f in frames {
        let step: [V3; 4] = [0, 1, 2, 3].map(|k| {
            measured[k]
                .frame_influence
                .iter()
                .find(|(frame, _)| *frame == f)
                .map_or(V3::zeros(), |(_, d)| *d)
        });
        let moved = |sign: f64| {
            let w = [0, 1, 2, 3].map(|k| omega[k] + sign * step[k]);
            derive(fits, Some(&w), bodies, contact_mm, g)
                .ok()
                .map(|d| d.to_vec())
                .filter(|v| v.len() == len)
        };
        // The mean square of the two moves, each way from the estimate: for a quantity linear
        // in the spins what a central difference gives, and where a term is large against the
        // curvature, its full reach. Why: ψ1 = |g_t|/|g_n| turns back where g_t passes zero, and a
        // central difference across that cancels (an independent render saved as JPEG: b's spin
        // before 853 ± 1458 rad/s, which moves ψ1 by +1.8 one way and +1.4 the other; its
        // central difference 0.2, ψ1 0.66 off at 5.7σ; docs/accuracy.md, session 49).
        if let (Some(up), Some(down)) = (moved(1.0), moved(-1.0)) {
            for i in 0..len {
                var[i] += 0.5 * ((up[i] - base[i]).powi(2) + (down[i] - base[i]).powi(2));
            }
        }
    }
    Ok(var)
}

pub(super) fn spin_estimate(f: &SpinFit) -> Vector {
    let s = |i: usize| f.cov[(i, i)].max(0.0).sqrt();
    Estimate {
        value: [f.omega.x, f.omega.y, f.omega.z],
        uncertainty: [s(0), s(1), s(2)],
    }
}

/// How many of its σ the tangential speed before the impact (ψ1) must lie from zero for β to
/// be reported (`beta_where_defined`).
const BETA_MIN_PSI1_SIGMAS: f64 = 3.0;

/// β with its σ, where it is defined: β = −ψ2/ψ1 (physics.md §1) is a ratio, and its σ,
/// propagated through the derivative at the estimate, holds only while ψ1 is well clear of
/// zero. Where ψ1 lies within `BETA_MIN_PSI1_SIGMAS` of its σ of zero, one spin error moves ψ1
/// and ψ2 together and β anywhere (a near head-on impact of the bench, seed 1111: ψ1 0.29 ±
/// 0.16 for 0.06, β −0.82 ± 0.15 for +0.30, 7σ): then β is null, with a warning. ψ1 and ψ2 are
/// reported as measured either way; a campaign's fit uses them, not β.
pub(super) fn beta_where_defined(
    beta: Option<(f64, f64)>,
    psi1: Option<(f64, f64)>,
    warnings: &mut Vec<String>,
) -> Option<Scalar> {
    let (value, uncertainty) = beta?;
    if let Some((p1, s1)) = psi1 {
        if p1.abs() < BETA_MIN_PSI1_SIGMAS * s1 {
            warnings.push(format!(
                "β is not reported: the tangential speed at contact before the impact, ψ1 = {p1:.3} ± {s1:.3}, is within {BETA_MIN_PSI1_SIGMAS}σ of zero, and β is the ratio of the tangential speeds after and before (ψ1 and ψ2 are reported)"
            ));
            return None;
        }
    }
    Some(Estimate { value, uncertainty })
}

#[cfg(test)]
mod tests;
