//! The Levenberg–Marquardt fit of one or two discs' grey-level model (`pixel`) to a ring's
//! pixels: the linear start, the robust rounds (the first finds the dots), their rejection,
//! the final round over each pixel's area, and the covariance.

use super::super::CircleFit;
use super::dark_patches::dark_patches;
use super::dist;
use super::pixel::PixelModel;
use super::ring::{RingPixel, STRIP_OFFSETS};

/// Parameters per disc in `fit_grey_levels`: centre (2), radius, edge width, and the shading's
/// floor a, lamp amplitude b, lamp direction (c₁, c₂) and first harmonic (a₁, a₂).
pub(super) const DISC_PARAMS: usize = 10;

/// The edge width s of `fit_grey_levels`'s logistic step is kept within these, px: a lens
/// blurs, but not by more than a few pixels at the sizes this fits; at the floor the step is
/// far sharper than the pixel it is averaged over.
const EDGE_WIDTH_PX: (f64, f64) = (0.05, 3.0);

/// The edge widths s the fit may start from, px (`fit_grey_levels`'s linear start takes the
/// one whose grey levels fit best): a sharp edge (the floor) and a blurred one. Why: from a
/// width far from the edge's, the descent spends its passes trading the width against the
/// shading's floor and slope (a sharp render's disc started at 0.5 px took 7–10 iterations to
/// reach the floor); started at the floor alone, a defocused recording's fits took a third
/// more. With both, the descents' model evaluations fell 16 % on the independent renders and
/// 11 % on 12 of hw-sim's varied-look recordings (11 % on the renders with the linear starts'
/// own passes counted), and the centres moved closer to the truth (docs/performance.md and
/// docs/accuracy.md, session 54).
const EDGE_WIDTH_STARTS_PX: [f64; 2] = [EDGE_WIDTH_PX.0, 0.5];

/// Cauchy's loss ρ(r) = c²·ln(1 + (r/c)²) in every round of `fit_grey_levels`
/// takes c = 2.385σ: the usual choice, 95 % as efficient as least squares on Gaussian noise.
const CAUCHY_SCALE: f64 = 2.385;

/// The most grey-level terms `fit_grey_levels`'s linear start solves for: the background and,
/// per disc, a, b and the harmonic (a₁, a₂).
const LIN_TERMS_MAX: usize = 1 + 4 * 2;

/// How two discs' model terms combine (`fit_grey_levels`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Layering {
    /// Side by side: the terms add (the blur of a sum is the sum of the blurs).
    Apart,
    /// Disc `k` hides the other where it covers it.
    InFront(usize),
}

/// Levenberg–Marquardt fit of `N` discs' grey-level model (see `profile_fit`) to `pixels`,
/// with `convolved` (a lone disc only) the shading's rise under the limb blurred with the edge
/// (`model::blurred_rise`) rather than taken at the blurred depth,
/// P = 1 + 10·N parameters: the background, then per disc [cx, cy, R, s, a, b, c₁, c₂, a₁, a₂]
/// (`DISC_PARAMS`); `layering`
/// says whether two discs' terms add or one hides the other. Each disc must settle within
/// `max_move_px` of its start, and its radius within a pixel of the start's; a disc's radius
/// is held where `radii_px` gives it (not with `InFront`, whose radii keep their ratio).
/// `rounds`: all of them, the box rounds only (then the result keeps what the final round
/// needs), or the final round only from such a kept state. `smears_px`: how far each disc
/// moved over the exposure (`FirstPassDisc::smear_px`; zero for none). Returns the discs and
/// their fitted edge widths s, px.
#[allow(clippy::too_many_arguments)]
pub(super) fn fit_grey_levels<const P: usize, const N: usize>(
    pixels: &[RingPixel],
    starts: [&CircleFit; N],
    background: f64,
    layering: Layering,
    radii_px: [Option<f64>; N],
    smears_px: [[f64; 2]; N],
    max_move_px: f64,
    convolved: bool,
    rounds: Rounds<'_>,
) -> Option<Fitted<N>>
where
    nalgebra::Const<P>: nalgebra::DimMin<nalgebra::Const<P>, Output = nalgebra::Const<P>>,
{
    type Vp<const P: usize> = nalgebra::SVector<f64, P>;
    type Mp<const P: usize> = nalgebra::SMatrix<f64, P, P>;
    debug_assert_eq!(P, 1 + DISC_PARAMS * N);
    // Only a disc that hides another needs its step's own derivatives (hot path: every pixel,
    // nine times near the edge).
    let hiding = matches!(layering, Layering::InFront(_)) && N == 2;
    // The disc behind shows a crescent, on which a lamp's direction and a harmonic round the
    // disc of its own trade off with its centre (one frame in a dozen came out 0.1 px off):
    // it has no harmonic, and its lamp is the front disc's (held to it below), the one lamp
    // of the view lighting both spheres a few millimetres apart. Held symmetric instead, as
    // it was, a crescent lit from 30° off the axis came out up to 1.1 px off.
    let back_disc = match layering {
        Layering::InFront(f) if N == 2 => Some(1 - f),
        _ => None,
    };
    let model = PixelModel::new(layering, hiding, back_disc, convolved, &smears_px);
    let eval = |p: &Vp<P>, px: &RingPixel, area: bool| model.eval::<P, N>(p, px, area);
    let mut p = Vp::<P>::zeros();
    // Where an earlier fit's box rounds stopped, if this one starts there.
    let from = match rounds {
        Rounds::AreaFrom(kept) | Rounds::BoxFrom(kept) => Some(kept),
        Rounds::All | Rounds::Box => None,
    };
    if let Some(kept) = from {
        if kept.p.len() != P {
            return None;
        }
        p.copy_from_slice(&kept.p);
    } else {
        p[0] = background;
    }
    // From the starts (the geometry given, the grey levels by linear least squares); the box
    // rounds that find the dots; only those.
    let cold = from.is_none();
    let boxes = !matches!(rounds, Rounds::AreaFrom(_));
    let box_only = matches!(rounds, Rounds::Box | Rounds::BoxFrom(_));
    for (k, st) in starts.iter().enumerate().filter(|_| cold) {
        let o = 1 + DISC_PARAMS * k;
        p[o] = st.centre[0];
        p[o + 1] = st.centre[1];
        p[o + 2] = st.radius;
    }
    // Grey-level parameters first, by linear least squares with the geometry held: the
    // background and each disc's (a, b, c), for each edge width in `EDGE_WIDTH_STARTS_PX`,
    // the one that fits best kept.
    if cold {
        let lin_index: Vec<usize> = std::iter::once(0)
            .chain((0..N).flat_map(|k| {
                let terms: &[usize] = if back_disc == Some(k) {
                    &[4, 5]
                } else {
                    &[4, 5, 8, 9]
                };
                terms.iter().map(move |i| 1 + DISC_PARAMS * k + i)
            }))
            .collect();
        let m = lin_index.len();
        if m > LIN_TERMS_MAX {
            return None;
        }
        // (residual sum of squares, edge width, the linear terms)
        let mut best: Option<(f64, f64, nalgebra::DVector<f64>)> = None;
        for s in EDGE_WIDTH_STARTS_PX {
            for k in 0..N {
                p[1 + DISC_PARAMS * k + 3] = s;
            }
            // Sums held in fixed arrays (at most `LIN_TERMS_MAX` terms): a row allocated per
            // pixel was a heap allocation on the hot path (two passes over every ring).
            let mut a = [[0.0; LIN_TERMS_MAX]; LIN_TERMS_MAX];
            let mut y = [0.0; LIN_TERMS_MAX];
            let mut yy = 0.0;
            for q in pixels {
                let (model, j) = eval(&p, q, false);
                let mut row = [0.0; LIN_TERMS_MAX];
                for (r, &i) in row.iter_mut().zip(&lin_index) {
                    *r = j[i];
                }
                // The part of the model these terms do not carry (what a disc hides).
                let rest = model - lin_index.iter().map(|&i| j[i] * p[i]).sum::<f64>();
                for (c, &rc) in row.iter().enumerate().take(m) {
                    for (r, &rr) in row.iter().enumerate().take(m) {
                        a[r][c] += rr * rc;
                    }
                    y[c] += rc * (q.grey - rest);
                }
                yy += (q.grey - rest).powi(2);
            }
            crate::analysis::stages::count_model_samples(pixels.len());
            let a = nalgebra::DMatrix::from_fn(m, m, |r, c| a[r][c]);
            let y = nalgebra::DVector::from_fn(m, |r, _| y[r]);
            let Some(lin) = a.lu().solve(&y) else {
                continue;
            };
            // At the least-squares solution, Σ r² = Σ (grey − rest)² − yᵀ·lin.
            let rss = yy - y.dot(&lin);
            if best.as_ref().is_none_or(|b| rss < b.0) {
                best = Some((rss, s, lin));
            }
        }
        let (_, s, lin) = best?;
        for k in 0..N {
            p[1 + DISC_PARAMS * k + 3] = s;
        }
        for (i, &idx) in lin_index.iter().enumerate() {
            p[idx] = lin[i];
        }
        // The lamp's direction from the harmonic the linear fit found (near the limb ρ ≈
        // 0.9, so b·c·ρ ≈ a₁), and the harmonic handed over to it; a disc darker inside than
        // at its rim gets no lamp.
        for k in 0..N {
            let o = 1 + DISC_PARAMS * k;
            if back_disc == Some(k) {
                p[o + 5] = p[o + 5].max(0.0);
                continue;
            }
            if p[o + 5] > 0.0 {
                p[o + 6] = (p[o + 8] / (0.9 * p[o + 5])).clamp(-2.0, 2.0);
                p[o + 7] = (p[o + 9] / (0.9 * p[o + 5])).clamp(-2.0, 2.0);
                p[o + 8] = 0.0;
                p[o + 9] = 0.0;
            } else {
                p[o + 5] = 0.0;
            }
        }
    }
    // A disc behind another shows a crescent, which fixes its radius poorly: there the radii
    // keep the ratio of the starts (the spheres' sizes are known), as a stiff penalty on
    // R_back − k·R_front whose gradient row is one of `tie_rows`; and its lamp's direction is
    // the front disc's, as penalties on their difference. (Its harmonic held to the front
    // one's too: on hw-sim renders lit 15–30° off axis 0.007–0.010 px against 0.009–0.011, but
    // on an independent render, v03, the front disc's centres 0.044 → 0.070 px RMS; and a
    // harmonic in grey levels is the same on two spheres only if they are painted alike.)
    let mut ties: [Option<(usize, usize, f64)>; 3] = [None; 3];
    if let (Layering::InFront(f), Some(b)) = (layering, back_disc) {
        let (of, ob) = (1 + DISC_PARAMS * f, 1 + DISC_PARAMS * b);
        ties[0] = Some((of + 2, ob + 2, starts[b].radius / starts[f].radius));
        ties[1] = Some((of + 6, ob + 6, 1.0));
        ties[2] = Some((of + 7, ob + 7, 1.0));
        if cold {
            p[ob + 6] = p[of + 6];
            p[ob + 7] = p[of + 7];
        }
    }
    // A disc of known radius (`radii_px`: a lone one cut by the view's border, whose visible
    // arc fixes its radius and its centre across the cut poorly together; a blurred one held
    // at its neighbours', `FirstPassDisc`) is held at it the same way, as R − radius.
    if ties[0].is_none() {
        for (k, r) in radii_px.iter().enumerate().take(2) {
            ties[k] = r.map(|r| (usize::MAX, 1 + DISC_PARAMS * k + 2, r));
        }
    }
    const TIE_WEIGHT: f64 = 1e6;
    let one_residual = |p: &Vp<P>, (rf, rb, k): (usize, usize, f64)| {
        if rf == usize::MAX {
            p[rb] - k
        } else {
            p[rb] - k * p[rf]
        }
    };
    // Σ of the ties' squared residuals.
    let tie_cost = |p: &Vp<P>| {
        ties.iter()
            .flatten()
            .map(|&t| one_residual(p, t).powi(2))
            .sum::<f64>()
    };
    let tie_rows: Vec<((usize, usize, f64), Vp<P>)> = ties
        .iter()
        .flatten()
        .map(|&(rf, rb, k)| {
            let mut a = Vp::<P>::zeros();
            a[rb] = 1.0;
            if rf != usize::MAX {
                a[rf] = -k;
            }
            ((rf, rb, k), a)
        })
        .collect();
    // Edge widths stay plausible, and a lamp gives light (b ≥ 0): with b < 0 the model has
    // other, unphysical ways to fit a band only 2.5 px deep. The bounds are kept by holding a
    // parameter that sits on one and is pushed beyond it, and by clipping the step to them
    // (a projected Levenberg–Marquardt). Rejecting a step that crossed a bound instead stalled
    // the fit wherever the edge is sharp: unblurred renders fit the width at its floor.
    let bounds = |k: usize| {
        let o = 1 + DISC_PARAMS * k;
        [
            (o + 3, EDGE_WIDTH_PX.0, EDGE_WIDTH_PX.1),
            (o + 5, 0.0, f64::INFINITY),
        ]
    };
    let project = |p: &mut Vp<P>| {
        for k in 0..N {
            for (i, lo, hi) in bounds(k) {
                p[i] = p[i].clamp(lo, hi);
            }
        }
    };
    let n_start = pixels.len();
    // One pass over the pixels at p (`evaluate`): each pixel's residual and Jacobian row, kept
    // so that a round that starts where the last one stopped, on fewer pixels, or a robust
    // round whose scale comes from the residuals at its start, needs no pass of its own (two
    // passes of about 22 a fit). A trial step is evaluated with its Jacobian, so that once
    // accepted the next iteration need not pass over the pixels again.
    let evaluate = |p: &Vp<P>, keep: &[RingPixel], area: bool, out: &mut Vec<(f64, Vp<P>)>| {
        out.clear();
        let mut samples = 0;
        for q in keep {
            samples += if q.in_parts(area) {
                STRIP_OFFSETS.len()
            } else {
                1
            };
            let (m, j) = eval(p, q, area);
            out.push((q.grey - m, j));
        }
        crate::analysis::stages::count_model_samples(samples);
    };
    // From the rows at p: the sum of squared residuals (without the tie), JᵀJ and Jᵀr; with
    // `robust` = Some(c), Cauchy's loss instead, Σ c²·ln(1 + (r/c)²), and each pixel's row and
    // residual weighted by √w, w = 1/(1 + (r/c)²) at p (iteratively reweighted least squares:
    // JᵀWJ, JᵀWr).
    const BATCH: usize = 8;
    // JᵀJ (its upper triangle) and Jᵀr plus one batch of rows, `rows[i][k]` the i-th
    // derivative of the batch's k-th pixel.
    let add_rows =
        |jtj: &mut Mp<P>, jtr: &mut Vp<P>, rows: &[[f64; BATCH]; P], res: &[f64; BATCH]| {
            let dot = |a: &[f64; BATCH], b: &[f64; BATCH]| {
                let mut acc = [0.0; BATCH];
                for k in 0..BATCH {
                    acc[k] = a[k] * b[k];
                }
                acc.iter().sum::<f64>()
            };
            for c in 0..P {
                for r in 0..=c {
                    jtj[(r, c)] += dot(&rows[r], &rows[c]);
                }
                jtr[c] += dot(&rows[c], res);
            }
        };
    let accumulate = |at: &[(f64, Vp<P>)], robust: Option<f64>| -> (f64, Mp<P>, Vp<P>) {
        let mut jtj = Mp::<P>::zeros();
        let mut jtr = Vp::<P>::zeros();
        let mut sum_sq = 0.0;
        // The pixels' Jacobian rows in batches of `BATCH`, held by column, so that each entry of
        // JᵀJ is a short dot product the compiler vectorises rather than one add to memory per
        // pixel (those adds were the largest single cost of the fit).
        let mut rows = [[0.0; BATCH]; P];
        let mut res = [0.0; BATCH];
        let mut filled = 0;
        for &(r, j) in at {
            let root_w = match robust {
                Some(c) => {
                    let t = (r / c) * (r / c);
                    sum_sq += c * c * t.ln_1p();
                    (1.0 + t).sqrt().recip()
                }
                None => {
                    sum_sq += r * r;
                    1.0
                }
            };
            for (i, col) in rows.iter_mut().enumerate() {
                col[filled] = j[i] * root_w;
            }
            res[filled] = r * root_w;
            filled += 1;
            if filled == BATCH {
                add_rows(&mut jtj, &mut jtr, &rows, &res);
                filled = 0;
            }
        }
        // The last, partial batch: the rows not refilled are zeroed.
        for col in rows.iter_mut() {
            col[filled..].fill(0.0);
        }
        res[filled..].fill(0.0);
        add_rows(&mut jtj, &mut jtr, &rows, &res);
        for c in 0..P {
            for r in c + 1..P {
                jtj[(r, c)] = jtj[(c, r)];
            }
        }
        (sum_sq, jtj, jtr)
    };
    // Levenberg–Marquardt from p on the pixels kept, until a step would move no centre or
    // radius by more than `settled_px`. Returns the cost at the final p (with the tie), the
    // JᵀJ the last iteration started from (with the tie's row) and each pixel's residual and row
    // at p in `keep`'s order, all from the passes the descent made: neither the dots' rejection
    // nor σ² needs a pass over the pixels of its own. `at_p`: the rows at p as it starts.
    let descend = |p: &mut Vp<P>,
                   keep: &[RingPixel],
                   area: bool,
                   settled_px: f64,
                   robust: Option<f64>,
                   mut at_p: Vec<(f64, Vp<P>)>|
     -> (f64, Mp<P>, Vec<(f64, Vp<P>)>) {
        let mut lambda = 1e-3;
        let mut at_trial = Vec::with_capacity(keep.len());
        let (sum_sq, mut jtj_at_p, mut jtr_at_p) = accumulate(&at_p, robust);
        let mut c_now = sum_sq + TIE_WEIGHT * tie_cost(p);
        // JᵀJ with the tie's row, as the last iteration began (what the covariance uses).
        let mut jtj = Mp::<P>::zeros();
        for _ in 0..30 {
            jtj = jtj_at_p;
            let mut jtr = jtr_at_p;
            for (t, a) in &tie_rows {
                jtj += a * a.transpose() * TIE_WEIGHT;
                jtr -= a * (TIE_WEIGHT * one_residual(p, *t));
            }
            let mut accepted = false;
            // A parameter on its bound that the descent pushes beyond it is held there.
            let mut held = [false; P];
            for k in 0..N {
                for (i, lo, hi) in bounds(k) {
                    held[i] = (p[i] <= lo && jtr[i] < 0.0) || (p[i] >= hi && jtr[i] > 0.0);
                }
            }
            for _ in 0..8 {
                let mut damped = jtj;
                let mut rhs = jtr;
                // The floor keeps a parameter the pixels do not fix (a lamp's direction on a
                // flat disc) from making the step singular.
                let floor = 1e-9 * (0..P).map(|i| jtj[(i, i)]).fold(0.0, f64::max);
                for i in 0..P {
                    damped[(i, i)] = damped[(i, i)] * (1.0 + lambda) + floor * (1.0 + lambda);
                }
                for i in (0..P).filter(|&i| held[i]) {
                    for c in 0..P {
                        damped[(i, c)] = 0.0;
                        damped[(c, i)] = 0.0;
                    }
                    damped[(i, i)] = 1.0;
                    rhs[i] = 0.0;
                }
                let Some(step) = damped.lu().solve(&rhs) else {
                    lambda *= 10.0;
                    continue;
                };
                // A step that would move no centre or radius by more than `settled_px` is not
                // worth a pass over the pixels to try: settled (or, damped this far, stuck).
                let moved = (0..N)
                    .map(|k| step.fixed_rows::<3>(1 + DISC_PARAMS * k).norm())
                    .fold(0.0, f64::max);
                if moved <= settled_px {
                    break;
                }
                let mut trial = *p + step;
                project(&mut trial);
                evaluate(&trial, keep, area, &mut at_trial);
                let (sum_sq, jtj_t, jtr_t) = accumulate(&at_trial, robust);
                let c_new = sum_sq + TIE_WEIGHT * tie_cost(&trial);
                // After a step is taken the damping falls by up to 3× if the cost fell as the
                // quadratic model predicted (gain ρ = actual / predicted decrease near 1), and
                // less, or rises, if it did not (Nielsen's rule). Against a fixed fall of 3×,
                // 6–7 % fewer iterations on the independent renders.
                let taken = trial - *p;
                let pred = 2.0 * taken.dot(&jtr) - (taken.transpose() * jtj * taken)[(0, 0)];
                if c_new <= c_now {
                    let gain = if pred > 0.0 {
                        (c_now - c_new) / pred
                    } else {
                        0.0
                    };
                    *p = trial;
                    c_now = c_new;
                    (jtj_at_p, jtr_at_p) = (jtj_t, jtr_t);
                    std::mem::swap(&mut at_p, &mut at_trial);
                    lambda =
                        (lambda * (1.0f64 / 3.0).max(1.0 - (2.0 * gain - 1.0).powi(3))).max(1e-9);
                    accepted = true;
                    break;
                }
                lambda *= 10.0;
            }
            if !accepted {
                break;
            }
        }
        (c_now, jtj, at_p)
    };
    // The residuals' σ from their median absolute value, with a floor of 3 % of the edge's
    // contrast: in a noise-free image the residuals are the model's own misfit, and rejecting
    // those would empty the ring.
    // (The median by selection, not a sort: the same element, and with Cauchy's loss in every
    // round this runs four times a fit.)
    let robust_sigma = |at: &[(f64, Vp<P>)], p: &Vp<P>| {
        let mut abs: Vec<f64> = at.iter().map(|(r, _)| r.abs()).collect();
        let half = abs.len() / 2;
        let median = if abs.is_empty() {
            0.0
        } else {
            *abs.select_nth_unstable_by(half, f64::total_cmp).1
        };
        let contrast = (0..N)
            .map(|k| p[5 + DISC_PARAMS * k].abs())
            .fold(f64::MAX, f64::min);
        (1.4826 * median).max(0.03 * contrast).max(0.5)
    };
    // How far each box round settles, px: the first, robust round only has to tell the dots
    // from the rim, to 1e-2 px (11 % fewer model evaluations on 38 varied-look recordings,
    // with the same centre RMS, 0.0741 px, and the independent renders' within their noise).
    // With plain least squares there, settling that loosely had put 5 estimates beyond 5σ on
    // the same recordings: where the dots steered the round, where it stopped mattered.
    let settle_px = |round: usize| if round == 0 { 1e-2 } else { 1e-3 };
    // Each pixel as one box first, rejecting dots; then pixels the edge crosses in strips
    // from there, which moves the centres by thousandths of a pixel.
    let mut keep = pixels.to_vec();
    if let Rounds::AreaFrom(kept) = rounds {
        if pixels.len() != kept.ring_len {
            return None;
        }
        keep.retain(|q| !kept.rejected.contains(&[q.u as i32, q.v as i32]));
    }
    let mut at_p = Vec::with_capacity(keep.len());
    // The last box round's cost and JᵀJ (what a fit that stops there gives its σ from).
    let mut boxed = None;
    if boxes {
        evaluate(&p, &keep, false, &mut at_p);
    }
    // The first round's Cauchy scale, from the residuals where a fit from the starts begins
    // (kept for a fit that starts where this one's box rounds stop: `Rounds::BoxFrom`).
    let mut first_scale = 0.0;
    for round in (0..3).filter(|_| boxes) {
        // Settled only to `settle_px`: the dots to reject are all that depend on it, and the final
        // round's model is smooth, so it converges to its own minimum from here. (With point
        // samples of a near step and of √ at the limb, that round zig-zagged and where it
        // started showed in its result: this had to settle to 1e-7 px.)
        // Every round weighs each pixel by Cauchy's loss on a scale from the residuals where
        // it starts, so that the dots' residuals do not steer the descent: in the first, with
        // every dot still in; in the later ones, the blurred or faint dots the rejection below
        // leaves (a dot blurred by defocus is 5–15σ darker over a dozen pixels, none of them
        // 4σ off a model that bends to meet it). Why in the first: with plain least squares
        // its minimum, and so which pixels the rejection below dropped, moved with where the
        // descent stopped (v03's centres 0.072 → 0.103 px RMS when the descent was only made
        // quicker, docs/performance.md); the dots' residuals also made Gauss–Newton misjudge
        // the curvature and zig-zag (12 passes a fit). Measured on the same frames: v03 0.072
        // → 0.037 px, 38 varied-look recordings 0.0783 → 0.0741 px, 12 % fewer model
        // evaluations. In the later ones: see the final round below.
        let scale = match from {
            Some(kept) if round == 0 => kept.first_scale,
            _ => CAUCHY_SCALE * robust_sigma(&at_p, &p),
        };
        if round == 0 {
            first_scale = scale;
        }
        let robust = Some(scale);
        let (cost, jtj, rows) = descend(&mut p, &keep, false, settle_px(round), robust, at_p);
        at_p = rows;
        boxed = Some((cost, jtj));
        if round == 2 {
            break;
        }
        // Dots on the rim are far darker than any model pixel; a pixel next to one may be
        // partly dot and only a little darker, so the neighbours of a rejected pixel go too.
        let sigma = robust_sigma(&at_p, &p);
        // On a blurred disc a dot is spread over a dozen pixels, none of them 4σ off a model
        // that bends to meet it, and it still pulls the centre: a lone defocused sphere's centre
        // scattered twice as much with its dots as without (0.21 against 0.10 px RMS, eight
        // varied-look recordings blurred by 1.0–1.2 px, drawn twice, the dots left off once).
        // There the dots are found as patches darker than the model in the disc
        // (`dark_patches`), which took that to 0.17 px. Only inside a disc: at its edge a
        // patch darker than the model is as often the model's own misfit of the limb (on one
        // independent render, v02, flagging it there moved centres 0.053 → 0.078 px RMS).
        // A lone disc only: between two discs fitted together a patch darker than the model is
        // the contact's own (shadow, the sum of two blurs), and flagging it moved v02's centres
        // 0.055 → 0.069 px.
        let lone_blurred = N == 1 && super::edge_is_blurred(p[4]);
        let inside_the_disc = |q: &RingPixel| dist(q.u - p[1], q.v - p[2]) < p[3];
        let bad: Vec<(f64, f64)> = keep
            .iter()
            .zip(&at_p)
            .filter(|(_, (r, _))| r.abs() > 4.0 * sigma)
            .map(|(q, _)| (q.u, q.v))
            .chain(
                lone_blurred
                    .then(|| dark_patches(&keep, &at_p, sigma, inside_the_disc))
                    .into_iter()
                    .flatten(),
            )
            .collect();
        if bad.is_empty() {
            break;
        }
        // (Pixel centres: whole-pixel offsets, so the squares compare exactly.) The rows kept
        // go with their pixels: the next round starts where this one stopped.
        (keep, at_p) = keep
            .into_iter()
            .zip(at_p)
            .filter(|(q, _)| {
                !bad.iter()
                    .any(|b| (q.u - b.0).powi(2) + (q.v - b.1).powi(2) <= 1.5 * 1.5)
            })
            .unzip();
        if keep.len() < n_start / 2 {
            return None;
        }
    }
    if keep.len() < n_start / 2 {
        return None;
    }
    // The final round too (Cauchy's loss in every round rather than the first only, the same
    // 190 varied-look recordings: centre RMS 0.0688 → 0.0657 px, lower in every look family;
    // 10 % more model evaluations; docs/accuracy.md, session 29). Its cost, Σ c²·ln(1 + (r/c)²),
    // gives σ² below: no smaller than the weighted residuals' Σ w·r², so the dots left in
    // still widen the σ.
    // It settles to 3e-4 px: 7 % fewer model evaluations than at 1e-4 on the independent
    // renders (27 167 → 25 278 a frame), the same centres to 0.0001 px on 190 varied-look
    // recordings and the renders' estimates within a unit of their last digit (docs/
    // performance.md, session 42). Tried first in session 41 and undone then: a disc behind
    // the other, its shading held symmetric, did not settle and came out 1.09 px off instead of
    // 0.79; lit by the front disc's lamp it settles, 0.036 px either way. At 1e-3 (session 38)
    // the centres moved 1 %.
    let (cost, jtj) = match (box_only, boxed) {
        (true, Some(b)) => b,
        (true, None) => return None,
        (false, _) => {
            evaluate(&p, &keep, true, &mut at_p);
            let final_robust = Some(CAUCHY_SCALE * robust_sigma(&at_p, &p));
            let (cost, jtj, _) = descend(&mut p, &keep, true, 3e-4, final_robust, at_p);
            (cost, jtj)
        }
    };
    if !p.iter().all(|x| x.is_finite()) {
        return None;
    }
    let n = keep.len() as f64;
    let s2 = cost / (n - P as f64).max(1.0);
    let mut ridged = jtj;
    let floor = 1e-9 * (0..P).map(|i| jtj[(i, i)]).fold(0.0, f64::max);
    for i in 0..P {
        ridged[(i, i)] += floor;
    }
    let cov = ridged.try_inverse()? * s2;
    let mut out = [*starts[0]; N];
    let mut widths = [0.0; N];
    for (k, st) in starts.iter().enumerate() {
        let o = 1 + DISC_PARAMS * k;
        widths[k] = p[o + 3];
        let moved = (p[o] - st.centre[0]).hypot(p[o + 1] - st.centre[1]);
        if moved > max_move_px || (p[o + 2] - st.radius).abs() > 1.0 {
            return None;
        }
        out[k] = CircleFit {
            centre: [p[o], p[o + 1]],
            radius: p[o + 2],
            centre_sigma: [
                cov[(o, o)].max(0.0).sqrt(),
                cov[(o + 1, o + 1)].max(0.0).sqrt(),
            ],
            radius_sigma: cov[(o + 2, o + 2)].max(0.0).sqrt(),
            grey_levels: true,
            edge_width_px: p[o + 3],
            ..**st
        };
    }
    // The pixels kept are those given, in order, less the ones dropped: one walk finds these.
    let kept = box_only.then(|| {
        let mut left = keep.iter().peekable();
        let rejected = pixels
            .iter()
            .filter(|q| {
                let kept = left.peek().is_some_and(|k| k.u == q.u && k.v == q.v);
                if kept {
                    left.next();
                }
                !kept
            })
            .map(|q| [q.u as i32, q.v as i32])
            .collect();
        Kept {
            ring_len: pixels.len(),
            p: p.iter().copied().collect(),
            rejected,
            first_scale,
        }
    });
    Some(Fitted {
        discs: out,
        widths,
        kept,
    })
}

/// Which of `fit_grey_levels`'s rounds to run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Rounds<'a> {
    /// All of them: the box rounds that find the dots, then the final round over each pixel's
    /// area.
    All,
    /// The box rounds only: the fit as they leave it, and what the final round needs to start
    /// from there (`Fitted::kept`).
    Box,
    /// The box rounds only, as `Box`, from where an earlier fit's box rounds stopped and with
    /// its first round's scale, on a ring that may have lost pixels to dots since (the second
    /// pass's): the rounds find the dots again from there. Why not from the starts: that is
    /// the same descent again to nearly the same place (the linear start and the first round
    /// were half of a fit's passes over its pixels); why with the kept scale: the first
    /// round's Cauchy scale comes from the residuals where a fit begins, and a scale from the
    /// small residuals at the minimum drops other pixels (session 38 started there with its
    /// own scale: side-lit and cluttered looks' centres 17 % further off, docs/performance.md).
    BoxFrom(&'a Kept),
    /// The final round only, from where an earlier fit's box rounds stopped, on the same
    /// pixels less those they dropped: what `All` would have done next (None if the pixels
    /// given are not as many as that fit's).
    AreaFrom(&'a Kept),
}

/// What a fit's box rounds leave for its final round (`Rounds::Box`): how many pixels its ring
/// had, every parameter, and the ring pixels the rounds dropped as dots (pixel coordinates).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Kept {
    pub(super) ring_len: usize,
    p: Vec<f64>,
    rejected: Vec<[i32; 2]>,
    /// The first box round's Cauchy scale (`Rounds::BoxFrom`).
    first_scale: f64,
}

/// A grey-level fit's discs, their edge widths s (px), and after `Rounds::Box` what its final
/// round needs.
pub(super) struct Fitted<const N: usize> {
    pub(super) discs: [CircleFit; N],
    pub(super) widths: [f64; N],
    pub(super) kept: Option<Kept>,
}
