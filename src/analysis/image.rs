//! A greyscale frame as floating-point grey levels on the 8-bit scale (16-bit frames are divided
//! by 256), with bilinear sampling at sub-pixel positions (pixel centres at integers).

pub struct GreyImage {
    pub width: usize,
    pub height: usize,
    pub data: Vec<f32>,
}

impl GreyImage {
    pub fn new() -> GreyImage {
        GreyImage {
            width: 0,
            height: 0,
            data: Vec::new(),
        }
    }

    /// Fills from raw camera bytes (1 or 2 bytes per pixel, little-endian).
    pub fn load(&mut self, raw: &[u8], width: usize, height: usize, bytes_per_pixel: usize) {
        self.width = width;
        self.height = height;
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
