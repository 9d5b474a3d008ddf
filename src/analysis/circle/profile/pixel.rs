//! The grey-level model of one or two discs at one pixel of a ring, and its derivatives: the
//! logistic step averaged over a box across the edge, times the shading (or, on a blurred lone
//! disc, with the shading's rise blurred with it), summed or one disc hiding the other, and
//! the pixel's area in strips where an edge crosses it, or over the exposure where the discs
//! moved while the shutter was open. `fit` fits it.

use super::dist;
use super::fit::{Layering, DISC_PARAMS};
use super::model::{blurred_rise, mean_lit, softplus};
use super::ring::{RingPixel, STRIP_OFFSETS};

type Vp<const P: usize> = nalgebra::SVector<f64, P>;

/// How the discs of one fit combine, and what that leaves out of the model (`fit_grey_levels`).
pub(super) struct PixelModel {
    pub(super) layering: Layering,
    /// A disc hides another (two discs, `Layering::InFront`): its step's own derivatives are
    /// needed.
    pub(super) hiding: bool,
    /// The disc behind another, which has no harmonic of its own (its lamp is the front
    /// disc's: `fit_grey_levels`).
    pub(super) back_disc: Option<usize>,
    /// A lone disc's shading rise blurred with its edge (`blurred_rise`).
    pub(super) convolved: bool,
    /// How far each disc moved over the exposure, px (zero for none, and for a second disc
    /// the fit does not have), and the instants of the exposure the model is averaged over
    /// (1: none, the disc still).
    smear_px: [[f64; 2]; 2],
    smear_instants: usize,
}

/// Instants of the exposure per pixel of the longest smear (`PixelModel::eval`), and at most:
/// a quarter of a pixel apart, as hw-sim draws a streak. A disc smeared by 3–4 px lit from 30°
/// off the axis (`circle::tests::lone::a_disc_smeared_over_the_exposure_is_fitted_as_smeared`): 12
/// instants left its centre within 0.01 px on average where the round model put it 0.06–0.19
/// px off, and a round model with the smear added to the edge's width (its variance) 0.02–0.04.
const SMEAR_INSTANTS_PER_PX: f64 = 4.0;
const SMEAR_INSTANTS_MAX: usize = 16;

impl PixelModel {
    pub(super) fn new<const N: usize>(
        layering: Layering,
        hiding: bool,
        back_disc: Option<usize>,
        convolved: bool,
        smears_px: &[[f64; 2]; N],
    ) -> PixelModel {
        let mut smear_px = [[0.0; 2]; 2];
        for (k, s) in smears_px.iter().enumerate().take(2) {
            smear_px[k] = *s;
        }
        let longest = smear_px
            .iter()
            .map(|s| s[0].hypot(s[1]))
            .fold(0.0, f64::max);
        let smear_instants = if longest > 0.0 {
            ((longest * SMEAR_INSTANTS_PER_PX).ceil() as usize).clamp(2, SMEAR_INSTANTS_MAX)
        } else {
            1
        };
        PixelModel {
            layering,
            hiding,
            back_disc,
            convolved,
            smear_px,
            smear_instants,
        }
    }

    /// The model at point (u, v) averaged over a box of sides `sides` across the edge, and its
    /// derivatives in the parameters `p` (see `fit_grey_levels`).
    ///
    /// `hidden`: the backdrop a disc hides at this pixel (`RingPixel::hidden`). A disc replaces
    /// what is behind it, and the normalisation subtracted that from every pixel, so a disc's
    /// term is its step times its shading less what it hides: over a flat ground the same, over
    /// a tube end or a ruler the occlusion a sum of terms would miss (spheres crossing a ruler
    /// came out up to 1.2 px off, and the tube ends' edges pulled centres 0.1–0.5 px).
    fn at_point<const P: usize, const N: usize>(
        &self,
        p: &Vp<P>,
        u: f64,
        v: f64,
        sides: [f64; 2],
        hidden: f64,
        instant: f64,
    ) -> (f64, Vp<P>) {
        // Per disc: its term l·inner, the term's derivatives, and l's own (for hiding).
        let mut term = [0.0; N];
        let mut d_term = [Vp::<P>::zeros(); N];
        let mut step = [0.0; N];
        let mut d_step = [Vp::<P>::zeros(); N];
        for k in 0..N {
            let o = 1 + DISC_PARAMS * k;
            // At `instant` (a fraction of the exposure from its middle) the disc stood that
            // much of its smear away from its centre, the frame's mid-exposure one.
            let (du, dv) = (
                u - p[o] - self.smear_px[k][0] * instant,
                v - p[o + 1] - self.smear_px[k][1] * instant,
            );
            let d = dist(du, dv).max(1e-9);
            // (Reciprocals taken once: divisions were a tenth of this function's time.)
            let inv_d = 1.0 / d;
            let (cs, sn) = (du * inv_d, dv * inv_d);
            let x = p[o + 2] - d;
            let s = p[o + 3];
            let r = p[o + 2];
            // The sample stands for a box of sides (w_u, w_v) = `sides` (a pixel, or a strip of
            // one). Seen across the edge, it has the variance of a box of width h along the
            // edge's normal, h² = (w_u cos θ)² + (w_v sin θ)² (h = the side for a square, at any
            // angle): the model is averaged over that. Why: renders without
            // blur fit s ≈ 0.05 px, a near step, and point samples of a step made the cost a
            // staircase in the centre that the fit zig-zagged down (10 iterations on average,
            // each a pass over the pixels).
            // The edge, a logistic step of width s, averages over the box to the difference of
            // its integral, the softplus sp = s·ln(1 + e^{x/s}), across the box. sp is also the
            // depth below the (blurred) edge: the box covers the sphere from depth y₀ = sp(x −
            // h/2) to y₁ = sp(x + h/2), i.e. radii ρ from (R − y₀)/R down to (R − y₁)/R.
            let h = if sides[0] == sides[1] {
                sides[0]
            } else {
                ((sides[0] * cs).powi(2) + (sides[1] * sn).powi(2)).sqrt()
            };
            let (l1, y1, ds1) = softplus(x + 0.5 * h, s);
            let (l0, y0, ds0) = softplus(x - 0.5 * h, s);
            let inv_h = 1.0 / h;
            let l = (y1 - y0) * inv_h;
            let dl_dx = (l1 - l0) * inv_h;
            let dl_ds = (ds1 - ds0) * inv_h;
            // The shading inside the edge, in the sphere's own terms: a matte sphere under a
            // distant lamp and an ambient floor shows a + b·max(0, l·n), n = (ρ cos θ,
            // ρ sin θ, n_z) its normal and l ∝ (c₁, c₂, 1) the lamp: lit along the view it
            // rises as n_z = √(1 − ρ²), i.e. as √x at the limb, which no polynomial follows;
            // lit from one side it is brighter there and flat at the floor on the other,
            // which no symmetric model follows (it put centres 0.1–0.4 px towards the lamp).
            // Added: a first harmonic (a₁, a₂) of the level round the disc, for what a lamp is
            // not (highlights, uneven light). (A slope in x beside n_z made the two trade off
            // within the band and the fit wander.)
            // The shading is averaged over the box too, exactly: over the radii ρ from ρ₁ to ρ₀
            // it covers, g(ρ) = λ·ρ + n_z(ρ) with λ = c·(cos θ, sin θ) the lamp's slope along
            // this radius, and only where g > 0 (the lit side of the terminator) — see
            // `mean_lit`. A point sample of max(0, g) and of √ at the limb is not the box's
            // mean, and has kinks where the mean has none. (Counted on the independent
            // renders, this part did not itself cut the iterations; the step's box did.)
            let (c1, c2) = (p[o + 6], p[o + 7]);
            let lamp = c1 * cs + c2 * sn;
            let b = p[o + 5];
            // dd/dcx = −cos θ, dd/dcy = −sin θ; d(cos θ)/dcx = −sin²θ/d, d(sin θ)/dcx =
            // cos θ sin θ/d, and for cy the same turned by 90°.
            let dlamp_dcx = (-c1 * sn * sn + c2 * cs * sn) * inv_d;
            let dlamp_dcy = (c1 * cs * sn - c2 * cs * cs) * inv_d;
            // The harmonic's level round the disc, moved with the centre.
            let harm_dcx = (-p[o + 8] * sn * sn + p[o + 9] * cs * sn) * inv_d;
            let harm_dcy = (p[o + 8] * cs * sn - p[o + 9] * cs * cs) * inv_d;
            // The image of a blurred disc is the blur of the step times the shading: the
            // shading at the limb times the blurred step, plus the blurred rise inside it
            // (`blurred_rise`); no box mean of the shading is needed, so none is taken. The
            // product (the step times the shading's mean at the blurred depth, below) put a
            // blurred disc lit 5–15° off the axis 0.03–0.1 px away from the lamp; this, within
            // 0.01 there and 0.026 lit from 30° (noise-free renders, docs/accuracy.md, session 36).
            if self.convolved && N == 1 && !self.hiding {
                let lit_limb = lamp > 0.0;
                let g1 = if lit_limb { lamp } else { 0.0 };
                let inner0 = p[o + 4] + b * g1 + p[o + 8] * cs + p[o + 9] * sn;
                let shown0 = inner0 - hidden;
                let rise = blurred_rise(x, h, s, r, lamp);
                let limb = if lit_limb { b } else { 0.0 };
                let j = &mut d_term[k];
                j[o] = dl_dx * cs * shown0
                    + l * (limb * dlamp_dcx + harm_dcx)
                    + b * (rise.d_x * cs + rise.d_lamp * dlamp_dcx);
                j[o + 1] = dl_dx * sn * shown0
                    + l * (limb * dlamp_dcy + harm_dcy)
                    + b * (rise.d_x * sn + rise.d_lamp * dlamp_dcy);
                j[o + 2] = dl_dx * shown0 + b * (rise.d_x + rise.d_r);
                j[o + 3] = dl_ds * shown0 + b * rise.d_s;
                j[o + 4] = l;
                j[o + 5] = l * g1 + rise.rise;
                j[o + 6] = (l * limb + b * rise.d_lamp) * cs;
                j[o + 7] = (l * limb + b * rise.d_lamp) * sn;
                j[o + 8] = l * cs;
                j[o + 9] = l * sn;
                term[k] = l * shown0 + b * rise.rise;
                step[k] = l;
                continue;
            }
            let inv_r = 1.0 / r;
            let rho0 = ((r - y0) * inv_r).clamp(-1.0, 1.0);
            let rho1 = ((r - y1) * inv_r).clamp(-1.0, 1.0);
            let lit = mean_lit(rho0, rho1, lamp);
            let inner = p[o + 4] + b * lit.mean + p[o + 8] * cs + p[o + 9] * sn;
            let shown = inner - hidden;
            // Through ρᵢ = (R − sp(R − d ± h/2, s))/R: ∂ρᵢ/∂d = lᵢ/R, ∂ρᵢ/∂R =
            // ((1 − lᵢ) − ρᵢ)/R, ∂ρᵢ/∂s = −(∂sp/∂s)ᵢ/R.
            let dg_dd = (lit.d_rho0 * l0 + lit.d_rho1 * l1) * inv_r;
            let dg_dr =
                (lit.d_rho0 * ((1.0 - l0) - rho0) + lit.d_rho1 * ((1.0 - l1) - rho1)) * inv_r;
            let dg_ds = -(lit.d_rho0 * ds0 + lit.d_rho1 * ds1) * inv_r;
            let di_dcx = b * (-dg_dd * cs + lit.d_lamp * dlamp_dcx) + harm_dcx;
            let di_dcy = b * (-dg_dd * sn + lit.d_lamp * dlamp_dcy) + harm_dcy;
            let di_dr = b * dg_dr;
            let j = &mut d_term[k];
            j[o] = dl_dx * cs * shown + l * di_dcx;
            j[o + 1] = dl_dx * sn * shown + l * di_dcy;
            j[o + 2] = dl_dx * shown + l * di_dr;
            j[o + 3] = dl_ds * shown + l * b * dg_ds;
            j[o + 4] = l;
            j[o + 5] = l * lit.mean;
            j[o + 6] = l * b * lit.d_lamp * cs;
            j[o + 7] = l * b * lit.d_lamp * sn;
            if self.back_disc != Some(k) {
                j[o + 8] = l * cs;
                j[o + 9] = l * sn;
            }
            if self.hiding {
                let js = &mut d_step[k];
                js[o] = dl_dx * cs;
                js[o + 1] = dl_dx * sn;
                js[o + 2] = dl_dx;
                js[o + 3] = dl_ds;
            }
            term[k] = l * shown;
            step[k] = l;
        }
        let mut j = Vp::<P>::zeros();
        let mut model = p[0];
        match self.layering {
            Layering::InFront(f) if N == 2 => {
                let b = 1 - f;
                model += term[f] + (1.0 - step[f]) * term[b];
                j += d_term[f] - d_step[f] * term[b] + d_term[b] * (1.0 - step[f]);
            }
            _ => {
                for k in 0..N {
                    model += term[k];
                    j += d_term[k];
                }
            }
        }
        j[0] = 1.0;
        (model, j)
    }

    /// The model over pixel `px` and its derivatives.
    ///
    /// A pixel integrates the image over its area. `at_point` averages the model over a box
    /// along the edge's normal; near the edge the pixel's square shape matters too: the edge's
    /// profile across it depends on the edge's direction (a step across a side, a ramp across a
    /// diagonal); that misfit cancels round a whole ring but not round one with dots masked
    /// out, and moved the centre 0.005 px (noise-free renders). So in the final round a pixel
    /// the edge crosses is averaged in three strips, each long along the image axis nearer the
    /// edge's normal (the nearer disc's): along that axis a strip spreads the edge as a box
    /// does, and the three strips' offsets across it rebuild the square's profile. Elsewhere,
    /// and in the rounds that find the dots, the pixel is one box. (Three strips cost a third
    /// of the 3 × 3 parts they replace, with the same noise-free scatter: masked rim dots
    /// 0.00229 → 0.00225 px, the 16 × 16 limb 0.00198 → 0.00199 px per axis; two strips left
    /// the limb at 0.00205.)
    pub(super) fn eval<const P: usize, const N: usize>(
        &self,
        p: &Vp<P>,
        px: &RingPixel,
        area: bool,
    ) -> (f64, Vp<P>) {
        if self.smear_instants > 1 {
            return self.smeared::<P, N>(p, px);
        }
        if !px.in_parts(area) {
            return self.at_point::<P, N>(p, px.u, px.v, [1.0, 1.0], px.hidden, 0.0);
        }
        let (_, du, dv) = (0..N)
            .map(|k| {
                let o = 1 + DISC_PARAMS * k;
                let (du, dv) = (px.u - p[o], px.v - p[o + 1]);
                ((dist(du, dv) - p[o + 2]).abs(), du, dv)
            })
            .fold(
                (f64::INFINITY, 1.0, 0.0),
                |a, b| if b.0 < a.0 { b } else { a },
            );
        let thin = 1.0 / STRIP_OFFSETS.len() as f64;
        let mut model = 0.0;
        let mut j = Vp::<P>::zeros();
        for a in STRIP_OFFSETS {
            let (m, jj) = if du.abs() >= dv.abs() {
                self.at_point::<P, N>(p, px.u, px.v + a, [1.0, thin], px.hidden, 0.0)
            } else {
                self.at_point::<P, N>(p, px.u + a, px.v, [thin, 1.0], px.hidden, 0.0)
            };
            model += m;
            j += jj;
        }
        (model * thin, j * thin)
    }

    /// The model over pixel `px` where the discs moved while the shutter was open: the mean of
    /// the pixel's box at evenly spread instants of the exposure, each disc that much of its
    /// smear from its mid-exposure centre. Why: a disc streaked by a few pixels is not round,
    /// and its edge is sharp across the motion and spread along it; fitted as round, a sphere
    /// lit from one side and smeared by 3 px came out 0.06–0.19 px off (hw-sim renders,
    /// `circle::tests`), and at a 1 ms exposure 24 varied-look recordings' centres were 0.078
    /// px RMS where they are 0.033 at 0.1 ms (docs/accuracy.md, session 43). (No strips: the
    /// smear spreads the edge far more than the pixel's square shape does.)
    fn smeared<const P: usize, const N: usize>(&self, p: &Vp<P>, px: &RingPixel) -> (f64, Vp<P>) {
        let n = self.smear_instants;
        let mut model = 0.0;
        let mut j = Vp::<P>::zeros();
        for i in 0..n {
            let instant = (i as f64 + 0.5) / n as f64 - 0.5;
            let (m, jj) = self.at_point::<P, N>(p, px.u, px.v, [1.0, 1.0], px.hidden, instant);
            model += m;
            j += jj;
        }
        let inv = 1.0 / n as f64;
        (model * inv, j * inv)
    }
}
