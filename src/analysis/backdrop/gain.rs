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
//! among many, and are weighed out), and the still's shape about its median is subtracted at
//! that gain (`Backdrop::apply`; the uniform part of the change is left to the per-frame
//! levels). The still itself is taken again from samples brought to its light first: under
//! flicker the samples' light orders them alike at every pixel, and the quantile would be one
//! frame's, its noise a fixed pattern in every frame.
//!
//! A gain can only be told from an offset where the still has shape: on a flat ground both move
//! every block alike, and there a uniform offset is all a flicker leaves, which the levels and
//! the disc fits take up. A frame's gain is not trusted where the blocks its fit kept hold
//! less than half the still's shape (a sphere in front of the only tube end in view). And only
//! a gain that differs from 1 beyond its own noise is applied: under a steady lamp every frame
//! is normalised exactly as before.

use crate::analysis::image::GreyImage;

/// A block's side, px: many pixels, so that a block's mean has little noise next to the
/// ground's shape; small enough that a view holds dozens.
const BLOCK_SIDES: [usize; 2] = [16, 8];
/// Fewer blocks than this fit no gain.
const MIN_BLOCKS: usize = 40;
/// The still's spread over its blocks must exceed its blocks' own noise by this factor (in
/// variance: 5 in amplitude) for a gain to be told from an offset.
const SHAPE_OVER_NOISE: f64 = 25.0;
/// The blocks a frame's fit keeps must hold this share of the still's shape (by variance).
const MIN_SHAPE_KEPT: f64 = 0.5;
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
        // A least-squares line first, then Cauchy's weights from its residuals' median absolute
        // deviation, refitted: the blocks a sphere crosses stand out and drop away.
        let mut weights = vec![1.0; s.len()];
        let mut line = self.weighted_line(&frame, &weights)?;
        let mut scale = 0.0;
        for _ in 0..6 {
            let residual: Vec<f64> = frame
                .iter()
                .zip(s)
                .map(|(p, s)| p - line.offset - line.gain * s)
                .collect();
            let centre = median(&mut residual.clone());
            let mut dev: Vec<f64> = residual.iter().map(|r| (r - centre).abs()).collect();
            // (Not below the still's own noise: a frame is at least as noisy.)
            scale = (1.4826 * median(&mut dev)).max(self.noise_var.sqrt());
            for (w, r) in weights.iter_mut().zip(&residual) {
                let z = r / (2.385 * scale);
                *w = 1.0 / (1.0 + z * z);
            }
            line = self.weighted_line(&frame, &weights)?;
        }
        // The blocks the fit kept must hold most of the still's shape: where a sphere stands
        // in front of the clutter, the little shape left elsewhere says little of the gain.
        let all: f64 = {
            let mean = s.iter().sum::<f64>() / s.len() as f64;
            s.iter().map(|s| (s - mean).powi(2)).sum()
        };
        let kept: f64 = weights
            .iter()
            .zip(s)
            .map(|(w, s)| w * (s - line.mean_still).powi(2))
            .sum();
        if kept < MIN_SHAPE_KEPT * all {
            return None;
        }
        let sigma_gain = scale / (line.weight * line.spread).sqrt();
        let gain = line.gain;
        ((gain - 1.0).abs() > SIGNIFICANT_SIGMA * sigma_gain && gain.is_finite() && gain > 0.0)
            .then_some(Light {
                gain,
                offset: line.offset,
            })
    }

    /// The weighted least-squares line through (still, frame) over the blocks; None where the
    /// weighted still has no spread beyond its noise.
    fn weighted_line(&self, frame: &[f64], weights: &[f64]) -> Option<Line> {
        let s = &self.still;
        let weight: f64 = weights.iter().sum();
        let mean_still = weights.iter().zip(s).map(|(w, s)| w * s).sum::<f64>() / weight;
        let mean_frame = weights.iter().zip(frame).map(|(w, p)| w * p).sum::<f64>() / weight;
        // The still's blocks carry noise of their own, which would pull the slope towards 0:
        // their expected share of the spread is taken out.
        let spread = weights
            .iter()
            .zip(s)
            .map(|(w, s)| w * (s - mean_still).powi(2))
            .sum::<f64>()
            / weight
            - self.noise_var;
        if spread.is_nan() || spread <= 0.0 {
            return None;
        }
        let cov = weights
            .iter()
            .zip(s)
            .zip(frame)
            .map(|((w, s), p)| w * (s - mean_still) * (p - mean_frame))
            .sum::<f64>()
            / weight;
        let gain = cov / spread;
        Some(Line {
            gain,
            offset: mean_frame - gain * mean_still,
            mean_still,
            spread,
            weight,
        })
    }
}

/// `Blocks::weighted_line`'s fit.
struct Line {
    gain: f64,
    offset: f64,
    mean_still: f64,
    /// The weighted still's variance, its noise taken out.
    spread: f64,
    /// The weights' sum.
    weight: f64,
}

fn median(v: &mut [f64]) -> f64 {
    let mid = v.len() / 2;
    *v.select_nth_unstable_by(mid, f64::total_cmp).1
}
