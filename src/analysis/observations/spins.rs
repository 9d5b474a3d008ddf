//! The spins of the four phases: measured from the markers on centres lifted onto the fitted
//! trajectories, widened by their difference from the first pass's, checked against and
//! combined with what the contact impulse predicts (`impulse`), and withheld where the
//! velocities are 2-D.

use super::super::geometry::View;
use super::super::handedness;
use super::super::impulse;
use super::super::kinematics::{derive, Bodies, Fits, ImpulseCoupling, V3};
use super::super::phases::{self, relift_on_trajectories};
use super::super::report::SpinCheck;
use super::super::rotation::SpinFit;
use super::super::spin::{self, SpinMeasurement};
use super::super::tracking::FrameObs;
use super::super::uncertainty::combined_uncertainties;
use super::Setup;
use crate::config::Config;

const PHASE_NAMES: [&str; 4] = ["a before", "b before", "a after", "b after"];

/// The spins of [a pre, b pre, a post, b post] as measured and as reported.
pub(super) struct PhaseSpins {
    /// What the markers gave, each phase.
    pub(super) measured: Vec<SpinMeasurement>,
    /// What is reported, each phase: the measured spin where it was reportable, reconciled with
    /// the impulse where that could be checked.
    pub(super) reconciled: [Option<SpinFit>; 4],
    /// The impulse–spin check of a and b.
    pub(super) checks: [Option<SpinCheck>; 2],
    /// Where the markers turn as if a view's image were mirrored otherwise than the config
    /// says: which, and how clearly (the spins above are measured so where it is clear, and
    /// widened by the other way's where it is in doubt).
    pub(super) handedness: Option<handedness::Verdict>,
    /// How the reported spins follow the impulse they were reconciled with, for the
    /// derivation and its uncertainties (`kinematics::ImpulseCoupling`); None where no check
    /// was made.
    pub(super) impulse: Option<ImpulseCoupling>,
}

impl PhaseSpins {
    #[allow(clippy::too_many_arguments)]
    pub(super) fn of(
        obs: &[FrameObs],
        views: &[View],
        fits: &Fits,
        ph: &[Vec<usize>; 4],
        split: f64,
        set: &Setup,
        bodies: Bodies,
        shared_bias: &[[f64; 3]; 4],
        cfg: &Config,
        first_pass_spins: [Option<V3>; 4],
        settle_handedness: bool,
        handedness_doubt: Option<&handedness::Verdict>,
        warnings: &mut Vec<String>,
    ) -> PhaseSpins {
        let method = cfg.analysis.rotation;
        let measure = |views: &[View]| -> Vec<SpinMeasurement> {
            let obs_spin = relift_on_trajectories(obs, views, fits, ph, split, set.g, set.radii);
            (0..4)
                .map(|k| {
                    let mut m = spin::measure(&obs_spin, &ph[k], k % 2, method);
                    if let (Some(fit), Some(earlier)) = (m.fit.as_mut(), first_pass_spins[k]) {
                        widen_by_first_pass(fit, earlier, k);
                    }
                    m
                })
                .collect()
        };
        let mut measured = measure(views);
        // A view lifting its markers to the hemisphere it does not see (an image mirrored
        // otherwise than the config says) turns its tracks into the spin's reflection, and the
        // views then disagree about one spin (`handedness`). Where the markers clearly say so,
        // they are lifted again as they turn; where they only lean that way, each spin's σ
        // takes in the other way's; either way the report says which key would settle it.
        // (Checked in the first pass: later runs are given its views and its doubt.)
        let verdict = if settle_handedness {
            handedness::check(&measured, views)
        } else {
            handedness_doubt.cloned()
        };
        if let Some(v) = &verdict {
            let other = measure(&handedness::reflected_views(views, v));
            if v.clear() {
                measured = other;
            } else {
                handedness::widen_by_doubt(&mut measured, &other);
            }
            warnings.push(handedness::warning(v, views));
        }
        // The impulse–spin check (impulse.rs): the velocities' change fixes each sphere's spin
        // change; the spins are checked against it, combined with it, or completed by it.
        let mut reconciled: [Option<SpinFit>; 4] =
            [0, 1, 2, 3].map(|k| measured[k].reportable().cloned());
        let mut checks: [Option<SpinCheck>; 2] = [None, None];
        let k_inertia = cfg.spheres.inertia_factor;
        let mut coupling: Option<ImpulseCoupling> = None;
        // The velocities' and the normal's σ with the jackknife over frames (the propagated
        // covariance alone understated the predicted Δω's scatter about twofold on the bench).
        if let (Ok(d0), Ok(s0)) = (
            derive(fits, None, bodies, set.contact_mm, set.g),
            combined_uncertainties(
                obs,
                views,
                ph,
                fits,
                None,
                bodies,
                shared_bias,
                set.contact_mm,
                split,
                set.g,
                set.masses_known,
            ),
        ) {
            let measured_3d = s0.velocities.iter().all(|v| v.iter().all(|x| *x > 0.0));
            if measured_3d {
                coupling = Some(ImpulseCoupling {
                    inertia_factor: k_inertia,
                    weight: [[nalgebra::Matrix3::zeros(); 2]; 2],
                    delta_omega: [V3::zeros(); 2],
                });
            }
            for s in 0..2 {
                if !measured_3d {
                    break;
                }
                let n = if s == 0 { d0.normal } else { -d0.normal };
                let dv = d0.velocities[2 + s] - d0.velocities[s];
                let dv_sigma = (s0.velocities[s].component_mul(&s0.velocities[s])
                    + s0.velocities[2 + s].component_mul(&s0.velocities[2 + s]))
                .map(f64::sqrt);
                let imp = impulse::predicted(n, s0.normal, dv, dv_sigma, set.radii[s], k_inertia);
                let (pre, post, check, warning, weights) = impulse::reconcile_weighted(
                    s,
                    reconciled[s].as_ref(),
                    reconciled[2 + s].as_ref(),
                    &imp,
                );
                if let Some(c) = coupling.as_mut() {
                    c.weight[s] = weights;
                    c.delta_omega[s] = imp.delta_omega;
                }
                reconciled[s] = pre;
                reconciled[2 + s] = post;
                checks[s] = Some(check);
                warnings.extend(warning);
            }
        }
        // The primary view lost the spheres for a whole phase (they overlap in it, as after an
        // impact at different depths), so that phase came from the other view alone and an axis
        // was lost: the velocities are 2-D, the contact impulse cannot check the markers' spins,
        // and the markers there can be wrong by many times their own σ (validation v03: 20σ).
        // Not reported.
        let axis_lost =
            views.len() == 2 && (0..3).any(|i| fits.iter().all(|f| f.axes[i].is_none()));
        if axis_lost
            && phases::primary_view_lost(obs, split, 0.5 * set.period)
            && reconciled.iter().any(Option::is_some)
        {
            reconciled = [None, None, None, None];
            warnings.push(
                "spins not reported: the direct view lost the spheres for a whole phase, so the velocities are 2-D and the contact impulse cannot check the markers' spins".into(),
            );
        }
        PhaseSpins {
            measured,
            reconciled,
            checks,
            handedness: verdict,
            impulse: coupling,
        }
    }

    /// The four reported spins where every phase has one, else None; with warnings for spins
    /// followed by a search, and for the phases without one.
    pub(super) fn all_four(&self, warnings: &mut Vec<String>) -> Option<[&SpinFit; 4]> {
        let missing: Vec<&str> = (0..4)
            .filter(|&k| self.reconciled[k].is_none())
            .map(|k| PHASE_NAMES[k])
            .collect();
        for (k, m) in self.measured.iter().enumerate() {
            if m.searched && m.reportable().is_some() {
                warnings.push(format!(
                    "sphere {} {} the impact: its markers turned too far between frames to be followed from rest; its spin ({:.0} rad/s) was followed from a search over rotations per frame",
                    ["a", "b"][k % 2],
                    ["before", "after"][k / 2],
                    m.fit.as_ref().map_or(0.0, |f| f.omega.norm()),
                ));
            }
        }
        let fits = match [0, 1, 2, 3].map(|k| self.reconciled[k].as_ref()) {
            [Some(a), Some(b), Some(c), Some(d)] => Some([a, b, c, d]),
            _ => None,
        };
        if fits.is_none() {
            warnings.push(format!(
                "spin not measured for sphere {} the impact (too few markers tracked over too few frames): spins there, beta, psi1, psi2 and branch_hint are null",
                missing.join(", ")
            ));
        }
        fits
    }
}

/// A spin the second pass measured, its difference from the first pass's added to its
/// covariance (in full, along the difference) and to its influences as one more source. Why:
/// the two passes measure the same markers on centres that differ by hundredths of a pixel
/// (the rim dots masked), so their spins should differ by far less than either's σ; where they
/// differ by more, the fit rests on something those hundredths move, which its σ from the
/// tracks' scatter does not see. Seed 3118 of the bench: b's spin after the impact moved by 5.4
/// rad/s between the passes, its σ 1.3 rad/s, and was 7.3 rad/s off (5.5σ; docs/accuracy.md,
/// session 38).
pub(in crate::analysis) fn widen_by_first_pass(fit: &mut SpinFit, earlier: V3, phase: usize) {
    let d = fit.omega - earlier;
    if !d.iter().all(|x| x.is_finite()) || d.norm() == 0.0 {
        return;
    }
    fit.cov += d * d.transpose();
    fit.frame_influence.push((first_pass_source(phase), d));
}

/// The index of the passes' difference among a spin's error sources (`SpinFit::frame_influence`),
/// one per phase: apart from every frame, from `spin_tracks`' model terms (just below
/// `usize::MAX − 64` and about `usize::MAX / 2`), the handedness doubt's (`usize::MAX / 4`) and
/// the impulse's (the top sixteen). Until session 49 it was `usize::MAX − 1 − phase`, two of
/// which are the impulse's own terms of sphere a: where the spins after the impact follow the
/// impulse, `uncertainty::spin_variance` leaves those out (the velocities carry them), and so
/// left out the passes' difference of the spins before it, which moves ψ1 (an independent
/// render saved as JPEG: b's spin before 853 ± 1458 rad/s about z, ψ1 0.66 off at 5.7σ).
pub(in crate::analysis) fn first_pass_source(phase: usize) -> usize {
    usize::MAX / 8 + phase
}
