//! A dot-grid calibration target as a view records it: a flat card through the world origin in
//! the x–y plane (the plane of collision, where the direct view looks), dark round dots of a
//! given diameter at a square pitch on a light ground, drawn through the view's exact map (its
//! projection under perspective) and its lens. What `impactcam calibrate --grid` reads.

use crate::config::ViewSpec;
use crate::Rng;

/// The target and how it is lit.
#[derive(Clone, Copy, Debug)]
pub struct GridTarget {
    pub pitch_mm: f64,
    pub dot_diameter_mm: f64,
    pub paper_grey: f64,
    pub dot_grey: f64,
    pub noise_sigma_grey: f64,
    pub seed: u64,
}

/// The 3×3 map from the target's (x, y, 1), mm, to the view's ideal homogeneous image point:
/// the projection's columns for x, y and 1 (z = 0 on the card), or the affine map's.
fn card_to_image(view: &ViewSpec) -> [[f64; 3]; 3] {
    match view.projection() {
        Some(p) => [0, 1, 2].map(|r| [p[r][0], p[r][1], p[r][3]]),
        None => {
            let m = view.matrix_px_per_mm();
            [
                [m[0][0], m[0][1], view.origin_px[0]],
                [m[1][0], m[1][1], view.origin_px[1]],
                [0.0, 0.0, 1.0],
            ]
        }
    }
}

fn inverse3(m: &[[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let c = |r: usize, k: usize| {
        let (r1, r2) = ((r + 1) % 3, (r + 2) % 3);
        let (k1, k2) = ((k + 1) % 3, (k + 2) % 3);
        m[r1][k1] * m[r2][k2] - m[r1][k2] * m[r2][k1]
    };
    let det = m[0][0] * c(0, 0) + m[0][1] * c(0, 1) + m[0][2] * c(0, 2);
    if det.abs() < 1e-12 {
        return None;
    }
    // inverse = adjugate / det; adj[k][r] = cofactor(r, k).
    Some([0, 1, 2].map(|k| [0, 1, 2].map(|r| c(r, k) / det)))
}

/// The frame (8-bit, row-major, `width`×`height`) with the card filling `view`'s region and the
/// rest of the frame left at 0. Each pixel averages 8×8 samples, each taken back through the
/// lens and the map onto the card; then Gaussian read noise.
pub fn render_grid(view: &ViewSpec, width: u32, height: u32, target: &GridTarget) -> Vec<u8> {
    let (w, h) = (width as usize, height as usize);
    let mut out = vec![0u8; w * h];
    let Some(inv) = inverse3(&card_to_image(view)) else {
        return out;
    };
    let mut rng = Rng::new(target.seed);
    let r2 = (0.5 * target.dot_diameter_mm).powi(2);
    let p = target.pitch_mm;
    const N: usize = 8;
    let [x0, y0, rw, rh] = view.region.map(|x| x as usize);
    for v in y0..(y0 + rh).min(h) {
        for u in x0..(x0 + rw).min(w) {
            let mut dark = 0usize;
            for sv in 0..N {
                for su in 0..N {
                    let rec = (
                        u as f64 - 0.5 + (su as f64 + 0.5) / N as f64,
                        v as f64 - 0.5 + (sv as f64 + 0.5) / N as f64,
                    );
                    let (iu, iv) = match &view.lens {
                        Some(lens) => lens.undistort(rec.0, rec.1),
                        None => rec,
                    };
                    let q = [0, 1, 2].map(|r| inv[r][0] * iu + inv[r][1] * iv + inv[r][2]);
                    let (x, y) = (q[0] / q[2], q[1] / q[2]);
                    let (dx, dy) = (x - p * (x / p).round(), y - p * (y / p).round());
                    if dx * dx + dy * dy < r2 {
                        dark += 1;
                    }
                }
            }
            let cover = dark as f64 / (N * N) as f64;
            let grey = target.paper_grey * (1.0 - cover)
                + target.dot_grey * cover
                + target.noise_sigma_grey * rng.gaussian();
            out[v * w + u] = grey.round().clamp(0.0, 255.0) as u8;
        }
    }
    out
}
