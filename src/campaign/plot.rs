//! The ψ2-against-ψ1 plot as SVG: each collision with its error bars, both fitted Walton lines
//! and the break point. Written by hand: a dozen elements do not need a plotting library.

use super::fit::{CampaignFit, Collision};
use std::fmt::Write as _;

pub fn psi_plot(collisions: &[Collision], f: &CampaignFit) -> String {
    let (w, h, m) = (640.0, 480.0, 60.0);
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
    let y_min = pts.iter().map(|p| p.1 - p.3).fold(-0.2, f64::min) * 1.1;
    let y_max = pts.iter().map(|p| p.1 + p.3).fold(0.2, f64::max) * 1.1;
    let sx = |x: f64| m + (x / x_max) * (w - 1.5 * m);
    let sy = |y: f64| h - m - (y - y_min) / (y_max - y_min) * (h - 1.5 * m);
    let mut s = format!("<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" viewBox=\"0 0 {w} {h}\" font-family=\"sans-serif\" font-size=\"12\">\n");
    let _ = writeln!(s, "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>");
    let _ = writeln!(
        s,
        "<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"black\"/>",
        sx(0.0),
        sy(0.0),
        sx(x_max),
        sy(0.0)
    );
    let _ = writeln!(
        s,
        "<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"black\"/>",
        sx(0.0),
        sy(y_min),
        sx(0.0),
        sy(y_max)
    );
    for k in 0..=5 {
        let x = x_max * k as f64 / 5.0;
        let _ = writeln!(
            s,
            "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">{x:.2}</text>",
            sx(x),
            h - m + 18.0
        );
        let y = y_min + (y_max - y_min) * k as f64 / 5.0;
        let _ = writeln!(
            s,
            "<text x=\"{}\" y=\"{}\" text-anchor=\"end\">{y:.2}</text>",
            m - 6.0,
            sy(y) + 4.0
        );
    }
    let _ = writeln!(
        s,
        "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">ψ1 = |g_t| / |g_n| (before)</text>",
        w / 2.0,
        h - 16.0
    );
    let _ = writeln!(s, "<text x=\"16\" y=\"{}\" transform=\"rotate(-90 16 {})\" text-anchor=\"middle\">ψ2 = g_t′·t / |g_n| (after)</text>", h / 2.0, h / 2.0);
    if let (Some(b0), Some(brk)) = (&f.beta0, &f.psi1_break) {
        let (b0, brk) = (b0.value, brk.value);
        let c = brk * (1.0 + b0);
        let _ = writeln!(
            s,
            "<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"#1f77b4\" stroke-width=\"2\"/>",
            sx(0.0),
            sy(0.0),
            sx(brk),
            sy(-b0 * brk)
        );
        let _ = writeln!(
            s,
            "<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"#d62728\" stroke-width=\"2\"/>",
            sx(brk),
            sy(brk - c),
            sx(x_max),
            sy(x_max - c)
        );
        let _ = writeln!(
            s,
            "<circle cx=\"{}\" cy=\"{}\" r=\"5\" fill=\"none\" stroke=\"black\"/>",
            sx(brk),
            sy(-b0 * brk)
        );
        let _ = writeln!(
            s,
            "<text x=\"{}\" y=\"{}\">ψ1* = {brk:.3}</text>",
            sx(brk) + 8.0,
            sy(-b0 * brk) + 16.0
        );
        let _ = writeln!(
            s,
            "<text x=\"{}\" y=\"{}\" fill=\"#1f77b4\">sticking: ψ2 = −β0 ψ1</text>",
            m + 10.0,
            m
        );
        let _ = writeln!(
            s,
            "<text x=\"{}\" y=\"{}\" fill=\"#d62728\">sliding: ψ2 = ψ1 − 7/2 μ (1 + e)</text>",
            m + 10.0,
            m + 16.0
        );
    }
    for (x, y, ex, ey, outlier) in &pts {
        let colour = if *outlier { "#ff7f0e" } else { "black" };
        let _ = writeln!(
            s,
            "<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"{colour}\"/>",
            sx(x - ex),
            sy(*y),
            sx(x + ex),
            sy(*y)
        );
        let _ = writeln!(
            s,
            "<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"{colour}\"/>",
            sx(*x),
            sy(y - ey),
            sx(*x),
            sy(y + ey)
        );
        let _ = writeln!(
            s,
            "<circle cx=\"{}\" cy=\"{}\" r=\"3\" fill=\"{colour}\"/>",
            sx(*x),
            sy(*y)
        );
    }
    s.push_str("</svg>\n");
    s
}
