//! A dot-grid target's image (`impactcam calibrate --grid`): dark round dots at a known square
//! pitch on a light card in the plane of collision, seen by the direct view. The dots are found
//! (dark components, each centred by its darkness), indexed on their lattice by walking from the
//! dot nearest the view's centre to its neighbours, and one plane-to-image homography and the
//! lens's k1 are fitted to them. Straight rows of dots that the image bends are what the flights
//! cannot show well: the grid gives the lens, and the view's scale as a check on free fall's.

use super::bundle::LensFrame;
use super::Fitted;
use crate::analysis::image::{four_neighbours, GreyImage};
use crate::analysis::AnalysisError;
use nalgebra::{DMatrix, DVector, SMatrix, SVector};
use std::path::Path;

/// What the grid gave.
#[derive(Clone, Copy, Debug)]
pub struct GridFit {
    /// The lens's k1 about the frame's centre, at its half-diagonal (`LensFrame`).
    pub lens_k1: Fitted,
    /// The card's scale at the dot nearest the view's centre, px per mm (the geometric mean of
    /// the two directions).
    pub scale_px_per_mm: Fitted,
    pub dots: usize,
    pub residual_rms_px: f64,
}

/// One dot: its image centre, px.
type Dot = [f64; 2];

/// The grid's image: that one file (a TIFF, PNG or BMP, even if its name is numbered like a
/// sequence's frame), or a session's (or a directory of frames') first frame.
pub(super) fn read_image(path: &Path, frame_rate_hz: f64) -> Result<GreyImage, AnalysisError> {
    let mut img = GreyImage::new();
    if path.is_dir() {
        let mut src = crate::analysis::source::open(path, Some(frame_rate_hz))?;
        if src.is_empty() {
            return Err(AnalysisError::Input {
                source_name: path.display().to_string(),
                message: "no frame in it: expected an image of the dot grid".into(),
            });
        }
        src.read(0, &mut img)?;
    } else {
        let mut raw = Vec::new();
        let (w, h, bpp) =
            crate::footage::read_image(path, &mut raw).map_err(|e| AnalysisError::Input {
                source_name: e.path.display().to_string(),
                message: e.message,
            })?;
        img.load(&raw, w as usize, h as usize, bpp);
    }
    Ok(img)
}

/// The dark components of `region` that do not touch its border, each centred by the weight
/// (light − grey) over its pixels and the ring around them.
fn find_dots(img: &GreyImage, region: [u32; 4]) -> Result<Vec<Dot>, String> {
    let [x0, y0, w, h] = region.map(|x| x as usize);
    let (x1, y1) = ((x0 + w).min(img.width), (y0 + h).min(img.height));
    if x1 <= x0 + 2 || y1 <= y0 + 2 {
        return Err(format!("the region {region:?} is not inside the image"));
    }
    let mut levels: Vec<f32> = (y0..y1)
        .flat_map(|v| (x0..x1).map(move |u| (u, v)))
        .map(|(u, v)| img.at(u, v))
        .collect();
    levels.sort_by(f32::total_cmp);
    let pick = |q: f64| f64::from(levels[((levels.len() - 1) as f64 * q) as usize]);
    let (dark, light) = (pick(0.02), pick(0.9));
    if light - dark < 10.0 {
        return Err(format!(
            "no dots: the region's grey levels span {dark:.0} to {light:.0}, expected dark dots on a light card"
        ));
    }
    let threshold = 0.5 * (dark + light);
    let (rw, rh) = (x1 - x0, y1 - y0);
    let is_dark = |u: usize, v: usize| f64::from(img.at(x0 + u, y0 + v)) < threshold;
    let mut label = vec![usize::MAX; rw * rh];
    let mut dots = Vec::new();
    let max_area = rw * rh / 20;
    for start in 0..rw * rh {
        if label[start] != usize::MAX || !is_dark(start % rw, start / rw) {
            continue;
        }
        let id = start;
        let mut stack = vec![start];
        let mut members = Vec::new();
        label[start] = id;
        let mut touches = false;
        while let Some(k) = stack.pop() {
            members.push(k);
            let (u, v) = (k % rw, k / rw);
            touches |= u == 0 || v == 0 || u + 1 == rw || v + 1 == rh;
            for (nu, nv) in four_neighbours(u, v, rw, rh) {
                let n = nv * rw + nu;
                if label[n] == usize::MAX && is_dark(nu, nv) {
                    label[n] = id;
                    stack.push(n);
                }
            }
        }
        if touches || members.len() < 3 || members.len() > max_area {
            continue;
        }
        // The component and its ring (the rim's partly covered pixels weigh by their darkness).
        let mut seen = std::collections::BTreeSet::new();
        for &k in &members {
            let (u, v) = ((k % rw) as i64, (k / rw) as i64);
            for dv in -1..=1 {
                for du in -1..=1 {
                    let (nu, nv) = (u + du, v + dv);
                    if nu >= 0 && nv >= 0 && (nu as usize) < rw && (nv as usize) < rh {
                        let n = nv as usize * rw + nu as usize;
                        if label[n] == id || label[n] == usize::MAX {
                            seen.insert(n);
                        }
                    }
                }
            }
        }
        let (mut sw, mut su, mut sv) = (0.0, 0.0, 0.0);
        for &k in &seen {
            let (u, v) = (k % rw, k / rw);
            let wgt = (light - f64::from(img.at(x0 + u, y0 + v))).max(0.0);
            sw += wgt;
            su += wgt * (x0 + u) as f64;
            sv += wgt * (y0 + v) as f64;
        }
        if sw > 0.0 {
            dots.push([su / sw, sv / sw]);
        }
    }
    Ok(dots)
}

/// Each dot's lattice index (i along the image's u, j along v), found by walking from the dot
/// nearest `centre` to neighbours one local step away; dots the walk does not reach are left
/// out. Returns (index, dot) pairs.
fn index_lattice(dots: &[Dot], centre: [f64; 2]) -> Result<Vec<([i64; 2], Dot)>, String> {
    let d2 = |a: &Dot, b: &Dot| (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2);
    let seed = (0..dots.len())
        .min_by(|&a, &b| d2(&dots[a], &centre).total_cmp(&d2(&dots[b], &centre)))
        .ok_or("no dots found")?;
    let p0 = dots[seed];
    let nearest = (0..dots.len())
        .filter(|&k| k != seed)
        .map(|k| d2(&dots[k], &p0).sqrt())
        .fold(f64::INFINITY, f64::min);
    if !nearest.is_finite() {
        return Err("only one dot found".into());
    }
    // The two lattice steps: the neighbours (within 1.4 spacings) most along u and most along v.
    let near: Vec<[f64; 2]> = dots
        .iter()
        .map(|q| [q[0] - p0[0], q[1] - p0[1]])
        .filter(|o| {
            let r = o[0].hypot(o[1]);
            r > 0.5 * nearest && r < 1.4 * nearest
        })
        .collect();
    let along = |axis: usize| {
        near.iter()
            .filter(|o| o[axis] > 0.0)
            .max_by(|a, b| (a[axis] / a[0].hypot(a[1])).total_cmp(&(b[axis] / b[0].hypot(b[1]))))
            .copied()
    };
    let (Some(a1), Some(a2)) = (along(0), along(1)) else {
        return Err("the dots nearest the view's centre do not form a square lattice".into());
    };
    let mut index: Vec<Option<[i64; 2]>> = vec![None; dots.len()];
    let mut taken = std::collections::HashMap::new();
    index[seed] = Some([0, 0]);
    taken.insert([0i64, 0i64], seed);
    let mut queue = std::collections::VecDeque::from([(seed, a1, a2)]);
    while let Some((k, b1, b2)) = queue.pop_front() {
        let Some([i, j]) = index[k] else { continue };
        for (step, di, dj) in [
            (b1, 1, 0),
            (b2, 0, 1),
            ([-b1[0], -b1[1]], -1, 0),
            ([-b2[0], -b2[1]], 0, -1),
        ] {
            let want = [i + di, j + dj];
            if taken.contains_key(&want) {
                continue;
            }
            let guess = [dots[k][0] + step[0], dots[k][1] + step[1]];
            let r = 0.3 * step[0].hypot(step[1]);
            let Some(n) = (0..dots.len())
                .filter(|&n| d2(&dots[n], &guess) < r * r)
                .min_by(|&a, &b| d2(&dots[a], &guess).total_cmp(&d2(&dots[b], &guess)))
            else {
                continue;
            };
            if index[n].is_some() {
                continue;
            }
            index[n] = Some(want);
            taken.insert(want, n);
            // The step as found here carries on (the lens and perspective bend it slowly).
            let found = [dots[n][0] - dots[k][0], dots[n][1] - dots[k][1]];
            let sign = (di + dj) as f64;
            let (n1, n2) = if di != 0 {
                ([sign * found[0], sign * found[1]], b2)
            } else {
                (b1, [sign * found[0], sign * found[1]])
            };
            queue.push_back((n, n1, n2));
        }
    }
    Ok(index
        .into_iter()
        .zip(dots)
        .filter_map(|(i, d)| i.map(|i| (i, *d)))
        .collect())
}

/// The model: a card point (i, j) in pitches, through the homography H (h33 = 1, eight
/// parameters) to an ideal image point in the frame's normalised coordinates ((p − c)/R), and
/// through the lens (the ninth parameter, k1).
fn model(th: &SVector<f64, 9>, ij: [f64; 2]) -> [f64; 2] {
    let w = th[6] * ij[0] + th[7] * ij[1] + 1.0;
    let x = (th[0] * ij[0] + th[1] * ij[1] + th[2]) / w;
    let y = (th[3] * ij[0] + th[4] * ij[1] + th[5]) / w;
    let f = 1.0 + th[8] * (x * x + y * y);
    [x * f, y * f]
}

/// Fits the grid in `img` seen in `region`, dots `pitch_mm` apart.
pub(super) fn fit_grid(
    img: &GreyImage,
    region: [u32; 4],
    pitch_mm: f64,
    frame: LensFrame,
) -> Result<GridFit, String> {
    let dots = find_dots(img, region)?;
    let [x, y, w, h] = region.map(f64::from);
    let centre = [x + 0.5 * w - 0.5, y + 0.5 * h - 0.5];
    let lattice = index_lattice(&dots, centre)?;
    if lattice.len() < 20 {
        return Err(format!(
            "{} dots found on one lattice ({} dark spots in all): a grid needs 20 or more",
            lattice.len(),
            dots.len()
        ));
    }
    let (c, r) = (frame.centre_px, frame.radius_px);
    let pts: Vec<([f64; 2], [f64; 2])> = lattice
        .iter()
        .map(|(ij, d)| {
            (
                [ij[0] as f64, ij[1] as f64],
                [(d[0] - c[0]) / r, (d[1] - c[1]) / r],
            )
        })
        .collect();
    // A start from the affine map through the dots (least squares), no lens.
    let mut ata = SMatrix::<f64, 3, 3>::zeros();
    let mut atb = SMatrix::<f64, 3, 2>::zeros();
    for (ij, q) in &pts {
        let a = SVector::<f64, 3>::new(ij[0], ij[1], 1.0);
        ata += a * a.transpose();
        atb += a * SMatrix::<f64, 1, 2>::new(q[0], q[1]);
    }
    let aff = ata.try_inverse().ok_or("the dots lie on one line")? * atb;
    let mut th = SVector::<f64, 9>::from_column_slice(&[
        aff[(0, 0)],
        aff[(1, 0)],
        aff[(2, 0)],
        aff[(0, 1)],
        aff[(1, 1)],
        aff[(2, 1)],
        0.0,
        0.0,
        0.0,
    ]);
    let mut keep = vec![true; pts.len()];
    let residuals = |th: &SVector<f64, 9>, keep: &[bool]| -> DVector<f64> {
        let mut out = DVector::zeros(2 * pts.len());
        for (k, (ij, q)) in pts.iter().enumerate() {
            if keep[k] {
                let m = model(th, *ij);
                out[2 * k] = r * (q[0] - m[0]);
                out[2 * k + 1] = r * (q[1] - m[1]);
            }
        }
        out
    };
    let jacobian = |th: &SVector<f64, 9>, keep: &[bool], r0: &DVector<f64>| {
        let mut jac = DMatrix::zeros(r0.len(), 9);
        for c in 0..9 {
            let step = 1e-7 * th[c].abs().max(1e-3);
            let mut t = *th;
            t[c] += step;
            jac.set_column(c, &((residuals(&t, keep) - r0) / step));
        }
        jac
    };
    for _round in 0..3 {
        let mut lambda = 1e-4;
        for _ in 0..100 {
            let r0 = residuals(&th, &keep);
            let cost = r0.norm_squared();
            let jac = jacobian(&th, &keep, &r0);
            let a = jac.transpose() * &jac;
            let g = jac.transpose() * &r0;
            let mut moved = false;
            while lambda < 1e10 {
                let mut damped = a.clone();
                for d in 0..9 {
                    damped[(d, d)] += lambda * a[(d, d)].max(1e-12);
                }
                if let Some(inv) = damped.try_inverse() {
                    let step = -(inv * &g);
                    let trial = th + SVector::<f64, 9>::from_iterator(step.iter().copied());
                    if residuals(&trial, &keep).norm_squared() < cost {
                        th = trial;
                        lambda = (lambda * 0.1).max(1e-12);
                        moved = step.amax() > 1e-13;
                        break;
                    }
                }
                lambda *= 10.0;
            }
            if !moved {
                break;
            }
        }
        // Dots beyond 5σ (a speck of dust read as a dot, a dot cut by the card's edge) are left
        // out and the fit repeated.
        let r0 = residuals(&th, &keep);
        let n = keep.iter().filter(|k| **k).count();
        let sigma = (r0.norm_squared() / (2 * n).saturating_sub(9).max(1) as f64).sqrt();
        let mut changed = false;
        for (k, kk) in keep.iter_mut().enumerate() {
            if *kk && r0[2 * k].hypot(r0[2 * k + 1]) > 5.0 * sigma.max(0.01) {
                *kk = false;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    let r0 = residuals(&th, &keep);
    let n = keep.iter().filter(|k| **k).count();
    let dof = (2 * n).saturating_sub(9).max(1) as f64;
    let s2 = r0.norm_squared() / dof;
    let jac = jacobian(&th, &keep, &r0);
    let cov = (jac.transpose() * &jac)
        .try_inverse()
        .ok_or("the grid's fit is degenerate")?
        * s2;
    // The scale at the seed dot (i, j = 0): √|det ∂(u, v)/∂(x, y)|, px per mm, before the lens.
    let scale = |th: &SVector<f64, 9>| {
        let d = th[0] * th[4] - th[1] * th[3] - th[2] * (th[6] * th[4] - th[7] * th[3])
            + th[5] * (th[6] * th[1] - th[7] * th[0]);
        r * d.abs().sqrt() / pitch_mm
    };
    let s = scale(&th);
    let mut grad = DVector::zeros(9);
    for c in 0..9 {
        let step = 1e-7 * th[c].abs().max(1e-3);
        let mut t = th;
        t[c] += step;
        grad[c] = (scale(&t) - s) / step;
    }
    let scale_sigma = (grad.transpose() * &cov * &grad)[(0, 0)].max(0.0).sqrt();
    Ok(GridFit {
        lens_k1: Fitted {
            value: th[8],
            sigma: cov[(8, 8)].max(0.0).sqrt(),
        },
        scale_px_per_mm: Fitted {
            value: s,
            sigma: scale_sigma,
        },
        dots: n,
        residual_rms_px: (r0.norm_squared() / (2 * n).max(1) as f64).sqrt(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The direct view of the thesis rig (2.1576 px/mm), rolled by 1°, optionally seen through a
    /// pinhole 300 mm away pitched by 2°, and through a lens of `k1`.
    fn view(k1: f64, perspective: bool) -> hw_sim::ViewSpec {
        let mut direct =
            crate::analysis::geometry::views(&crate::config::Config::default_config()).remove(0);
        direct.lens = (k1 != 0.0).then(|| LensFrame::of_frame(240, 192).lens(k1));
        let mut v = crate::analysis::geometry::sim_view(&direct);
        v.distance_mm = perspective.then_some(300.0);
        if perspective {
            v.turn_about_x(2f64.to_radians());
        }
        v.roll_about([119.5, 95.5], 1f64.to_radians());
        v
    }

    /// A 4 mm grid of 1.5 mm dots drawn by hw-sim through the view (σ = 2 read noise): the fit
    /// gives the lens's k1 within 0.002 and within 4σ, and the scale within 0.3 % and 4σ of the
    /// map's at the dot nearest the view's centre; with no lens, k1 within 4σ of 0. A frame with
    /// no dots is refused with a reason.
    #[test]
    fn a_dot_grid_gives_the_lens_and_the_scale() {
        let frame = LensFrame::of_frame(240, 192);
        let target = hw_sim::GridTarget {
            pitch_mm: 4.0,
            dot_diameter_mm: 1.5,
            paper_grey: 200.0,
            dot_grey: 30.0,
            noise_sigma_grey: 2.0,
            seed: 3,
        };
        for (k1, perspective) in [(-0.03, false), (0.02, true), (0.0, false)] {
            let v = view(k1, perspective);
            let raw = hw_sim::render_grid(&v, 240, 192, &target);
            let mut img = GreyImage::new();
            img.load(&raw, 240, 192, 1);
            let fit = fit_grid(&img, [0, 0, 240, 96], target.pitch_mm, frame)
                .unwrap_or_else(|e| panic!("k1 {k1}: {e}"));
            let case = format!("k1 {k1}, perspective {perspective}: {fit:?}");
            assert!(fit.dots > 80, "{case}");
            let dk = fit.lens_k1.value - k1;
            assert!(
                dk.abs() < 0.002 && dk.abs() < 4.0 * fit.lens_k1.sigma,
                "{case}"
            );
            // Under perspective the scale at the central dot is the pinhole's there (the card
            // at z = 0, the dot at about y = −20 mm, nearer the pitched camera or farther).
            if !perspective {
                let ds = fit.scale_px_per_mm.value - 2.1576;
                assert!(
                    ds.abs() < 0.003 * 2.1576 && ds.abs() < 4.0 * fit.scale_px_per_mm.sigma,
                    "{case}"
                );
            }
            assert!(fit.residual_rms_px < 0.1, "{case}");
        }
        let blank = GreyImage {
            width: 240,
            height: 192,
            data: vec![120.0; 240 * 192],
            ..GreyImage::new()
        };
        let e = fit_grid(&blank, [0, 0, 240, 96], 4.0, frame).unwrap_err();
        assert!(e.contains("no dots"), "{e}");
    }
}
