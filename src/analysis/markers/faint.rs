//! Dots too faint to stand out pixel by pixel, found by a dot-sized patch's darkness against
//! the ring round it, and the plane of the coverage round a dot that such a dot's centroid is
//! measured against.

use super::super::geometry::View;
use super::super::image::GreyImage;

/// How far a faint dot's mean darkness must stand above that of the ring round it, in σ of that
/// difference (`faint_dots`). Set by the false alarms it lets through: Gaussian noise passes 4σ
/// at one position in 30 000, and a disc holds a few dozen dot-sized positions, so about one
/// disc in a thousand shows a dot that is not there — which the spin fit must then also see
/// again where the spin carries it, frame after frame, to count. (At 5σ, the bar for a dot
/// found pixel by pixel, a backlit face's dots at 4–5.5σ are missed in most frames.)
const FAINT_DOT_SIGNIFICANCE: f64 = 4.0;

/// How far a faint dot's core must stand darker than each quarter of the ring round it, in σ of
/// that difference (`faint_dots`). A dot is darker than all its surround; a dark band or an
/// edge (the terminator of a side light, which the shading model does not follow) is not darker
/// than the quarters it runs through, yet can pass the ring's mean. On a side-lit 640×480
/// recording (seed 137) the faint pass found 451 dots that are not there without this test,
/// 242 at 1σ and 27 at 2σ; the independent renders' backlit dots (v04) pass it.
const FAINT_DOT_APART: f64 = 2.0;

/// The least fraction of the shading's light a faint dot's core must take away (`faint_dots`;
/// a dot found pixel by pixel takes a quarter). The shading model misses a shiny or side-lit
/// face by a few per cent of its level (3–12 grey levels on faces of 100–200), and a pocket of
/// that misfit between a highlight and its surround passed the contrast tests on the
/// independent renders' v03 (a shiny sphere: a "dot" 1–2 px from the mirror disc's centre in
/// frame after frame, its spin after the impact 4.5σ off; gone at 0.1, not at 0.05). Paint
/// darker than that by a tenth of the light is still found: the backlit v04's dots take 20–40 %.
const FAINT_DOT_DARKER: f64 = 0.1;

/// Dots too faint for any one of their pixels to stand out (dark paint on a backlit sphere's
/// dark face, pale paint), found where the darkness averaged over a dot's area stands above the
/// darkness of a ring just outside it by `FAINT_DOT_SIGNIFICANCE` (a matched filter less its
/// surround, so that a slow misfit of the shading model cancels) and above each quarter of that
/// ring by `FAINT_DOT_APART`. The dot's own darkness must also be clear of the noise (3σ of its
/// mean) and a tenth of the light (`FAINT_DOT_DARKER`), so that a bright ring (a highlight
/// beside it) or the shading model's misfit does not make a dot of ordinary surface. One rough
/// centre per local maximum of that contrast. Why: a backlit sphere's dots are 5–10 grey levels
/// below its face with a noise of 2–4 there (the independent renders' v04, a's direct view over
/// 12 frames: 28 of 36 visible dots at 3–7.6σ this way, nothing else above 3σ; pixel by pixel,
/// a dot in a view now and then). Only on a sharp disc without dots found pixel by pixel
/// (`find`).
pub(super) fn faint_dots(
    img: &GreyImage,
    view: &View,
    centre: [f64; 2],
    [inner, outer]: [f64; 2],
    expected: &dyn Fn(f64, f64) -> f64,
    noise_sigma: f64,
    marker_radius_px: f64,
) -> Vec<[f64; 2]> {
    let [cu, cv] = centre;
    // A dot's core (at least the pixel and its four neighbours) and the ring round it.
    let core_r = marker_radius_px.max(1.0);
    let (ring_r0, ring_r1) = (core_r + 0.8, core_r + 2.3);
    let reach = outer + 0.5;
    let [u0, u1, v0, v1] = img.box_around([cu, cv], reach);
    let (w, h) = (u1 - u0 + 1, v1 - v0 + 1);
    // Darkness below the shading, signed (noise averages out); NaN off the disc.
    let mut dark = vec![f64::NAN; w * h];
    for v in v0..=v1 {
        for u in u0..=u1 {
            let (fu, fv) = (u as f64, v as f64);
            if (fu - cu).hypot(fv - cv) < outer && view.contains(fu, fv) {
                dark[(v - v0) * w + (u - u0)] = img.below(u, v, expected(fu, fv));
            }
        }
    }
    let span = ring_r1.ceil() as isize;
    let mut contrast = vec![f64::NEG_INFINITY; w * h];
    for y in 0..h {
        for x in 0..w {
            let (fu, fv) = ((u0 + x) as f64, (v0 + y) as f64);
            if (fu - cu).hypot(fv - cv) >= inner {
                continue;
            }
            let (mut core, mut nc, mut ring, mut nr) = (0.0, 0usize, 0.0, 0usize);
            // The ring by quarter (right, below, left, above): a dot is darker than all of
            // them, a dark band or edge (a terminator the shading model does not follow) is
            // not darker than the quarters it runs through.
            let (mut quarter, mut nq) = ([0.0f64; 4], [0usize; 4]);
            for dy in -span..=span {
                for dx in -span..=span {
                    let (xx, yy) = (x as isize + dx, y as isize + dy);
                    if xx < 0 || yy < 0 || xx >= w as isize || yy >= h as isize {
                        continue;
                    }
                    let d = dark[yy as usize * w + xx as usize];
                    if d.is_nan() {
                        continue;
                    }
                    let rr = (dx as f64).hypot(dy as f64);
                    if rr <= core_r {
                        core += d;
                        nc += 1;
                    } else if rr > ring_r0 && rr <= ring_r1 {
                        ring += d;
                        nr += 1;
                        let q = if dx.abs() >= dy.abs() {
                            if dx > 0 {
                                0
                            } else {
                                2
                            }
                        } else if dy > 0 {
                            1
                        } else {
                            3
                        };
                        quarter[q] += d;
                        nq[q] += 1;
                    }
                }
            }
            if nc < 3 || nr < 6 {
                continue;
            }
            let (mc, mr) = (core / nc as f64, ring / nr as f64);
            let sigma_diff = noise_sigma * (1.0 / nc as f64 + 1.0 / nr as f64).sqrt();
            if mc < 3.0 * noise_sigma / (nc as f64).sqrt()
                || mc < FAINT_DOT_DARKER * expected(fu, fv)
            {
                continue;
            }
            let apart = quarter.iter().zip(&nq).all(|(&sq, &n)| {
                n == 0
                    || (mc - sq / n as f64)
                        >= FAINT_DOT_APART * noise_sigma * (1.0 / nc as f64 + 1.0 / n as f64).sqrt()
            });
            if !apart {
                continue;
            }
            contrast[y * w + x] = (mc - mr) / sigma_diff;
        }
    }
    let mut out: Vec<[f64; 2]> = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let c = contrast[y * w + x];
            if c < FAINT_DOT_SIGNIFICANCE {
                continue;
            }
            // A local maximum over the eight neighbours (ties to the first in raster order).
            let mut peak = true;
            for (dx, dy) in [
                (-1, -1),
                (0, -1),
                (1, -1),
                (-1, 0),
                (1, 0),
                (-1, 1),
                (0, 1),
                (1, 1),
            ] {
                let (xx, yy) = (x as isize + dx, y as isize + dy);
                if xx < 0 || yy < 0 || xx >= w as isize || yy >= h as isize {
                    continue;
                }
                let n = contrast[yy as usize * w + xx as usize];
                if n > c || (n == c && (dy < 0 || (dy == 0 && dx < 0))) {
                    peak = false;
                }
            }
            let p = [(u0 + x) as f64, (v0 + y) as f64];
            if peak
                && !out
                    .iter()
                    .any(|o| (o[0] - p[0]).hypot(o[1] - p[1]) < ring_r0)
            {
                out.push(p);
            }
        }
    }
    out
}

/// The plane c₀ + c₁·(u − u₀) + c₂·(v − v₀) fitted by least squares to the coverage
/// (shading − grey)/shading of the disc's pixels between `window` + 0.5 and `window` + 2 px from
/// `at` = (u₀, v₀): what a faint dot's coverage is measured against (`find`). None where the
/// ring holds too few of the disc's pixels to fit it (`disc` = centre u, v and the radius
/// pixels are taken within).
pub(super) fn local_plane(
    img: &GreyImage,
    view: &View,
    at: [f64; 2],
    window: f64,
    disc: [f64; 3],
    expected: &dyn Fn(f64, f64) -> f64,
) -> Option<[f64; 3]> {
    let [mu, mv] = at;
    let [cu, cv, within] = disc;
    let (r0, r1) = (window + 0.5, window + 2.0);
    let [u0, u1, v0, v1] = img.box_around([mu, mv], r1);
    let mut ata = nalgebra::Matrix3::<f64>::zeros();
    let mut atb = nalgebra::Vector3::<f64>::zeros();
    let mut n = 0;
    for v in v0..=v1 {
        for u in u0..=u1 {
            let (fu, fv) = (u as f64, v as f64);
            let rr = (fu - mu).hypot(fv - mv);
            if rr <= r0 || rr > r1 || (fu - cu).hypot(fv - cv) >= within || !view.contains(fu, fv) {
                continue;
            }
            let e = expected(fu, fv);
            if e <= 0.0 {
                continue;
            }
            let a = nalgebra::Vector3::new(1.0, fu - mu, fv - mv);
            ata += a * a.transpose();
            atb += a * (img.below(u, v, e) / e);
            n += 1;
        }
    }
    if n < 8 {
        return None;
    }
    let p = ata.lu().solve(&atb)?;
    Some([p[0], p[1], p[2]])
}
