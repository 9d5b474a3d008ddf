//! Segmentation of one view: background and noise level, threshold, connected bright blobs.
//! A blob is a candidate sphere; it is flagged when it touches the view's border (clipped) or is
//! too large for one sphere (two silhouettes merged), because neither gives a true centre.

use super::geometry::View;
use super::image::{four_neighbours, GreyImage};

#[derive(Clone, Debug)]
pub struct Blob {
    /// Intensity-weighted centroid, px (full frame).
    pub centroid: [f64; 2],
    pub area_px: usize,
    /// The first and last pixel column and row the blob covers, [u0, v0, u1, v1] (full frame).
    pub extent_px: [usize; 4],
    pub clipped: bool,
    pub merged: bool,
}

impl Blob {
    /// The diameter of a disc of the blob's area, px.
    pub fn diameter_px(&self) -> f64 {
        2.0 * (self.area_px as f64 / std::f64::consts::PI).sqrt()
    }
}

#[derive(Clone, Copy, Debug)]
pub struct ViewLevels {
    pub background: f64,
    pub noise_sigma: f64,
    pub peak: f64,
}

/// Background (median), noise (MAD) and peak (99.7th percentile) of a view's region.
pub fn levels(img: &GreyImage, view: &View) -> ViewLevels {
    const BINS: usize = 4096;
    let mut hist = vec![0u32; BINS];
    let [x0, y0, w, h] = view.region.map(|x| x as usize);
    let scale = BINS as f64 / 256.0;
    let (u_end, v_end) = ((x0 + w).min(img.width), (y0 + h).min(img.height));
    if x0 < u_end {
        // Row slices: one bounds check per row, not per pixel (every pixel of every view, in
        // every frame of both passes).
        for v in y0..v_end {
            let row = &img.data[v * img.width + x0..v * img.width + u_end];
            for &grey in row {
                hist[((grey as f64 * scale) as usize).min(BINS - 1)] += 1;
            }
        }
    }
    let total: u64 = hist.iter().map(|&c| c as u64).sum();
    let quantile = |q: f64| -> f64 {
        let target = (q * total as f64) as u64;
        let mut acc = 0u64;
        for (i, &c) in hist.iter().enumerate() {
            acc += c as u64;
            if acc > target {
                return (i as f64 + 0.5) / scale;
            }
        }
        256.0
    };
    let background = quantile(0.5);
    // MAD through the quartiles of the background: robust while spheres cover < 25 % of the view.
    let noise_sigma = ((quantile(0.75) - quantile(0.25)) / 1.349).max(0.5 / scale);
    ViewLevels {
        background,
        noise_sigma,
        peak: quantile(0.997),
    }
}

/// Bright connected blobs of plausible sphere size in one view.
pub fn find_blobs(
    img: &GreyImage,
    view: &View,
    lv: &ViewLevels,
    radius_px: f64,
    threshold_fraction: f64,
) -> Vec<Blob> {
    let contrast = lv.peak - lv.background;
    if contrast < (8.0 * lv.noise_sigma).max(5.0) {
        return Vec::new();
    }
    let threshold = (lv.background + threshold_fraction * contrast) as f32;
    // Where the subtracted backdrop stood out from the ground by more than the threshold's
    // height (a tube end, a ruler), a sphere in front of it hides it and comes out as its
    // shading less the backdrop, as likely below the ground as above: there a pixel is
    // foreground by how far it is from the ground either way.
    let rise = threshold - lv.background as f32;
    let bg = lv.background as f32;
    let level = |u: usize, v: usize| -> f32 {
        let val = img.at(u, v);
        if img.ground_at(u, v).abs() > rise {
            bg + (val - bg).abs()
        } else {
            val
        }
    };
    let [x0, y0, w, h] = view.region.map(|x| x as usize);
    let (x1, y1) = ((x0 + w).min(img.width), (y0 + h).min(img.height));
    let (rw, rh) = (x1 - x0, y1 - y0);
    let mut seen = vec![false; rw * rh];
    let mut blobs = Vec::new();
    let disc_area = std::f64::consts::PI * radius_px * radius_px;
    let mut stack = Vec::new();
    for sv in 0..rh {
        for su in 0..rw {
            if seen[sv * rw + su] || level(x0 + su, y0 + sv) < threshold {
                continue;
            }
            seen[sv * rw + su] = true;
            stack.push((su, sv));
            let (mut area, mut sw, mut su_acc, mut sv_acc, mut clipped) =
                (0usize, 0.0, 0.0, 0.0, false);
            let mut extent = [x0 + su, y0 + sv, x0 + su, y0 + sv];
            while let Some((cu, cv)) = stack.pop() {
                let val = level(x0 + cu, y0 + cv) as f64 - lv.background;
                area += 1;
                sw += val;
                su_acc += val * (x0 + cu) as f64;
                sv_acc += val * (y0 + cv) as f64;
                extent = [
                    extent[0].min(x0 + cu),
                    extent[1].min(y0 + cv),
                    extent[2].max(x0 + cu),
                    extent[3].max(y0 + cv),
                ];
                if cu == 0 || cv == 0 || cu + 1 == rw || cv + 1 == rh {
                    clipped = true;
                }
                for (nu, nv) in four_neighbours(cu, cv, rw, rh) {
                    let k = nv * rw + nu;
                    if !seen[k] && level(x0 + nu, y0 + nv) >= threshold {
                        seen[k] = true;
                        stack.push((nu, nv));
                    }
                }
            }
            // Noise specks and marker fragments are far smaller than a sphere.
            if (area as f64) < 0.2 * disc_area || sw <= 0.0 {
                continue;
            }
            blobs.push(Blob {
                centroid: [su_acc / sw, sv_acc / sw],
                area_px: area,
                extent_px: extent,
                clipped,
                merged: area as f64 > 1.45 * disc_area,
            });
        }
    }
    blobs
}
