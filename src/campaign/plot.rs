//! The campaign's figures, drawn once onto a `Canvas` and written as SVG and PNG:
//! - ψ2 against ψ1: each collision with error bars, both fitted Walton lines, the break point;
//! - per experiment, the trajectories in both views (measured centres, fitted ballistic paths,
//!   the impact marked) and the fit residuals against time.

use super::canvas::{Anchor, Canvas, Raster, Rgb, Svg};
use super::fit::{CampaignFit, Collision};
use crate::analysis::report::Report;

const BLACK: Rgb = [0, 0, 0];
const BLUE: Rgb = [31, 119, 180];
const RED: Rgb = [214, 39, 40];
const ORANGE: Rgb = [255, 127, 14];
const GREY: Rgb = [150, 150, 150];

/// A plot area mapping data coordinates to canvas pixels.
struct Frame {
    left: f64,
    top: f64,
    w: f64,
    h: f64,
    x: (f64, f64),
    y: (f64, f64),
}

impl Frame {
    fn at(&self, x: f64, y: f64) -> (f64, f64) {
        (
            self.left + (x - self.x.0) / (self.x.1 - self.x.0) * self.w,
            self.top + self.h - (y - self.y.0) / (self.y.1 - self.y.0) * self.h,
        )
    }

    fn inside(&self, x: f64, y: f64) -> bool {
        x >= self.x.0 && x <= self.x.1 && y >= self.y.0 && y <= self.y.1
    }

    /// A data-space segment, drawn only where both ends are inside the plot area.
    fn segment(&self, c: &mut dyn Canvas, a: (f64, f64), b: (f64, f64), colour: Rgb, width: f64) {
        if self.inside(a.0, a.1) && self.inside(b.0, b.1) {
            c.line(self.at(a.0, a.1), self.at(b.0, b.1), colour, width);
        }
    }

    fn axes(&self, c: &mut dyn Canvas, x_label: &str, y_label: &str, title: &str) {
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

fn range(values: impl Iterator<Item = f64>, pad: f64) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |a, v| {
        (a.0.min(v), a.1.max(v))
    });
    if !lo.is_finite() || !hi.is_finite() {
        return (0.0, 1.0);
    }
    let span = (hi - lo).max(1e-6);
    (lo - pad * span, hi + pad * span)
}

pub fn draw_psi(c: &mut dyn Canvas, collisions: &[Collision], f: &CampaignFit) {
    let pts: Vec<(f64, f64, f64, f64, bool)> = collisions
        .iter()
        .filter_map(|c| {
            Some((
                c.psi1?,
                c.psi2?,
                c.psi1_sigma.unwrap_or(0.0),
                c.psi2_sigma.unwrap_or(0.0),
                c.outlier,
            ))
        })
        .collect();
    let x_max = pts.iter().map(|p| p.0 + p.2).fold(0.5, f64::max) * 1.1;
    let (y0, y1) = range(
        pts.iter().flat_map(|p| [p.1 - p.3, p.1 + p.3]).chain([0.0]),
        0.1,
    );
    let fr = Frame {
        left: 70.0,
        top: 40.0,
        w: 540.0,
        h: 370.0,
        x: (0.0, x_max),
        y: (y0, y1),
    };
    fr.axes(
        c,
        "ψ1 = |g_t| / |g_n| before impact",
        "ψ2 = g_t′·t / |g_n| after",
        "ψ2 against ψ1",
    );
    c.line(fr.at(0.0, 0.0), fr.at(x_max, 0.0), GREY, 1.0);
    if let (Some(b0), Some(brk)) = (&f.beta0, &f.psi1_break) {
        let (b0, brk) = (b0.value, brk.value);
        let cc = brk * (1.0 + b0);
        c.line(fr.at(0.0, 0.0), fr.at(brk, -b0 * brk), BLUE, 2.0);
        // The sliding line up to where it leaves the plot.
        let x_end = x_max.min(y1 + cc);
        c.line(fr.at(brk, brk - cc), fr.at(x_end, x_end - cc), RED, 2.0);
        c.circle(fr.at(brk, -b0 * brk), 5.0, BLACK, false);
        let p = fr.at(brk, -b0 * brk);
        c.text(
            (p.0 + 8.0, p.1 + 18.0),
            &format!("ψ1* = {brk:.3}"),
            Anchor::Start,
            BLACK,
        );
        c.text(
            (fr.left + 10.0, fr.top + 16.0),
            &format!("sticking: ψ2 = −β0·ψ1, β0 = {b0:.3}"),
            Anchor::Start,
            BLUE,
        );
        c.text(
            (fr.left + 10.0, fr.top + 32.0),
            &format!("sliding: ψ2 = ψ1 − {cc:.3}"),
            Anchor::Start,
            RED,
        );
    }
    for (x, y, ex, ey, outlier) in pts {
        let colour = if outlier { ORANGE } else { BLACK };
        c.line(fr.at(x - ex, y), fr.at(x + ex, y), colour, 1.0);
        c.line(fr.at(x, y - ey), fr.at(x, y + ey), colour, 1.0);
        c.circle(fr.at(x, y), 3.0, colour, true);
    }
}

/// Measured centres (mm) of sphere s per frame: (time s, [x, y, z]).
fn centres(r: &Report, s: usize) -> Vec<(f64, [Option<f64>; 3])> {
    r.tracks
        .iter()
        .filter_map(|t| {
            let tr = if s == 0 { t.a.as_ref() } else { t.b.as_ref() }?;
            Some((t.time_s, tr.centre_mm))
        })
        .collect()
}

/// The fitted trajectory of sphere s at time t (pre-impact fit before, post-impact after);
/// None for reports that predate `position_impact_mm`.
fn fitted(r: &Report, s: usize, t: f64, g: f64) -> Option<[f64; 3]> {
    let sp = if s == 0 { &r.spheres.a } else { &r.spheres.b };
    let tc = r.impact.time_s.value;
    let v = if t < tc {
        sp.velocity_pre_mm_s.value
    } else {
        sp.velocity_post_mm_s.value
    };
    let p = sp.position_impact_mm.as_ref()?.value;
    let dt = t - tc;
    Some([
        p[0] + v[0] * dt,
        p[1] + v[1] * dt - 0.5 * g * dt * dt,
        p[2] + v[2] * dt,
    ])
}

pub fn draw_trajectories(c: &mut dyn Canvas, r: &Report, g: f64) {
    let cs = [centres(r, 0), centres(r, 1)];
    let tc = r.impact.time_s.value;
    for (panel, (axis, name)) in [(1usize, "y, mm (direct view)"), (2, "z, mm (mirror view)")]
        .into_iter()
        .enumerate()
    {
        let xs = cs.iter().flatten().filter_map(|(_, p)| p[0]);
        let ys = cs.iter().flatten().filter_map(|(_, p)| p[axis]);
        let fr = Frame {
            left: 70.0,
            top: 40.0 + panel as f64 * 240.0,
            w: 540.0,
            h: 170.0,
            x: range(xs, 0.05),
            y: range(ys, 0.1),
        };
        fr.axes(
            c,
            "x, mm",
            name,
            &format!("trajectories, impact at {:.4} s", tc),
        );
        for (s, colour) in [(0, BLUE), (1, RED)] {
            // The fits hold in free flight: over the frames where every coordinate was seen.
            let (t0, t1) = range(
                cs[s]
                    .iter()
                    .filter(|(_, p)| p.iter().all(|v| v.is_some()))
                    .map(|(t, _)| *t),
                0.0,
            );
            let steps = 120;
            let mut prev: Option<(f64, f64)> = None;
            for k in 0..=steps {
                let t = t0 + (t1 - t0) * k as f64 / steps as f64;
                let Some(p) = fitted(r, s, t, g) else { break };
                let q = (p[0], p[axis]);
                if let Some(a) = prev {
                    fr.segment(c, a, q, colour, 1.5);
                }
                prev = Some(q);
            }
            for (_, p) in &cs[s] {
                if let (Some(x), Some(y)) = (p[0], p[axis]) {
                    c.circle(fr.at(x, y), 2.0, colour, false);
                }
            }
            if let Some(p) = fitted(r, s, tc, g) {
                c.circle(fr.at(p[0], p[axis]), 5.0, BLACK, false);
            }
        }
        c.text(
            (fr.left + fr.w - 10.0, fr.top + 16.0),
            "a",
            Anchor::End,
            BLUE,
        );
        c.text(
            (fr.left + fr.w - 10.0, fr.top + 32.0),
            "b",
            Anchor::End,
            RED,
        );
    }
}

pub fn draw_residuals(c: &mut dyn Canvas, r: &Report, g: f64) {
    let tc = r.impact.time_s.value;
    let mut pts: Vec<(f64, f64, Rgb)> = Vec::new();
    for (s, colour) in [(0, BLUE), (1, RED)] {
        for (t, p) in centres(r, s) {
            let Some(f) = fitted(r, s, t, g) else {
                continue;
            };
            let d2: f64 = (0..3)
                .filter_map(|i| p[i].map(|v| (v - f[i]).powi(2)))
                .sum();
            pts.push(((t - tc) * 1e3, d2.sqrt(), colour));
        }
    }
    let fr = Frame {
        left: 70.0,
        top: 40.0,
        w: 540.0,
        h: 200.0,
        x: range(pts.iter().map(|p| p.0), 0.05),
        y: (0.0, range(pts.iter().map(|p| p.1), 0.1).1),
    };
    fr.axes(
        c,
        "time from impact, ms",
        "mm",
        "distance of each centre from its fitted trajectory",
    );
    for (x, y, colour) in pts {
        c.circle(fr.at(x, y), 2.0, colour, true);
    }
}

/// SVG text and PNG bytes of one figure.
pub fn render(w: usize, h: usize, draw: &dyn Fn(&mut dyn Canvas)) -> (String, Vec<u8>) {
    let mut svg = Svg::new(w as f64, h as f64);
    draw(&mut svg);
    let mut raster = Raster::new(w, h);
    draw(&mut raster);
    (svg.finish(), raster.png().unwrap_or_default())
}

pub fn psi_plot(collisions: &[Collision], f: &CampaignFit) -> (String, Vec<u8>) {
    render(640, 470, &|c| draw_psi(c, collisions, f))
}

pub fn trajectory_plot(r: &Report, g: f64) -> (String, Vec<u8>) {
    render(640, 500, &|c| draw_trajectories(c, r, g))
}

pub fn residual_plot(r: &Report, g: f64) -> (String, Vec<u8>) {
    render(640, 290, &|c| draw_residuals(c, r, g))
}
