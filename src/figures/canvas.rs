//! Drawing for the campaign's plots, once for two outputs: SVG (vector, for editing) and PNG
//! (raster, for slides and documents). A plot draws onto `Canvas`; it does not know which.

use super::font::{glyph, GLYPH_H, GLYPH_W};
use std::fmt::Write as _;

#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Anchor {
    Start,
    Middle,
    End,
}

pub type Rgb = [u8; 3];

pub trait Canvas {
    fn line(&mut self, a: (f64, f64), b: (f64, f64), colour: Rgb, width: f64);
    fn circle(&mut self, c: (f64, f64), r: f64, colour: Rgb, filled: bool);
    fn text(&mut self, at: (f64, f64), text: &str, anchor: Anchor, colour: Rgb);
    /// The outline of the rectangle from `a` to `b`.
    fn rect(&mut self, a: (f64, f64), b: (f64, f64), colour: Rgb, width: f64) {
        self.line(a, (b.0, a.1), colour, width);
        self.line((b.0, a.1), b, colour, width);
        self.line(b, (a.0, b.1), colour, width);
        self.line((a.0, b.1), a, colour, width);
    }
}

pub struct Svg {
    body: String,
    w: f64,
    h: f64,
}

fn hex(c: Rgb) -> String {
    format!("#{:02x}{:02x}{:02x}", c[0], c[1], c[2])
}

impl Svg {
    pub fn new(w: f64, h: f64) -> Svg {
        Svg {
            body: String::new(),
            w,
            h,
        }
    }
    pub fn finish(self) -> String {
        format!(
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{0}\" height=\"{1}\" viewBox=\"0 0 {0} {1}\" font-family=\"sans-serif\" font-size=\"12\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n{2}</svg>\n",
            self.w, self.h, self.body
        )
    }
}

impl Canvas for Svg {
    fn line(&mut self, a: (f64, f64), b: (f64, f64), colour: Rgb, width: f64) {
        let _ = writeln!(self.body, "<line x1=\"{:.2}\" y1=\"{:.2}\" x2=\"{:.2}\" y2=\"{:.2}\" stroke=\"{}\" stroke-width=\"{width}\"/>", a.0, a.1, b.0, b.1, hex(colour));
    }
    fn circle(&mut self, c: (f64, f64), r: f64, colour: Rgb, filled: bool) {
        let style = if filled {
            format!("fill=\"{}\"", hex(colour))
        } else {
            format!("fill=\"none\" stroke=\"{}\"", hex(colour))
        };
        let _ = writeln!(
            self.body,
            "<circle cx=\"{:.2}\" cy=\"{:.2}\" r=\"{r}\" {style}/>",
            c.0, c.1
        );
    }
    fn text(&mut self, at: (f64, f64), text: &str, anchor: Anchor, colour: Rgb) {
        let a = match anchor {
            Anchor::Start => "start",
            Anchor::Middle => "middle",
            Anchor::End => "end",
        };
        let t = text.replace('&', "&amp;").replace('<', "&lt;");
        let _ = writeln!(
            self.body,
            "<text x=\"{:.2}\" y=\"{:.2}\" text-anchor=\"{a}\" fill=\"{}\">{t}</text>",
            at.0,
            at.1,
            hex(colour)
        );
    }
}

/// An RGB raster with anti-aliased lines (supersampled coverage) and the embedded bitmap font.
pub struct Raster {
    w: usize,
    h: usize,
    px: Vec<u8>,
}

impl Raster {
    pub fn new(w: usize, h: usize) -> Raster {
        Raster {
            w,
            h,
            px: vec![255; w * h * 3],
        }
    }

    pub fn width(&self) -> usize {
        self.w
    }
    pub fn height(&self) -> usize {
        self.h
    }

    /// A raster showing a greyscale camera frame (8-bit scale values).
    pub fn from_grey(w: usize, h: usize, grey: &[f32]) -> Raster {
        let px = grey.iter().flat_map(|&g| {
            let v = g.round().clamp(0.0, 255.0) as u8;
            [v, v, v]
        });
        Raster {
            w,
            h,
            px: px.collect(),
        }
    }

    fn blend(&mut self, x: i64, y: i64, c: Rgb, alpha: f64) {
        if x < 0 || y < 0 || x as usize >= self.w || y as usize >= self.h || alpha <= 0.0 {
            return;
        }
        let i = (y as usize * self.w + x as usize) * 3;
        let a = alpha.min(1.0);
        for (p, &ck) in self.px[i..i + 3].iter_mut().zip(c.iter()) {
            *p = (*p as f64 * (1.0 - a) + ck as f64 * a).round() as u8;
        }
    }

    /// Encodes as PNG.
    pub fn png(&self) -> Result<Vec<u8>, png::EncodingError> {
        let mut out = Vec::new();
        {
            let mut enc = png::Encoder::new(&mut out, self.w as u32, self.h as u32);
            enc.set_color(png::ColorType::Rgb);
            enc.set_depth(png::BitDepth::Eight);
            let mut writer = enc.write_header()?;
            writer.write_image_data(&self.px)?;
        }
        Ok(out)
    }
}

impl Canvas for Raster {
    fn line(&mut self, a: (f64, f64), b: (f64, f64), colour: Rgb, width: f64) {
        let (x0, x1) = (a.0.min(b.0) - width - 1.0, a.0.max(b.0) + width + 1.0);
        let (y0, y1) = (a.1.min(b.1) - width - 1.0, a.1.max(b.1) + width + 1.0);
        let (dx, dy) = (b.0 - a.0, b.1 - a.1);
        let len2 = (dx * dx + dy * dy).max(1e-12);
        let half = width.max(1.0) / 2.0;
        for y in y0.floor() as i64..=y1.ceil() as i64 {
            for x in x0.floor() as i64..=x1.ceil() as i64 {
                // Distance from the pixel centre to the segment, turned into coverage.
                let (px, py) = (x as f64 + 0.5, y as f64 + 0.5);
                let t = (((px - a.0) * dx + (py - a.1) * dy) / len2).clamp(0.0, 1.0);
                let d = ((px - a.0 - t * dx).powi(2) + (py - a.1 - t * dy).powi(2)).sqrt();
                self.blend(x, y, colour, (half + 0.5 - d).clamp(0.0, 1.0));
            }
        }
    }

    fn circle(&mut self, c: (f64, f64), r: f64, colour: Rgb, filled: bool) {
        for y in (c.1 - r - 2.0).floor() as i64..=(c.1 + r + 2.0).ceil() as i64 {
            for x in (c.0 - r - 2.0).floor() as i64..=(c.0 + r + 2.0).ceil() as i64 {
                let d = ((x as f64 + 0.5 - c.0).powi(2) + (y as f64 + 0.5 - c.1).powi(2)).sqrt();
                let alpha = if filled {
                    (r + 0.5 - d).clamp(0.0, 1.0)
                } else {
                    (1.0 - (d - r).abs()).clamp(0.0, 1.0)
                };
                self.blend(x, y, colour, alpha);
            }
        }
    }

    fn text(&mut self, at: (f64, f64), text: &str, anchor: Anchor, colour: Rgb) {
        let n = text.chars().count() as f64;
        let x_start = match anchor {
            Anchor::Start => at.0,
            Anchor::Middle => at.0 - n * GLYPH_W as f64 / 2.0,
            Anchor::End => at.0 - n * GLYPH_W as f64,
        };
        // `at` is the baseline, as in SVG; the glyph cell's baseline is about 3 px above its bottom.
        let top = at.1.round() as i64 - GLYPH_H as i64 + 3;
        for (k, ch) in text.chars().enumerate() {
            let Some(data) = glyph(ch) else { continue };
            let left = x_start.round() as i64 + (k * GLYPH_W) as i64;
            for gy in 0..GLYPH_H {
                for gx in 0..GLYPH_W {
                    let nibble = data[gy * GLYPH_W + gx];
                    self.blend(
                        left + gx as i64,
                        top + gy as i64,
                        colour,
                        nibble as f64 / 15.0,
                    );
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_round_trips_and_text_and_lines_leave_ink() {
        let mut r = Raster::new(60, 30);
        r.line((2.0, 2.0), (50.0, 2.0), [0, 0, 0], 1.0);
        r.text((5.0, 25.0), "e 0.97", Anchor::Start, [0, 0, 0]);
        let ink = r.px.iter().filter(|&&v| v < 128).count();
        assert!(ink > 40, "{ink}");
        let bytes = r.png().unwrap();
        let dec = png::Decoder::new(std::io::Cursor::new(bytes));
        let reader = dec.read_info().unwrap();
        assert_eq!((reader.info().width, reader.info().height), (60, 30));
    }
}
