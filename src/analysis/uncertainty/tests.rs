use super::{beta_where_defined, spin_variance};
use crate::analysis::kinematics::{Fits, Series, SideFit, V3};
use crate::analysis::observations::widen_by_first_pass;
use crate::analysis::rotation::SpinFit;

/// β is reported with ψ1 clear of zero, and left null with a warning that gives ψ1 where
/// ψ1 lies within 3σ of zero (the ratio's propagated σ does not hold there).
#[test]
fn beta_is_null_where_psi1_is_not_clear_of_zero() {
    let mut warnings = Vec::new();
    let kept = beta_where_defined(Some((0.45, 0.02)), Some((0.60, 0.10)), &mut warnings);
    assert_eq!(kept.map(|b| (b.value, b.uncertainty)), Some((0.45, 0.02)));
    assert!(warnings.is_empty());
    let dropped = beta_where_defined(Some((-0.82, 0.15)), Some((0.285, 0.16)), &mut warnings);
    assert!(dropped.is_none());
    assert_eq!(warnings.len(), 1);
    assert!(
        warnings[0].contains("ψ1 = 0.285 ± 0.160"),
        "{}",
        warnings[0]
    );
    // No β, nothing to say.
    assert!(beta_where_defined(None, Some((0.0, 1.0)), &mut warnings).is_none());
    assert_eq!(warnings.len(), 1);
}

/// The four phases' fits of spheres meeting at contact (a at −r, b at +r along x) at t = 0
/// with velocities [a before, b before, a after, b after], mm/s, falling under `g`: 14 exact
/// samples a side, 1 ms apart.
fn noise_free_fits(r: f64, g: f64, v: [V3; 4]) -> Fits {
    let side = |p0: V3, v: V3, sign: f64| {
        let ts: Vec<f64> = (1..15).map(|k| sign * k as f64 * 1e-3).collect();
        let line = |i: usize| -> Series {
            let gi = if i == 1 { -g } else { 0.0 };
            ts.iter()
                .map(|&t| (t, p0[i] + v[i] * t + 0.5 * gi * t * t))
                .collect()
        };
        SideFit::fit(&[line(0), line(1), line(2)], 0.0, g)
    };
    let (pa, pb) = (V3::new(-r, 0.0, 0.0), V3::new(r, 0.0, 0.0));
    [
        side(pa, v[0], -1.0),
        side(pb, v[1], -1.0),
        side(pa, v[2], 1.0),
        side(pb, v[3], 1.0),
    ]
}

/// A spin known exactly: no covariance, no error sources.
fn exact_spin(omega: V3) -> SpinFit {
    SpinFit {
        omega,
        cov: nalgebra::Matrix3::zeros(),
        pairs: 10,
        frame_influence: Vec::new(),
    }
}

/// The passes' difference of a spin before the impact (`widen_by_first_pass`) moves ψ1 in its
/// σ whether or not the spins after follow the impulse: its source is none of the impulse's
/// own terms, which `spin_variance` leaves to the velocities where they do. (Until session 49
/// the sources of phases 0 and 1 were two of sphere a's impulse terms: coupled, ψ1's σ left
/// them out; an independent render saved as JPEG had ψ1 0.66 off at 5.7σ so.)
#[test]
fn the_passes_difference_of_a_spin_before_the_impact_is_in_psi1s_sigma_when_coupled() {
    use crate::analysis::kinematics::{Bodies, ImpulseCoupling};
    use crate::analysis::observations::first_pass_source;
    for phase in 0..4 {
        for sphere in 0..2 {
            assert!(!crate::analysis::impulse::is_impulse_term(
                first_pass_source(phase),
                sphere
            ));
        }
    }
    let g = 9806.65;
    let r = 3.175;
    // An oblique impact, noise-free: b slips past a along y and z.
    let (va, vb) = (V3::new(800.0, 150.0, 20.0), V3::new(-700.0, -100.0, -30.0));
    let (va2, vb2) = (V3::new(-500.0, 100.0, 10.0), V3::new(600.0, -50.0, -20.0));
    let fits = noise_free_fits(r, g, [va, vb, va2, vb2]);
    let omega = [
        V3::new(5.0, -20.0, 40.0),
        V3::new(-10.0, 15.0, -35.0),
        V3::new(5.0, -20.0, 40.0),
        V3::new(-10.0, 15.0, -35.0),
    ];
    let mut spins = omega.map(exact_spin);
    // The passes gave b's spin before 300 rad/s apart about z.
    widen_by_first_pass(&mut spins[1], omega[1] - V3::new(0.0, 0.0, 300.0), 1);
    let plain: Bodies = [r; 2].into();
    let coupled = Bodies {
        impulse: Some(ImpulseCoupling {
            inertia_factor: 0.4,
            weight: [[nalgebra::Matrix3::zeros(); 2]; 2],
            delta_omega: [V3::zeros(); 2],
        }),
        ..plain
    };
    let measured = [&spins[0], &spins[1], &spins[2], &spins[3]];
    let psi1_var = |bodies: Bodies| {
        let v = spin_variance(&fits, &omega, measured, bodies, 2.0 * r, g).unwrap();
        v[v.len() - 3]
    };
    let (p, c) = (psi1_var(plain), psi1_var(coupled));
    assert!(p > 0.01, "a 300 rad/s difference moves ψ1: variance {p}");
    assert!(
        (c - p).abs() <= 1e-9 * p,
        "coupled or not, ψ1's variance from it is the same: {c} against {p}"
    );
}

/// A spin term large against ψ1's curvature reaches ψ1's σ in full (`spin_variance`): near a
/// head-on impact ψ1 = |g_t|/|g_n| grows whichever way a spin error turns the contact, and a
/// central difference across that cancels to nothing. Here b's spin before carries a 100 rad/s
/// term about z, which moves ψ1 from 0 to 317.5/1500 either way.
#[test]
fn a_large_spin_term_reaches_psi1s_sigma_where_psi1_turns_back() {
    let g = 9806.65;
    let r = 3.175;
    let (va, vb) = (V3::new(800.0, 0.0, 0.0), V3::new(-700.0, 1e-3, 0.0));
    let (va2, vb2) = (V3::new(-600.0, 0.0, 0.0), V3::new(700.0, 1e-3, 0.0));
    let fits = noise_free_fits(r, g, [va, vb, va2, vb2]);
    let omega = [V3::zeros(); 4];
    let mut spins = omega.map(exact_spin);
    let term = V3::new(0.0, 0.0, 100.0);
    spins[1].cov = term * term.transpose();
    spins[1].frame_influence.push((7, term));
    let measured = [&spins[0], &spins[1], &spins[2], &spins[3]];
    let v = spin_variance(&fits, &omega, measured, [r; 2].into(), 2.0 * r, g).unwrap();
    let psi1_sigma = v[v.len() - 3].sqrt();
    let reach = 100.0 * r / 1500.0;
    assert!(
        (psi1_sigma - reach).abs() < 0.01 * reach,
        "ψ1's σ from the term {psi1_sigma:.4}, its reach {reach:.4}"
    );
}
