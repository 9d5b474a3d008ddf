//! Dots a blur has spread: patches of a ring where the grey levels lie below the fitted model
//! over several neighbouring pixels, though no one pixel lies far enough below to be rejected
//! on its own.

use super::ring::RingPixel;

/// How far below zero, in its own σ, the mean residual over a pixel's 3 × 3 neighbourhood must
/// lie for the pixel to count as part of a dark patch. The mean of n residuals of σ has σ/√n;
/// on noise alone 0.13 % of the pixels a disc is searched over pass (one in a few fits, and
/// then a handful of its pixels lost), where a dot blurred by a pixel is several times darker.
const DARK_PATCH_SIGMAS: f64 = 3.0;

/// Of the pixels `keep` that `search` admits, those at the middle of a dark patch: the mean of
/// the residuals `at` (grey − model, in `keep`'s order) over the pixel's 3 × 3 neighbourhood,
/// counting those of it in the ring (at least five), lies more than `DARK_PATCH_SIGMAS` of that
/// mean's σ below zero, `sigma` being one pixel's. Dots darken whatever their paint, so only
/// patches below the model count (a highlight above it is the lamp's, which the model follows
/// in part). Pixel centres (u, v), px.
pub(super) fn dark_patches<T>(
    keep: &[RingPixel],
    at: &[(f64, T)],
    sigma: f64,
    search: impl Fn(&RingPixel) -> bool,
) -> Vec<(f64, f64)> {
    let Some(first) = keep.first() else {
        return Vec::new();
    };
    // The ring's pixels lie on whole-pixel offsets: a grid over their bounding box, one
    // pixel wider all round, holds each residual (NaN off the ring).
    let (mut u0, mut v0, mut u1, mut v1) = (first.u, first.v, first.u, first.v);
    for q in keep {
        u0 = u0.min(q.u);
        v0 = v0.min(q.v);
        u1 = u1.max(q.u);
        v1 = v1.max(q.v);
    }
    let width = (u1 - u0) as usize + 3;
    let height = (v1 - v0) as usize + 3;
    let cell = |q: &RingPixel| ((q.v - v0) as usize + 1) * width + (q.u - u0) as usize + 1;
    let mut grid = vec![f64::NAN; width * height];
    for (q, (r, _)) in keep.iter().zip(at) {
        grid[cell(q)] = *r;
    }
    keep.iter()
        .filter(|q| search(q))
        .filter(|q| {
            let c = cell(q);
            let (mut sum, mut n) = (0.0, 0usize);
            for row in [c - width, c, c + width] {
                for r in &grid[row - 1..=row + 1] {
                    if !r.is_nan() {
                        sum += r;
                        n += 1;
                    }
                }
            }
            let n = n as f64;
            n >= 5.0 && sum / n < -DARK_PATCH_SIGMAS * sigma / n.sqrt()
        })
        .map(|q| (q.u, q.v))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::super::ring::{Area, RingPixel};
    use super::dark_patches;

    /// A 20 × 20 patch of pixels with residuals `r(u, v)`.
    fn patch(r: impl Fn(f64, f64) -> f64) -> (Vec<RingPixel>, Vec<(f64, ())>) {
        let pixels: Vec<RingPixel> = (0..400)
            .map(|i| RingPixel {
                u: 10.0 + (i % 20) as f64,
                v: 30.0 + (i / 20) as f64,
                grey: 0.0,
                hidden: 0.0,
                area: Area::Whole,
            })
            .collect();
        let at = pixels.iter().map(|q| (r(q.u, q.v), ())).collect();
        (pixels, at)
    }

    /// A blurred dot's residuals, 1.5σ below the model at its middle and fading over two
    /// pixels, no one of them 4σ off, is found round its middle; a patch as bright is not (dots
    /// darken), nor is noise of σ (a fixed pseudo-random pattern), nor a pixel the search
    /// leaves out.
    #[test]
    fn a_spread_dark_dot_is_found_and_noise_and_bright_patches_are_not() {
        let sigma = 2.0;
        let dot = |u: f64, v: f64| {
            let d2 = (u - 18.0).powi(2) + (v - 37.0).powi(2);
            -1.5 * sigma * (-d2 / 8.0).exp()
        };
        // Uniform on ±√3σ (σ overall) from a hash of the pixel (splitmix64's finaliser).
        let noise = |u: f64, v: f64| {
            let mut x = (u as u64) << 32 | v as u64;
            x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            x ^= x >> 31;
            let h = (x >> 11) as f64 / (1u64 << 53) as f64;
            sigma * 3f64.sqrt() * (2.0 * h - 1.0)
        };
        let (pixels, at) = patch(dot);
        let found = dark_patches(&pixels, &at, sigma, |_| true);
        assert!(found.contains(&(18.0, 37.0)), "the dot's middle: {found:?}");
        assert!(
            found.iter().all(|&(u, v)| (u - 18.0).hypot(v - 37.0) < 3.0),
            "only round the dot: {found:?}"
        );
        let away = dark_patches(&pixels, &at, sigma, |q| q.u > 24.0);
        assert!(away.is_empty(), "outside the search: {away:?}");
        let (pixels, at) = patch(|u, v| -dot(u, v));
        assert!(dark_patches(&pixels, &at, sigma, |_| true).is_empty());
        let (pixels, at) = patch(noise);
        let false_alarms = dark_patches(&pixels, &at, sigma, |_| true);
        assert!(false_alarms.len() <= 2, "on noise: {false_alarms:?}");
    }
}
