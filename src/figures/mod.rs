//! Figures drawn once onto a `Canvas` and written as SVG and PNG: the drawing surfaces
//! (`canvas`, with the embedded bitmap `font`), the plot area and axes shared by every figure,
//! and the per-experiment figures (`trajectory`). The campaign's ψ plot and the daemon's pages
//! both draw with these.

pub mod canvas;
pub mod carried;
mod font;
pub mod trajectory;

use canvas::{Anchor, Canvas, Raster, Rgb, Svg};

pub const BLACK: Rgb = [0, 0, 0];
pub const BLUE: Rgb = [31, 119, 180];
pub const RED: Rgb = [214, 39, 40];
pub const ORANGE: Rgb = [255, 127, 14];
pub const GREY: Rgb = [150, 150, 150];

/// A plot area mapping data coordinates to canvas pixels.
pub struct Frame {
    pub left: f64,
    pub top: f64,
    pub w: f64,
    pub h: f64,
    pub x: (f64, f64),
    pub y: (f64, f64),
}

impl Frame {
    pub fn at(&self, x: f64, y: f64) -> (f64, f64) {
        (
            self.left + (x - self.x.0) / (self.x.1 - self.x.0) * self.w,
            self.top + self.h - (y - self.y.0) / (self.y.1 - self.y.0) * self.h,
        )
    }

    pub fn inside(&self, x: f64, y: f64) -> bool {
        x >= self.x.0 && x <= self.x.1 && y >= self.y.0 && y <= self.y.1
    }

    /// A data-space segment, drawn only where both ends are inside the plot area.
    pub fn segment(
        &self,
        c: &mut dyn Canvas,
        a: (f64, f64),
        b: (f64, f64),
        colour: Rgb,
        width: f64,
    ) {
        if self.inside(a.0, a.1) && self.inside(b.0, b.1) {
            c.line(self.at(a.0, a.1), self.at(b.0, b.1), colour, width);
        }
    }

    pub fn axes(&self, c: &mut dyn Canvas, x_label: &str, y_label: &str, title: &str) {
        let (l, t, r, b) = (self.left, self.top, self.left + self.w, self.top + self.h);
        for (a, z) in [
            ((l, b), (r, b)),
            ((l, t), (l, b)),
            ((l, t), (r, t)),
            ((r, t), (r, b)),
        ] {
            c.line(a, z, BLACK, 1.0);
        }
        for k in 0..=4 {
            let x = self.x.0 + (self.x.1 - self.x.0) * k as f64 / 4.0;
            let (px, _) = self.at(x, self.y.0);
            c.line((px, b), (px, b + 4.0), BLACK, 1.0);
            c.text((px, b + 17.0), &format!("{x:.2}"), Anchor::Middle, BLACK);
            let y = self.y.0 + (self.y.1 - self.y.0) * k as f64 / 4.0;
            let (_, py) = self.at(self.x.0, y);
            c.line((l - 4.0, py), (l, py), BLACK, 1.0);
            c.text((l - 6.0, py + 4.0), &format!("{y:.2}"), Anchor::End, BLACK);
        }
        c.text(((l + r) / 2.0, b + 34.0), x_label, Anchor::Middle, BLACK);
        c.text(
            (l, t - 8.0),
            &format!("{title}   ({y_label})"),
            Anchor::Start,
            BLACK,
        );
    }
}

/// The span of `values`, padded by `pad` of itself on each side ((0, 1) when empty).
pub fn range(values: impl Iterator<Item = f64>, pad: f64) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |a, v| {
        (a.0.min(v), a.1.max(v))
    });
    if !lo.is_finite() || !hi.is_finite() {
        return (0.0, 1.0);
    }
    let span = (hi - lo).max(1e-6);
    (lo - pad * span, hi + pad * span)
}

/// SVG text and PNG bytes of one figure.
pub fn render(w: usize, h: usize, draw: &dyn Fn(&mut dyn Canvas)) -> (String, Vec<u8>) {
    let mut svg = Svg::new(w as f64, h as f64);
    draw(&mut svg);
    let mut raster = Raster::new(w, h);
    draw(&mut raster);
    (svg.finish(), raster.png().unwrap_or_default())
}
