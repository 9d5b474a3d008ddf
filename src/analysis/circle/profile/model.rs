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

/// The shading's rise inside a blurred edge and its derivatives (`blurred_rise`).
pub(super) struct BlurredRise {
    pub(super) rise: f64,
    pub(super) d_x: f64,
    pub(super) d_s: f64,
    pub(super) d_r: f64,
    pub(super) d_lamp: f64,
}

/// Gauss–Legendre nodes and weights on [−1, 1], twelve of them.
const GL12: [(f64, f64); 12] = [
    (-0.981_560_634_246_719_2, 0.047_175_336_386_511_83),
    (-0.904_117_256_370_474_8, 0.106_939_325_995_318_18),
    (-0.769_902_674_194_304_7, 0.160_078_328_543_346_33),
    (-0.587_317_954_286_617_5, 0.203_167_426_723_065_84),
    (-0.367_831_498_998_180_2, 0.233_492_536_538_354_78),
    (-0.125_233_408_511_468_9, 0.249_147_045_813_402_88),
    (0.125_233_408_511_468_9, 0.249_147_045_813_402_88),
    (0.367_831_498_998_180_2, 0.233_492_536_538_354_78),
    (0.587_317_954_286_617_5, 0.203_167_426_723_065_84),
    (0.769_902_674_194_304_7, 0.160_078_328_543_346_33),
    (0.904_117_256_370_474_8, 0.106_939_325_995_318_18),
    (0.981_560_634_246_719_2, 0.047_175_336_386_511_83),
];

/// The blur of a lit sphere's shading rise under its limb, averaged over a box: ∫ K(x − t)
/// ΔG(t) dt over the depth t ≥ 0 below the limb, where ΔG(t) = G(ρ) − G(1) with
/// G(ρ) = max(0, λ·ρ + √(1 − ρ²)) and ρ = 1 − t/R, and K is the logistic step's density (width
/// s) averaged over a box of width h across the edge: the same kernel whose integral is the
/// step `softplus` averages. Why: the step times the shading at the blurred depth (`mean_lit`)
/// is the blur of their product only where the shading is flat; a lit limb's shading rises as
/// √t, and a lamp a few degrees off the axis put blurred discs' centres 0.03–0.1 px away from
/// it (docs/accuracy.md, session 36). By quadrature in u = √t (which takes out the √ at the
/// limb) over the kernel's reach, x ± (h/2 + 6s).
pub(super) fn blurred_rise(x: f64, h: f64, s: f64, r: f64, lamp: f64) -> BlurredRise {
    let mut out = BlurredRise {
        rise: 0.0,
        d_x: 0.0,
        d_s: 0.0,
        d_r: 0.0,
        d_lamp: 0.0,
    };
    let reach = 0.5 * h + 6.0 * s;
    let t_hi = x + reach;
    if t_hi <= 0.0 {
        return out;
    }
    let (u_lo, u_hi) = ((x - reach).max(0.0).sqrt(), t_hi.sqrt());
    let g_limb = lamp.max(0.0);
    let lit_limb = if lamp > 0.0 { 1.0 } else { 0.0 };
    let inv_h = 1.0 / h;
    let inv_s = 1.0 / s;
    // The logistic L(z) = 1/(1 + e^{−z/s}), its density L(1 − L)/s and ∂L/∂s = −z·L(1 − L)/s²,
    // from e = e^{−|z|/s}.
    let logistic = |z: f64, e: f64| {
        let l = if z >= 0.0 {
            1.0 / (1.0 + e)
        } else {
            e / (1.0 + e)
        };
        let k = l * (1.0 - l) * inv_s;
        (l, k, -z * k * inv_s)
    };
    // The kernel's two ends, z ± h/2, lie on one side of zero at most nodes, where their
    // exponentials differ by the factor e^{−h/s}: one exponential a node there instead of two
    // (the exponentials were a quarter or more of this quadrature's cost, and it is most of a
    // blurred disc's).
    let across = (-h * inv_s).exp();
    let ends = |z: f64| {
        let (hi, lo) = (z + 0.5 * h, z - 0.5 * h);
        let (e_hi, e_lo) = if lo >= 0.0 {
            let e = (-lo * inv_s).exp();
            (e * across, e)
        } else if hi <= 0.0 {
            let e = (hi * inv_s).exp();
            (e, e * across)
        } else {
            ((-hi * inv_s).exp(), (lo * inv_s).exp())
        };
        (logistic(hi, e_hi), logistic(lo, e_lo))
    };
    // ΔG at depth t, ∂ΔG/∂λ and ∂G/∂ρ. Past the far limb (t > 2R: the kernel of a pixel near
    // the middle of a small, much blurred disc reaches there) ρ stays at −1 and G no longer
    // changes with it; ∂G/∂ρ there was −1/n_z with n_z = 0, 10¹² (through ∂ρ/∂R, a column of
    // JᵀJ of 10²¹, whose ridge then made the disc's centre σ 10⁻⁵ px for a fit 1.3 px off).
    let rise_at = |t: f64| {
        let raw = 1.0 - t / r;
        let rho = raw.max(-1.0);
        let nz = (1.0 - rho * rho).max(0.0).sqrt();
        let g = lamp * rho + nz;
        if g > 0.0 {
            let d_rho = if raw > -1.0 {
                lamp - rho / nz.max(1e-12)
            } else {
                0.0
            };
            (g - g_limb, rho, d_rho)
        } else {
            (-g_limb, 0.0, 0.0)
        }
    };
    // The kernel at x − t: its value, ∂/∂x and ∂/∂s.
    let kernel = |t: f64| {
        let ((l1, k1, s1), (l0, k0, s0)) = ends(x - t);
        ((l1 - l0) * inv_h, (k1 - k0) * inv_h, (s1 - s0) * inv_h)
    };
    // The reach's ends move with x and s: what the kernel leaves there (e^{−6} of it) counts in
    // the derivatives, as the quadrature itself moves with them.
    let end = |t: f64| kernel(t).0 * rise_at(t).0;
    out.d_x += end(t_hi);
    out.d_s += 6.0 * end(t_hi);
    if x - reach > 0.0 {
        out.d_x -= end(x - reach);
        out.d_s += 6.0 * end(x - reach);
    }
    // The shading has a kink where a side lamp's terminator crosses this radius (beyond it
    // nothing is lit) and another at the far limb (depth 2R, where n_z returns to 0 and ρ
    // stops): the quadrature is split at each, each side smooth.
    let u_kink = (lamp < 0.0)
        .then(|| (r * (1.0 - 1.0 / (1.0 + lamp * lamp).sqrt())).sqrt())
        .filter(|&u| u > u_lo && u < u_hi);
    let u_far = Some((2.0 * r).sqrt()).filter(|&u| u > u_lo && u < u_hi);
    let (k0, k1) = match (u_kink, u_far) {
        (Some(a), Some(b)) => (a.min(b), a.max(b)),
        (Some(a), None) | (None, Some(a)) => (a, a),
        (None, None) => (u_hi, u_hi),
    };
    for (a, b) in [(u_lo, k0), (k0, k1), (k1, u_hi)] {
        if b <= a {
            continue;
        }
        let (mid, half) = (0.5 * (b + a), 0.5 * (b - a));
        for (node, weight) in GL12 {
            let u = mid + half * node;
            let t = u * u;
            let w = weight * half * 2.0 * u;
            let (dg, g_dlamp, g_drho) = rise_at(t);
            let (kern, k_dx, k_ds) = kernel(t);
            out.rise += w * kern * dg;
            out.d_x += w * k_dx * dg;
            out.d_s += w * k_ds * dg;
            // ∂ρ/∂R = t/R².
            out.d_r += w * kern * g_drho * t / (r * r);
            out.d_lamp += w * kern * (g_dlamp - lit_limb);
        }
    }
    out
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

    /// `blurred_rise`'s derivatives against central differences (across the limb, inside, past
    /// a side lamp's terminator, with a box and with a strip), and its limits: nothing far
    /// outside the disc, and deep inside the shading's own rise at that depth (the blur of a
    /// smooth function over a kernel much narrower than its curvature).
    #[test]
    fn the_blurred_rise_has_the_derivatives_it_claims_and_its_limits() {
        let h = 1e-6;
        let r = 6.85;
        for (x, bw, s, lamp) in [
            (0.0, 1.0, 0.6, 0.18),
            (-0.8, 1.0, 0.3, 0.05),
            (1.5, 1.0 / 3.0, 0.4, -0.6),
            (3.0, 1.0, 0.2, 0.36),
            // A pixel near the middle of a small, much blurred disc: the kernel reaches past
            // the far limb (depth 2R), where the shading no longer changes with R.
            (5.3, 1.0, 1.45, 0.3),
            (6.0, 1.0, 1.2, -0.4),
        ] {
            let b = super::blurred_rise(x, bw, s, r, lamp);
            let num = |f: &dyn Fn(f64) -> f64, v: f64| (f(v + h) - f(v - h)) / (2.0 * h);
            let dx = num(&|v| super::blurred_rise(v, bw, s, r, lamp).rise, x);
            let ds = num(&|v| super::blurred_rise(x, bw, v, r, lamp).rise, s);
            let dr = num(&|v| super::blurred_rise(x, bw, s, v, lamp).rise, r);
            let dl = num(&|v| super::blurred_rise(x, bw, s, r, v).rise, lamp);
            // (The kernel's reach moves with x and s; what lies beyond it is below 1e-3.)
            let ok = |a: f64, c: f64| (a - c).abs() < 2e-3 * (1.0 + c.abs());
            assert!(
                ok(dx, b.d_x) && ok(ds, b.d_s) && ok(dr, b.d_r) && ok(dl, b.d_lamp),
                "x {x}, s {s}, λ {lamp}: numeric ({dx}, {ds}, {dr}, {dl}) vs ({}, {}, {}, {})",
                b.d_x,
                b.d_s,
                b.d_r,
                b.d_lamp
            );
        }
        assert_eq!(super::blurred_rise(-10.0, 1.0, 0.5, r, 0.2).rise, 0.0);
        let deep = 4.0;
        let rho = 1.0 - deep / r;
        let g = 0.2 * rho + (1.0 - rho * rho).sqrt() - 0.2;
        let b = super::blurred_rise(deep, 1.0, 0.1, r, 0.2);
        assert!((b.rise - g).abs() < 0.01, "{} vs {g}", b.rise);
    }
}
