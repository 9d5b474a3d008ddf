//! First-order propagation of the fit covariances (and the spins' where given) through a
//! numerical Jacobian of everything `derive` gives: the fits' own part of every σ, which
//! `uncertainty` combines with the jackknife, the spins' influences and the shared biases.

use super::{derive, Bodies, Derived, Fits, ImpactError, Spins, V3};
use nalgebra::DMatrix;

/// The fits' (and spins') parameters as one vector: each measured axis's p0 and v, in order,
/// then the four spins.
pub(super) fn params(fits: &Fits, spins: Option<&[V3; 4]>) -> Vec<f64> {
    let mut p = Vec::new();
    for f in fits {
        for l in f.axes.iter().flatten() {
            p.push(l.p0);
            p.push(l.v);
        }
    }
    for w in spins.iter().flat_map(|s| s.iter()) {
        p.extend_from_slice(w.as_slice());
    }
    p
}

/// `fits` and `spins` with their parameters set from `p` (`params`' order).
pub(super) fn with_params(
    fits: &Fits,
    spins: Option<&[V3; 4]>,
    p: &[f64],
) -> (Fits, Option<[V3; 4]>) {
    let mut out = *fits;
    let mut k = 0;
    for f in out.iter_mut() {
        for l in f.axes.iter_mut().flatten() {
            l.p0 = p[k];
            l.v = p[k + 1];
            k += 2;
        }
    }
    let spins = spins
        .map(|_| [0, 1, 2, 3].map(|i| V3::new(p[k + 3 * i], p[k + 3 * i + 1], p[k + 3 * i + 2])));
    (out, spins)
}

/// One-sigma uncertainties of everything in `Derived`, by first-order propagation of the fit
/// covariances (fits are independent of each other).
pub fn uncertainties(
    fits: &Fits,
    spins: Option<&Spins>,
    bodies: impl Into<Bodies>,
    contact_mm: f64,
    g: f64,
) -> Result<Derived, ImpactError> {
    let bodies: Bodies = bodies.into();
    let omega = spins.map(|s| &s.omega);
    let base = derive(fits, omega, bodies, contact_mm, g)?;
    let p = params(fits, omega);
    let mut cov = DMatrix::<f64>::zeros(p.len(), p.len());
    let mut k = 0;
    for f in fits {
        for l in f.axes.iter().flatten() {
            for (i, j) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
                cov[(k + i, k + j)] = l.cov[(i, j)];
            }
            k += 2;
        }
    }
    for c in spins.iter().flat_map(|s| s.cov.iter()) {
        for i in 0..3 {
            for j in 0..3 {
                cov[(k + i, k + j)] = c[(i, j)];
            }
        }
        k += 3;
    }
    let y0 = base.to_vec();
    let mut jac = DMatrix::<f64>::zeros(y0.len(), p.len());
    for j in 0..p.len() {
        let h = (cov[(j, j)].sqrt() * 1e-3).max(1e-9);
        let eval = |delta: f64| {
            let mut q = p.clone();
            q[j] += delta;
            let (f, w) = with_params(fits, omega, &q);
            derive(&f, w.as_ref(), bodies, contact_mm, g)
                .ok()
                .map(|d| d.to_vec())
                .filter(|v| v.len() == y0.len())
        };
        let col: Option<Vec<f64>> = match (eval(h), eval(-h)) {
            (Some(a), Some(b)) => {
                Some(a.iter().zip(&b).map(|(x, y)| (x - y) / (2.0 * h)).collect())
            }
            (Some(a), None) => Some(a.iter().zip(&y0).map(|(x, y)| (x - y) / h).collect()),
            (None, Some(b)) => Some(y0.iter().zip(&b).map(|(x, y)| (x - y) / h).collect()),
            (None, None) => None,
        };
        if let Some(col) = col {
            for (i, v) in col.into_iter().enumerate() {
                jac[(i, j)] = v;
            }
        }
    }
    let out_cov = &jac * cov * jac.transpose();
    let s: Vec<f64> = (0..y0.len())
        .map(|i| out_cov[(i, i)].max(0.0).sqrt())
        .collect();
    let v3 = |i: usize| V3::new(s[i], s[i + 1], s[i + 2]);
    Ok(Derived {
        tau_c: s[0],
        e: s[1],
        normal: v3(2),
        velocities: [v3(5), v3(8), v3(11), v3(14)],
        tau_intersection: s[17],
        tau_contact_distance: 0.0,
        closest_mm: 0.0,
        psi1: base.psi1.map(|_| s[18]),
        psi2: base.psi2.map(|_| s[19]),
        beta: base.beta.map(|_| s[20]),
    })
}
