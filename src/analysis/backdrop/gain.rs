//! A frame's light against the backdrop's: the lamps' flicker.
//!
//! A lamp on the mains (fluorescent tubes, many LED drivers, even halogen) brightens and dims at
//! twice the mains frequency, and a camera at 1000 fps sees each frame at another phase of it:
//! the ground, the clutter and the spheres, lit by the same lamps, all scale together. The
//! backdrop is one still image, a low quantile over frames at every phase, so subtracting it as
//! it is leaves `(gain − 1)·still` in a frame: nothing on a flat dark ground, but the shape of
//! every tube end, ruler and vignette where the ground has one (30 % flicker left the cluttered
//! family's centres 2.6× worse). So each frame's view is matched to the still as
//! `offset + gain·still`, fitted robustly over blocks of pixels (the spheres are a few blocks
//! among many, and are weighed out), and that is subtracted instead.
//!
//! A gain can only be told from an offset where the still has shape: on a flat ground both move
//! every block alike, and there a uniform offset is all a flicker leaves, which the levels and
//! the disc fits take up. And only a gain that differs from 1 beyond its own noise is applied:
//! under a steady lamp every frame is normalised exactly as before.

use crate::analysis::image::GreyImage;

/// A block's side, px: many pixels, so that a block's mean has little noise next to the
/// ground's shape; small enough that a view holds dozens.
const BLOCK_SIDES: [usize; 2] = [16, 8];
/// Fewer blocks than this fit no gain.
const MIN_BLOCKS: usize = 12;
/// The still's spread over its blocks must exceed its blocks' own noise by this factor (in
/// variance: 5 in amplitude) for a gain to be told from an offset.
const SHAPE_OVER_NOISE: f64 = 25.0;
/// A gain is applied only this many of its σ away from 1.
const SIGNIFICANT_SIGMA: f64 = 5.0;

/// How a frame's view is lit against the still: `offset + gain·still` is its backdrop.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Light {
    pub gain: f64,
    pub offset: f64,
}

impl Light {
    /// Brings `rect` of `img` to the still's light: (level − offset)/gain.
    pub(super) fn undo(&self, img: &mut GreyImage, rect: [usize; 4]) {
        let w = img.width;
        for v in rect[1]..rect[3] {
            for p in &mut img.data[v * w + rect[0]..v * w + rect[2]] {
                *p = ((*p as f64 - self.offset) / self.gain) as f32;
            }
        }
    }
}

/// A view's still in blocks, for fitting each frame's light.
#[derive(Clone, Debug)]
pub(super) struct Blocks {
    side: usize,
    /// The blocks' top-left corners in the frame.
    corners: Vec<[usize; 2]>,
    /// The still's mean over each block.
    still: Vec<f64>,
    /// The variance a block's still mean has from the still's pixel noise.
    noise_var: f64,
}

impl Blocks {
    /// The blocks of `rect` ([x0, y0, x1, y1), exclusive ends) over `still` (row-major over the
    /// rect); None where the view is too small or the still too flat to tell a gain from an
    /// offset.
    pub(super) fn new(still: &[f32], rect: [usize; 4]) -> Option<Blocks> {
        let (w, h) = (rect[2] - rect[0], rect[3] - rect[1]);
        if still.len() != w * h || w < 2 {
            return None;
        }
        let side = BLOCK_SIDES
            .into_iter()
            .find(|&s| (w / s) * (h / s) >= MIN_BLOCKS)?;
        let at = |u: usize, v: usize| still[v * w + u] as f64;
        let mut corners = Vec::new();
        let mut means = Vec::new();
        for by in 0..h / side {
            for bx in 0..w / side {
                let (u0, v0) = (bx * side, by * side);
                let mut sum = 0.0;
                for v in v0..v0 + side {
                    for u in u0..u0 + side {
                        sum += at(u, v);
                    }
                }
                corners.push([rect[0] + u0, rect[1] + v0]);
                means.push(sum / (side * side) as f64);
            }
        }
        // The still's pixel noise from neighbours' differences (a ground's shape hardly moves
        // their median): |difference of two pixels| has median 0.954·σ·√2.
        let mut steps: Vec<f64> = (0..h)
            .flat_map(|v| (0..w - 1).map(move |u| (u, v)))
            .map(|(u, v)| (at(u + 1, v) - at(u, v)).abs())
            .collect();
        let mid = steps.len() / 2;
        let step_median = *steps.select_nth_unstable_by(mid, f64::total_cmp).1;
        let pixel_sigma = step_median / (0.954 * std::f64::consts::SQRT_2);
        let noise_var = pixel_sigma * pixel_sigma / (side * side) as f64;
        let n = means.len() as f64;
        let mean = means.iter().sum::<f64>() / n;
        let spread = means.iter().map(|m| (m - mean).powi(2)).sum::<f64>() / n - noise_var;
        // (An absolute floor as well: a noise-free still as flat as a tenth of a grey level
        // tells nothing either.)
        (spread > SHAPE_OVER_NOISE * noise_var && spread > 0.01).then_some(Blocks {
            side,
            corners,
            still: means,
            noise_var,
        })
    }

    /// The frame's light against the still, where it differs from the still's by more than
    /// its noise; None where it does not (the frame is normalised as it always was).
    pub(super) fn light(&self, img: &GreyImage) -> Option<Light> {
        let area = (self.side * self.side) as f64;
        let frame: Vec<f64> = self
            .corners
            .iter()
            .map(|&[u0, v0]| {
                let mut sum = 0.0;
                for v in v0..v0 + self.side {
                    let row = &img.data[v * img.width + u0..v * img.width + u0 + self.side];
                    sum += row.iter().map(|&p| p as f64).sum::<f64>();
                }
                sum / area
            })
            .collect();
        let s = &self.still;
        let mut residual: Vec<f64> = frame.iter().zip(s).map(|(p, s)| p - s).collect();
        let (mut gain, mut offset) = (1.0, median(&mut residual.clone()));
        let mut weights = vec![1.0; s.len()];
        let mut sigma_gain = f64::INFINITY;
        // Cauchy's weights from the residuals' median absolute deviation, refitted: the blocks
        // a sphere crosses stand out and drop away.
        for _ in 0..6 {
            for ((r, p), s) in residual.iter_mut().zip(&frame).zip(s) {
                *r = p - offset - gain * s;
            }
            let centre = median(&mut residual.clone());
            let mut dev: Vec<f64> = residual.iter().map(|r| (r - centre).abs()).collect();
            let scale = (1.4826 * median(&mut dev)).max(1e-6);
            for (w, r) in weights.iter_mut().zip(&residual) {
                let z = r / (2.385 * scale);
                *w = 1.0 / (1.0 + z * z);
            }
            let sw: f64 = weights.iter().sum();
            let mean_s = weights.iter().zip(s).map(|(w, s)| w * s).sum::<f64>() / sw;
            let mean_p = weights.iter().zip(&frame).map(|(w, p)| w * p).sum::<f64>() / sw;
            // The still's blocks carry noise of their own, which would pull the slope towards
            // 0: their expected share of the spread is taken out.
            let spread = weights
                .iter()
                .zip(s)
                .map(|(w, s)| w * (s - mean_s).powi(2))
                .sum::<f64>()
                / sw
                - self.noise_var;
            if spread <= 0.0 {
                return None;
            }
            let cov = weights
                .iter()
                .zip(s)
                .zip(&frame)
                .map(|((w, s), p)| w * (s - mean_s) * (p - mean_p))
                .sum::<f64>()
                / sw;
            gain = cov / spread;
            offset = mean_p - gain * mean_s;
            sigma_gain = scale / (sw * spread).sqrt();
        }
        ((gain - 1.0).abs() > SIGNIFICANT_SIGMA * sigma_gain && gain.is_finite() && gain > 0.0)
            .then_some(Light { gain, offset })
    }
}

fn median(v: &mut [f64]) -> f64 {
    let mid = v.len() / 2;
    *v.select_nth_unstable_by(mid, f64::total_cmp).1
}
