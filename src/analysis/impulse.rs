//! The impulse–spin cross-check (physics.md §8): for rigid spheres the contact impulse that
//! changes the velocities also fixes the change of spin, Δω_a = (1/(K r_a)) n × Δv_a and
//! Δω_b = (1/(K r_b)) (−n) × Δv_b (n from a to b, I = K m r²). The velocities are measured far
//! more precisely than the spins, so each sphere's marker-measured Δω is checked against the
//! impulse's (χ², 3 degrees of freedom); the post-impact spin is estimated from the markers and
//! from the pre-impact spin plus the impulse together (inverse-covariance weighted), or from the
//! latter alone where the markers after the impact fail (and the pre-impact spin from the
//! post-impact one where they fail before). A sphere whose check fails beyond 3σ has both its
//! spins' uncertainties inflated by √(χ²/3) and widened by the disagreement itself, with a
//! warning: a spin 20σ from the truth is worse than one with an honest, larger σ. Where the
//! check passes, the part of the disagreement beyond twice its expected scatter still widens
//! both spins' reported uncertainties (not the combination).

use super::kinematics::V3;
use super::report::{Estimate, SpinCheck};
use super::rotation::SpinFit;
use nalgebra::Matrix3;

/// χ² for 3 degrees of freedom beyond which the check fails: the 3σ (99.73 %) point.
const CHI2_3SIGMA_3DOF: f64 = 14.16;

/// What the velocities say about one sphere's change of spin.
#[derive(Clone, Copy, Debug)]
pub struct Impulse {
    /// Δω the impulse implies, rad/s, and its covariance.
    pub delta_omega: V3,
    pub cov: Matrix3<f64>,
}

fn cross_matrix(v: V3) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// Δω = (1/(K r)) n × Δv, rad/s, for a sphere of radius `radius_mm` whose velocity changed by
/// `dv` at the contact normal `n_for_sphere` from it towards the other (one formula for the
/// check and for `kinematics::ImpulseCoupling`, so that both give the same bits).
pub fn delta_omega(n_for_sphere: V3, dv: V3, radius_mm: f64, k: f64) -> V3 {
    n_for_sphere.cross(&dv) * (1.0 / (k * radius_mm))
}

/// The impulse's Δω, Δω = (1/(K r)) n × Δv, for a sphere of radius `radius_mm` whose velocity
/// changed by `dv` (per-axis σ `dv_sigma`); `n_for_sphere` is the contact normal from this
/// sphere towards the other (n for a, −n for b), with per-axis σ `n_sigma`.
pub fn predicted(
    n_for_sphere: V3,
    n_sigma: V3,
    dv: V3,
    dv_sigma: V3,
    radius_mm: f64,
    k: f64,
) -> Impulse {
    let scale = 1.0 / (k * radius_mm);
    let c_dv = Matrix3::from_diagonal(&dv_sigma.component_mul(&dv_sigma));
    let c_n = Matrix3::from_diagonal(&n_sigma.component_mul(&n_sigma));
    let nx = cross_matrix(n_for_sphere);
    let dvx = cross_matrix(dv);
    Impulse {
        delta_omega: delta_omega(n_for_sphere, dv, radius_mm, k),
        cov: (nx * c_dv * nx.transpose() + dvx * c_n * dvx.transpose()) * (scale * scale),
    }
}

/// Frame indices used for the impulse's own error terms in `SpinFit::frame_influence`: each
/// is an independent source, like a frame, and must not collide with a real frame.
fn synthetic_frame(sphere: usize, column: usize) -> usize {
    usize::MAX - 8 * sphere - column
}

/// The columns of a covariance's Cholesky factor (C = Σ l lᵀ), or of its diagonal's square root
/// where it is not positive definite.
fn factor(c: &Matrix3<f64>) -> [V3; 3] {
    match c.cholesky() {
        Some(ch) => {
            let l = ch.l();
            [0, 1, 2].map(|i| V3::new(l[(0, i)], l[(1, i)], l[(2, i)]))
        }
        None => [0, 1, 2].map(|i| {
            let mut v = V3::zeros();
            v[i] = c[(i, i)].max(0.0).sqrt();
            v
        }),
    }
}

fn scaled(f: &SpinFit, by: f64) -> SpinFit {
    SpinFit {
        omega: f.omega,
        cov: f.cov * (by * by),
        pairs: f.pairs,
        frame_influence: f
            .frame_influence
            .iter()
            .map(|(k, d)| (*k, d * by))
            .collect(),
    }
}

/// A fit whose covariance also holds `r rᵀ`, as one more independent source of error: the
/// disagreement between markers and impulse lies wholly on whichever spin is wrong, and
/// nothing says which, so each spin gets all of it. Scaling alone (the Birge ratio) keeps the
/// covariance's shape, and a spin wrong along a direction its fit claims to know well (few
/// frames, few markers) stays many σ off after it; this covers the error where it is.
fn widened(f: &SpinFit, r: V3, source: usize) -> SpinFit {
    let mut frame_influence = f.frame_influence.clone();
    frame_influence.push((source, r));
    SpinFit {
        omega: f.omega,
        cov: f.cov + r * r.transpose(),
        pairs: f.pairs,
        frame_influence,
    }
}

/// The part of a disagreement `r` beyond twice the scatter its covariance `c` expects of it
/// along its own direction, as a vector along `r`; None where there is no such part.
fn beyond_twice_the_scatter(r: V3, c: &Matrix3<f64>) -> Option<V3> {
    let n = r.norm();
    if n <= 0.0 || !n.is_finite() {
        return None;
    }
    let u = r / n;
    let scatter = u.dot(&(c * u)).max(0.0);
    let excess = n * n - 4.0 * scatter;
    (excess > 0.0).then(|| u * excess.sqrt())
}

/// `m·ω` of a fit as a fit: influences mapped by `m`.
fn mapped(f: &SpinFit, m: &Matrix3<f64>) -> Vec<(usize, V3)> {
    f.frame_influence.iter().map(|(k, d)| (*k, m * d)).collect()
}

/// Reconciles one sphere's pre- and post-impact spin fits with its impulse. Returns the new
/// pair, the check for the report, and a warning where there is one.
#[cfg(test)]
pub fn reconcile(
    sphere: usize,
    pre: Option<&SpinFit>,
    post: Option<&SpinFit>,
    impulse: &Impulse,
) -> (Option<SpinFit>, Option<SpinFit>, SpinCheck, Option<String>) {
    let (pre, post, check, warning, _) = reconcile_weighted(sphere, pre, post, impulse);
    (pre, post, check, warning)
}

/// The weight of the impulse's Δω in the spins `reconcile` returns (before, after): I for a
/// spin after taken from the one before plus Δω, −I for one before from the one after less Δω,
/// the combination's weight where both were measured, zero where Δω was not used
/// (`kinematics::ImpulseCoupling`).
pub type ImpulseWeights = [Matrix3<f64>; 2];

/// Whether a frame index of a spin's influences is one of the impulse's own error terms (its
/// Δω's covariance, `synthetic_frame` columns 0–2), which `kinematics::ImpulseCoupling`
/// carries through the velocities and the normal instead.
pub fn is_impulse_term(frame: usize, sphere: usize) -> bool {
    (0..3).any(|column| frame == synthetic_frame(sphere, column))
}

/// `reconcile`, with the weight the impulse's Δω has in each spin returned.
pub fn reconcile_weighted(
    sphere: usize,
    pre: Option<&SpinFit>,
    post: Option<&SpinFit>,
    impulse: &Impulse,
) -> (
    Option<SpinFit>,
    Option<SpinFit>,
    SpinCheck,
    Option<String>,
    ImpulseWeights,
) {
    let none = [Matrix3::zeros(); 2];
    let name = ["a", "b"][sphere];
    let extra: Vec<(usize, V3)> = factor(&impulse.cov)
        .iter()
        .enumerate()
        .map(|(i, l)| (synthetic_frame(sphere, i), *l))
        .collect();
    let est = |v: V3, c: &Matrix3<f64>| Estimate {
        value: [v.x, v.y, v.z],
        uncertainty: [0, 1, 2].map(|i| c[(i, i)].max(0.0).sqrt()),
    };
    let mut check = SpinCheck {
        delta_spin_markers_rad_s: None,
        delta_spin_impulse_rad_s: est(impulse.delta_omega, &impulse.cov),
        chi2: None,
        dof: 3,
        spin_post_from: "markers".into(),
        uncertainty_inflated_by: 1.0,
    };
    match (pre, post) {
        (Some(pre), Some(post)) => {
            let d = post.omega - pre.omega;
            let c_meas = pre.cov + post.cov;
            check.delta_spin_markers_rad_s = Some(est(d, &c_meas));
            let r = d - impulse.delta_omega;
            let chi2 = (c_meas + impulse.cov)
                .try_inverse()
                .map(|w| (r.transpose() * w * r)[(0, 0)]);
            check.chi2 = chi2;
            let mut warning = None;
            let (pre, post) = match chi2 {
                Some(x) if x > CHI2_3SIGMA_3DOF => {
                    let by = (x / 3.0).sqrt();
                    check.uncertainty_inflated_by = by;
                    warning = Some(format!(
                        "sphere {name}: the spin change its markers show disagrees with the one the impulse implies (χ² = {x:.1} for 3 degrees of freedom, beyond 3σ): both its spins' uncertainties are inflated ×{by:.1} and widened by the disagreement itself"
                    ));
                    (
                        widened(&scaled(pre, by), r, synthetic_frame(sphere, 3)),
                        widened(&scaled(post, by), r, synthetic_frame(sphere, 4)),
                    )
                }
                _ => (pre.clone(), post.clone()),
            };
            // Within 3σ, the part of the disagreement beyond twice the scatter expected of it
            // along its direction is still taken as an error of one of the spins, the same way
            // (`spin_tracks::fit` treats its models' differences so), but only in what is
            // reported: the spins are combined as before (combined from the widened ones, the
            // spin after leaned on whichever was worse: β's p95 0.088 -> 0.105 on the 190). A
            // check passed at 2.5σ whose disagreement sat on one axis had left that axis's
            // spins 5–6σ off (seed 2131 of the 190 varied-look recordings, specular: a's spin
            // before 8.7 rad/s off about z with σ 1.5).
            let excess = if warning.is_none() {
                beyond_twice_the_scatter(r, &(c_meas + impulse.cov))
            } else {
                None
            };
            let widen = |f: SpinFit, column: usize| match excess {
                Some(e) => widened(&f, e, synthetic_frame(sphere, column)),
                None => f,
            };
            // Two estimates of ω after: the markers', and ω before plus the impulse's Δω.
            let c1 = post.cov;
            let c2 = pre.cov + impulse.cov;
            // Weights from each estimate's variances alone. A spin fit's correlations rest on a
            // few dozen frames and are not to be trusted: on 59 post-impact fits of varied looks
            // the error's Mahalanobis distance was above 3 in 22 (χ₃ expects 3 %), most where
            // the covariance is thin, and full weights trusted the thin direction. The
            // covariance below is still the combination's own, with every correlation in it.
            let diagonal = |c: &Matrix3<f64>| Matrix3::from_diagonal(&c.diagonal());
            let weights = diagonal(&c1)
                .try_inverse()
                .zip(diagonal(&c2).try_inverse())
                .and_then(|(w1, w2)| Some((w1, (w1 + w2).try_inverse()?)));
            let Some((w1, sum_inv)) = weights else {
                return (
                    Some(widen(pre, 3)),
                    Some(widen(post, 4)),
                    check,
                    warning,
                    none,
                );
            };
            let a = sum_inv * w1;
            let b = Matrix3::identity() - a;
            let omega = a * post.omega + b * (pre.omega + impulse.delta_omega);
            let mut influence = mapped(&post, &a);
            for (k, d) in mapped(&pre, &b) {
                match influence.iter_mut().find(|(f, _)| *f == k) {
                    Some((_, e)) => *e += d,
                    None => influence.push((k, d)),
                }
            }
            influence.extend(extra.iter().map(|(k, l)| (*k, b * l)));
            let cov = a * c1 * a.transpose() + b * c2 * b.transpose();
            check.spin_post_from = "markers and impulse".into();
            let post = SpinFit {
                omega,
                cov,
                pairs: post.pairs,
                frame_influence: influence,
            };
            (
                Some(widen(pre, 3)),
                Some(widen(post, 4)),
                check,
                warning,
                [Matrix3::zeros(), b],
            )
        }
        (Some(pre), None) => {
            let mut influence = pre.frame_influence.clone();
            influence.extend(extra);
            check.spin_post_from = "impulse".into();
            let post = SpinFit {
                omega: pre.omega + impulse.delta_omega,
                cov: pre.cov + impulse.cov,
                pairs: 0,
                frame_influence: influence,
            };
            let warning = format!(
                "sphere {name}: too few markers tracked after the impact (none, or under two tracks' worth); its spin after is the spin before plus the change the impulse implies"
            );
            (
                Some(pre.clone()),
                Some(post),
                check,
                Some(warning),
                [Matrix3::zeros(), Matrix3::identity()],
            )
        }
        (None, Some(post)) => {
            let mut influence = post.frame_influence.clone();
            influence.extend(extra.iter().map(|(k, l)| (*k, -l)));
            check.spin_post_from = "markers (the spin before from the impulse)".into();
            let pre = SpinFit {
                omega: post.omega - impulse.delta_omega,
                cov: post.cov + impulse.cov,
                pairs: 0,
                frame_influence: influence,
            };
            let warning = format!(
                "sphere {name}: too few markers tracked before the impact (none, or under two tracks' worth); its spin before is the spin after minus the change the impulse implies"
            );
            (
                Some(pre),
                Some(post.clone()),
                check,
                Some(warning),
                [-Matrix3::identity(), Matrix3::zeros()],
            )
        }
        (None, None) => {
            check.spin_post_from = "not measured".into();
            (None, None, check, None, none)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sum of a fit's influences' outer products: its covariance.
    fn influence_sum(influence: &[(usize, V3)]) -> Matrix3<f64> {
        influence
            .iter()
            .fold(Matrix3::zeros(), |c, (_, d)| c + d * d.transpose())
    }

    /// Each spin, before and after, within `k` of its σ of the truth on every axis, its frames'
    /// influences carrying its covariance.
    fn covered_within(spins: [Option<SpinFit>; 2], truths: [V3; 2], k: f64) {
        for ((got, truth), what) in spins.into_iter().zip(truths).zip(["before", "after"]) {
            let got = got.expect("a spin");
            for i in 0..3 {
                let z = (got.omega[i] - truth[i]) / got.cov[(i, i)].sqrt();
                assert!(z.abs() <= k, "{what}, axis {i}: {z:.1}σ");
            }
            assert!(
                (influence_sum(&got.frame_influence) - got.cov).norm() < 1e-9 * got.cov.norm(),
                "influences carry the covariance"
            );
        }
    }

    /// A fit whose covariance is that of its influences, as `rotation::fit_spin` makes them.
    fn from_influences(omega: V3, pairs: usize, frame_influence: Vec<(usize, V3)>) -> SpinFit {
        SpinFit {
            omega,
            cov: influence_sum(&frame_influence),
            pairs,
            frame_influence,
        }
    }

    /// Independent axes of σ `sigma`, one influence each, on frames `frame`…`frame + 2`.
    fn fit_axes(omega: V3, sigma: V3, frame: usize) -> SpinFit {
        let influence = (0..3)
            .map(|i| {
                let mut d = V3::zeros();
                d[i] = sigma[i];
                (frame + i, d)
            })
            .collect();
        from_influences(omega, 5, influence)
    }

    fn fit(omega: V3, sigma: f64, frame: usize) -> SpinFit {
        fit_axes(omega, V3::repeat(sigma), frame)
    }

    /// A fit whose covariance is long along `long` and thin across it (`across`).
    fn thin_fit(omega: V3, long: V3, across: [V3; 2]) -> SpinFit {
        from_influences(omega, 3, vec![(40, long), (41, across[0]), (42, across[1])])
    }

    /// A rolling-free glancing impulse: n = x, Δv along y spins the sphere about z.
    #[test]
    fn the_impulse_predicts_the_spin_change_and_a_wrong_one_is_inflated() {
        let imp = predicted(
            V3::x(),
            V3::repeat(1e-3),
            V3::new(0.0, 400.0, 0.0),
            V3::repeat(1.0),
            3.175,
            0.4,
        );
        // n × Δv = x × 400 y = 400 z; / (0.4 · 3.175) = 314.96 rad/s.
        assert!((imp.delta_omega - V3::new(0.0, 0.0, 314.96)).norm() < 0.01);
        let pre = fit(V3::new(10.0, -20.0, 30.0), 5.0, 10);
        let good = fit(
            pre.omega + imp.delta_omega + V3::new(2.0, -3.0, 1.0),
            5.0,
            40,
        );
        let (_, post, check, warn) = reconcile(0, Some(&pre), Some(&good), &imp);
        assert!(warn.is_none() && check.chi2.is_some_and(|x| x < 14.16));
        let post = post.expect("combined");
        assert!(
            post.cov[(2, 2)] < good.cov[(2, 2)],
            "two estimates beat one"
        );
        // The z spin's sign flipped, as a marker mismatch does: caught and inflated.
        let flipped = fit(V3::new(10.0, -20.0, -300.0), 5.0, 40);
        let (pre2, post2, check, warn) = reconcile(0, Some(&pre), Some(&flipped), &imp);
        let x = check.chi2.expect("chi2");
        assert!(x > 14.16 && warn.is_some(), "χ² {x}");
        let post2 = post2.expect("post");
        let pre2 = pre2.expect("pre");
        assert!(pre2.cov[(0, 0)] > 10.0 * pre.cov[(0, 0)]);
        let err = (post2.omega.z - (pre.omega.z + imp.delta_omega.z)).abs();
        assert!(
            err / post2.cov[(2, 2)].sqrt() < 5.0,
            "within 5σ after inflation"
        );
    }

    /// A post-impact fit on few frames whose covariance is long and thin (correlations of 0.93
    /// to 0.995, as a fit on three frames with two markers had in session 22) and whose error
    /// lies across it: after the failed check, every axis of both spins must cover its error
    /// within 2σ. Scaling the covariances alone leaves the combined spin after 8.6σ off in x
    /// here (on the recording it came out further off than either estimate it combined).
    #[test]
    fn a_spin_wrong_where_its_fit_claims_precision_is_covered_after_the_check_fails() {
        // Figures like those of that recording (sphere a of the quick sweep at 60°), its error a
        // little larger: the pre fit here has no correlations, so the check is less sharp.
        let truth_pre = V3::new(-7.48, 6.93, -236.62);
        let imp = Impulse {
            delta_omega: V3::new(1.06, -1.40, 22.95),
            cov: Matrix3::from_diagonal(&V3::new(1.83, 0.89, 0.51).map(|s| s * s)),
        };
        let truth_post = truth_pre + V3::new(1.0, -1.33, 22.52);
        let pre = fit_axes(
            truth_pre + V3::new(0.19, -0.16, -1.51),
            V3::new(0.39, 0.66, 1.44),
            10,
        );
        // The long axis of the post fit's covariance, with a little width across it.
        let post = thin_fit(
            truth_post + V3::new(2.6, -1.2, 6.2),
            V3::new(-0.18, 0.117, 1.14),
            [V3::new(0.02, 0.01, 0.0), V3::new(0.0, 0.01, 0.001)],
        );
        let (pre2, post2, check, warn) = reconcile(0, Some(&pre), Some(&post), &imp);
        assert!(
            check.chi2.is_some_and(|x| x > CHI2_3SIGMA_3DOF) && warn.is_some(),
            "χ² {:?}",
            check.chi2
        );
        covered_within([pre2, post2], [truth_pre, truth_post], 2.0);
    }

    /// A post-impact fit with a long, thin covariance (correlations 0.94–0.99) whose error lies
    /// across it, beside a wide impulse side, so that the check passes (as seed offset 7000's
    /// c004 in session 22): the combined spin after must be within 3σ on every axis. With
    /// weights from the full covariances it is 4.4σ off in x here (5.7σ on the recording).
    #[test]
    fn a_thin_covariance_does_not_pull_the_combined_spin_where_the_check_passes() {
        let truth_pre = V3::new(-14.2, 2.6, -84.4);
        let d_omega = V3::new(1.4, -0.8, 10.8);
        let truth_post = truth_pre + d_omega;
        let imp = Impulse {
            delta_omega: d_omega,
            cov: Matrix3::from_diagonal(&V3::new(15.0, 3.0, 6.0).map(|s| s * s)),
        };
        let pre = fit(truth_pre + V3::new(-0.6, 1.8, 1.2), 2.0, 10);
        let post = thin_fit(
            truth_post + V3::new(10.2, -0.5, 4.6),
            V3::new(3.9, 4.4, 4.3),
            [V3::new(0.6, -0.5, 0.0), V3::new(0.0, 0.4, -0.5)],
        );
        let (_, post2, check, warn) = reconcile(0, Some(&pre), Some(&post), &imp);
        assert!(
            check.chi2.is_some_and(|x| x < CHI2_3SIGMA_3DOF) && warn.is_none(),
            "the check passes: χ² {:?}",
            check.chi2
        );
        let got = post2.expect("combined");
        for i in 0..3 {
            let z = (got.omega[i] - truth_post[i]) / got.cov[(i, i)].sqrt();
            assert!(z.abs() <= 3.0, "axis {i}: {z:.1}σ");
        }
    }

    /// A check passed at about 2.5σ whose disagreement lies on one axis (the figures of seed
    /// 2131's sphere a, a specular look, in session 40's 190 recordings): the spin before was
    /// 5.8σ off about z. Widened by the disagreement beyond twice its expected scatter, both
    /// spins cover their errors within 3σ on every axis, their values as without it; a
    /// disagreement within that leaves them as they were.
    #[test]
    fn a_disagreement_the_check_passes_beyond_twice_its_scatter_is_covered() {
        let truth_pre = V3::new(-16.64, -6.14, -162.52);
        let truth_post = V3::new(-16.85, 16.40, -146.83);
        let imp = Impulse {
            delta_omega: V3::new(-0.27, 22.96, 15.50),
            cov: Matrix3::from_diagonal(&V3::new(0.12, 0.94, 0.67).map(|s| s * s)),
        };
        let pre = fit_axes(
            truth_pre + V3::new(1.84, -2.09, 8.68),
            V3::new(0.44, 1.05, 1.49),
            10,
        );
        let post = fit_axes(
            truth_post + V3::new(2.69, -4.05, 2.17),
            V3::new(1.54, 1.60, 1.19),
            40,
        );
        let (pre2, post2, check, warn) = reconcile(0, Some(&pre), Some(&post), &imp);
        // Only the uncertainties widen: the spin after is combined as without it.
        let combined = post2.as_ref().expect("a spin").omega;
        for i in 0..3 {
            let w1 = 1.0 / post.cov[(i, i)];
            let w2 = 1.0 / (pre.cov[(i, i)] + imp.cov[(i, i)]);
            let want = (w1 * post.omega[i] + w2 * (pre.omega[i] + imp.delta_omega[i])) / (w1 + w2);
            assert!(
                (combined[i] - want).abs() < 1e-9,
                "axis {i}: {} against {want}",
                combined[i]
            );
        }
        assert_eq!(pre2.as_ref().expect("a spin").omega, pre.omega);
        assert!(
            check.chi2.is_some_and(|x| x > 7.8 && x < CHI2_3SIGMA_3DOF) && warn.is_none(),
            "the check passes, beyond 2σ: χ² {:?}",
            check.chi2
        );
        covered_within([pre2, post2], [truth_pre, truth_post], 3.0);
        // The same spins agreeing with the impulse to within its scatter: left as they were.
        let close = fit_axes(
            pre.omega + imp.delta_omega + V3::new(0.5, -1.0, 1.0),
            V3::new(1.54, 1.60, 1.19),
            40,
        );
        let (pre3, _, check, _) = reconcile(0, Some(&pre), Some(&close), &imp);
        assert!(check.chi2.is_some_and(|x| x < 3.0), "χ² {:?}", check.chi2);
        assert_eq!(pre3.expect("a spin").cov, pre.cov);
    }

    #[test]
    fn without_markers_after_the_spin_after_comes_from_the_impulse() {
        let imp = predicted(
            V3::x(),
            V3::zeros(),
            V3::new(0.0, 400.0, 0.0),
            V3::repeat(1.0),
            3.175,
            0.4,
        );
        let pre = fit(V3::new(1.0, 2.0, 3.0), 5.0, 10);
        let (_, post, check, warn) = reconcile(1, Some(&pre), None, &imp);
        let post = post.expect("from the impulse");
        assert_eq!(check.spin_post_from, "impulse");
        assert!((post.omega - (pre.omega + imp.delta_omega)).norm() < 1e-9);
        assert!(warn.is_some_and(|w| w.contains("sphere b")));
    }
}
