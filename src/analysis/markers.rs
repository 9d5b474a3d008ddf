//! Markers: the dark dots painted on each sphere. Found inside each fitted disc as pixels much
//! darker than the disc's own shading at that radius, located at sub-pixel precision by their
//! darkness-weighted centroid, and lifted to 3-D on the sphere (physics.md §5): the view sees the
//! hemisphere facing its camera, so depth is +√(R² − ρ²) along the view's facing direction.
//! Markers beyond 53° from the view axis are dropped: foreshortening makes their depth unreliable.

use super::circle::CircleFit;
use super::geometry::{View, V3};
use super::image::GreyImage;

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
}

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
    let (u0, u1) = (
        (cu - inner).floor().max(0.0) as usize,
        ((cu + inner).ceil() as usize).min(img.width - 1),
    );
    let (v0, v1) = (
        (cv - inner).floor().max(0.0) as usize,
        ((cv + inner).ceil() as usize).min(img.height - 1),
    );
    // Radial shading profile: the upper quartile in each 0.5 px ring (markers are a minority).
    let bins = (inner / 0.5).ceil() as usize + 1;
    let mut rings: Vec<Vec<f32>> = vec![Vec::new(); bins];
    for v in v0..=v1 {
        for u in u0..=u1 {
            let rho = (u as f64 - cu).hypot(v as f64 - cv);
            if rho < outer {
                rings[(rho / 0.5) as usize].push(img.at(u, v));
            }
        }
    }
    let profile: Vec<Option<f64>> = rings
        .iter_mut()
        .map(|ring| {
            if ring.is_empty() {
                return None;
            }
            ring.sort_by(f32::total_cmp);
            Some(ring[ring.len() * 3 / 4] as f64)
        })
        .collect();
    let expected = |rho: f64| -> Option<f64> {
        let k = (rho / 0.5) as usize;
        profile
            .get(k)
            .copied()
            .flatten()
            .or_else(|| profile.iter().rev().flatten().next().copied())
    };
    let w = u1 - u0 + 1;
    let h = v1 - v0 + 1;
    let mut dark = vec![0.0f64; w * h];
    for v in v0..=v1 {
        for u in u0..=u1 {
            let rho = (u as f64 - cu).hypot(v as f64 - cv);
            if rho >= inner {
                continue;
            }
            if let Some(e) = expected(rho) {
                let d = e - img.at(u, v) as f64;
                if d > (0.25 * e).max(5.0 * noise_sigma) {
                    dark[(v - v0) * w + (u - u0)] = d;
                }
            }
        }
    }
    let mut out = Vec::new();
    let mut stack = Vec::new();
    for start in 0..dark.len() {
        if dark[start] <= 0.0 {
            continue;
        }
        let (mut sw, mut su, mut sv) = (0.0, 0.0, 0.0);
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
            sw += d;
            su += d * (u0 + x) as f64;
            sv += d * (v0 + y) as f64;
            if x > 0 {
                stack.push(k - 1);
            }
            if x + 1 < w {
                stack.push(k + 1);
            }
            if y > 0 {
                stack.push(k - w);
            }
            if y + 1 < h {
                stack.push(k + w);
            }
        }
        // A marker blob larger than a quarter of the disc is not a marker (shading model failed).
        if sw <= 0.0 || members.len() as f64 > 0.25 * std::f64::consts::PI * r * r {
            continue;
        }
        // Sub-pixel position: the centroid of the dot's coverage (not of its darkness, which
        // follows the shading and would pull the centre towards the bright middle of the disc).
        let level = members
            .iter()
            .map(|&k| img.at(u0 + k % w, v0 + k / w) as f64)
            .fold(f64::INFINITY, f64::min);
        let window = marker_radius_px + 1.5;
        let (mut mu, mut mv) = (su / sw, sv / sw);
        for _ in 0..2 {
            let (mut cw, mut cu_acc, mut cv_acc) = (0.0, 0.0, 0.0);
            let (wu0, wu1) = (
                (mu - window).floor().max(0.0) as usize,
                ((mu + window).ceil() as usize).min(img.width - 1),
            );
            let (wv0, wv1) = (
                (mv - window).floor().max(0.0) as usize,
                ((mv + window).ceil() as usize).min(img.height - 1),
            );
            for v in wv0..=wv1 {
                for u in wu0..=wu1 {
                    let (fu, fv) = (u as f64, v as f64);
                    if (fu - mu).hypot(fv - mv) > window {
                        continue;
                    }
                    let rho = (fu - cu).hypot(fv - cv);
                    if rho >= outer {
                        continue;
                    }
                    let Some(e) = expected(rho) else { continue };
                    if e - level <= 0.0 {
                        continue;
                    }
                    let cover = ((e - img.at(u, v) as f64) / (e - level)).clamp(0.0, 1.0);
                    if cover > 0.1 {
                        cw += cover;
                        cu_acc += cover * fu;
                        cv_acc += cover * fv;
                    }
                }
            }
            if cw <= 0.0 {
                break;
            }
            (mu, mv) = (cu_acc / cw, cv_acc / cw);
        }
        let du_mm = (mu - cu) / view.px_per_mm;
        let dv_mm = (mv - cv) / view.px_per_mm;
        let rho2 = du_mm * du_mm + dv_mm * dv_mm;
        if rho2 > (MAX_RHO_FRACTION * radius_mm).powi(2) {
            continue;
        }
        let depth = (radius_mm * radius_mm - rho2).max(0.0).sqrt();
        let rel = view.u_axis * du_mm + view.v_axis * dv_mm + view.facing * depth;
        out.push(MarkerObs {
            centre_px: [mu, mv],
            rel_mm: rel,
            weight: (depth / radius_mm).powi(2),
        });
    }
    out
}
