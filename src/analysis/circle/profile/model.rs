//! The disc's edge and shading averaged over a box across the edge: the logistic step's
//! integral (softplus) and the mean of a lamp-lit sphere's shading over a range of radii.

/// The logistic step l(x) = 1/(1 + e^{−x/s}), its integral sp(x) = s·ln(1 + e^{x/s}) and
/// ∂sp/∂s, from one exponential and without overflow for any x/s.
pub(super) fn softplus(x: f64, s: f64) -> (f64, f64, f64) {
    let e = (-x.abs() / s).exp();
    let l = if x >= 0.0 {
        1.0 / (1.0 + e)
    } else {
        e / (1.0 + e)
    };
    let sp = s * ln_1p_unit(e) + x.max(0.0);
    (l, sp, sp / s - l * x / s)
}

/// ln(1 + e) for e in [0, 1], to a few ulp, at a fraction of `f64::ln_1p`'s cost (libm's log1p
/// was 15 % of the whole analysis, called twice for every sample of every fit). Below 1e-4
/// (most samples off a sharp edge) four terms of the series, whose next term is below e·2e-17;
/// above, Goldberg's ln(u)·e/(u − 1) with u = 1 + e rounded, which cancels u's rounding.
fn ln_1p_unit(e: f64) -> f64 {
    if e < 1e-4 {
        e * (1.0 - e * (0.5 - e * (1.0 / 3.0 - 0.25 * e)))
    } else {
        let u = 1.0 + e;
        u.ln() * (e / (u - 1.0))
    }
}

/// The mean over a box of a lit sphere's shading and its derivatives (`mean_lit`).
pub(super) struct LitMean {
    pub(super) mean: f64,
    pub(super) d_rho0: f64,
    pub(super) d_rho1: f64,
    pub(super) d_lamp: f64,
}

/// The mean of max(0, g(ρ)), g = λ·ρ + √(1 − ρ²), over ρ from `rho1` to `rho0` (ρ₁ ≤ ρ₀): a
/// matte sphere's shading along one radius, λ the lamp's slope along it. Exact, through
/// F(ρ) = (ρ·√(1 − ρ²) + asin ρ)/2 (F' = √(1 − ρ²)): g falls with ρ where λ < 0 and is zero
/// at the terminator ρ* = 1/√(1 + λ²), beyond which nothing is lit. The mean is smooth in
/// ρ₀, ρ₁ and λ (at the terminator g = 0, so moving it changes nothing to first order). Over a
/// span too short to difference (the box outside the sphere, where the step is flat anyway),
/// g at its middle, without derivatives.
pub(super) fn mean_lit(rho0: f64, rho1: f64, lamp: f64) -> LitMean {
    let nz = |rho: f64| (1.0 - rho * rho).max(0.0).sqrt();
    let g = |rho: f64| lamp * rho + nz(rho);
    let span = rho0 - rho1;
    if span < 1e-6 {
        return LitMean {
            mean: g(0.5 * (rho0 + rho1)).max(0.0),
            d_rho0: 0.0,
            d_rho1: 0.0,
            d_lamp: 0.0,
        };
    }
    let top = if lamp < 0.0 {
        rho0.min(1.0 / (1.0 + lamp * lamp).sqrt())
    } else {
        rho0
    };
    if top <= rho1 {
        return LitMean {
            mean: 0.0,
            d_rho0: 0.0,
            d_rho1: 0.0,
            d_lamp: 0.0,
        };
    }
    // F(top) − F(ρ₁) with each √ taken once, and the two asins' difference as one asin where
    // both radii are ≥ 0 (always, in the band): asin a − asin b = asin(a√(1 − b²) − b√(1 − a²))
    // for 0 ≤ b ≤ a ≤ 1, the difference then within [0, π/2]. (This function and its asins
    // were a fifth of the fit's time.)
    let (n_top, n1) = (nz(top), nz(rho1));
    let arcs = if rho1 >= 0.0 {
        (top * n1 - rho1 * n_top).clamp(-1.0, 1.0).asin()
    } else {
        top.asin() - rho1.asin()
    };
    let integral = 0.5 * (top * n_top - rho1 * n1 + arcs) + 0.5 * lamp * (top * top - rho1 * rho1);
    let inv_span = 1.0 / span;
    let mean = integral * inv_span;
    // Where the terminator does not cut the span, top = ρ₀.
    let g_top = if top < rho0 { 0.0 } else { lamp * rho0 + n_top };
    LitMean {
        mean,
        d_rho0: (g_top - mean) * inv_span,
        d_rho1: (mean - (lamp * rho1 + n1)) * inv_span,
        d_lamp: 0.5 * (top * top - rho1 * rho1) * inv_span,
    }
}

#[cfg(test)]
mod tests {
    use super::{mean_lit, softplus};

    /// The box averages' derivatives, on which the fit's steps rest, against central
    /// differences: through the limb, across the terminator, and deep inside.
    #[test]
    fn box_averages_have_the_derivatives_they_claim() {
        let h = 1e-6;
        for (x, s) in [(-0.4, 0.05), (0.0, 0.3), (0.2, 0.05), (1.5, 0.8)] {
            let (l, sp, dsp_ds) = softplus(x, s);
            let dx = (softplus(x + h, s).1 - softplus(x - h, s).1) / (2.0 * h);
            let ds = (softplus(x, s + h).1 - softplus(x, s - h).1) / (2.0 * h);
            assert!((dx - l).abs() < 1e-6, "x {x}, s {s}: sp' {dx} vs l {l}");
            assert!(
                (ds - dsp_ds).abs() < 1e-6,
                "x {x}, s {s}: ∂sp/∂s {ds} vs {dsp_ds}"
            );
            assert!(sp >= x.max(0.0));
        }
        // (ρ₀, ρ₁, λ): a box reaching the limb, one across a side lamp's terminator
        // (ρ* = 1/√1.36 ≈ 0.857), one inside lit from the front, one wholly past the terminator.
        for (rho0, rho1, lamp) in [
            (0.999, 0.95, 0.0),
            (0.9, 0.8, -0.6),
            (0.6, 0.5, 0.3),
            (0.99, 0.95, -2.0),
        ] {
            let m = mean_lit(rho0, rho1, lamp);
            let num = |f: &dyn Fn(f64) -> f64, v: f64| (f(v + h) - f(v - h)) / (2.0 * h);
            let d0 = num(&|r| mean_lit(r, rho1, lamp).mean, rho0);
            let d1 = num(&|r| mean_lit(rho0, r, lamp).mean, rho1);
            let dl = num(&|l| mean_lit(rho0, rho1, l).mean, lamp);
            let ok = |a: f64, b: f64| (a - b).abs() < 1e-4 * (1.0 + b.abs());
            assert!(
                ok(d0, m.d_rho0) && ok(d1, m.d_rho1) && ok(dl, m.d_lamp),
                "ρ₀ {rho0}, ρ₁ {rho1}, λ {lamp}: numeric ({d0}, {d1}, {dl}) vs ({}, {}, {})",
                m.d_rho0,
                m.d_rho1,
                m.d_lamp
            );
            // The mean lies within the shading's range over the box.
            assert!(m.mean >= 0.0 && m.mean <= 1.0 + lamp.abs());
        }
        // Past the terminator nothing is lit.
        assert_eq!(mean_lit(0.99, 0.95, -2.0).mean, 0.0);
    }

    /// The cheaper ln(1 + e) agrees with libm's to a few ulp over [0, 1], on both sides of the
    /// switch from the series to Goldberg's formula and at the ends.
    #[test]
    fn ln_1p_unit_matches_libm() {
        let mut e: f64 = 1e-300;
        let mut worst: f64 = 0.0;
        while e <= 1.0 {
            for x in [
                e,
                e * 1.37,
                1e-4 * (1.0 - 1e-12),
                1e-4,
                1e-4 * (1.0 + 1e-12),
                1.0,
            ] {
                let x = x.min(1.0);
                let exact = x.ln_1p();
                worst = worst.max(((super::ln_1p_unit(x) - exact) / exact).abs());
            }
            e *= 1.9;
        }
        assert!(worst < 1e-15, "relative error {worst:e}");
        assert_eq!(super::ln_1p_unit(0.0), 0.0);
    }
}
