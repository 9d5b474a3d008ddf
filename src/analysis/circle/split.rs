//! Two spheres in one silhouette: split into two circles fitted together with one radius,
//! without the points where the two outlines meet.

use super::edge::{fit_fixed_radius, sectors_covered};
use super::{gauss_newton, CircleFit, GreyImage, View};

/// Both circles of a split silhouette at once, with one radius between them: the radius a
/// single disc measures is not quite the radius of the union's outline (its edge level comes from
/// a different interior), and with a radius held wrong, arcs that face away from each other pull
/// the centres together or apart.
fn fit_pair_shared_radius(
    a: &[[f64; 2]],
    b: &[[f64; 2]],
    start: [CircleFit; 2],
    oversampling: f64,
) -> Option<[CircleFit; 2]> {
    if a.len() < 8 || b.len() < 8 {
        return None;
    }
    let mut p = nalgebra::Vector5::new(
        start[0].centre[0],
        start[0].centre[1],
        start[1].centre[0],
        start[1].centre[1],
        0.5 * (start[0].radius + start[1].radius),
    );
    let (jtj, _, ss) = gauss_newton(&mut p, 20, |p| {
        let mut jtj = nalgebra::Matrix5::<f64>::zeros();
        let mut jtr = nalgebra::Vector5::<f64>::zeros();
        let mut ss = 0.0;
        for (k, pts) in [a, b].iter().enumerate() {
            for q in pts.iter() {
                let (dx, dy) = (q[0] - p[2 * k], q[1] - p[2 * k + 1]);
                let d = dx.hypot(dy).max(1e-12);
                let mut j = nalgebra::Vector5::<f64>::zeros();
                j[2 * k] = -dx / d;
                j[2 * k + 1] = -dy / d;
                j[4] = -1.0;
                let r = d - p[4];
                jtj += j * j.transpose();
                jtr += j * r;
                ss += r * r;
            }
        }
        (jtj, jtr, ss)
    })?;
    let n = (a.len() + b.len()) as f64;
    let s2 = ss / (n - 5.0).max(1.0);
    let inv = jtj.try_inverse()?;
    let cov_scale = s2 * oversampling.max(1.0);
    let circle = |k: usize, pts: &[[f64; 2]], total: usize| CircleFit {
        centre: [p[2 * k], p[2 * k + 1]],
        radius: p[4],
        centre_sigma: [
            (cov_scale * inv[(2 * k, 2 * k)]).sqrt(),
            (cov_scale * inv[(2 * k + 1, 2 * k + 1)]).sqrt(),
        ],
        radius_sigma: (cov_scale * inv[(4, 4)]).sqrt(),
        rms_px: s2.sqrt(),
        points_used: pts.len(),
        points_total: total,
        arc_sectors: sectors_covered(pts, [p[2 * k], p[2 * k + 1]]),
        grey_levels: false,
        edge_width_px: f64::NAN,
    };
    Some([
        circle(0, a, start[0].points_total),
        circle(1, b, start[1].points_total),
    ])
}

/// How far outside the other circle an outline point must lie to count for this one, px.
const CUSP_MARGIN_PX: f64 = 1.0;

/// The discs in one silhouette that holds both spheres (touching, or one partly hiding the
/// other in this view): the outermost edge on rays from the blob's centroid traces the union's
/// outline, two arcs of circles of about the known radius. Each circle is found by consensus —
/// every pair of outline points a radius apart proposes the two circles of that radius through
/// them, and the proposal most points agree with wins — then refined by the robust fit on its
/// own points; the second is searched among the points the first does not explain. Circles
/// resting on less than a quarter of the outline are not returned. Two circles are then
/// refitted together (one radius, without the points where the outlines meet); one circle is
/// returned only if it explains the whole outline (the other sphere wholly behind it).
pub fn split_pair(
    img: &GreyImage,
    view: &View,
    centroid: [f64; 2],
    radius_px: f64,
    background: f64,
    peak: f64,
) -> Vec<CircleFit> {
    let rays = ((std::f64::consts::TAU * 2.0 * radius_px * 1.5).round() as usize).clamp(48, 1440);
    let oversampling = rays as f64 / (std::f64::consts::TAU * 2.0 * radius_px);
    let r_max = 2.0 * radius_px + 4.0;
    let step = 0.2;
    // Outermost fall through `level` on each ray, searching inwards from beyond the union.
    let outline = |level: f64| -> Vec<([f64; 2], f64)> {
        let mut pts = Vec::with_capacity(rays);
        for k in 0..rays {
            let a = std::f64::consts::TAU * k as f64 / rays as f64;
            let (dx, dy) = (a.cos(), a.sin());
            let mut r = r_max;
            let mut outer: Option<(f64, f64)> = None;
            while r > 0.0 {
                let (u, v) = (centroid[0] + r * dx, centroid[1] + r * dy);
                let val = if view.contains(u, v) {
                    img.sample(u, v)
                } else {
                    None
                };
                match (val, outer) {
                    (Some(val), Some((ro, vo))) if val >= level => {
                        let f = (val - level) / (val - vo);
                        let re = r + f * (ro - r);
                        let rim = img
                            .sample(centroid[0] + (re - 1.5) * dx, centroid[1] + (re - 1.5) * dy)
                            .unwrap_or(level);
                        pts.push(([centroid[0] + re * dx, centroid[1] + re * dy], rim));
                        break;
                    }
                    (Some(val), _) => outer = Some((r, val)),
                    // Outside the view: the outline is clipped here.
                    (None, _) if outer.is_some() => break,
                    (None, _) => {}
                }
                r -= step;
            }
        }
        pts
    };
    let first = outline(background + 0.5 * (peak - background));
    if first.len() < rays / 2 {
        return Vec::new();
    }
    let mut rims: Vec<f64> = first.iter().map(|p| p.1).collect();
    rims.sort_by(f64::total_cmp);
    let interior = rims[rims.len() * 3 / 4];
    if interior <= background {
        return Vec::new();
    }
    let mut points: Vec<[f64; 2]> = outline(background + 0.5 * (interior - background))
        .into_iter()
        .map(|p| p.0)
        .collect();
    let tol = 0.3;
    let ring_sq = (
        (radius_px - tol).max(0.0).powi(2),
        (radius_px + tol).powi(2),
    );
    let all_points = points.clone();
    let mut out = Vec::new();
    for _ in 0..2 {
        let n = points.len();
        if n < rays / 4 {
            break;
        }
        let mut best: Option<([f64; 2], usize)> = None;
        for i in 0..n {
            for j in (i + 1..n).step_by((n / 24).max(1)) {
                let (p, q) = (points[i], points[j]);
                let d = (q[0] - p[0]).hypot(q[1] - p[1]);
                if d < 0.5 * radius_px || d >= 2.0 * radius_px {
                    continue;
                }
                let h = (radius_px * radius_px - d * d / 4.0).sqrt();
                let mid = [(p[0] + q[0]) / 2.0, (p[1] + q[1]) / 2.0];
                let perp = [-(q[1] - p[1]) / d, (q[0] - p[0]) / d];
                for sgn in [-1.0, 1.0] {
                    let c = [mid[0] + sgn * h * perp[0], mid[1] + sgn * h * perp[1]];
                    // |d − r| < tol as squares: this count runs for every pair of outline
                    // points, and `hypot` there was 4 % of the whole analysis.
                    let support = points
                        .iter()
                        .filter(|x| {
                            let d2 = (x[0] - c[0]).powi(2) + (x[1] - c[1]).powi(2);
                            d2 > ring_sq.0 && d2 < ring_sq.1
                        })
                        .count();
                    if best.is_none_or(|(_, b)| support > b) {
                        best = Some((c, support));
                    }
                }
            }
        }
        let Some((c, support)) = best else { break };
        if support < rays / 4 {
            break;
        }
        // Its points, then the centre by least squares with the radius held: a free radius
        // would reach for the other arc where the two meet.
        let mine: Vec<[f64; 2]> = points
            .iter()
            .copied()
            .filter(|x| ((x[0] - c[0]).hypot(x[1] - c[1]) - radius_px).abs() < tol)
            .collect();
        let Some(fit) = fit_fixed_radius(&mine, c, radius_px, oversampling) else {
            break;
        };
        points.retain(|x| {
            ((x[0] - fit.centre[0]).hypot(x[1] - fit.centre[1]) - fit.radius).abs() >= tol
        });
        // A short arc fixes the centre well only across its chord: at least half the circle
        // must be seen.
        if sectors_covered(&mine, fit.centre) < 18 {
            continue;
        }
        out.push(fit);
    }
    if out.len() == 1 {
        // One circle in a silhouette of two is right only if the other sphere is wholly behind
        // it; otherwise the outline bulges past it and it sits 0.2–0.3 px off, between both.
        let c = &out[0];
        let on = all_points
            .iter()
            .filter(|x| ((x[0] - c.centre[0]).hypot(x[1] - c.centre[1]) - c.radius).abs() < tol)
            .count();
        if (on as f64) < 0.9 * all_points.len() as f64 {
            return Vec::new();
        }
    }
    if out.len() == 2 {
        // Two things pulled the pair 0.06–0.14 px towards each other (noise-free renders, 4–13
        // px apart): where the outlines meet, the anti-aliased corner puts the edge outside
        // both circles; and the radius a lone disc measures is not the outline's. So both
        // circles are refitted together with one free radius, without the points near the
        // other's outline.
        let margin = CUSP_MARGIN_PX;
        let mut fit = [out[0], out[1]];
        for _ in 0..3 {
            let sets: Vec<Vec<[f64; 2]>> = (0..2)
                .map(|i| {
                    let (me, other) = (&fit[i], &fit[1 - i]);
                    all_points
                        .iter()
                        .copied()
                        .filter(|x| {
                            ((x[0] - me.centre[0]).hypot(x[1] - me.centre[1]) - me.radius).abs()
                                < tol
                                && (x[0] - other.centre[0]).hypot(x[1] - other.centre[1])
                                    > other.radius + margin
                        })
                        .collect()
                })
                .collect();
            // The shared radius holds the pair together, so shorter arcs than a lone circle's
            // half will do; a pair too deep in each other to leave that is not measured.
            if (0..2).any(|i| sectors_covered(&sets[i], fit[i].centre) < 12) {
                return Vec::new();
            }
            let Some(j) = fit_pair_shared_radius(&sets[0], &sets[1], fit, oversampling) else {
                return Vec::new();
            };
            fit = j;
        }
        out = fit.to_vec();
    }
    out
}
