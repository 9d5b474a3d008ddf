//! Markers: the dark dots painted on each sphere. Found inside each fitted disc as pixels much
//! darker than the disc's own shading at that radius, or, where a dot is too faint for that, as
//! a dot-sized patch darker than the ring round it (`faint_dots`); located at sub-pixel
//! precision by their coverage centroid, and lifted to 3-D on the sphere (physics.md §5): the
//! view sees the hemisphere facing its camera, so depth is +√(R² − ρ²) along the view's facing
//! direction. Markers beyond 53° from the view axis are dropped: foreshortening makes their
//! depth unreliable.

use super::circle::CircleFit;
use super::geometry::{View, V3};
use super::image::{four_neighbours, GreyImage};

mod faint;
mod shading;

use faint::{faint_dots, local_plane};
use shading::Shading;

/// One marker seen in one view of one frame.
#[derive(Clone, Copy, Debug)]
pub struct MarkerObs {
    /// Image position, px.
    pub centre_px: [f64; 2],
    /// Position relative to the sphere centre, world mm (on the sphere surface).
    pub rel_mm: V3,
    /// Relative weight in rotation fits: cos²α, α the angle from the view axis. The lifted depth
    /// error grows as σ·tan α, so markers near the limb count less.
    pub weight: f64,
    /// Unit vector from the sphere's centre towards the view that saw the dot (world): the
    /// direction its depth was lifted along, so a fit can tell what an error in the image does
    /// to the lifted point (`spin_tracks`).
    pub toward: V3,
}

/// How far a dot's darkness summed over its pixels must stand above the noise, in σ of that
/// sum (σ·√n for n pixels).
const DOT_SIGNIFICANCE: f64 = 5.0;

/// Whether a blob of `pixels` dark pixels with darkness-weighted second moments `[uu, vv, uv]`
/// (px²) is two dots (or a dot and something else dark) run together rather than one dot:
/// larger than one dot of radius `marker_radius_px` (1.2 times its area: two dots
/// foreshortened to 0.6 of their width near the limb still cover that), longer along its major
/// axis than one dot can be, and more than `MERGED_ELONGATION` times as long as it is wide. (A
/// dot a pixel or two across gives a blob of three pixels in a row as often as a square; the
/// size keeps that from counting.) Why: two dots a few pixels apart join through the pixels
/// between them, and their common centroid, the midpoint, is neither dot (on a 640×480
/// recording spinning at 200 rad/s, such midpoints in one frame and the separate dots in the
/// next put the spin 25 % low at 9.6σ). Such a blob gives one dot, started at its darkest
/// pixel, from where the coverage centroid settles on that dot; where the two part, the frames
/// on either side see each. (Leaving such blobs out instead fixed that recording too but lost
/// dots elsewhere: on 190 varied-look recordings 11 estimates beyond 5σ against 6, ψ2 within
/// ±1σ 59 % against 68 %.)
fn two_dots_touching(moments: [f64; 3], pixels: usize, marker_radius_px: f64) -> bool {
    let one_dot_px = std::f64::consts::PI * marker_radius_px * marker_radius_px;
    if (pixels as f64) < 1.2 * one_dot_px {
        return false;
    }
    let [uu, vv, uv] = moments;
    let half_trace = 0.5 * (uu + vv);
    let spread = (0.25 * (uu - vv).powi(2) + uv * uv).sqrt();
    let (major, minor) = (half_trace + spread, (half_trace - spread).max(0.0));
    major > 0.5 * marker_radius_px * marker_radius_px && major > MERGED_ELONGATION * minor
}

/// How many times longer than wide (as the ratio of its second moments) a dark blob may be and
/// still be one dot. A round dot's image is an ellipse foreshortened by cos α along the radius,
/// α ≤ 53° where markers are kept (`MAX_RHO_FRACTION`): at most 1/cos²53° = 2.8 (blur and the
/// pixel grid make it rounder). Two dots of radius r whose centres are 2r or more apart: at
/// least 1 + (2r)²/r² = 5.
const MERGED_ELONGATION: f64 = 4.0;

/// sin 53°: markers further out than this fraction of the radius are not lifted (closer to the
/// limb their centroid is biased inwards by the steep shading and the clipped dot).
const MAX_RHO_FRACTION: f64 = 0.8;

/// Markers inside a fitted disc. `radius_mm` is the sphere's known radius (the lifting uses it,
/// not the fitted image radius, which carries the edge-level bias).
pub fn find(
    img: &GreyImage,
    view: &View,
    disc: &CircleFit,
    radius_mm: f64,
    marker_diameter_mm: f64,
    noise_sigma: f64,
) -> Vec<MarkerObs> {
    let marker_radius_px = marker_diameter_mm / 2.0 * view.px_per_mm;
    let (cu, cv) = (disc.centre[0], disc.centre[1]);
    let r = disc.radius;
    // Markers are detected inside `inner`; the shading profile and the coverage centroid reach
    // closer to the limb (`outer`) so that dots near it are not cut in half.
    let inner = r - 1.0;
    let outer = r - 0.5;
    if inner < 2.0 {
        return Vec::new();
    }
    let [u0, u1, v0, v1] = img.box_around([cu, cv], inner);
    let Some(shading) = Shading::fit(img, view, [cu, cv], r, outer, noise_sigma) else {
        return Vec::new();
    };
    let expected = |u: f64, v: f64| shading.at(u, v);
    // The noise on the disc itself, not the view's: under shot noise a dark sphere on a bright
    // ground (backlit, lit from the front too) is far quieter than its ground, and its dots,
    // dark paint on a dark surface, stand out by little more than the ground's noise.
    let noise_sigma = shading.sigma;
    let w = u1 - u0 + 1;
    let h = v1 - v0 + 1;
    // A blur spreads a dot's darkening: at its middle a dot of radius a under a Gaussian blur
    // of σ keeps 1 − e^{−a²/2σ²} of it (σ = π·s/√3 from the grey-level fit's edge width s; 1
    // where the edge is sharp or unknown). The candidate test below asks for that share of a
    // sharp dot's quarter. Why: a dot blurred by a pixel is 15–20 % darker than the shading at
    // its middle, and none was found pixel by pixel — on eight varied-look rigs blurred by
    // 1.0–1.2 px no spin at all was measured (docs/accuracy.md, session 37).
    let blur_px = std::f64::consts::PI * disc.edge_width_px / 3f64.sqrt();
    let kept_at_middle = if blur_px > 0.0 {
        1.0 - (-(marker_radius_px * marker_radius_px) / (2.0 * blur_px * blur_px)).exp()
    } else {
        1.0
    };
    let mut dark = vec![0.0f64; w * h];
    for v in v0..=v1 {
        for u in u0..=u1 {
            let rho = (u as f64 - cu).hypot(v as f64 - cv);
            // (Beyond the view's region lies another view, or what a larger frame holds
            // around it: not this disc.)
            if rho >= inner || !view.contains(u as f64, v as f64) {
                continue;
            }
            let e = expected(u as f64, v as f64);
            let d = img.below(u, v, e);
            // A pixel is a candidate when it is a quarter darker than the shading (under a
            // blur, the share of that its middle keeps) and clear of the noise; a dot is kept
            // below when its darkness summed over its pixels is (see `DOT_SIGNIFICANCE`). Why
            // the sum: a faint dot (dark paint on a dark sphere) is darker than the noise in
            // each of its pixels by only a few σ, but over all of them by many; a lone noisy
            // pixel is not.
            if d > (0.25 * kept_at_middle * e).max(2.5 * noise_sigma) {
                dark[(v - v0) * w + (u - u0)] = d;
            }
        }
    }
    let mut out = Vec::new();
    let mut stack = Vec::new();
    // The rough centre of each dot.
    let mut dots: Vec<[f64; 2]> = Vec::new();
    for start in 0..dark.len() {
        if dark[start] <= 0.0 {
            continue;
        }
        let (mut sw, mut su, mut sv) = (0.0, 0.0, 0.0);
        let (mut suu, mut svv, mut suv) = (0.0, 0.0, 0.0);
        let mut darkest = (0.0, [0.0, 0.0]);
        stack.push(start);
        let mut members = Vec::new();
        while let Some(k) = stack.pop() {
            let d = dark[k];
            if d <= 0.0 {
                continue;
            }
            dark[k] = 0.0;
            members.push(k);
            let (x, y) = (k % w, k / w);
            let (fu, fv) = ((u0 + x) as f64, (v0 + y) as f64);
            sw += d;
            su += d * fu;
            sv += d * fv;
            suu += d * fu * fu;
            svv += d * fv * fv;
            suv += d * fu * fv;
            if d > darkest.0 {
                darkest = (d, [fu, fv]);
            }
            stack.extend(four_neighbours(x, y, w, h).map(|(nu, nv)| nv * w + nu));
        }
        // A marker blob larger than a quarter of the disc is not a marker (shading model failed).
        if sw <= 0.0 || members.len() as f64 > 0.25 * std::f64::consts::PI * r * r {
            continue;
        }
        if sw < DOT_SIGNIFICANCE * noise_sigma * (members.len() as f64).sqrt() {
            continue;
        }
        let (mu, mv) = (su / sw, sv / sw);
        if two_dots_touching(
            [suu / sw - mu * mu, svv / sw - mv * mv, suv / sw - mu * mv],
            members.len(),
            marker_radius_px,
        ) {
            dots.push(darkest.1);
            continue;
        }
        dots.push([mu, mv]);
    }
    // Faint dots are looked for only on a disc that shows none pixel by pixel (paint that stands
    // out anywhere on a face stands out pixel by pixel on it; the faint test's false alarms, a
    // few in a thousand discs, are not worth spending where dots are seen already: on the 190
    // kept varied-look recordings, looking on every disc made sharp looks' centres 3–10 % worse
    // through the dot masks of the second pass), and only where the disc's edge says the view
    // is sharp: a blur (σ = π·s/√3 from the grey-level fit's edge width s) beyond half a dot's
    // radius spreads the dot past the filter's core into its ring, where neither its detection
    // nor its centroid holds (on defocused varied looks such dots came out up to a pixel off,
    // and the spins resting on them up to 10σ). Unknown blur (a fit on edge points) counts as
    // blurred.
    let faint = dots.is_empty() && blur_px <= 0.5 * marker_radius_px;
    if faint {
        dots.extend(faint_dots(
            img,
            view,
            [cu, cv],
            [inner, outer],
            &expected,
            noise_sigma,
            marker_radius_px,
        ));
    }
    // The centroid of a dot's projected area lies closer to the disc centre than the projection
    // of the dot's centre, by the factor 1 − θ²/2 (θ its angular radius on the sphere): the part
    // of the dot nearer the view axis is foreshortened less.
    let theta = marker_diameter_mm / 2.0 / radius_mm;
    let foreshortening = 1.0 - theta * theta / 2.0;
    // Where each faint dot settled, to drop a second start that settles on the same dot.
    let mut settled: Vec<[f64; 2]> = Vec::new();
    // (Faint dots are only looked for where no dot was found pixel by pixel: `faint` holds for
    // every dot or for none.)
    for rough in dots {
        // Sub-pixel position: the centroid of the dot's coverage in a window re-centred on each
        // pass. Coverage, not darkness: the darkness of a dot follows the shading under it and
        // would pull the centre towards the bright middle of the disc. Coverage is taken as the
        // fraction of the light the pixel lost, (shading − grey)/shading: matte paint returns a
        // fixed fraction of the light that falls on it, so a dot's darkening is its coverage
        // times that constant whatever the shading, and the constant drops out of the centroid.
        // Dividing by (shading − one paint grey) instead, as before, weighted a dot's dimmer
        // (limb-ward) side more wherever the paint is not one grey: under defocus, dots between
        // a third and two thirds of the radius came out 0.17 px outwards (0.05 now), and 33
        // recorded varied-look sessions had 12 estimates beyond 5σ against 7 now. Paint of one fixed grey (hw-sim's default look)
        // is weighted by 1 − grey/shading, a slow change across a dot. Weights are signed, so
        // noise averages out instead of being clipped to one side.
        let window = marker_radius_px + 1.0;
        let [mut mu, mut mv] = rough;
        for _ in 0..3 {
            // A faint dot's coverage is a few times the noise and the shading model's slow
            // misfit, which a centroid weights by distance and so turns into a pull: it is
            // measured against a plane fitted to the coverage on a ring round the window.
            let local = if faint {
                match local_plane(img, view, [mu, mv], window, [cu, cv, outer], &expected) {
                    Some(p) => p,
                    None => break,
                }
            } else {
                [0.0; 3]
            };
            let (mut cw, mut cu_acc, mut cv_acc) = (0.0, 0.0, 0.0);
            let [wu0, wu1, wv0, wv1] = img.box_around([mu, mv], window);
            for v in wv0..=wv1 {
                for u in wu0..=wu1 {
                    let (fu, fv) = (u as f64, v as f64);
                    if (fu - mu).hypot(fv - mv) > window
                        || (fu - cu).hypot(fv - cv) >= outer
                        || !view.contains(fu, fv)
                    {
                        continue;
                    }
                    let e = expected(fu, fv);
                    if e <= 0.0 {
                        continue;
                    }
                    let d = img.below(u, v, e) / e
                        - (local[0] + local[1] * (fu - mu) + local[2] * (fv - mv));
                    cw += d;
                    cu_acc += d * fu;
                    cv_acc += d * fv;
                }
            }
            if cw <= 0.0 {
                break;
            }
            let next = (cu_acc / cw, cv_acc / cw);
            if (next.0 - mu).hypot(next.1 - mv) > window {
                break;
            }
            (mu, mv) = next;
        }
        // Two faint starts on one dot (two maxima of its contrast) settle within a pixel of each
        // other: one dot, reported once. (Dots found pixel by pixel are left as they were:
        // there, two blobs of one dot split by a noisy pixel also settle together and are
        // reported twice, 39 pairs in one 400-frame recording; dropping the second moved
        // defocused recordings' spins and velocities to 5–7σ (docs/accuracy.md, session 34).)
        if faint {
            if settled
                .iter()
                .any(|s| (s[0] - mu).hypot(s[1] - mv) < marker_radius_px.max(1.0))
            {
                continue;
            }
            settled.push([mu, mv]);
        }
        let dot = [
            cu + (mu - cu) / foreshortening,
            cv + (mv - cv) / foreshortening,
        ];
        out.extend(lift(view, dot, [cu, cv], radius_mm));
    }
    out
}

/// A dot at image position `dot_px` on the sphere whose centre is at `centre_px`, lifted onto
/// the hemisphere facing the view; None beyond `MAX_RHO_FRACTION` of the radius.
pub fn lift(
    view: &View,
    dot_px: [f64; 2],
    centre_px: [f64; 2],
    radius_mm: f64,
) -> Option<MarkerObs> {
    let du_mm = (dot_px[0] - centre_px[0]) / view.px_per_mm;
    let dv_mm = (dot_px[1] - centre_px[1]) / view.px_per_mm;
    let rho2 = du_mm * du_mm + dv_mm * dv_mm;
    if rho2 > (MAX_RHO_FRACTION * radius_mm).powi(2) {
        return None;
    }
    let depth = (radius_mm * radius_mm - rho2).max(0.0).sqrt();
    Some(MarkerObs {
        centre_px: dot_px,
        rel_mm: view.u_axis * du_mm + view.v_axis * dv_mm + view.facing * depth,
        weight: (depth / radius_mm).powi(2),
        toward: view.facing,
    })
}

/// As `lift`, for a sphere whose centre is known to be at world point `at`: the dot's offset is
/// read through the view's map there (a pinhole's scale and line of sight at the sphere, an
/// affine matrix as it is, and a lens's stretch there) instead of the view's scale and axes at
/// the origin. Aligned views without a lens are lifted exactly as by `lift`.
pub fn lift_at(
    view: &View,
    dot_px: [f64; 2],
    centre_px: [f64; 2],
    radius_mm: f64,
    at: &V3,
) -> Option<MarkerObs> {
    if view.aligned && view.lens.is_none() {
        return lift(view, dot_px, centre_px, radius_mm);
    }
    let (j, toward) = view.local_at(at);
    let jjt = j * j.transpose();
    let inv = jjt.try_inverse()?;
    let d = nalgebra::Vector2::new(dot_px[0] - centre_px[0], dot_px[1] - centre_px[1]);
    // The offset in the plane square to the line of sight (J's row space).
    let across: V3 = j.transpose() * (inv * d);
    let rho2 = across.norm_squared();
    if rho2 > (MAX_RHO_FRACTION * radius_mm).powi(2) {
        return None;
    }
    let depth = (radius_mm * radius_mm - rho2).max(0.0).sqrt();
    Some(MarkerObs {
        centre_px: dot_px,
        rel_mm: across + toward * depth,
        weight: (depth / radius_mm).powi(2),
        toward,
    })
}

/// Where the two spheres' discs overlap in a view (passing at different depths, one partly
/// behind the other), a dot inside the other sphere's disc may be either sphere's: it is left
/// out of both, so that one sphere's markers never turn the other's spin.
pub(super) fn drop_in_the_other_disc(obs: &mut [super::tracking::FrameObs]) {
    for f in obs.iter_mut() {
        let [a, b] = &mut f.spheres;
        for (ma, mb) in a.iter_mut().zip(b.iter_mut()) {
            let (Some(ma), Some(mb)) = (ma.as_mut(), mb.as_mut()) else {
                continue;
            };
            let d = (ma.centre_px[0] - mb.centre_px[0]).hypot(ma.centre_px[1] - mb.centre_px[1]);
            if d >= 0.5 * (ma.diameter_px + mb.diameter_px) {
                continue;
            }
            let inside = |m: &MarkerObs, other: &super::tracking::Measurement| {
                (m.centre_px[0] - other.centre_px[0]).hypot(m.centre_px[1] - other.centre_px[1])
                    < 0.5 * other.diameter_px
            };
            let (ca, cb) = (ma.clone(), mb.clone());
            ma.markers.retain(|m| !inside(m, &cb));
            mb.markers.retain(|m| !inside(m, &ca));
        }
    }
}

#[cfg(test)]
mod tests;
