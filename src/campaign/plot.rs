//! The campaign's figure: ψ2 against ψ1, each collision with error bars, both fitted Walton
//! lines and the break point (drawn with `figures`).

use super::fit::{CampaignFit, Collision};
use crate::figures::canvas::{Anchor, Canvas};
use crate::figures::{range, render, Frame, BLACK, BLUE, GREY, ORANGE, RED};

pub fn draw_psi(c: &mut dyn Canvas, collisions: &[Collision], f: &CampaignFit) {
    let pts: Vec<(f64, f64, f64, f64, bool)> = collisions
        .iter()
        .filter_map(|c| {
            let (x, y, sx, sy) = c.psi_point()?;
            Some((x, y, sx, sy, c.outlier))
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

/// The ψ2–ψ1 figure as (SVG text, PNG bytes).
pub fn psi_plot(collisions: &[Collision], f: &CampaignFit) -> (String, Vec<u8>) {
    render(640, 470, &|c| draw_psi(c, collisions, f))
}
