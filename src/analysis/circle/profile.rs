//! Grey-level fits: the disc's edge modelled over every pixel within `PROFILE_BAND_PX` of it
//! (further inside where the edge is blurred), integrated over each pixel's area where the edge
//! crosses it; one disc, two discs whose rings meet fitted together, or the front disc hiding
//! the back one.

use super::edge::sectors_covered;
use super::{CircleFit, DotMask, GreyImage, View};

/// Half-width of the band round the edge whose pixels the profile fit uses, px.
pub const PROFILE_BAND_PX: f64 = 2.5;

/// The disc's centre and radius from the grey levels of every pixel near its edge, not from
/// edge points: a model I = background + L((R − d)/s)·S (L a logistic step of width s, S the
/// sphere's shading inside the edge, see `fit_grey_levels`), integrated over each pixel's
/// area, is fitted by
/// Levenberg–Marquardt, starting from the edge-point fit. Why: a threshold crossing
/// uses two samples per ray, and the edge-point fit's centre scatters about three times the
/// Cramér–Rao bound (physics.md §6), most of it pixel locking; the model fit uses all of the
/// edge's pixels. Pixels far off the model (dots on the rim) and their neighbours are dropped,
/// and so are pixels near the other sphere's disc or beyond the view's border, as long as 20 of
/// the ring's 36 sectors stay. Where the fit finds the edge blurred, it is fitted again from
/// there on a ring reaching further inside (`INNER_BAND_PER_EDGE_WIDTH`). None when the fit
/// does not settle near the start.
pub fn profile_fit(
    img: &GreyImage,
    view: &View,
    start: &CircleFit,
    background: f64,
    other: Option<([f64; 2], f64)>,
    dots: &[DotMask],
) -> Option<CircleFit> {
    fit_one(img, view, start, background, other, dots, None)
}

/// `profile_fit` with the disc's radius held at `radius_px`: for a disc cut by the view's
/// border, where the radius and the centre across the cut trade off (a free radius 0.5 px too
/// small put such centres 0.9 px off).
pub fn profile_fit_known_radius(
    img: &GreyImage,
    view: &View,
    start: &CircleFit,
    background: f64,
    other: Option<([f64; 2], f64)>,
    dots: &[DotMask],
    radius_px: f64,
) -> Option<CircleFit> {
    fit_one(img, view, start, background, other, dots, Some(radius_px))
}

/// One disc's grey-level fit, its radius free or held at `radius_px` (then 12 of the ring's
/// sectors suffice: the radius no longer needs the ring to go round).
fn fit_one(
    img: &GreyImage,
    view: &View,
    start: &CircleFit,
    background: f64,
    other: Option<([f64; 2], f64)>,
    dots: &[DotMask],
    radius_px: Option<f64>,
) -> Option<CircleFit> {
    let near_other = |u: f64, v: f64| {
        other.is_some_and(|(oc, or)| dist(u - oc[0], v - oc[1]) < or + PROFILE_BAND_PX + 1.0)
    };
    let start = CircleFit {
        radius: radius_px.unwrap_or(start.radius),
        ..*start
    };
    let min_sectors = if radius_px.is_some() { 12 } else { 20 };
    let fit = |discs: [&CircleFit; 1], inner_px: f64| {
        let pixels = ring_pixels(img, view, &discs, dots, near_other, min_sectors, inner_px)?;
        fit_grey_levels::<11, 1>(&pixels, discs, background, Layering::Apart, radius_px)
    };
    let ([first], widths) = fit([&start], PROFILE_BAND_PX)?;
    let Some(inner_px) = blurred_inner_band(&widths) else {
        return Some(first);
    };
    let again = CircleFit {
        centre: first.centre,
        radius: first.radius,
        ..start
    };
    Some(fit([&again], inner_px).map_or(first, |([f], _)| f))
}

/// How far inside a disc's edge the ring reaches once the fit has found the edge blurred, in
/// edge widths s of the logistic step beyond `PROFILE_BAND_PX`: the blurred edge itself
/// reaches about 2s in (where the step is within 12 % of its plateau), and the band must go
/// past it to see the shading on its own. Why: on a defocused sphere the edge's blur, the
/// shading's slope and its harmonic round the disc all explain the same few pixels, and the
/// centre trades off with them — a lone sphere blurred by 1.1 px scattered 0.20 px (σ = 2)
/// where its fit claimed 0.11, and lit from 30° to one side came out 0.05–0.06 px towards the
/// lamp. With the ring reaching past the blur: 0.10 px against a claimed 0.085, and within
/// 0.01 px (`circle::tests::a_defocused_sphere_is_measured_as_well_as_its_fit_claims`).
const INNER_BAND_PER_EDGE_WIDTH: f64 = 2.0;

/// The inner band a second fit should use after a first one (on `PROFILE_BAND_PX`) found the
/// edge widths `widths`, px; None where the edges are sharp enough that it would add less
/// than a quarter of a pixel (a sharp render's fit is left exactly as it was).
fn blurred_inner_band(widths: &[f64]) -> Option<f64> {
    let s = widths.iter().copied().fold(0.0, f64::max);
    let extra = INNER_BAND_PER_EDGE_WIDTH * s;
    (extra >= 0.25).then_some(PROFILE_BAND_PX + extra)
}

/// Two discs side by side whose rings come close, fitted together: the model is the background
/// plus both discs' terms of `profile_fit`'s model, so the pixels between them, where both
/// edges' blur adds up, are explained instead of left out. Why: fitted one at a time, each disc
/// loses the part of its ring that faces the other — the part that fixes its centre along the
/// line between them — just in the frames next to the impact that fix the contact normal; on
/// the bench the centres there scattered 1.5–2 times as much along that line as far from it.
/// Only for discs that do not overlap in the view (one partly behind the other hides, and
/// hiding does not add up); None there and where the fit does not settle.
pub fn profile_fit_pair(
    img: &GreyImage,
    view: &View,
    starts: [&CircleFit; 2],
    background: f64,
    dots: &[DotMask],
) -> Option<[CircleFit; 2]> {
    let [a, b] = starts;
    let apart = (a.centre[0] - b.centre[0]).hypot(a.centre[1] - b.centre[1]);
    if apart < a.radius + b.radius - PAIR_OVERLAP_PX {
        return None;
    }
    let fit = |discs: [&CircleFit; 2], inner_px: f64| {
        let pixels = ring_pixels(img, view, &discs, dots, |_, _| false, 20, inner_px)?;
        fit_grey_levels::<21, 2>(&pixels, discs, background, Layering::Apart, None)
    };
    let (first, widths) = fit(starts, PROFILE_BAND_PX)?;
    let Some(inner_px) = blurred_inner_band(&widths) else {
        return Some(first);
    };
    let again = [0, 1].map(|k| CircleFit {
        centre: first[k].centre,
        radius: first[k].radius,
        ..*starts[k]
    });
    Some(fit([&again[0], &again[1]], inner_px).map_or(first, |(f, _)| f))
}

/// Two discs of one silhouette, one partly hiding the other (the mirror after an oblique
/// impact), fitted together on the grey levels: the model is the front disc's term of
/// `profile_fit`'s model over the back disc's, which shows only where the front one does not
/// (and through the front's blurred edge), and the two radii keep the ratio of the starts.
/// Why: the split into circles rests on outline points, and where the outlines meet they are
/// neither circle's; as the spheres slide behind each other over a few frames the split circles
/// drifted by 0.1 px, which a line fit took for a z velocity several σ off. `front` is the
/// index (0 or 1) of the disc nearer the camera. None unless the discs are three quarters of
/// the back one's radius apart or more and the back one shows at least a third of its edge, and
/// where the fit does not settle.
pub fn profile_fit_behind(
    img: &GreyImage,
    view: &View,
    starts: [&CircleFit; 2],
    front: usize,
    background: f64,
    dots: &[DotMask],
) -> Option<[CircleFit; 2]> {
    let (f, b) = (starts[front], starts[1 - front]);
    // A crescent narrower than three quarters of the radius let the back disc slide along it by
    // a tenth of a pixel in renders; the split's circles are better there.
    if (f.centre[0] - b.centre[0]).hypot(f.centre[1] - b.centre[1]) < MIN_CRESCENT_RADII * b.radius
    {
        return None;
    }
    // (Only the ring's usual band: a crescent's inside is mostly the front disc's.)
    let pixels = ring_pixels(img, view, &starts, dots, |_, _| false, 20, PROFILE_BAND_PX)?;
    let shown: Vec<[f64; 2]> = pixels
        .iter()
        .filter(|q| {
            ((q.u - b.centre[0]).hypot(q.v - b.centre[1]) - b.radius).abs() < 1.0
                && (q.u - f.centre[0]).hypot(q.v - f.centre[1]) > f.radius + 1.0
        })
        .map(|q| [q.u, q.v])
        .collect();
    if sectors_covered(&shown, b.centre) < 12 {
        return None;
    }
    fit_grey_levels::<21, 2>(&pixels, starts, background, Layering::InFront(front), None)
        .map(|(fit, _)| fit)
}

/// Parameters per disc in `fit_grey_levels`: centre (2), radius, edge width, and the shading's
/// floor a, lamp amplitude b, lamp direction (c₁, c₂) and first harmonic (a₁, a₂).
const DISC_PARAMS: usize = 10;

/// The edge width s of `fit_grey_levels`'s logistic step is kept within these, px: a lens
/// blurs, but not by more than a few pixels at the sizes this fits; at the floor the step is
/// far sharper than the pixel it is averaged over.
const EDGE_WIDTH_PX: (f64, f64) = (0.05, 3.0);

/// Cauchy's loss ρ(r) = c²·ln(1 + (r/c)²) in the first, dot-finding round of `fit_grey_levels`
/// takes c = 2.385σ: the usual choice, 95 % as efficient as least squares on Gaussian noise.
const CAUCHY_SCALE: f64 = 2.385;

/// The narrowest crescent `profile_fit_behind` fits, in radii of the back disc.
const MIN_CRESCENT_RADII: f64 = 0.75;

/// How two discs' model terms combine (`fit_grey_levels`).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Layering {
    /// Side by side: the terms add (the blur of a sum is the sum of the blurs).
    Apart,
    /// Disc `k` hides the other where it covers it.
    InFront(usize),
}

/// How far two discs may overlap in a view and still be fitted as a sum (`profile_fit_pair`),
/// px: touching spheres whose contact normal leans a few degrees out of the view's plane.
pub const PAIR_OVERLAP_PX: f64 = 0.3;

/// Whether two discs' rings are close enough that fitting each alone leaves part of it out
/// (`profile_fit` drops the pixels near the other disc).
pub fn rings_meet(a: &CircleFit, b: &CircleFit) -> bool {
    let apart = (a.centre[0] - b.centre[0]).hypot(a.centre[1] - b.centre[1]);
    apart < a.radius + b.radius + 2.0 * PROFILE_BAND_PX + 1.0
}

/// √(dx² + dy²): at pixel scale nothing overflows, and `hypot`'s care costs several times a
/// √ on every pixel of every ring.
fn dist(dx: f64, dy: f64) -> f64 {
    (dx * dx + dy * dy).sqrt()
}

/// The pixels within `PROFILE_BAND_PX` outside and `inner_px` inside any of the discs' edges,
/// inside the view, off the dots and not `excluded`; None unless each disc keeps
/// `min_sectors` of its ring's 36 sectors and at least 40 pixels.
fn ring_pixels(
    img: &GreyImage,
    view: &View,
    discs: &[&CircleFit],
    dots: &[DotMask],
    excluded: impl Fn(f64, f64) -> bool,
    min_sectors: usize,
    inner_px: f64,
) -> Option<Vec<RingPixel>> {
    if img.width == 0 || img.height == 0 || discs.is_empty() {
        return None;
    }
    let reach = |d: &CircleFit| d.radius + PROFILE_BAND_PX + 1.0;
    let span = |lo: f64, hi: f64, len: usize| -> Option<(usize, usize)> {
        let lo = lo.floor().max(0.0);
        let hi = hi.ceil().min((len - 1) as f64);
        (lo <= hi).then_some((lo as usize, hi as usize))
    };
    let lo = |i: usize| {
        discs
            .iter()
            .map(|d| d.centre[i] - reach(d))
            .fold(f64::MAX, f64::min)
    };
    let hi = |i: usize| {
        discs
            .iter()
            .map(|d| d.centre[i] + reach(d))
            .fold(f64::MIN, f64::max)
    };
    let (u_lo, u_hi) = span(lo(0), hi(0), img.width)?;
    let (v_lo, v_hi) = span(lo(1), hi(1), img.height)?;
    let on_ring = |d: &CircleFit, u: f64, v: f64| {
        let out = dist(u - d.centre[0], v - d.centre[1]) - d.radius;
        out <= PROFILE_BAND_PX && out >= -inner_px
    };
    let mut pixels: Vec<RingPixel> = Vec::new();
    for v in v_lo..=v_hi {
        for u in u_lo..=u_hi {
            let (uf, vf) = (u as f64, v as f64);
            if !discs.iter().any(|d| on_ring(d, uf, vf)) {
                continue;
            }
            // A disc cut by the view's border is fitted on the part of its ring inside: the
            // sector count below asks for more than half of it. Beyond lies another view.
            if !view.contains(uf, vf) || excluded(uf, vf) {
                continue;
            }
            if dots
                .iter()
                .any(|d| dist(uf - d.centre_px[0], vf - d.centre_px[1]) < d.radius_px)
            {
                continue;
            }
            let to_edge = discs
                .iter()
                .map(|d| (dist(uf - d.centre[0], vf - d.centre[1]) - d.radius).abs())
                .fold(f64::INFINITY, f64::min);
            pixels.push(RingPixel {
                u: uf,
                v: vf,
                grey: img.at(u, v) as f64,
                hidden: img.ground_at(u, v) as f64,
                area: if to_edge < EDGE_ZONE_PX {
                    Area::Fine
                } else {
                    Area::Whole
                },
            });
        }
    }
    for d in discs {
        let ring: Vec<[f64; 2]> = pixels
            .iter()
            .filter(|q| on_ring(d, q.u, q.v))
            .map(|q| [q.u, q.v])
            .collect();
        if ring.len() < 40 || sectors_covered(&ring, d.centre) < min_sectors {
            return None;
        }
    }
    Some(pixels)
}

/// The centres of a pixel's 3 × 3 parts, px from the pixel's centre, over which the model is
/// averaged where an edge crosses the pixel (each part a box of side 1/3 px; on noise-free
/// renders 4 × 4 point samples did no better than 3 × 3).
const SUBPIXEL_OFFSETS: [f64; 3] = [-1.0 / 3.0, 0.0, 1.0 / 3.0];

/// Pixels whose centre lies within this of an edge are averaged over in 3 × 3 parts
/// (`SUBPIXEL_OFFSETS`), px; the rest of the band as one box. The box average along the edge's
/// normal matches a square's spread across an edge but not its shape (a step across a side, a
/// ramp across a diagonal), which matters where the edge crosses the pixel: 2 × 2 parts there
/// left noise-free centres with masked rim dots scattered 0.0025 px instead of 0.0023.
const EDGE_ZONE_PX: f64 = 1.0;

/// How a ring pixel's model is averaged over its area in the final round.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Area {
    /// An edge crosses it: in 3 × 3 parts.
    Fine,
    /// As one box.
    Whole,
}

/// One pixel of a ring: its centre (u, v), grey level, what a disc covering it hides
/// (`GreyImage::ground`), and how its area is integrated.
#[derive(Clone, Copy, Debug)]
struct RingPixel {
    u: f64,
    v: f64,
    grey: f64,
    hidden: f64,
    area: Area,
}

impl RingPixel {
    /// Whether the model is averaged over this pixel in 3 × 3 parts: in the last round
    /// (`area`), where an edge crosses it.
    fn in_parts(&self, area: bool) -> bool {
        area && self.area == Area::Fine
    }
}

/// The logistic step l(x) = 1/(1 + e^{−x/s}), its integral sp(x) = s·ln(1 + e^{x/s}) and
/// ∂sp/∂s, from one exponential and without overflow for any x/s.
fn softplus(x: f64, s: f64) -> (f64, f64, f64) {
    let e = (-x.abs() / s).exp();
    let l = if x >= 0.0 {
        1.0 / (1.0 + e)
    } else {
        e / (1.0 + e)
    };
    let sp = s * e.ln_1p() + x.max(0.0);
    (l, sp, sp / s - l * x / s)
}

/// The mean over a box of a lit sphere's shading and its derivatives (`mean_lit`).
struct LitMean {
    mean: f64,
    d_rho0: f64,
    d_rho1: f64,
    d_lamp: f64,
}

/// The mean of max(0, g(ρ)), g = λ·ρ + √(1 − ρ²), over ρ from `rho1` to `rho0` (ρ₁ ≤ ρ₀): a
/// matte sphere's shading along one radius, λ the lamp's slope along it. Exact, through
/// F(ρ) = (ρ·√(1 − ρ²) + asin ρ)/2 (F' = √(1 − ρ²)): g falls with ρ where λ < 0 and is zero
/// at the terminator ρ* = 1/√(1 + λ²), beyond which nothing is lit. The mean is smooth in
/// ρ₀, ρ₁ and λ (at the terminator g = 0, so moving it changes nothing to first order). Over a
/// span too short to difference (the box outside the sphere, where the step is flat anyway),
/// g at its middle, without derivatives.
fn mean_lit(rho0: f64, rho1: f64, lamp: f64) -> LitMean {
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
    let mean = integral / span;
    // Where the terminator does not cut the span, top = ρ₀.
    let g_top = if top < rho0 { 0.0 } else { lamp * rho0 + n_top };
    LitMean {
        mean,
        d_rho0: (g_top - mean) / span,
        d_rho1: (mean - (lamp * rho1 + n1)) / span,
        d_lamp: 0.5 * (top * top - rho1 * rho1) / span,
    }
}

/// Levenberg–Marquardt fit of `N` discs' grey-level model (see `profile_fit`) to `pixels`,
/// P = 1 + 10·N parameters: the background, then per disc [cx, cy, R, s, a, b, c₁, c₂, a₁, a₂]
/// (`DISC_PARAMS`); `layering`
/// says whether two discs' terms add or one hides the other. Each disc must settle within a
/// pixel of its start. Returns the discs and their fitted edge widths s, px.
fn fit_grey_levels<const P: usize, const N: usize>(
    pixels: &[RingPixel],
    starts: [&CircleFit; N],
    background: f64,
    layering: Layering,
    radius_px: Option<f64>,
) -> Option<([CircleFit; N], [f64; N])>
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
    // disc trade off with its centre (one frame in a dozen came out 0.1 px off): its shading
    // is held symmetric, those four terms at zero.
    let symmetric_disc = match layering {
        Layering::InFront(f) if N == 2 => Some(1 - f),
        _ => None,
    };
    // `hidden`: the backdrop a disc hides at this pixel (`RingPixel::hidden`). A disc replaces
    // what is behind it, and the normalisation subtracted that from every pixel, so a disc's
    // term is its step times its shading less what it hides: over a flat ground the same, over
    // a tube end or a ruler the occlusion a sum of terms would miss (spheres crossing a ruler
    // came out up to 1.2 px off, and the tube ends' edges pulled centres 0.1–0.5 px).
    let at_point = |p: &Vp<P>, u: f64, v: f64, h: f64, hidden: f64| -> (f64, Vp<P>) {
        // Per disc: its term l·inner, the term's derivatives, and l's own (for hiding).
        let mut term = [0.0; N];
        let mut d_term = [Vp::<P>::zeros(); N];
        let mut step = [0.0; N];
        let mut d_step = [Vp::<P>::zeros(); N];
        for k in 0..N {
            let o = 1 + DISC_PARAMS * k;
            let (du, dv) = (u - p[o], v - p[o + 1]);
            let d = dist(du, dv).max(1e-9);
            let (cs, sn) = (du / d, dv / d);
            let x = p[o + 2] - d;
            let s = p[o + 3];
            let r = p[o + 2];
            // The sample stands for a box of side h (a pixel, or a part of one). Seen across
            // the edge, a square box at any angle has the variance of a box of width h along
            // the edge's normal, h²/12: the model is averaged over that. Why: renders without
            // blur fit s ≈ 0.05 px, a near step, and point samples of a step made the cost a
            // staircase in the centre that the fit zig-zagged down (10 iterations on average,
            // each a pass over the pixels).
            // The edge, a logistic step of width s, averages over the box to the difference of
            // its integral, the softplus sp = s·ln(1 + e^{x/s}), across the box. sp is also the
            // depth below the (blurred) edge: the box covers the sphere from depth y₀ = sp(x −
            // h/2) to y₁ = sp(x + h/2), i.e. radii ρ from (R − y₀)/R down to (R − y₁)/R.
            let (l1, y1, ds1) = softplus(x + 0.5 * h, s);
            let (l0, y0, ds0) = softplus(x - 0.5 * h, s);
            let l = (y1 - y0) / h;
            let dl_dx = (l1 - l0) / h;
            let dl_ds = (ds1 - ds0) / h;
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
            let rho0 = ((r - y0) / r).clamp(-1.0, 1.0);
            let rho1 = ((r - y1) / r).clamp(-1.0, 1.0);
            let (c1, c2) = (p[o + 6], p[o + 7]);
            let lamp = c1 * cs + c2 * sn;
            let lit = mean_lit(rho0, rho1, lamp);
            let b = p[o + 5];
            let inner = p[o + 4] + b * lit.mean + p[o + 8] * cs + p[o + 9] * sn;
            let shown = inner - hidden;
            // Through ρᵢ = (R − sp(R − d ± h/2, s))/R: ∂ρᵢ/∂d = lᵢ/R, ∂ρᵢ/∂R =
            // ((1 − lᵢ) − ρᵢ)/R, ∂ρᵢ/∂s = −(∂sp/∂s)ᵢ/R.
            let dg_dd = (lit.d_rho0 * l0 + lit.d_rho1 * l1) / r;
            let dg_dr = (lit.d_rho0 * ((1.0 - l0) - rho0) + lit.d_rho1 * ((1.0 - l1) - rho1)) / r;
            let dg_ds = -(lit.d_rho0 * ds0 + lit.d_rho1 * ds1) / r;
            // dd/dcx = −cos θ, dd/dcy = −sin θ; d(cos θ)/dcx = −sin²θ/d, d(sin θ)/dcx =
            // cos θ sin θ/d, and for cy the same turned by 90°.
            let dlamp_dcx = (-c1 * sn * sn + c2 * cs * sn) / d;
            let dlamp_dcy = (c1 * cs * sn - c2 * cs * cs) / d;
            let di_dcx = b * (-dg_dd * cs + lit.d_lamp * dlamp_dcx)
                + (-p[o + 8] * sn * sn + p[o + 9] * cs * sn) / d;
            let di_dcy = b * (-dg_dd * sn + lit.d_lamp * dlamp_dcy)
                + (p[o + 8] * cs * sn - p[o + 9] * cs * cs) / d;
            let di_dr = b * dg_dr;
            let j = &mut d_term[k];
            j[o] = dl_dx * cs * shown + l * di_dcx;
            j[o + 1] = dl_dx * sn * shown + l * di_dcy;
            j[o + 2] = dl_dx * shown + l * di_dr;
            j[o + 3] = dl_ds * shown + l * b * dg_ds;
            j[o + 4] = l;
            j[o + 5] = l * lit.mean;
            if symmetric_disc != Some(k) {
                j[o + 6] = l * b * lit.d_lamp * cs;
                j[o + 7] = l * b * lit.d_lamp * sn;
                j[o + 8] = l * cs;
                j[o + 9] = l * sn;
            }
            if hiding {
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
        match layering {
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
    };
    // A pixel integrates the image over its area. `at_point` averages the model over a box
    // along the edge's normal; near the edge the pixel's square shape matters too: the edge's
    // profile across it depends on the edge's direction (a step across a side, a ramp across a
    // diagonal); that misfit cancels round a whole ring but not round one with dots masked
    // out, and moved the centre 0.005 px (noise-free renders). So in the final round a pixel
    // the edge crosses is averaged in 3 × 3 parts; elsewhere, and in the rounds that find the
    // dots, the pixel is one box.
    let eval = |p: &Vp<P>, px: &RingPixel, area: bool| -> (f64, Vp<P>) {
        if !px.in_parts(area) {
            return at_point(p, px.u, px.v, 1.0, px.hidden);
        }
        let offsets = &SUBPIXEL_OFFSETS;
        let h = 1.0 / offsets.len() as f64;
        let mut model = 0.0;
        let mut j = Vp::<P>::zeros();
        for a in offsets {
            for b in offsets {
                let (m, jj) = at_point(p, px.u + a, px.v + b, h, px.hidden);
                model += m;
                j += jj;
            }
        }
        let w = 1.0 / (offsets.len() * offsets.len()) as f64;
        (model * w, j * w)
    };
    let mut p = Vp::<P>::zeros();
    p[0] = background;
    for (k, st) in starts.iter().enumerate() {
        let o = 1 + DISC_PARAMS * k;
        p[o] = st.centre[0];
        p[o + 1] = st.centre[1];
        p[o + 2] = st.radius;
        p[o + 3] = 0.5;
    }
    // Grey-level parameters first, by linear least squares with the geometry held: the
    // background and each disc's (a, b, c).
    {
        let lin_index: Vec<usize> = std::iter::once(0)
            .chain((0..N).flat_map(|k| {
                let terms: &[usize] = if symmetric_disc == Some(k) {
                    &[4, 5]
                } else {
                    &[4, 5, 8, 9]
                };
                terms.iter().map(move |i| 1 + DISC_PARAMS * k + i)
            }))
            .collect();
        let m = lin_index.len();
        let mut a = nalgebra::DMatrix::<f64>::zeros(m, m);
        let mut y = nalgebra::DVector::<f64>::zeros(m);
        for q in pixels {
            let (model, j) = eval(&p, q, false);
            let row = nalgebra::DVector::from_iterator(m, lin_index.iter().map(|&i| j[i]));
            // The part of the model these terms do not carry (what a disc hides).
            let rest = model - lin_index.iter().map(|&i| j[i] * p[i]).sum::<f64>();
            a += &row * row.transpose();
            y += &row * (q.grey - rest);
        }
        let lin = a.lu().solve(&y)?;
        for (i, &idx) in lin_index.iter().enumerate() {
            p[idx] = lin[i];
        }
        // The lamp's direction from the harmonic the linear fit found (near the limb ρ ≈
        // 0.9, so b·c·ρ ≈ a₁), and the harmonic handed over to it; a disc darker inside than
        // at its rim gets no lamp.
        for k in 0..N {
            let o = 1 + DISC_PARAMS * k;
            if symmetric_disc == Some(k) {
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
    // R_back − k·R_front whose gradient row is `tie_row`.
    let tie = match layering {
        Layering::InFront(f) if N == 2 => {
            let (rf, rb) = (1 + DISC_PARAMS * f + 2, 1 + DISC_PARAMS * (1 - f) + 2);
            Some((rf, rb, starts[1 - f].radius / starts[f].radius))
        }
        _ => None,
    };
    // A lone disc of known radius (`radius_px`: one cut by the view's border, whose visible
    // arc fixes its radius and its centre across the cut poorly together) is held at it the
    // same way, as R − radius_px.
    let tie = tie.or_else(|| radius_px.filter(|_| N == 1).map(|r| (usize::MAX, 3, r)));
    const TIE_WEIGHT: f64 = 1e6;
    let tie_residual = |p: &Vp<P>| {
        tie.map_or(0.0, |(rf, rb, k)| {
            if rf == usize::MAX {
                p[rb] - k
            } else {
                p[rb] - k * p[rf]
            }
        })
    };
    let tie_row = tie.map(|(rf, rb, k)| {
        let mut a = Vp::<P>::zeros();
        a[rb] = 1.0;
        if rf != usize::MAX {
            a[rf] = -k;
        }
        a
    });
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
    // One pass over the pixels at p: the sum of squared residuals (without the tie), JᵀJ and
    // Jᵀr; with `robust` = Some(c), Cauchy's loss instead, Σ c²·ln(1 + (r/c)²), and each
    // pixel's row and residual weighted by √w, w = 1/(1 + (r/c)²) at p (iteratively
    // reweighted least squares: JᵀWJ, JᵀWr). `residuals` gets the plain residuals. A trial
    // step is evaluated with its Jacobian, so that once accepted the next iteration need not
    // pass over the pixels again (the same numbers, in the same order, as a separate cost pass
    // and Jacobian pass).
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
    let normal = |p: &Vp<P>,
                  keep: &[RingPixel],
                  area: bool,
                  robust: Option<f64>,
                  residuals: &mut Vec<f64>|
     -> (f64, Mp<P>, Vp<P>) {
        let mut jtj = Mp::<P>::zeros();
        let mut jtr = Vp::<P>::zeros();
        let mut sum_sq = 0.0;
        residuals.clear();
        let mut samples = 0;
        // The pixels' Jacobian rows in batches of `BATCH`, held by column, so that each entry of
        // JᵀJ is a short dot product the compiler vectorises rather than one add to memory per
        // pixel (those adds were the largest single cost of the fit).
        let mut rows = [[0.0; BATCH]; P];
        let mut res = [0.0; BATCH];
        let mut filled = 0;
        for q in keep {
            samples += if q.in_parts(area) {
                SUBPIXEL_OFFSETS.len() * SUBPIXEL_OFFSETS.len()
            } else {
                1
            };
            let (m, j) = eval(p, q, area);
            let r = q.grey - m;
            residuals.push(r);
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
        crate::analysis::stages::count_model_samples(samples);
        (sum_sq, jtj, jtr)
    };
    // Levenberg–Marquardt from p on the pixels kept, until a step would move no centre or
    // radius by more than `settled_px`. Returns the cost at the final p (with the tie), the
    // JᵀJ the last iteration started from (with the tie's row) and each pixel's residual at p in
    // `keep`'s order, all from the passes the descent made: neither the dots' rejection nor σ²
    // needs a pass over the pixels of its own.
    let descend = |p: &mut Vp<P>,
                   keep: &[RingPixel],
                   area: bool,
                   settled_px: f64,
                   robust: Option<f64>|
     -> (f64, Mp<P>, Vec<f64>) {
        let mut lambda = 1e-3;
        let mut res_at_p = Vec::with_capacity(keep.len());
        let mut res_trial = Vec::with_capacity(keep.len());
        let (sum_sq, mut jtj_at_p, mut jtr_at_p) = normal(p, keep, area, robust, &mut res_at_p);
        let mut c_now = sum_sq + TIE_WEIGHT * tie_residual(p).powi(2);
        // JᵀJ with the tie's row, as the last iteration began (what the covariance uses).
        let mut jtj = Mp::<P>::zeros();
        for _ in 0..30 {
            jtj = jtj_at_p;
            let mut jtr = jtr_at_p;
            if let Some(a) = &tie_row {
                jtj += a * a.transpose() * TIE_WEIGHT;
                jtr -= a * (TIE_WEIGHT * tie_residual(p));
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
                let (sum_sq, jtj_t, jtr_t) = normal(&trial, keep, area, robust, &mut res_trial);
                let c_new = sum_sq + TIE_WEIGHT * tie_residual(&trial).powi(2);
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
                    std::mem::swap(&mut res_at_p, &mut res_trial);
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
        (c_now, jtj, res_at_p)
    };
    // The residuals' σ from their median absolute value, with a floor of 3 % of the edge's
    // contrast: in a noise-free image the residuals are the model's own misfit, and rejecting
    // those would empty the ring.
    let robust_sigma = |res: &[f64], p: &Vp<P>| {
        let mut sorted: Vec<f64> = res.iter().map(|r| r.abs()).collect();
        sorted.sort_by(f64::total_cmp);
        let contrast = (0..N)
            .map(|k| p[5 + DISC_PARAMS * k].abs())
            .fold(f64::MAX, f64::min);
        (1.4826 * sorted[sorted.len() / 2])
            .max(0.03 * contrast)
            .max(0.5)
    };
    // How far each box round settles, px: the first, robust round only has to tell the dots
    // from the rim, to 1e-2 px (11 % fewer model evaluations on 38 varied-look recordings,
    // with the same centre RMS, 0.0741 px, and the independent renders' within their noise).
    // With plain least squares there, settling that loosely had put 5 estimates beyond 5σ on
    // the same recordings: where the dots steered the round, where it stopped mattered.
    let settle_px = |round: usize| if round == 0 { 1e-2 } else { 1e-3 };
    // Each pixel as one box first, rejecting dots; then pixels the edge crosses in 3 × 3 parts
    // from there, which moves the centres by thousandths of a pixel.
    let mut keep = pixels.to_vec();
    for round in 0..3 {
        // Settled only to `settle_px`: the dots to reject are all that depend on it, and the final
        // round's model is smooth, so it converges to its own minimum from here. (With point
        // samples of a near step and of √ at the limb, that round zig-zagged and where it
        // started showed in its result: this had to settle to 1e-7 px.)
        // The first round, with every dot still in, weighs each pixel by Cauchy's loss on a
        // scale from the residuals at the start, so that the dots' residuals do not steer the
        // descent. Why: with plain least squares the first round's minimum, and so which
        // pixels the rejection below dropped, moved with where the descent stopped (v03's
        // centres 0.072 → 0.103 px RMS when the descent was only made quicker,
        // docs/performance.md); the dots' residuals also made Gauss–Newton misjudge the
        // curvature and zig-zag (12 passes a fit). Measured on the same frames: v03 0.072 →
        // 0.037 px, 38 varied-look recordings 0.0783 → 0.0741 px, 12 % fewer model
        // evaluations.
        let robust = (round == 0).then(|| {
            let mut at_start = Vec::with_capacity(keep.len());
            normal(&p, &keep, false, None, &mut at_start);
            CAUCHY_SCALE * robust_sigma(&at_start, &p)
        });
        let (_, _, mut res) = descend(&mut p, &keep, false, settle_px(round), robust);
        if round == 2 {
            break;
        }
        // Dots on the rim are far darker than any model pixel; a pixel next to one may be
        // partly dot and only a little darker, so the neighbours of a rejected pixel go too.
        res.iter_mut().for_each(|r| *r = r.abs());
        let sigma = robust_sigma(&res, &p);
        let bad: Vec<(f64, f64)> = keep
            .iter()
            .zip(&res)
            .filter(|(_, r)| **r > 4.0 * sigma)
            .map(|(q, _)| (q.u, q.v))
            .collect();
        if bad.is_empty() {
            break;
        }
        // (Pixel centres: whole-pixel offsets, so the squares compare exactly.)
        keep.retain(|q| {
            !bad.iter()
                .any(|b| (q.u - b.0).powi(2) + (q.v - b.1).powi(2) <= 1.5 * 1.5)
        });
        if keep.len() < n_start / 2 {
            return None;
        }
    }
    let (cost, jtj, _) = descend(&mut p, &keep, true, 1e-4, None);
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
        if moved > 1.0 || (p[o + 2] - st.radius).abs() > 1.0 {
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
            ..**st
        };
    }
    Some((out, widths))
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
}
