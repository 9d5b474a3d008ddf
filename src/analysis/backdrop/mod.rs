//! What stands still in each view, and which way the spheres differ from it.
//!
//! A rig shows more than two spheres: tube ends, a ruler, the mirror's edge, dust, a background
//! lit unevenly; and it may be backlit, the spheres dark on a bright ground. Everything after
//! this module expects bright spheres on a flat dark ground, so each frame is normalised here
//! before it is measured: per view, the static backdrop (a low quantile over frames sampled
//! across the recording, taken per pixel) is subtracted and the view's backdrop level added
//! back, and a view whose moving things are darker than their ground is inverted. The backdrop
//! is what is there when no sphere is: a sphere covers a pixel for a short part of a flight, so
//! a quantile on the ground's side of the spheres (the 20th percentile for bright spheres, the
//! 80th for dark ones) leaves them out as long as no pixel is covered in more than 80 % of the
//! sampled frames. Spheres both brighter and darker than their ground (lit from the side over a
//! grey ground) have no side the ground is on: there the median, which leaves them out while no
//! pixel is covered in half the samples (`polarity`). With fewer than `MIN_FRAMES` frames there
//! is no backdrop, only the polarity.
//! Where the lamps flicker, each frame's view is matched to the still first (`gain`). A pixel
//! that shows one level in every sample while its neighbours change is a defective one, hot or
//! dead (`stuck_pixels`): marked unmeasured in every frame, as an overexposed one is.

mod gain;

use super::geometry::View;
use super::image::{GreyImage, GroundLight, SATURATED_GREY};
use super::source::{FrameFilter, FrameSource};
use super::AnalysisError;
use std::sync::Arc;

/// Frames sampled for the backdrop, at most.
const SAMPLES: usize = 31;
/// Fewer frames than this give no backdrop (a quantile of so few says little).
pub const MIN_FRAMES: usize = 9;
/// Memory the sampled frames may take, bytes.
const MAX_SAMPLE_BYTES: usize = 256 << 20;
/// The backdrop's quantile on the ground's side of the spheres.
const GROUND_QUANTILE: f64 = 0.2;
/// How far, in grey levels, each of a stuck pixel's four neighbours must have ranged over the
/// samples (`stuck_pixels`): a sphere passed there, or the noise shows that pixels vary there.
/// A few levels: the range of σ = 2 noise over 31 samples is about 16, a sphere's far more,
/// and a noise-free render's ground (range 0) never counts.
const STUCK_NEIGHBOUR_RANGE: f32 = 3.0;

/// The noise σ a still keeps of its frames' (`GreyImage::ground_noise`): the quantile q of k
/// samples of noise σ scatters by √(q(1 − q)/k)/φ(Φ⁻¹(q))·σ (the order statistic's asymptotic
/// spread; 0.26 at 31 samples for the 20th percentile, 0.23 for the median). Why not measured
/// on the still itself: its levels are the frames', whole grey levels, and its pixel-to-pixel
/// differences a level or two, which a median quantises to 0 or 1 — twice the true figure at
/// σ = 2.
fn still_noise_ratio(samples: usize, q: Quantile) -> f64 {
    let density = (-0.5 * q.z * q.z).exp() / std::f64::consts::TAU.sqrt();
    (q.q * (1.0 - q.q) / samples.max(1) as f64).sqrt() / density
}

/// A quantile the still is taken at, and Φ⁻¹ of it (or of its complement: the spread is the
/// same), in σ.
#[derive(Clone, Copy, Debug)]
struct Quantile {
    q: f64,
    z: f64,
}

/// The still's quantile on the ground's side of bright spheres (dark ones: its complement);
/// z = Φ⁻¹(1 − `GROUND_QUANTILE`).
const GROUND: Quantile = Quantile {
    q: GROUND_QUANTILE,
    z: 0.8416,
};

/// The still's quantile where the spheres are both brighter and darker than the ground (a
/// side-lit sphere over a grey ground: its lit side above, its shaded limb below): either
/// side's quantile would take in the other side's part wherever a sphere covers a pixel in a
/// fifth of the samples, so the median, which holds while no pixel is covered in half.
const MEDIAN: Quantile = Quantile { q: 0.5, z: 0.0 };

/// The frames' noise σ over a view, grey levels: the median absolute change of a pixel from
/// one sampled frame to the next, over √2 (the spheres pass over a few of the pixels only);
/// every other column, which is plenty.
fn frames_noise(frames: &[GreyImage], rect: [usize; 4]) -> f64 {
    let [x0, y0, x1, y1] = rect;
    let mut steps: Vec<f32> = Vec::new();
    for p in frames.windows(2) {
        for v in y0..y1 {
            let row = |f| row_of(f, v, x0, x1);
            let (Some(a), Some(b)) = (row(&p[0]), row(&p[1])) else {
                continue;
            };
            steps.extend(a.iter().zip(b).step_by(2).map(|(a, b)| (b - a).abs()));
        }
    }
    if steps.is_empty() {
        return 0.0;
    }
    let mid = steps.len() / 2;
    let median = order_stats(&mut steps, [mid; 3])[0] as f64;
    1.4826 * median / std::f64::consts::SQRT_2
}

/// Columns `x0..x1` of row `v` of a frame; None where the frame is smaller.
fn row_of(f: &GreyImage, v: usize, x0: usize, x1: usize) -> Option<&[f32]> {
    f.data.get(v * f.width + x0..v * f.width + x1)
}

/// One view's normalisation.
#[derive(Clone, Debug)]
struct ViewBackdrop {
    name: &'static str,
    /// x0, y0, x1, y1 in the frame (exclusive ends).
    rect: [usize; 4],
    /// The spheres are darker than the ground here: the view is inverted.
    dark_spheres: bool,
    /// The static image of the view (row-major over `rect`), when there are enough frames.
    still: Option<Vec<f32>>,
    /// The level the ground is given after normalisation.
    level: f32,
    /// The still in blocks, where its shape can tell a frame's gain from an offset.
    blocks: Option<gain::Blocks>,
    /// Stuck pixels (`stuck_pixels`), as indices into the frame.
    stuck: Vec<usize>,
}

/// The per-view normalisation of a recording's frames.
#[derive(Clone, Debug, Default)]
pub struct Backdrop {
    views: Vec<ViewBackdrop>,
    /// The frame's `GreyImage::ground`: per pixel, the subtracted backdrop above its view's
    /// level (bright side up); None without a backdrop.
    ground: Option<Arc<[f32]>>,
    /// `GreyImage::ground_noise`: the largest of the views' frames' noise, times what a still
    /// keeps of it (`still_noise_ratio`).
    ground_noise: f32,
    /// The rectangles of the inverted views (`GreyImage::inverted`).
    inverted: Arc<[[usize; 4]]>,
}

impl Backdrop {
    /// Samples the recording and estimates each view's polarity and static backdrop.
    pub fn estimate(src: &mut dyn FrameSource, views: &[View]) -> Result<Backdrop, AnalysisError> {
        let n = src.len();
        // The samples are held at once as f32: at most `MAX_SAMPLE_BYTES` of them (for large
        // frames, fewer samples; below `MIN_FRAMES`, the polarity only).
        let (w, h) = src.dimensions();
        let frame_bytes = (w as usize)
            .saturating_mul(h as usize)
            .saturating_mul(4)
            .max(1);
        let k = n.min(SAMPLES).min((MAX_SAMPLE_BYTES / frame_bytes).max(1));
        let mut frames: Vec<GreyImage> = Vec::with_capacity(k);
        for j in 0..k {
            // Evenly spread, first and last included.
            let i = if k > 1 { j * (n - 1) / (k - 1) } else { 0 };
            let mut img = GreyImage::new();
            src.read(i, &mut img)?;
            frames.push(img);
        }
        let Some((w, h)) = frames.first().map(|f| (f.width, f.height)) else {
            return Ok(Backdrop::default());
        };
        let rects: Vec<[usize; 4]> = views
            .iter()
            .map(|view| {
                let [x, y, vw, vh] = view.region.map(|v| v as usize);
                [x.min(w), y.min(h), (x + vw).min(w), (y + vh).min(h)]
            })
            .collect();
        // On the samples as recorded (the still below may bring them to one light).
        let stuck: Vec<Vec<usize>> = rects.iter().map(|&r| stuck_pixels(&frames, r)).collect();
        let mut out = Vec::with_capacity(views.len());
        let mut quantiles_used = Vec::with_capacity(views.len());
        for ((view, &rect), stuck) in views.iter().zip(&rects).zip(stuck) {
            // Each pixel's low quantile, median and high quantile in one pass over its
            // samples: the median says which way the spheres differ (`polarity`), and that
            // says which of the three is the still.
            let rank = |q: f64| ((k - 1) as f64 * q).round() as usize;
            let ranks = [
                rank(GROUND_QUANTILE),
                (k - 1) / 2,
                rank(1.0 - GROUND_QUANTILE),
            ];
            let columns = (k >= MIN_FRAMES).then(|| quantiles(&frames, rect, ranks));
            let polarity = polarity(&frames, rect, columns.as_ref().map(|c| &c[1][..]));
            let dark_spheres = polarity == Polarity::Dark;
            let (q, pick) = match polarity {
                Polarity::Bright => (GROUND, 0),
                Polarity::TwoSided => (MEDIAN, 1),
                Polarity::Dark => (GROUND, 2),
            };
            quantiles_used.push(q);
            let still = columns.map(|mut columns| {
                let idx = ranks[pick];
                let still = std::mem::take(&mut columns[pick]);
                // Under a flickering lamp the samples' light decides their order at every
                // pixel alike, so the quantile is one frame's, noise and all: a fixed pattern
                // of noise subtracted from every frame. Each sample is brought to the still's
                // light first, and the quantile taken again.
                let Some(blocks) = gain::Blocks::new(&still, rect) else {
                    return still;
                };
                let mut relit = false;
                for f in frames.iter_mut() {
                    // (A sample lit a tenth of the still or less is left as it is: brought up,
                    // its noise would be ten times the others'.)
                    if let Some(l) = blocks.light(f).filter(|l| l.gain > 0.1) {
                        relit = true;
                        l.undo(f, rect);
                    }
                }
                if relit {
                    quantile(&frames, rect, idx)
                } else {
                    still
                }
            });
            let mut ground: Vec<f32> = match &still {
                Some(s) => s.clone(),
                None => (rect[1]..rect[3])
                    .flat_map(|v| (rect[0]..rect[2]).map(move |u| (u, v)))
                    .map(|(u, v)| frames[0].at(u, v))
                    .collect(),
            };
            let level = if ground.is_empty() {
                0.0
            } else {
                let mid = ground.len() / 2;
                *ground.select_nth_unstable_by(mid, f32::total_cmp).1
            };
            let level = if dark_spheres { 255.0 - level } else { level };
            let blocks = still.as_ref().and_then(|s| gain::Blocks::new(s, rect));
            out.push(ViewBackdrop {
                name: view.kind.name(),
                rect,
                dark_spheres,
                still,
                level,
                blocks,
                stuck,
            });
        }
        // What a sphere in front of the backdrop hides: the subtracted still, bright side up,
        // above the level put in its place.
        let ground = out.iter().any(|vb| vb.still.is_some()).then(|| {
            let mut g = vec![0f32; w * h];
            for vb in &out {
                let Some(still) = &vb.still else { continue };
                let [x0, y0, x1, _] = vb.rect;
                let rw = x1 - x0;
                for (k, &b) in still.iter().enumerate() {
                    let bright = if vb.dark_spheres { 255.0 - b } else { b };
                    g[(y0 + k / rw) * w + x0 + k % rw] = bright - vb.level;
                }
                // A stuck pixel shows its own level, not what stands behind it: taken as the
                // backdrop, a hot one is a 255-level step that every ray of a disc crossing
                // it reads as a tube end's edge. Its four neighbours (never stuck: they vary)
                // say what is there.
                for &i in &vb.stuck {
                    let mut n = [g[i - 1], g[i + 1], g[i - w], g[i + w]];
                    n.sort_by(f32::total_cmp);
                    g[i] = 0.5 * (n[1] + n[2]);
                }
            }
            Arc::from(g)
        });
        let inverted = out
            .iter()
            .filter(|vb| vb.dark_spheres)
            .map(|vb| vb.rect)
            .collect();
        let ground_noise = if ground.is_some() {
            rects
                .iter()
                .zip(&quantiles_used)
                .map(|(&r, &q)| still_noise_ratio(k, q) * frames_noise(&frames, r))
                .fold(0.0, f64::max) as f32
        } else {
            0.0
        };
        Ok(Backdrop {
            views: out,
            ground,
            ground_noise,
            inverted,
        })
    }

    /// Normalises one frame in place (see the module's doc).
    pub fn apply(&self, img: &mut GreyImage) {
        let w = img.width;
        img.ground = self
            .ground
            .clone()
            .filter(|g| g.len() == img.width * img.height);
        img.ground_noise = if img.ground.is_some() {
            self.ground_noise
        } else {
            0.0
        };
        img.inverted = self.inverted.clone();
        img.unmeasured.clear();
        img.ground_light.clear();
        for vb in &self.views {
            let [x0, y0, x1, y1] = vb.rect;
            if x1 > img.width || y1 > img.height {
                continue;
            }
            let rw = x1 - x0;
            // The frame's light against the still's, where it differs (a flickering lamp): the
            // still's shape about its median is subtracted at the frame's gain, so the ground
            // comes out flat and what a sphere hides is that shape at that gain. The uniform
            // part of the change (the fitted offset, and the gain at the median) is left in
            // the frame, whose levels are measured per frame anyway; counted as hidden ground
            // it would put every sphere of a backlit view in front of clutter.
            let light = vb.blocks.as_ref().and_then(|b| b.light(img));
            if let Some(l) = light {
                img.ground_light.push(GroundLight {
                    rect: vb.rect,
                    gain: l.gain as f32,
                });
            }
            // The still's median, as recorded (the level is it, turned where inverted).
            let median = if vb.dark_spheres {
                255.0 - vb.level
            } else {
                vb.level
            };
            if !vb.stuck.is_empty() {
                if img.unmeasured.is_empty() {
                    img.unmeasured.resize(img.width * img.height, false);
                }
                for &i in &vb.stuck {
                    if let Some(m) = img.unmeasured.get_mut(i) {
                        *m = true;
                    }
                }
            }
            let lit = |s: f32| match light {
                Some(l) => median + (l.gain * (s - median) as f64) as f32,
                None => s,
            };
            // Row by row, over slices (every pixel of every view of every frame, both
            // passes: per-pixel indexing was a few per cent of a recording's analysis).
            for v in y0..y1 {
                let row_at = v * w + x0;
                // Overexposed: marked before the level is moved (bright spheres only; in a
                // backlit view what saturates is the ground).
                if !vb.dark_spheres
                    && img.data[row_at..row_at + rw]
                        .iter()
                        .any(|&p| p >= SATURATED_GREY)
                {
                    if img.unmeasured.is_empty() {
                        img.unmeasured.resize(img.width * img.height, false);
                    }
                    let (data, unmeasured) = (&img.data, &mut img.unmeasured);
                    for (m, &p) in unmeasured[row_at..row_at + rw]
                        .iter_mut()
                        .zip(&data[row_at..row_at + rw])
                    {
                        if p >= SATURATED_GREY {
                            *m = true;
                        }
                    }
                }
                let row = &mut img.data[row_at..row_at + rw];
                let still = vb
                    .still
                    .as_ref()
                    .map(|s| &s[(v - y0) * rw..(v - y0 + 1) * rw]);
                for (k, p) in row.iter_mut().enumerate() {
                    let ground = still.map(|s| lit(s[k])).unwrap_or(median);
                    *p = if vb.dark_spheres {
                        vb.level + (ground - *p)
                    } else {
                        vb.level + (*p - ground)
                    };
                }
            }
        }
    }

    /// What a reader of the report must know: views measured inverted, and stuck pixels.
    pub fn warnings(&self) -> Vec<String> {
        let inverted = self.views.iter().filter(|v| v.dark_spheres).map(|v| {
            format!(
                "{} view: the spheres are darker than their ground (backlit); measured inverted, its markers looked for as dots darker still (seen only where a light in front shows them)",
                v.name
            )
        });
        let stuck = self.views.iter().filter(|v| !v.stuck.is_empty()).map(|v| {
            format!(
                "{} view: {} stuck pixel(s) (one level in every sampled frame while their neighbours changed: hot or dead) left out of the disc fits and the dots' shading",
                v.name,
                v.stuck.len()
            )
        });
        inverted.chain(stuck).collect()
    }
}

/// The pixels of `rect` (indices into the frame) that show one level in every sample while
/// each of their four neighbours ranged over `STUCK_NEIGHBOUR_RANGE` or more: a defective
/// pixel, hot or dead, which does not see a sphere pass over it. Why: such a pixel on a disc's
/// ring is a residual the size of the sphere's contrast in every frame the sphere covers it;
/// 200 of them on the independent renders (half at 255, half at 0) put v08's centres 0.208 px
/// RMS off where they were 0.018 (docs/accuracy.md, session 49). None with fewer than
/// `MIN_FRAMES` samples.
fn stuck_pixels(frames: &[GreyImage], rect: [usize; 4]) -> Vec<usize> {
    let [x0, y0, x1, y1] = rect;
    let Some(w) = frames.first().map(|f| f.width) else {
        return Vec::new();
    };
    if frames.len() < MIN_FRAMES || x1 < x0 + 3 || y1 < y0 + 3 {
        return Vec::new();
    }
    let rw = x1 - x0;
    // Row slices, frame by frame: the samples are walked in memory order.
    let mut lo = vec![f32::MAX; rw * (y1 - y0)];
    let mut hi = vec![f32::MIN; rw * (y1 - y0)];
    for f in frames {
        for v in y0..y1 {
            // (Every sample has the recording's size; a frame that had not is passed over.)
            let Some(row) = row_of(f, v, x0, x1) else {
                continue;
            };
            let at = (v - y0) * rw;
            for ((g, l), h) in row
                .iter()
                .zip(&mut lo[at..at + rw])
                .zip(&mut hi[at..at + rw])
            {
                *l = l.min(*g);
                *h = h.max(*g);
            }
        }
    }
    let range: Vec<f32> = hi.iter().zip(&lo).map(|(h, l)| h - l).collect();
    let at = |u: usize, v: usize| range[(v - y0) * rw + (u - x0)];
    let mut out = Vec::new();
    for v in y0 + 1..y1 - 1 {
        for u in x0 + 1..x1 - 1 {
            if at(u, v) == 0.0
                && [(u - 1, v), (u + 1, v), (u, v - 1), (u, v + 1)]
                    .iter()
                    .all(|&(a, b)| at(a, b) >= STUCK_NEIGHBOUR_RANGE)
            {
                out.push(v * w + u);
            }
        }
    }
    out
}

/// Per pixel of `rect`, the `idx`-th smallest of the frames' values (row-major over the rect).
fn quantile(frames: &[GreyImage], rect: [usize; 4], idx: usize) -> Vec<f32> {
    let [still, _, _] = quantiles(frames, rect, [idx; 3]);
    still
}

/// Per pixel of `rect`, three order statistics of its samples (ascending `ranks`, each below
/// the number of frames), as three stills.
fn quantiles(frames: &[GreyImage], rect: [usize; 4], ranks: [usize; 3]) -> [Vec<f32>; 3] {
    let mut column = vec![0f32; frames.len()];
    let n = (rect[2] - rect[0]) * (rect[3] - rect[1]);
    let mut out = [(); 3].map(|_| Vec::with_capacity(n));
    for v in rect[1]..rect[3] {
        for u in rect[0]..rect[2] {
            for (c, f) in column.iter_mut().zip(frames) {
                *c = f.at(u, v);
            }
            for (o, x) in out.iter_mut().zip(selected(&mut column, ranks)) {
                o.push(x);
            }
        }
    }
    out
}

/// The `ranks`-th smallest of `vals` (ascending ranks, each below `vals.len()`), which may be
/// reordered. Whole numbers from −256 to 255 — 8-bit frames' grey levels, their pixels'
/// differences, and frames less a still taken from their own samples — are counted in a
/// histogram of those 512 values, one pass; anything else is selected. The two give the same
/// elements. Why: selecting three ranks of a view's 23 040 pixels in each sampled frame was half
/// the backdrop's estimate, a tenth of the analysis of a 40-frame recording (and, for the
/// frames less their median that `polarity` votes on, 40 % of the estimate again).
fn order_stats(vals: &mut [f32], ranks: [usize; 3]) -> [f32; 3] {
    const OFFSET: f32 = 256.0;
    let mut counts = [0u32; 512];
    let whole = vals.iter().all(|&x| {
        let shifted = x + OFFSET;
        // (`as` saturates: anything below −256 lands on 0, anything above on u16::MAX, and
        // neither equals its own shifted value unless it is that whole number.)
        let level = shifted as u16;
        let exact = usize::from(level) < counts.len() && f32::from(level) == shifted;
        if exact {
            counts[usize::from(level)] += 1;
        }
        exact
    });
    if whole {
        let mut out = [0.0; 3];
        let mut next = 0;
        let mut below = 0usize;
        for (level, &n) in counts.iter().enumerate() {
            below += n as usize;
            while next < 3 && ranks[next] < below {
                out[next] = level as f32 - OFFSET;
                next += 1;
            }
        }
        return out;
    }
    selected(vals, ranks)
}

/// `order_stats` by selection: each rank selected in turn, in the part above the last
/// (ascending ranks).
fn selected(vals: &mut [f32], ranks: [usize; 3]) -> [f32; 3] {
    let mut out = [0.0; 3];
    let mut start = 0;
    for (o, &rank) in out.iter_mut().zip(&ranks) {
        if rank < start {
            // The same rank again (or one already placed): the element there.
            *o = vals[rank];
            continue;
        }
        let (_, x, _) = vals[start..].select_nth_unstable_by(rank - start, f32::total_cmp);
        *o = *x;
        start = rank + 1;
    }
    out
}

/// Which way what moves in a view differs from its ground.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Polarity {
    /// Brighter: the still is a low quantile.
    Bright,
    /// Darker (backlit): the view is inverted, the still a high quantile.
    Dark,
    /// Both, by amounts within a factor two of each other over the frames (a side-lit sphere
    /// over a grey ground): the still is the median.
    TwoSided,
}

/// Which way what differs from a view's ground differs from it (`votes_dark`). A ground that
/// is not flat — vignetting, a gradient, clutter — has tails of its own, which on a bright
/// ground reach as far as a sphere's (a grey ground of 104 vignetted by a fifth: its darkest
/// 0.3 % 26 levels below its median, its brightest 12 above, in every frame without a sphere,
/// and the view was turned over). So each frame is voted again less the per-pixel median of the
/// samples (the ground as it is: the spheres pass, it stays), where only what moves stands out:
/// dark where both votes say so and the dark outweighs the bright twice over all the frames;
/// two-sided where neither side outweighs the other twice (a sphere whose shaded limb is as far
/// below a grey ground as its lit side is above); else bright. `median`: the samples' per-pixel
/// median, None with fewer than `MIN_FRAMES` of them (there is no still then either): the
/// frames as recorded decide.
fn polarity(frames: &[GreyImage], rect: [usize; 4], median: Option<&[f32]>) -> Polarity {
    let raw_dark = votes(frames, rect, None).votes < 0;
    let Some(median) = median else {
        return if raw_dark {
            Polarity::Dark
        } else {
            Polarity::Bright
        };
    };
    let moving = votes(frames, rect, Some(median));
    if raw_dark && moving.votes < 0 && moving.dark > 2.0 * moving.bright {
        Polarity::Dark
    } else if moving.bright > 2.0 * moving.dark {
        Polarity::Bright
    } else if moving.dark > 0.0 {
        Polarity::TwoSided
    } else {
        // Nothing stood out in any frame (a view without spheres).
        Polarity::Bright
    }
}

/// What `votes`'s frames said: the votes (each −1 dark, +1 bright), and the dark and the
/// bright extremes summed over the frames where either stood out.
struct Votes {
    votes: i32,
    dark: f64,
    bright: f64,
}

/// How the sampled frames vote on what differs from the view's ground: in each, the view's
/// darkest 0.3 % against its brightest 0.3 %, each measured from the median; a frame votes only
/// where one side stands out clearly (8× the noise) and is at least twice the other, and adds
/// both extremes to the sums where either stands out. The noise is measured between
/// neighbouring pixels, which an uneven ground does not inflate. `ground`: subtracted from each
/// frame first (the rect's pixels, row by row). (A sphere lit from one side over a grey ground
/// is as much darker as brighter than it, and its few frames that vote dark — half a disc in
/// view at a border, its dark side first — do not speak for the view: `polarity` weighs the
/// sums too.)
fn votes(frames: &[GreyImage], rect: [usize; 4], ground: Option<&[f32]>) -> Votes {
    let mut tally = Votes {
        votes: 0,
        dark: 0.0,
        bright: 0.0,
    };
    let mut vals: Vec<f32> = Vec::new();
    let mut steps: Vec<f32> = Vec::new();
    let rw = rect[2] - rect[0];
    for f in frames {
        vals.clear();
        steps.clear();
        // Row by row, each pixel read once and its step to the next taken from the row.
        for v in rect[1]..rect[3] {
            let Some(row) = row_of(f, v, rect[0], rect[2]) else {
                continue;
            };
            let first = vals.len();
            match ground {
                Some(g) => {
                    let under = &g[(v - rect[1]) * rw..(v - rect[1] + 1) * rw];
                    vals.extend(row.iter().zip(under).map(|(x, g)| x - g));
                }
                None => vals.extend_from_slice(row),
            }
            steps.extend(vals[first..].windows(2).map(|p| (p[1] - p[0]).abs()));
        }
        if vals.len() < 16 || steps.is_empty() {
            continue;
        }
        // Three order statistics, each selected rather than the whole view sorted (the sort
        // was 1.5 % of the analysis of a 40-frame recording): the same elements.
        let n = vals.len();
        let at = |p: f64| ((n - 1) as f64 * p).round() as usize;
        let [q_lo, med, q_hi] =
            order_stats(&mut vals, [at(0.003), at(0.5), at(0.997)]).map(f64::from);
        let step_mid = steps.len() / 2;
        let step_median = order_stats(&mut steps, [step_mid; 3])[0] as f64;
        // |difference of two pixels| has median 0.954·σ·√2.
        let noise = (step_median / (0.954 * std::f64::consts::SQRT_2)).max(0.5);
        let (dark, bright) = (med - q_lo, q_hi - med);
        if dark > 8.0 * noise && dark > 2.0 * bright {
            tally.votes -= 1;
        } else if bright > 8.0 * noise && bright > 2.0 * dark {
            tally.votes += 1;
        }
        if dark.max(bright) > 8.0 * noise {
            tally.dark += dark;
            tally.bright += bright;
        }
    }
    tally
}

/// Each frame normalised by the backdrop as it is read (`source::Filtered`).
impl FrameFilter for Backdrop {
    fn apply(&mut self, img: &mut GreyImage) {
        Backdrop::apply(self, img);
    }
    fn warnings(&self) -> Vec<String> {
        Backdrop::warnings(self)
    }
}

#[cfg(test)]
mod tests;
