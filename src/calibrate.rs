//! `impactcam calibrate`: each view's map found from a recording of a collision, knowing only
//! the spheres' diameter, the frame rate and g. The recording is analysed once with the
//! config's provisional geometry (its regions, rough scales and the mirror's flips); then
//!
//! - the direct view's scale comes from free fall (the parabola's acceleration in px/s² over g)
//!   and from the imaged diameter, and its roll from the image direction of gravity;
//! - the mirror view's scale, roll and tilt (the view turned about x, which puts world y into its
//!   image) from the x both views share and from free fall: a least-squares fit of its image
//!   positions against the direct view's x and y, with each flight's z a straight line in time.
//!
//! What the data cannot give is kept from the config: the world origin (the direct view's
//! `origin_px`, and the mirror's v offset, which sets z = 0), the regions, and the sign of z in
//! the mirror (which side of the collision the mirror is on).

use crate::analysis::geometry::{View, ViewKind, V3};
use crate::analysis::tracking::FrameObs;
use crate::analysis::{self, AnalysisError, FrameSource};
use crate::config::{Config, ViewGeometry};
use nalgebra::{DMatrix, DVector};

/// A fitted parameter and its standard deviation.
#[derive(Clone, Copy, Debug)]
pub struct Fitted {
    pub value: f64,
    pub sigma: f64,
}

/// The direct view as found.
#[derive(Clone, Debug)]
pub struct DirectFit {
    pub scale_from_free_fall: Fitted,
    pub scale_from_diameter: Fitted,
    /// From both views' flights fitted together, g known (the one used: the imaged edge's
    /// position depends on the light, free fall does not; the diameter's is the check).
    pub scale: Fitted,
    /// Image direction of gravity away from straight down, deg (positive: towards +u).
    pub roll_deg: Fitted,
    pub residual_rms_px: f64,
}

/// The mirror view as found.
#[derive(Clone, Debug)]
pub struct MirrorFit {
    pub scale: Fitted,
    pub scale_from_diameter: Fitted,
    /// Rotation of the mirror view's image, deg.
    pub roll_deg: Fitted,
    /// The mirror view turned about world x, deg (twice the mirror's own tilt from 45°).
    pub tilt_deg: Fitted,
    /// Image u of the world origin, px.
    pub origin_u_px: Fitted,
    /// Whether the mirror shows world x reversed (u decreasing with x).
    pub x_reversed: bool,
    pub residual_rms_px: f64,
    pub points: usize,
}

#[derive(Clone, Debug)]
pub struct Calibrated {
    pub source: String,
    pub frames: usize,
    /// The frame nearest the impact (drawn in the PNG).
    pub impact_frame: usize,
    pub direct: DirectFit,
    pub mirror: Option<MirrorFit>,
    pub geometry: crate::config::Geometry,
}

#[derive(Debug, thiserror::Error)]
pub enum CalibrateError {
    #[error("{source_name}: calibrate needs a [geometry.direct] view in the config (its region at least) to start from")]
    NoDirectView { source_name: String },
    #[error("{source_name}: the recording could not be analysed with the provisional geometry, so nothing can be fitted: {cause}")]
    Provisional {
        source_name: String,
        cause: AnalysisError,
    },
    #[error("{source_name}: {message}")]
    Data {
        source_name: String,
        message: String,
    },
}

/// Calibrates from a session or a TIFF stack: with `cfg`, else a session's own config, else the
/// embedded default (the thesis's layout). Returns the fit and a PNG of the frame nearest the
/// impact with the regions and axes drawn.
pub fn calibrate_path(
    path: &std::path::Path,
    cfg: Option<&Config>,
) -> Result<(Calibrated, Vec<u8>), crate::experiment::ExperimentError> {
    let mut src = analysis::source::open(path, cfg.map(|c| c.camera.frame_rate_hz))?;
    let cfg = match cfg {
        Some(c) => c.clone(),
        None => src
            .recorded_config()
            .cloned()
            .unwrap_or_else(Config::default_config),
    };
    let cal = calibrate(src.as_mut(), &cfg).map_err(|e| AnalysisError::Input {
        source_name: path.display().to_string(),
        message: e.to_string(),
    })?;
    let mut img = analysis::image::GreyImage::new();
    src.read(cal.impact_frame, &mut img)?;
    let png = cal.png(&img).map_err(|message| AnalysisError::Input {
        source_name: path.display().to_string(),
        message,
    })?;
    Ok((cal, png))
}

/// Fits the views' maps from one recording.
pub fn calibrate(src: &mut dyn FrameSource, cfg: &Config) -> Result<Calibrated, CalibrateError> {
    let name = src.source().name;
    let data = |message: String| CalibrateError::Data {
        source_name: name.clone(),
        message,
    };
    let Some(direct_cfg) = cfg.geometry.direct.clone() else {
        return Err(CalibrateError::NoDirectView { source_name: name });
    };
    let (_, details) = analysis::analyze_detailed(src, cfg, &mut |_, _| {}).map_err(|cause| {
        CalibrateError::Provisional {
            source_name: name.clone(),
            cause,
        }
    })?;
    let views = &details.views;
    let obs = &details.obs;
    let g = cfg.analysis.gravity_mm_s2;
    let diam = [cfg.spheres.sphere(0).0, cfg.spheres.sphere(1).0];
    let di = views
        .iter()
        .position(|v| v.kind == ViewKind::Direct)
        .ok_or_else(|| data("no direct view".into()))?;

    // Direct view: free fall per flight, pooled.
    let mut acc = Vec::new();
    for (k, frames) in details.phases.iter().enumerate() {
        let pts: Vec<(f64, [f64; 2])> = frames
            .iter()
            .filter_map(|&i| Some((obs[i].time_s, obs[i].spheres[k % 2][di].as_ref()?.centre_px)))
            .collect();
        if let Some(a) = parabola_acceleration(&pts) {
            acc.push(a);
        }
    }
    if acc.is_empty() {
        return Err(data(
            "no flight of 6 frames or more in the direct view: free fall cannot be measured".into(),
        ));
    }
    let (mut w, mut au, mut av) = (0.0, 0.0, 0.0);
    for (a, s) in &acc {
        let wk = 1.0 / (s * s);
        w += wk;
        au += wk * a[0];
        av += wk * a[1];
    }
    let (au, av, sa) = (au / w, av / w, w.recip().sqrt());
    let a_norm = au.hypot(av);
    let scale_from_free_fall = Fitted {
        value: a_norm / g,
        sigma: sa / g,
    };
    let roll_deg = Fitted {
        value: au.atan2(av).to_degrees(),
        sigma: (sa / a_norm).to_degrees(),
    };
    let scale_from_diameter = diameter_scale(obs, di, diam)
        .ok_or_else(|| data("no sphere diameter measured in the direct view".into()))?;
    let origin_direct = direct_cfg
        .local_affine()
        .map(|(_, o)| o)
        .ok_or_else(|| data("the direct view's provisional map is incomplete".into()))?;
    let mi = views.iter().position(|v| v.kind == ViewKind::Mirror);
    let bundle = fit_bundle(
        obs,
        &details.phases,
        g,
        di,
        mi,
        origin_direct,
        (scale_from_free_fall.value, roll_deg.value.to_radians()),
        mi.map(|i| &views[i]),
    )
    .map_err(&data)?;
    let m_direct = direct_matrix(
        bundle.direct_scale.value,
        bundle.direct_roll.value.to_radians(),
    );
    let mut geometry = crate::config::Geometry {
        direct: Some(ViewGeometry::affine(
            direct_cfg.region,
            m_direct,
            origin_direct,
        )),
        mirror: None,
    };
    let mut mirror = None;
    if let (Some(mi), Some(mut fit)) = (mi, bundle.mirror) {
        let region = cfg
            .geometry
            .mirror
            .as_ref()
            .map(|m| m.region)
            .unwrap_or(views[mi].region);
        let f = z_sign(&views[mi]);
        let sx = if fit.x_reversed { -1.0 } else { 1.0 };
        let m = mirror_matrix(
            fit.scale.value,
            fit.roll_deg.value.to_radians(),
            fit.tilt_deg.value.to_radians(),
            sx,
            f,
        );
        let origin = [fit.origin_u_px.value, views[mi].origin_px[1]];
        geometry.mirror = Some(ViewGeometry::affine(region, m, origin));
        if let Some(d) = diameter_scale(obs, mi, diam) {
            fit.scale_from_diameter = d;
        }
        mirror = Some(fit);
    }
    Ok(Calibrated {
        source: name,
        frames: obs.len(),
        impact_frame: obs
            .iter()
            .enumerate()
            .min_by(|a, b| {
                (a.1.time_s - details.impact_time_s)
                    .abs()
                    .total_cmp(&(b.1.time_s - details.impact_time_s).abs())
            })
            .map(|(i, _)| i)
            .unwrap_or(0),
        direct: DirectFit {
            scale_from_free_fall,
            scale_from_diameter,
            scale: bundle.direct_scale,
            roll_deg: bundle.direct_roll,
            residual_rms_px: bundle.residual_rms_px[0],
        },
        mirror,
        geometry,
    })
}

/// The sign with which world z shows along the mirror's v (from the provisional map: which side
/// of the collision the mirror is on, which spheres alone cannot tell).
fn z_sign(view: &View) -> f64 {
    if view.v_axis.z < 0.0 {
        -1.0
    } else {
        1.0
    }
}

/// M = s·R(φ)·[[sx, 0, 0], [0, f·sin τ, f·cos τ]], R(φ) = [[cos, −sin], [sin, cos]].
fn mirror_matrix(s: f64, phi: f64, tau: f64, sx: f64, f: f64) -> [[f64; 3]; 2] {
    let (sp, cp) = phi.sin_cos();
    let (st, ct) = tau.sin_cos();
    let col_x = [s * cp * sx, s * sp * sx];
    let zeta = [-s * sp * f, s * cp * f]; // image of the turned depth axis
    [
        [col_x[0], zeta[0] * st, zeta[0] * ct],
        [col_x[1], zeta[1] * st, zeta[1] * ct],
    ]
}

/// Median imaged diameter over the true one, px/mm, with σ from the spread.
fn diameter_scale(obs: &[FrameObs], vi: usize, diam_mm: [f64; 2]) -> Option<Fitted> {
    let mut r: Vec<f64> = obs
        .iter()
        .flat_map(|f| {
            (0..2).filter_map(move |s| Some(f.spheres[s][vi].as_ref()?.diameter_px / diam_mm[s]))
        })
        .filter(|x| x.is_finite() && *x > 0.0)
        .collect();
    if r.len() < 3 {
        return None;
    }
    r.sort_by(f64::total_cmp);
    let med = r[r.len() / 2];
    let mut dev: Vec<f64> = r.iter().map(|x| (x - med).abs()).collect();
    dev.sort_by(f64::total_cmp);
    Some(Fitted {
        value: med,
        sigma: 1.4826 * dev[dev.len() / 2] * (std::f64::consts::PI / 2.0 / r.len() as f64).sqrt(),
    })
}

/// Acceleration (u, v) of a parabola through image points over time, px/s², and its σ per
/// component; None under 6 points.
fn parabola_acceleration(pts: &[(f64, [f64; 2])]) -> Option<([f64; 2], f64)> {
    if pts.len() < 6 {
        return None;
    }
    let t0 = pts.iter().map(|p| p.0).sum::<f64>() / pts.len() as f64;
    let mut ata = nalgebra::Matrix3::<f64>::zeros();
    let mut atb = [V3::zeros(); 2];
    for (t, q) in pts {
        let a = V3::new(1.0, t - t0, (t - t0).powi(2));
        ata += a * a.transpose();
        for c in 0..2 {
            atb[c] += a * q[c];
        }
    }
    let inv = ata.try_inverse()?;
    let coef = atb.map(|b| inv * b);
    let mut ss = 0.0;
    for (t, q) in pts {
        let a = V3::new(1.0, t - t0, (t - t0).powi(2));
        for c in 0..2 {
            ss += (q[c] - coef[c].dot(&a)).powi(2);
        }
    }
    let var = ss / (2.0 * pts.len() as f64 - 6.0);
    Some((
        [2.0 * coef[0][2], 2.0 * coef[1][2]],
        2.0 * (var * inv[(2, 2)]).max(0.0).sqrt(),
    ))
}

/// One image point of a sphere in free flight: flight index, time from the flight's mean,
/// view (0 direct, 1 mirror) and the point.
struct FlightPoint {
    flight: usize,
    dt: f64,
    view: usize,
    q: [f64; 2],
}

/// What the joint fit found: the direct view's scale and roll, the mirror's scale, roll, tilt
/// and u offset, with σ, and the residuals per view.
struct Bundle {
    direct_scale: Fitted,
    direct_roll: Fitted,
    mirror: Option<MirrorFit>,
    residual_rms_px: [f64; 2],
}

/// Direct view: M = s·[[cos φ, −sin φ, 0], [−sin φ, −cos φ, 0]] (φ: gravity's image turned
/// from straight down towards +u).
fn direct_matrix(s: f64, phi: f64) -> [[f64; 3]; 2] {
    let (sp, cp) = phi.sin_cos();
    [[s * cp, -s * sp, 0.0], [-s * sp, -s * cp, 0.0]]
}

/// Both views fitted together (a small bundle adjustment): every flight is a ballistic
/// trajectory with g known (x, z straight lines, y a parabola), seen by the direct view through
/// (s_d, φ_d) and by the mirror through (s_m, φ_m, τ, o_u). Held: the direct view's origin and
/// the mirror's v offset (the world origin, a choice), the mirror's flips.
#[allow(clippy::too_many_arguments)]
fn fit_bundle(
    obs: &[FrameObs],
    phases: &[Vec<usize>; 4],
    g: f64,
    di: usize,
    mi: Option<usize>,
    origin_direct: [f64; 2],
    start: (f64, f64),
    provisional_mirror: Option<&View>,
) -> Result<Bundle, String> {
    let mut pts = Vec::new();
    for (k, frames) in phases.iter().enumerate() {
        let s = k % 2;
        let mean_t =
            frames.iter().map(|&i| obs[i].time_s).sum::<f64>() / frames.len().max(1) as f64;
        for &i in frames {
            let f = &obs[i];
            for (view, vi) in [(0, Some(di)), (1, mi)] {
                let Some(vi) = vi else { continue };
                if let Some(m) = &f.spheres[s][vi] {
                    pts.push(FlightPoint {
                        flight: k,
                        dt: f.time_s - mean_t,
                        view,
                        q: m.centre_px,
                    });
                }
            }
        }
    }
    let flights: Vec<usize> = (0..4)
        .filter(|k| pts.iter().filter(|p| p.flight == *k && p.view == 0).count() >= 6)
        .collect();
    pts.retain(|p| flights.contains(&p.flight));
    let mirror_points = pts.iter().filter(|p| p.view == 1).count();
    let with_mirror = mi.is_some() && provisional_mirror.is_some();
    if flights.len() < 2 || (with_mirror && mirror_points < 12) {
        return Err(format!(
            "{} flight(s) of 6 frames or more in the direct view and {mirror_points} mirror centres: calibrate needs 2 flights (a collision gives 4) and 12 mirror centres",
            flights.len()
        ));
    }
    let (f, ov) = provisional_mirror
        .map(|v| (z_sign(v), v.origin_px[1]))
        .unwrap_or((1.0, 0.0));
    // Parameters: s_d, φ_d, s_m, φ_m, τ, o_u, then (x0, vx, y0, vy, z0, vz) per flight.
    let nv = 6;
    let np = nv + 6 * flights.len();
    let mut th = DVector::zeros(np);
    th[0] = start.0;
    th[1] = start.1;
    if let Some(v) = provisional_mirror {
        th[2] = v.px_per_mm;
        th[5] = v.origin_px[0];
    }
    let slot = |k: usize| flights.iter().position(|&x| x == k).unwrap_or(0);
    // Starting trajectories: the direct view inverted with the starting map; z from the
    // provisional mirror, each a straight line per flight.
    let m0 = direct_matrix(start.0, start.1);
    let inv = nalgebra::Matrix2::new(m0[0][0], m0[0][1], m0[1][0], m0[1][1])
        .try_inverse()
        .ok_or("the direct view's starting map is singular")?;
    for (j, &k) in flights.iter().enumerate() {
        let line = |vals: &[(f64, f64)]| -> (f64, f64) {
            let n = vals.len().max(1) as f64;
            let (mt, mv) = (
                vals.iter().map(|x| x.0).sum::<f64>() / n,
                vals.iter().map(|x| x.1).sum::<f64>() / n,
            );
            let stt: f64 = vals.iter().map(|x| (x.0 - mt).powi(2)).sum();
            let stv: f64 = vals.iter().map(|x| (x.0 - mt) * (x.1 - mv)).sum();
            let b = if stt > 0.0 { stv / stt } else { 0.0 };
            (mv - b * mt, b)
        };
        let xy: Vec<(f64, nalgebra::Vector2<f64>)> = pts
            .iter()
            .filter(|p| p.flight == k && p.view == 0)
            .map(|p| {
                let d =
                    nalgebra::Vector2::new(p.q[0] - origin_direct[0], p.q[1] - origin_direct[1]);
                (p.dt, inv * d)
            })
            .collect();
        let xs: Vec<(f64, f64)> = xy.iter().map(|(t, p)| (*t, p[0])).collect();
        let ys: Vec<(f64, f64)> = xy
            .iter()
            .map(|(t, p)| (*t, p[1] + 0.5 * g * t * t))
            .collect();
        let (x0, vx) = line(&xs);
        let (y0, vy) = line(&ys);
        let zs: Vec<(f64, f64)> = pts
            .iter()
            .filter(|p| p.flight == k && p.view == 1)
            .map(|p| (p.dt, f * (p.q[1] - ov) / th[2].max(1e-9)))
            .collect();
        let (z0, vz) = line(&zs);
        for (c, v) in [x0, vx, y0, vy, z0, vz].into_iter().enumerate() {
            th[nv + 6 * j + c] = v;
        }
    }
    // x runs the same way in the mirror as in the direct view unless the mirror's u falls with it.
    let sx = provisional_mirror
        .map(|v| if v.u_axis.x < 0.0 { -1.0 } else { 1.0 })
        .unwrap_or(1.0);
    let residuals = |th: &DVector<f64>| -> DVector<f64> {
        let md = direct_matrix(th[0], th[1]);
        let mm = mirror_matrix(th[2], th[3], th[4], sx, f);
        let mut r = DVector::zeros(2 * pts.len());
        for (i, p) in pts.iter().enumerate() {
            let b = nv + 6 * slot(p.flight);
            let t = p.dt;
            let w = [
                th[b] + th[b + 1] * t,
                th[b + 2] + th[b + 3] * t - 0.5 * g * t * t,
                th[b + 4] + th[b + 5] * t,
            ];
            let (m, o) = if p.view == 0 {
                (&md, origin_direct)
            } else {
                (&mm, [th[5], ov])
            };
            for c in 0..2 {
                r[2 * i + c] = p.q[c] - (m[c][0] * w[0] + m[c][1] * w[1] + m[c][2] * w[2] + o[c]);
            }
        }
        r
    };
    // Without a mirror its parameters are held (their columns left out).
    let free: Vec<usize> = (0..np)
        .filter(|&c| with_mirror || !(2..6).contains(&c))
        .filter(|&c| with_mirror || (c < nv || (c - nv) % 6 < 4))
        .collect();
    let mut jac = DMatrix::zeros(2 * pts.len(), free.len());
    for _ in 0..30 {
        let r0 = residuals(&th);
        for (jc, &c) in free.iter().enumerate() {
            let h = 1e-6 * th[c].abs().max(1e-3);
            let mut t2 = th.clone();
            t2[c] += h;
            jac.set_column(jc, &((residuals(&t2) - &r0) / h));
        }
        let step = (jac.transpose() * &jac)
            .try_inverse()
            .map(|inv| -(inv * jac.transpose() * &r0))
            .ok_or("the fit is degenerate: the flights do not tell the views apart")?;
        for (jc, &c) in free.iter().enumerate() {
            th[c] += step[jc];
        }
        if step.amax() < 1e-10 {
            break;
        }
    }
    let r = residuals(&th);
    let dof = (r.len() as f64 - free.len() as f64).max(1.0);
    let cov = (jac.transpose() * &jac)
        .try_inverse()
        .ok_or("the fit is degenerate")?
        * (r.norm_squared() / dof);
    let fitted = |c: usize, k: f64| {
        let jc = free.iter().position(|&x| x == c);
        Fitted {
            value: th[c] * k,
            sigma: jc
                .map(|j| cov[(j, j)].max(0.0).sqrt() * k.abs())
                .unwrap_or(0.0),
        }
    };
    let rms = |view: usize| {
        let (ss, n) = pts
            .iter()
            .enumerate()
            .filter(|(_, p)| p.view == view)
            .fold((0.0, 0usize), |(ss, n), (i, _)| {
                (ss + r[2 * i].powi(2) + r[2 * i + 1].powi(2), n + 2)
            });
        if n == 0 {
            f64::NAN
        } else {
            (ss / n as f64).sqrt()
        }
    };
    let deg = 180.0 / std::f64::consts::PI;
    Ok(Bundle {
        direct_scale: fitted(0, 1.0),
        direct_roll: fitted(1, deg),
        mirror: with_mirror.then(|| MirrorFit {
            scale: fitted(2, 1.0),
            scale_from_diameter: Fitted {
                value: f64::NAN,
                sigma: f64::NAN,
            },
            roll_deg: fitted(3, deg),
            tilt_deg: fitted(4, deg),
            origin_u_px: fitted(5, 1.0),
            x_reversed: sx < 0.0,
            residual_rms_px: rms(1),
            points: mirror_points,
        }),
        residual_rms_px: [rms(0), rms(1)],
    })
}

impl Calibrated {
    /// The `[geometry]` TOML, each parameter's value and σ and the residuals in comments above.
    pub fn toml(&self) -> String {
        let p = |f: &Fitted, unit: &str, d: usize| {
            format!("{:.d$} ± {:.d$} {unit}", f.value, f.sigma, d = d)
        };
        let d = &self.direct;
        let mut out = format!(
            "# impactcam calibrate: {}, {} frames. The world origin is the config's (a choice).\n\
             # direct: scale {} from free fall, {} from the diameter, {} used;\n\
             #   roll {} (image direction of gravity); parabola residuals {:.3} px RMS\n",
            self.source,
            self.frames,
            p(&d.scale_from_free_fall, "px/mm", 4),
            p(&d.scale_from_diameter, "px/mm", 4),
            p(&d.scale, "px/mm", 4),
            p(&d.roll_deg, "deg", 3),
            d.residual_rms_px
        );
        if let Some(m) = &self.mirror {
            out += &format!(
                "# mirror: scale {} (diameter: {}); roll {}; tilt {} (the view turned about x,\n\
                 #   twice the mirror's tilt from 45°); x {}; origin u {}; residuals {:.3} px RMS over {} centres\n",
                p(&m.scale, "px/mm", 4),
                p(&m.scale_from_diameter, "px/mm", 4),
                p(&m.roll_deg, "deg", 3),
                p(&m.tilt_deg, "deg", 3),
                if m.x_reversed { "reversed" } else { "not reversed" },
                p(&m.origin_u_px, "px", 2),
                m.residual_rms_px,
                m.points
            );
        }
        for (name, v) in [
            ("direct", &self.geometry.direct),
            ("mirror", &self.geometry.mirror),
        ] {
            let Some(v) = v else { continue };
            let (Some(m), Some(o)) = (v.matrix_px_per_mm, v.origin_px) else {
                continue;
            };
            let row = |r: [f64; 3]| format!("[{:.6}, {:.6}, {:.6}]", r[0], r[1], r[2]);
            out += &format!(
                "\n[geometry.{name}]\nregion = [{}, {}, {}, {}]\nmatrix_px_per_mm = [{}, {}]\norigin_px = [{:.4}, {:.4}]\n",
                v.region[0],
                v.region[1],
                v.region[2],
                v.region[3],
                row(m[0]),
                row(m[1]),
                o[0],
                o[1]
            );
        }
        out
    }

    /// A PNG of frame `img` with the regions outlined and each view's world axes drawn from its
    /// origin (x red, the other axis green, 10 mm long).
    pub fn png(&self, img: &analysis::image::GreyImage) -> Result<Vec<u8>, String> {
        use crate::figures::canvas::{Canvas, Raster};
        let mut r = Raster::from_grey(img.width, img.height, &img.data);
        for (kind, v) in [
            (ViewKind::Direct, &self.geometry.direct),
            (ViewKind::Mirror, &self.geometry.mirror),
        ] {
            let Some(g) = v else { continue };
            let view = View::from_config(kind, g);
            let [x, y, w, h] = g.region.map(f64::from);
            let (x0, y0, x1, y1) = (x - 0.5, y - 0.5, x + w - 0.5, y + h - 0.5);
            for (a, b) in [
                ((x0, y0), (x1, y0)),
                ((x1, y0), (x1, y1)),
                ((x1, y1), (x0, y1)),
                ((x0, y1), (x0, y0)),
            ] {
                r.line(a, b, [255, 200, 0], 1.0);
            }
            let o = view.project(&V3::zeros());
            // y for the direct view, z for the mirror.
            let mut second = V3::zeros();
            second[3 - kind.depth_axis()] = 10.0;
            for (end, colour) in [
                (V3::new(10.0, 0.0, 0.0), [230, 40, 40]),
                (second, [40, 200, 40]),
            ] {
                let q = view.project(&end);
                r.line((o[0], o[1]), (q[0], q[1]), colour, 1.0);
            }
        }
        r.png().map_err(|e| format!("PNG: {e}"))
    }
}
