//! The sphere's own shading under its markers, fitted to the disc's pixels: what a dot's
//! darkness and coverage are measured against.

use super::super::geometry::View;
use super::super::image::GreyImage;

/// The sphere's own shading under its markers: grey = a + b·n + c·n² + d·x + f·y, with n the
/// surface normal's component towards the camera (√(1 − ρ²/R²)) and x, y the image offsets over
/// R (light from one side). Fitted to the disc's pixels by least squares, dropping pixels far
/// below the fit (markers) and repeating. A ring-by-ring median failed at the middle of the disc,
/// where a ring holds a pixel or two and a dot there is the whole ring.
pub(super) struct Shading {
    centre: [f64; 2],
    radius: f64,
    p: nalgebra::SVector<f64, 5>,
    /// The robust scatter of the disc's pixels about the fit (floored at 0.5 grey level).
    pub(super) sigma: f64,
}

impl Shading {
    fn basis(&self, u: f64, v: f64) -> nalgebra::SVector<f64, 5> {
        Self::basis_of(self.centre, self.radius, u, v)
    }

    fn basis_of(centre: [f64; 2], radius: f64, u: f64, v: f64) -> nalgebra::SVector<f64, 5> {
        let (x, y) = ((u - centre[0]) / radius, (v - centre[1]) / radius);
        let n = (1.0 - (x * x + y * y)).max(0.0).sqrt();
        nalgebra::SVector::<f64, 5>::new(1.0, n, n * n, x, y)
    }

    pub(super) fn at(&self, u: f64, v: f64) -> f64 {
        self.basis(u, v).dot(&self.p)
    }

    pub(super) fn fit(
        img: &GreyImage,
        view: &View,
        centre: [f64; 2],
        radius: f64,
        within: f64,
        noise_sigma: f64,
    ) -> Option<Shading> {
        let [u0, u1, v0, v1] = img.box_around(centre, within);
        let mut pix: Vec<(nalgebra::SVector<f64, 5>, f64)> = Vec::new();
        for v in v0..=v1 {
            for u in u0..=u1 {
                let (fu, fv) = (u as f64, v as f64);
                // (An overexposed pixel says only that the shading is at least its level.)
                if (fu - centre[0]).hypot(fv - centre[1]) < within
                    && view.contains(fu, fv)
                    && !img.unmeasured_at(u, v)
                {
                    pix.push((
                        Self::basis_of(centre, radius, fu, fv),
                        img.lit_at(u, v) as f64,
                    ));
                }
            }
        }
        let mut keep = vec![true; pix.len()];
        let mut p = None;
        let mut own_sigma = noise_sigma;
        for _ in 0..4 {
            let mut ata = nalgebra::SMatrix::<f64, 5, 5>::zeros();
            let mut atb = nalgebra::SVector::<f64, 5>::zeros();
            let mut n = 0;
            for ((a, b), k) in pix.iter().zip(&keep) {
                if *k {
                    ata += a * a.transpose();
                    atb += a * *b;
                    n += 1;
                }
            }
            if n < 12 {
                return None;
            }
            let sol = ata.lu().solve(&atb)?;
            let res: Vec<f64> = pix.iter().map(|(a, b)| b - a.dot(&sol)).collect();
            let mut abs: Vec<f64> = res
                .iter()
                .zip(&keep)
                .filter(|(_, k)| **k)
                .map(|(r, _)| r.abs())
                .collect();
            abs.sort_by(f64::total_cmp);
            own_sigma = (1.4826 * abs[abs.len() / 2]).max(0.5);
            let sigma = own_sigma.max(noise_sigma);
            let changed = res
                .iter()
                .zip(keep.iter_mut())
                .fold(false, |changed, (r, k)| {
                    let new = *r > -3.0 * sigma && *r < 5.0 * sigma;
                    let c = new != *k;
                    *k = new;
                    changed || c
                });
            p = Some(sol);
            if !changed {
                break;
            }
        }
        Some(Shading {
            centre,
            radius,
            p: p?,
            sigma: own_sigma,
        })
    }
}
