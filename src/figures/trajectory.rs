//! Per-experiment figures from a report: the trajectories in both views (measured centres,
//! fitted ballistic paths, the impact marked) and the fit residuals against time.

use super::canvas::{Anchor, Canvas, Rgb};
use super::{range, render, Frame, BLACK, BLUE, RED};
use crate::analysis::report::Report;

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

pub fn trajectory_plot(r: &Report, g: f64) -> (String, Vec<u8>) {
    render(640, 500, &|c| draw_trajectories(c, r, g))
}

pub fn residual_plot(r: &Report, g: f64) -> (String, Vec<u8>) {
    render(640, 290, &|c| draw_residuals(c, r, g))
}
