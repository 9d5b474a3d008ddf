//! Segmentation of one view: background and noise level, threshold, connected blobs (bright
//! parts, with the parts of the same disc darker than the ground).
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

/// Of a disc's area, the least a part must cover to be a sphere's: noise specks and a dot's
/// fragments are far smaller.
const FRAGMENT_OF_DISC: f64 = 0.2;

/// Of a disc's area, the most a dark part and the bright part it joins may cover together
/// (`find_blobs`): a sphere's shaded limb and its lit side make one disc, and less than one
/// once the band where its shading crosses the ground's level is left out; a shadow or a dark
/// thing beside a sphere's lit side would make more.
const TWO_SIDED_MAX_DISC: f64 = 1.1;

/// Connected blobs of plausible sphere size in one view: bright ones, each with the parts of the
/// same disc darker than the ground beside it.
///
/// A sphere lit from the side over a ground as bright as its shaded limb is partly brighter and
/// partly darker than the ground: its lit side a blob above the threshold, its limb one below
/// the ground by as much, with a band between where its shading crosses the ground's level. A
/// dark part of a sphere's fragment's size or more (a limb; not a dot) joins the bright blob
/// within half a radius (the band's width) where that blob is the only one of a fragment's size
/// there and the two together are no more than a disc; a dark part alone is never a sphere (a
/// view whose spheres are darker than their ground is inverted before this: `backdrop`).
pub fn find_blobs(
    img: &GreyImage,
    view: &View,
    lv: &ViewLevels,
    radius_px: f64,
    threshold_fraction: f64,
) -> Vec<Blob> {
    // A sphere seen at all stands 8σ from the ground: where the view's 99.7th percentile does
    // not, the spheres cover too little of it to reach that percentile (a side-lit sphere's lit
    // part over a grey ground is a fraction of a percent of a view), or there are none, and the
    // threshold is held at that fraction of 8σ (noise alone does not make a blob there: 4σ
    // pixels are isolated).
    let contrast = (lv.peak - lv.background).max(8.0 * lv.noise_sigma).max(5.0);
    let threshold = (lv.background + threshold_fraction * contrast) as f32;
    // Where the subtracted backdrop stood out from the ground by more than the threshold's
    // height (a tube end, a ruler), a sphere in front of it hides it and comes out as its
    // shading less the backdrop, as likely below the ground as above: there a pixel is
    // foreground by how far it is from the ground either way.
    let rise = threshold - lv.background as f32;
    let bg = lv.background as f32;
    let over_clutter = |u: usize, v: usize| img.ground_at(u, v).abs() > rise;
    // 1: brighter than the threshold (or, over clutter, as far from the ground either way);
    // 2: as far below the ground; 0: neither.
    let class = |u: usize, v: usize| -> u8 {
        let val = img.at(u, v);
        if over_clutter(u, v) {
            u8::from((val - bg).abs() >= rise)
        } else if val >= threshold {
            1
        } else if val <= bg - rise {
            2
        } else {
            0
        }
    };
    // How far from the ground the pixel is, as the centroid weighs it.
    let weight = |u: usize, v: usize| -> f64 { (img.at(u, v) - bg).abs() as f64 };
    let [x0, y0, w, h] = view.region.map(|x| x as usize);
    let (x1, y1) = ((x0 + w).min(img.width), (y0 + h).min(img.height));
    let (rw, rh) = (x1 - x0, y1 - y0);
    let mut seen = vec![false; rw * rh];
    let disc_area = std::f64::consts::PI * radius_px * radius_px;
    let mut parts: Vec<Part> = Vec::new();
    // Every part's pixels, (u, v) in the region, each part a range of them.
    let mut pixels: Vec<(usize, usize)> = Vec::new();
    let mut stack = Vec::new();
    for sv in 0..rh {
        for su in 0..rw {
            if seen[sv * rw + su] {
                continue;
            }
            let c = class(x0 + su, y0 + sv);
            if c == 0 {
                continue;
            }
            seen[sv * rw + su] = true;
            stack.push((su, sv));
            let first = pixels.len();
            let mut part = Part {
                bright: c == 1,
                pixels: first..first,
                area: 0,
                sw: 0.0,
                su: 0.0,
                sv: 0.0,
                extent: [x0 + su, y0 + sv, x0 + su, y0 + sv],
                clipped: false,
            };
            while let Some((cu, cv)) = stack.pop() {
                let (u, v) = (x0 + cu, y0 + cv);
                pixels.push((cu, cv));
                part.add(u, v, weight(u, v));
                if cu == 0 || cv == 0 || cu + 1 == rw || cv + 1 == rh {
                    part.clipped = true;
                }
                for (nu, nv) in four_neighbours(cu, cv, rw, rh) {
                    let k = nv * rw + nu;
                    if !seen[k] && class(x0 + nu, y0 + nv) == c {
                        seen[k] = true;
                        stack.push((nu, nv));
                    }
                }
            }
            part.pixels = first..pixels.len();
            parts.push(part);
        }
    }
    // Each dark part of a fragment's size or more (a shaded limb), largest first, joins the one
    // bright part of a fragment's size within reach, where their areas together leave room.
    // Not a dot: dark inside a lit disc, it only moved the grey-level fits' starts, and on
    // hw-sim's grey-ground look that lost frames and put the worst centres 3–11 px off where
    // they had been 0.1–0.9. Not where two bright parts are within reach: by the spheres' gap a
    // limb may be either's. Nor to a fleck of noise or highlight: no disc's lit side.
    let reach = (0.5 * radius_px).max(2.0);
    let fragment = FRAGMENT_OF_DISC * disc_area;
    let (bright, mut dark): (Vec<Part>, Vec<Part>) = parts.into_iter().partition(|p| p.bright);
    let mut blobs: Vec<Part> = bright;
    dark.sort_by_key(|d| std::cmp::Reverse(d.area));
    for d in dark.iter().filter(|d| d.area as f64 >= fragment) {
        let mut near = blobs
            .iter()
            .enumerate()
            .filter(|(_, b)| b.area as f64 >= fragment)
            .filter(|(_, b)| b.within_reach(d, &pixels, reach))
            .map(|(i, _)| i);
        let (Some(i), None) = (near.next(), near.next()) else {
            continue;
        };
        if (blobs[i].area + d.area) as f64 <= TWO_SIDED_MAX_DISC * disc_area {
            blobs[i].join(d);
        }
    }
    blobs
        .into_iter()
        // Noise specks and marker fragments are far smaller than a sphere.
        .filter(|p| p.area as f64 >= fragment && p.sw > 0.0)
        .map(|p| Blob {
            centroid: [p.su / p.sw, p.sv / p.sw],
            area_px: p.area,
            extent_px: p.extent,
            clipped: p.clipped,
            merged: p.area as f64 > 1.45 * disc_area,
        })
        .collect()
}

/// A connected set of pixels on one side of the ground (`find_blobs`), and the dark parts
/// joined to it.
struct Part {
    bright: bool,
    /// Its own pixels (before any join), in `find_blobs`'s list.
    pixels: std::ops::Range<usize>,
    area: usize,
    /// Sums of the weights and of the weighted u and v.
    sw: f64,
    su: f64,
    sv: f64,
    extent: [usize; 4],
    clipped: bool,
}

impl Part {
    fn add(&mut self, u: usize, v: usize, weight: f64) {
        self.area += 1;
        self.sw += weight;
        self.su += weight * u as f64;
        self.sv += weight * v as f64;
        self.cover([u, v, u, v]);
    }

    /// The extent grown to take in `other`'s, [u0, v0, u1, v1].
    fn cover(&mut self, other: [usize; 4]) {
        let e = &mut self.extent;
        *e = [
            e[0].min(other[0]),
            e[1].min(other[1]),
            e[2].max(other[2]),
            e[3].max(other[3]),
        ];
    }

    fn join(&mut self, other: &Part) {
        self.area += other.area;
        self.sw += other.sw;
        self.su += other.su;
        self.sv += other.sv;
        self.cover(other.extent);
        self.clipped |= other.clipped;
    }

    /// Whether any of this part's own pixels lies within `reach` px of one of `other`'s.
    fn within_reach(&self, other: &Part, pixels: &[(usize, usize)], reach: f64) -> bool {
        let (a, b) = (self.extent, other.extent);
        let box_gap_u = a[0].saturating_sub(b[2]).max(b[0].saturating_sub(a[2]));
        let box_gap_v = a[1].saturating_sub(b[3]).max(b[1].saturating_sub(a[3]));
        if box_gap_u as f64 > reach || box_gap_v as f64 > reach {
            return false;
        }
        let reach2 = reach * reach;
        pixels[self.pixels.clone()].iter().any(|&(pu, pv)| {
            pixels[other.pixels.clone()].iter().any(|&(qu, qv)| {
                let du = pu as f64 - qu as f64;
                let dv = pv as f64 - qv as f64;
                du * du + dv * dv <= reach2
            })
        })
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::analysis::geometry::ViewKind;

    const W: usize = 240;
    const H: usize = 96;

    pub(crate) fn view() -> View {
        let g = crate::config::ViewGeometry::shorthand(
            [0, 0, W as u32, H as u32],
            2.0,
            [0.0, 0.0],
            "+x",
            "-y",
        );
        View::from_config(ViewKind::Direct, &g)
    }

    /// Gaussian noise of σ `sigma` at pixel i, the same every run (a hash, Box–Muller).
    fn noise(i: usize, sigma: f64) -> f64 {
        let hash = |x: u64| {
            let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
        };
        let (u1, u2) = (hash(2 * i as u64).max(1e-12), hash(2 * i as u64 + 1));
        sigma * (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    /// A view of `ground` with noise σ 4 (shot noise at a grey ground's level), and over it
    /// discs of radius `r` at `centres`, each shaded by `shade(x, y)` (offsets from its centre,
    /// px; None outside), 4 × 4 samples per pixel.
    pub(crate) fn frame(
        ground: f64,
        r: f64,
        centres: &[[f64; 2]],
        shade: &dyn Fn(f64, f64) -> f64,
    ) -> GreyImage {
        frame_each(ground, r, centres, &|_, x, y| shade(x, y))
    }

    /// `frame` with each disc's shading its own: `shade(k, x, y)` for the k-th of `centres`.
    fn frame_each(
        ground: f64,
        r: f64,
        centres: &[[f64; 2]],
        shade: &dyn Fn(usize, f64, f64) -> f64,
    ) -> GreyImage {
        let mut img = GreyImage::new();
        img.width = W;
        img.height = H;
        img.data = (0..W * H)
            .map(|i| {
                let (u, v) = ((i % W) as f64, (i / W) as f64);
                let mut sum = 0.0;
                for j in 0..16 {
                    let (su, sv) = (
                        u + ((j % 4) as f64 - 1.5) / 4.0,
                        v + ((j / 4) as f64 - 1.5) / 4.0,
                    );
                    let inside = centres
                        .iter()
                        .enumerate()
                        .find(|(_, c)| (su - c[0]).hypot(sv - c[1]) < r);
                    sum += match inside {
                        Some((k, c)) => shade(k, su - c[0], sv - c[1]),
                        None => ground,
                    };
                }
                (sum / 16.0 + noise(i, 4.0)).round().clamp(0.0, 255.0) as f32
            })
            .collect();
        img
    }

    /// A matte sphere of albedo 159 and radius `r` lit from 33° off the axis, up and to the
    /// left, with an ambient floor of 0.13: its lit side above a ground of 104, its shaded
    /// limb at 21, far below it (an independent renderer's look drawn at random: seed 2 of
    /// `scripts/random-look.py`).
    pub(crate) fn side_lit(r: f64) -> impl Fn(f64, f64) -> f64 {
        let (s, c) = 33f64.to_radians().sin_cos();
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let light = [-s * h, -s * h, c];
        move |x, y| {
            let (nx, ny) = (x / r, y / r);
            let nz = (1.0 - nx * nx - ny * ny).max(0.0).sqrt();
            let lambert = (light[0] * nx + light[1] * ny + light[2] * nz).max(0.0);
            159.0 * (0.13 + 0.87 * lambert)
        }
    }

    /// Two side-lit spheres over a grey ground whose lit sides cover a tenth of a percent of the
    /// view, and whose shaded limbs are as far below the ground as the lit sides are above it:
    /// each is found, once, its centroid within 1.5 px of its centre (the grey-level fit starts
    /// from there). The view's 99.7th percentile stood 24 levels above the ground at a noise of
    /// 4.4, below the 8σ a sphere must stand, and such recordings gave no blob at all; with the
    /// lit side alone the centroid lay 3 px towards the light.
    #[test]
    fn side_lit_spheres_over_a_grey_ground_are_found_where_they_are() {
        let r = 6.25;
        let centres = [[80.3, 40.7], [160.6, 52.2]];
        let img = frame(104.0, r, &centres, &side_lit(r));
        let lv = levels(&img, &view());
        let blobs = find_blobs(&img, &view(), &lv, r, 0.5);
        assert_eq!(blobs.len(), 2, "blobs {blobs:?}");
        for (b, c) in blobs.iter().zip(&centres) {
            let off = (b.centroid[0] - c[0]).hypot(b.centroid[1] - c[1]);
            assert!(off < 1.5, "blob {b:?} {off:.2} px from its centre {c:?}");
            assert!(!b.merged && !b.clipped, "{b:?}");
        }
    }

    /// A fleck of noise or highlight just beyond a side-lit sphere's shaded limb does not take
    /// the limb from the sphere: the limb joins the sphere's lit side, the largest bright part
    /// within reach, and the sphere is one blob. (Joined to the nearest, a one-pixel fleck
    /// took a limb of 84 pixels, and one sphere made two blobs.)
    #[test]
    fn a_fleck_beside_a_shaded_limb_does_not_take_it() {
        let r = 6.25;
        let centre = [100.3, 40.7];
        let mut img = frame(104.0, r, &[centre], &side_lit(r));
        // The shaded limb faces down and to the right; the fleck 1.5 px beyond it.
        let d = (r + 1.5) * std::f64::consts::FRAC_1_SQRT_2;
        let (fu, fv) = (
            (centre[0] + d).round() as usize,
            (centre[1] + d).round() as usize,
        );
        img.data[fv * W + fu] = 220.0;
        let lv = levels(&img, &view());
        let blobs = find_blobs(&img, &view(), &lv, r, 0.5);
        let [b] = &blobs[..] else {
            panic!("blobs {blobs:?}, expected the sphere's alone");
        };
        let off = (b.centroid[0] - centre[0]).hypot(b.centroid[1] - centre[1]);
        assert!(off < 1.5, "blob {b:?} {off:.2} px from the centre");
    }

    /// Two side-lit spheres a pixel apart, the first one's shaded limb against the second one's
    /// lit side, the second's paint brighter (a larger lit side): the limb is within reach of
    /// both lit sides, joins neither, and does not drag the second sphere's blob towards the
    /// first, as it did joined to the larger lit side within reach.
    #[test]
    fn a_limb_between_two_spheres_joins_neither() {
        let r = 6.25;
        let a = [100.3, 40.7];
        let step = (2.0 * r + 1.0) * std::f64::consts::FRAC_1_SQRT_2;
        let b = [a[0] + step, a[1] + step];
        let lit = side_lit(r);
        let img = frame_each(104.0, r, &[a, b], &|k, x, y| {
            if k == 0 {
                lit(x, y)
            } else {
                (1.4 * lit(x, y)).min(250.0)
            }
        });
        let lv = levels(&img, &view());
        let blobs = find_blobs(&img, &view(), &lv, r, 0.5);
        let dist = |x: &Blob| (x.centroid[0] - b[0]).hypot(x.centroid[1] - b[1]);
        let nearest_b = blobs
            .iter()
            .min_by(|p, q| dist(p).total_cmp(&dist(q)))
            .expect("blobs");
        assert!(
            dist(nearest_b) < 1.5,
            "the second sphere's blob {nearest_b:?} {:.2} px from its centre; blobs {blobs:?}",
            dist(nearest_b)
        );
    }

    /// A dark disc alone (a shadow on a backdrop, a dark thing passing) is not a sphere; beside
    /// a bright sphere, a dark disc as large joins it only where the two would be one disc,
    /// which they are not: the sphere's blob stays its own.
    #[test]
    fn a_dark_disc_is_no_sphere_and_does_not_join_one() {
        let r = 6.0;
        // A dark disc alone.
        let img = frame(100.0, r, &[[60.0, 40.0]], &|_, _| 40.0);
        let lv = levels(&img, &view());
        assert!(find_blobs(&img, &view(), &lv, r, 0.5).is_empty());
        // A bright disc at (120, 40) and a dark one touching it at (132, 40).
        let bright = [120.0, 40.0];
        let mut img = frame(100.0, r, &[bright], &|_, _| 200.0);
        let dark = frame(100.0, r, &[[132.5, 40.0]], &|_, _| 40.0);
        for (i, d) in dark.data.iter().enumerate() {
            if (i % W) as f64 > 126.5 {
                img.data[i] = *d;
            }
        }
        let lv = levels(&img, &view());
        let blobs = find_blobs(&img, &view(), &lv, r, 0.5);
        let [b] = &blobs[..] else {
            panic!("blobs {blobs:?}, expected the bright disc's");
        };
        let off = (b.centroid[0] - bright[0]).hypot(b.centroid[1] - bright[1]);
        assert!(
            off < 0.3,
            "blob {b:?} {off:.2} px from the bright disc's centre"
        );
    }
}
