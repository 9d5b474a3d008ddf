//! A greyscale frame as floating-point grey levels on the 8-bit scale (16-bit frames are divided
//! by 256), with bilinear sampling at sub-pixel positions (pixel centres at integers), and what
//! the normalisation took out of each pixel (`ground`).

use std::sync::Arc;

/// The 4-connected neighbours of pixel (u, v) in a `width` × `height` grid, always in the order
/// left, right, above, below: the step of every flood fill (blobs, marker dots, grid dots).
pub fn four_neighbours(
    u: usize,
    v: usize,
    width: usize,
    height: usize,
) -> impl Iterator<Item = (usize, usize)> {
    [
        (u > 0).then(|| (u - 1, v)),
        (u + 1 < width).then_some((u + 1, v)),
        (v > 0).then(|| (u, v - 1)),
        (v + 1 < height).then_some((u, v + 1)),
    ]
    .into_iter()
    .flatten()
}

pub struct GreyImage {
    pub width: usize,
    pub height: usize,
    pub data: Vec<f32>,
    /// Per pixel (row-major, the frame's size), how far the static backdrop that the
    /// normalisation subtracted stands above the level it put in its place (`backdrop`): 0 on a
    /// flat ground, large on a tube end or a ruler. A sphere hides what is behind it, so where
    /// it covers a pixel the normalised frame holds its shading minus this; None where nothing
    /// was subtracted (all zero).
    pub ground: Option<Arc<[f32]>>,
    /// The noise σ `ground` keeps from the frames it was estimated from, grey levels
    /// (`Backdrop::estimate`: a quantile of a few dozen keeps about a quarter of theirs): how far
    /// it may differ from pixel to pixel where nothing stands. 0 where nothing was subtracted.
    pub ground_noise: f32,
    /// Views where this frame's light differed from the backdrop's (a flickering lamp,
    /// `backdrop`): there the backdrop's shape was subtracted at that gain, and what a sphere
    /// hides is `gain·ground`. Empty under a steady lamp.
    pub ground_light: Vec<GroundLight>,
    /// The rectangles [x0, y0, x1, y1) (exclusive ends) of views the normalisation inverted
    /// (backlit: the spheres darker than their ground); empty where none was.
    pub inverted: Arc<[[usize; 4]]>,
    /// Per pixel (row-major), whether its level says nothing reliable of what the pixel sees
    /// (`backdrop`): it was at the top of the camera's range before normalisation
    /// (`SATURATED_GREY`) in a view whose spheres are brighter than their ground, where an
    /// overexposed sphere's level is only known to be at least what it shows; or it is stuck,
    /// a defective pixel that showed one level in every sampled frame while its neighbours
    /// changed. The disc fits and the dots' shading leave such pixels out. Empty where nothing
    /// was marked.
    pub unmeasured: Vec<bool>,
}

/// One view's frame lit differently from its backdrop (`GreyImage::ground_light`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GroundLight {
    /// [x0, y0, x1, y1) (exclusive ends).
    pub rect: [usize; 4],
    pub gain: f32,
}

/// A raw level at or above this is the top of the camera's range (8-bit 255; a 16-bit
/// camera's top 256 codes, as `GreyImage::load` scales them).
pub const SATURATED_GREY: f32 = 255.0;

impl GreyImage {
    pub fn new() -> GreyImage {
        GreyImage {
            width: 0,
            height: 0,
            data: Vec::new(),
            ground: None,
            ground_noise: 0.0,
            ground_light: Vec::new(),
            inverted: Arc::from([]),
            unmeasured: Vec::new(),
        }
    }

    /// Fills from raw camera bytes (1 or 2 bytes per pixel, little-endian).
    pub fn load(&mut self, raw: &[u8], width: usize, height: usize, bytes_per_pixel: usize) {
        self.width = width;
        self.height = height;
        self.ground = None;
        self.ground_noise = 0.0;
        self.ground_light.clear();
        self.inverted = Arc::from([]);
        self.unmeasured.clear();
        self.data.clear();
        if bytes_per_pixel == 1 {
            self.data.extend(raw.iter().map(|&b| b as f32));
        } else {
            self.data.extend(
                raw.chunks_exact(2)
                    .map(|c| u16::from_le_bytes([c[0], c[1]]) as f32 / 256.0),
            );
        }
    }

    #[inline]
    pub fn at(&self, u: usize, v: usize) -> f32 {
        self.data[v * self.width + u]
    }

    /// How far pixel (u, v), as a sphere shows it (`lit_at`), lies below `expected`: 0 where it
    /// is unmeasured, since its level is at most a floor (a dot on an overexposed face is darker
    /// than the ceiling; the face around it is not) or nothing at all (a stuck pixel).
    #[inline]
    pub fn below(&self, u: usize, v: usize, expected: f64) -> f64 {
        if self.unmeasured_at(u, v) {
            0.0
        } else {
            expected - self.lit_at(u, v) as f64
        }
    }

    /// Whether pixel (u, v)'s level is unreliable (`unmeasured`).
    #[inline]
    pub fn unmeasured_at(&self, u: usize, v: usize) -> bool {
        self.unmeasured
            .get(v * self.width + u)
            .copied()
            .unwrap_or(false)
    }

    /// `ground` at pixel (u, v): what stands behind a sphere there, above the ground's level.
    #[inline]
    pub fn ground_at(&self, u: usize, v: usize) -> f32 {
        let g = self
            .ground
            .as_ref()
            .and_then(|g| g.get(v * self.width + u).copied())
            .unwrap_or(0.0);
        match self
            .ground_light
            .iter()
            .find(|l| u >= l.rect[0] && v >= l.rect[1] && u < l.rect[2] && v < l.rect[3])
        {
            Some(l) => l.gain * g,
            None => g,
        }
    }

    /// The grey level at pixel (u, v) as a sphere that covers it shows it: the normalised level
    /// plus the backdrop it hides (`ground`), which the normalisation subtracted though the
    /// sphere was in front of it. Inside a disc this is the sphere's own shading on a flat
    /// ground, whatever stands behind.
    #[inline]
    pub fn sphere_at(&self, u: usize, v: usize) -> f32 {
        self.at(u, v) + self.ground_at(u, v)
    }

    /// The grey level at pixel (u, v) that a covering sphere's own surface gives, the right way
    /// up: `sphere_at`, turned back where the view was inverted. In a backlit view lit from the
    /// front too, the sphere is dark and its painted dots darker still; inverted, they would be
    /// brighter than the disc. Markers are found in these levels (which are the frame's greys
    /// as recorded, wherever a backdrop was subtracted).
    #[inline]
    pub fn lit_at(&self, u: usize, v: usize) -> f32 {
        let s = self.sphere_at(u, v);
        if self
            .inverted
            .iter()
            .any(|r| u >= r[0] && v >= r[1] && u < r[2] && v < r[3])
        {
            // The inversion put p at level + (still − p) and `ground` holds (255 − still) −
            // level, so p = 255 − sphere_at.
            255.0 - s
        } else {
            s
        }
    }

    /// The largest |`ground` − `reference`| over the pixels a bilinear sample at (u, v) reads:
    /// how far the backdrop there differs from a level; 0 outside the image or without a ground.
    pub fn ground_off(&self, u: f64, v: f64, reference: f64) -> f64 {
        if self.ground.is_none() || !(u >= 0.0 && v >= 0.0) {
            return 0.0;
        }
        let (u0, v0) = (u.floor() as usize, v.floor() as usize);
        let mut most = 0f64;
        for (du, dv) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            if u0 + du < self.width && v0 + dv < self.height {
                most = most.max((self.ground_at(u0 + du, v0 + dv) as f64 - reference).abs());
            }
        }
        most
    }

    /// The pixels of the square of half-side `reach` round `centre` that lie in the image:
    /// columns `[0]..=[1]` and rows `[2]..=[3]` (the edges rounded outwards).
    pub fn box_around(&self, centre: [f64; 2], reach: f64) -> [usize; 4] {
        [
            (centre[0] - reach).floor().max(0.0) as usize,
            ((centre[0] + reach).ceil() as usize).min(self.width.saturating_sub(1)),
            (centre[1] - reach).floor().max(0.0) as usize,
            ((centre[1] + reach).ceil() as usize).min(self.height.saturating_sub(1)),
        ]
    }

    /// Bilinear interpolation; None outside the image.
    pub fn sample(&self, u: f64, v: f64) -> Option<f64> {
        if !(u >= 0.0 && v >= 0.0) {
            return None;
        }
        let (u0, v0) = (u.floor() as usize, v.floor() as usize);
        if u0 + 1 >= self.width || v0 + 1 >= self.height {
            return None;
        }
        let (fu, fv) = (u - u0 as f64, v - v0 as f64);
        let p = |x: usize, y: usize| self.at(x, y) as f64;
        Some(
            p(u0, v0) * (1.0 - fu) * (1.0 - fv)
                + p(u0 + 1, v0) * fu * (1.0 - fv)
                + p(u0, v0 + 1) * (1.0 - fu) * fv
                + p(u0 + 1, v0 + 1) * fu * fv,
        )
    }
}

impl Default for GreyImage {
    fn default() -> Self {
        Self::new()
    }
}
