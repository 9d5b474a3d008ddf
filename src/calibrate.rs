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
    /// The pinhole's distance from the world origin, when perspective was found (`distance`).
    pub camera_distance_mm: Option<Fitted>,
}

/// The mirror view as found.
#[derive(Clone, Debug)]
pub struct MirrorFit {
    pub scale: Fitted,
    pub scale_from_diameter: Fitted,
    /// The mirror view turned about world y, its line of sight (its image rotated), deg.
    pub roll_deg: Fitted,
    /// The mirror view turned about world x, deg (twice the mirror's own tilt from 45°): its
    /// v takes in world y.
    pub tilt_deg: Fitted,
    /// The mirror view turned about world z, deg: its u takes in world y.
    pub yaw_deg: Fitted,
    /// Image u of the world origin, px.
    pub origin_u_px: Fitted,
    /// Whether the mirror shows world x reversed (u decreasing with x).
    pub x_reversed: bool,
    pub residual_rms_px: f64,
    pub points: usize,
    /// The virtual pinhole's distance from the world origin, when perspective was found.
    pub camera_distance_mm: Option<Fitted>,
}

#[derive(Clone, Debug)]
pub struct Calibrated {
    pub source: String,
    /// Recordings whose flights were fitted together.
    pub recordings: usize,
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
    calibrate_paths(&[path.to_path_buf()], cfg)
}

/// As `calibrate_path`, pooling the flights of several recordings of one rig (the first sets
/// the provisional scale; the config is the first session's own when none is given).
pub fn calibrate_paths(
    paths: &[std::path::PathBuf],
    cfg: Option<&Config>,
) -> Result<(Calibrated, Vec<u8>), crate::experiment::ExperimentError> {
    let first = paths.first().ok_or_else(|| AnalysisError::Input {
        source_name: "calibrate".into(),
        message: "no recording given".into(),
    })?;
    let mut sources = Vec::new();
    for p in paths {
        sources.push(analysis::source::open(
            p,
            cfg.map(|c| c.camera.frame_rate_hz),
        )?);
    }
    let cfg = match cfg {
        Some(c) => c.clone(),
        None => sources[0]
            .recorded_config()
            .cloned()
            .unwrap_or_else(Config::default_config),
    };
    let cal = {
        let mut refs: Vec<&mut dyn FrameSource> = sources
            .iter_mut()
            .map(|s| s.as_mut() as &mut dyn FrameSource)
            .collect();
        calibrate(&mut refs, &cfg).map_err(|e| AnalysisError::Input {
            source_name: first.display().to_string(),
            message: e.to_string(),
        })?
    };
    let src = &mut sources[0];
    let path = first;
    let mut img = analysis::image::GreyImage::new();
    src.read(cal.impact_frame, &mut img)?;
    let png = cal.png(&img).map_err(|message| AnalysisError::Input {
        source_name: path.display().to_string(),
        message,
    })?;
    Ok((cal, png))
}

/// Fits the views' maps from one or more recordings of one rig (the first sets the
/// provisional scale; the flights of all are fitted together).
pub fn calibrate(
    sources: &mut [&mut dyn FrameSource],
    cfg: &Config,
) -> Result<Calibrated, CalibrateError> {
    let (src, others) = sources.split_first_mut().ok_or(CalibrateError::Data {
        source_name: "calibrate".into(),
        message: "no recording given".into(),
    })?;
    let src: &mut dyn FrameSource = &mut **src;
    let name = src.source().name;
    let data = |message: String| CalibrateError::Data {
        source_name: name.clone(),
        message,
    };
    let Some(direct_cfg) = cfg.geometry.direct.clone() else {
        return Err(CalibrateError::NoDirectView { source_name: name });
    };
    // Where the spheres are, before any geometry is trusted: every view's whole blobs.
    let survey =
        analysis::blob_survey(src, cfg, 60).map_err(|cause| CalibrateError::Provisional {
            source_name: name.clone(),
            cause,
        })?;
    let kinds: Vec<ViewKind> = analysis::geometry::views(cfg)
        .iter()
        .map(|v| v.kind)
        .collect();
    let di = kinds
        .iter()
        .position(|k| *k == ViewKind::Direct)
        .ok_or_else(|| data("no direct view".into()))?;
    let mi = kinds.iter().position(|k| *k == ViewKind::Mirror);
    // The mirror's x against the direct view's: where each view shows the same number of
    // blobs (one or two), paired in order of u; u_mirror = a·u_direct + b gives the mirror's
    // scale along x (and whether it reverses x) and the u offset that makes the two x agree, so
    // that the spheres are labelled alike in both views.
    let mirror_line = mi.and_then(|mi| {
        let mut pairs = Vec::new();
        for f in &survey {
            let (mut d, mut m) = (f[di].clone(), f[mi].clone());
            if d.len() != m.len() || d.is_empty() || d.len() > 2 {
                continue;
            }
            d.sort_by(|p, q| p.0[0].total_cmp(&q.0[0]));
            m.sort_by(|p, q| p.0[0].total_cmp(&q.0[0]));
            pairs.extend(d.iter().zip(&m).map(|(p, q)| (p.0[0], q.0[0])));
        }
        line_fit(&pairs)
    });
    // The direct view's scale must be within 10 % for its discs to be taken for spheres. Tried
    // in turn: the config's, then the blobs' median size (which the light biases: a highlight
    // raises the threshold and shrinks the blob) and 15 % either side of it.
    let mean_diameter_mm = 0.5 * (cfg.spheres.sphere(0).0 + cfg.spheres.sphere(1).0);
    let config_scale = local_scale(&direct_cfg).unwrap_or(1.0);
    let mut scales = vec![config_scale];
    let mut sizes: Vec<f64> = survey
        .iter()
        .flat_map(|f| f[di].iter().map(|b| b.1))
        .collect();
    if sizes.len() >= 3 {
        sizes.sort_by(f64::total_cmp);
        let blob = sizes[sizes.len() / 2] / mean_diameter_mm;
        for k in [1.0, 1.15, 1.0 / 1.15] {
            let c = blob * k;
            if scales.iter().all(|x| (c / x - 1.0).abs() > 0.05) {
                scales.push(c);
            }
        }
    }
    let mut tried = Vec::new();
    let mut found = None;
    for s_d in scales {
        let mut trial = cfg.clone();
        if let Some(v) = trial.geometry.direct.as_mut() {
            set_scale(v, s_d);
        }
        let direct_now = trial.geometry.direct.clone();
        if let (Some(m), Some(d)) = (trial.geometry.mirror.as_mut(), direct_now.as_ref()) {
            match mirror_line {
                Some(line) => align_mirror(d, m, line),
                None => {
                    let ratio = local_scale(m).unwrap_or(config_scale) / config_scale;
                    set_scale(m, s_d * ratio);
                }
            }
        }
        let attempt = analysis::measure(src, &trial)
            .map_err(|e| e.to_string())
            .and_then(|(views, obs)| {
                let (split, phases) = flights(&obs, di)?;
                Ok((views, obs, split, phases))
            });
        match attempt {
            Ok(ok) => {
                found = Some((trial, ok));
                break;
            }
            Err(e) => tried.push(format!("at {s_d:.3} px/mm: {e}")),
        }
    }
    let Some((cfg, (views, obs, split_frame, phases))) = found else {
        return Err(data(format!(
            "no provisional scale gives flights in the direct view ({})",
            tried.join("; ")
        )));
    };
    let cfg = &cfg;
    // The other recordings, measured with the same provisional geometry; their frames follow
    // the first's, their flights too (four per recording: sphere k % 2).
    let (mut obs, mut phases) = (obs, phases.to_vec());
    let mut used = 1;
    for other in others.iter_mut() {
        let other: &mut dyn FrameSource = &mut **other;
        let oname = other.source().name;
        let (_, o) =
            analysis::measure(other, cfg).map_err(|cause| CalibrateError::Provisional {
                source_name: oname.clone(),
                cause,
            })?;
        let (_, ph) = flights(&o, di).map_err(|message| CalibrateError::Data {
            source_name: oname,
            message,
        })?;
        let offset = obs.len();
        phases.extend(
            ph.into_iter()
                .map(|f| f.into_iter().map(|i| i + offset).collect()),
        );
        obs.extend(o);
        used += 1;
    }
    let (views, obs) = (&views, &obs);
    let g = cfg.analysis.gravity_mm_s2;
    let diam = [cfg.spheres.sphere(0).0, cfg.spheres.sphere(1).0];

    // Direct view: free fall per flight, pooled.
    let mut acc = Vec::new();
    for (k, frames) in phases.iter().enumerate() {
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
        &phases,
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
        direct: Some(view_geometry(
            direct_cfg.region,
            m_direct,
            origin_direct,
            ViewKind::Direct,
            bundle.kappa[0],
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
            [fit.tilt_deg.value, fit.roll_deg.value, fit.yaw_deg.value].map(f64::to_radians),
            sx,
            f,
        );
        let origin = [fit.origin_u_px.value, views[mi].origin_px[1]];
        geometry.mirror = Some(view_geometry(
            region,
            m,
            origin,
            ViewKind::Mirror,
            bundle.kappa[1],
        ));
        fit.camera_distance_mm = distance(bundle.kappa[1]);
        if let Some(d) = diameter_scale(obs, mi, diam) {
            fit.scale_from_diameter = d;
        }
        mirror = Some(fit);
    }
    Ok(Calibrated {
        source: name,
        recordings: used,
        frames: obs.len(),
        impact_frame: split_frame,
        direct: DirectFit {
            scale_from_free_fall,
            scale_from_diameter,
            scale: bundle.direct_scale,
            roll_deg: bundle.direct_roll,
            residual_rms_px: bundle.residual_rms_px[0],
            camera_distance_mm: distance(bundle.kappa[0]),
        },
        mirror,
        geometry,
    })
}

/// The flights in the direct view, in its image alone: split at the frame where a and b are
/// closest, then for each sphere and side a parabola per image coordinate seeded on the 8
/// frames nearest the split and grown outwards while each next frame lies within 5σ of it (a
/// sphere still rolling in its tube leaves the parabola). Returns the split frame and the frames
/// of [a before, b before, a after, b after].
fn flights(obs: &[FrameObs], di: usize) -> Result<(usize, [Vec<usize>; 4]), String> {
    let centre = |i: usize, s: usize| obs[i].spheres[s][di].as_ref().map(|m| m.centre_px);
    let split = (0..obs.len())
        .filter_map(|i| {
            let (a, b) = (centre(i, 0)?, centre(i, 1)?);
            Some((i, (a[0] - b[0]).hypot(a[1] - b[1])))
        })
        .min_by(|x, y| x.1.total_cmp(&y.1))
        .map(|(i, _)| i)
        .ok_or("spheres a and b are never both measured in the direct view")?;
    const SEED: usize = 8;
    let mut out: [Vec<usize>; 4] = Default::default();
    for (k, slot) in out.iter_mut().enumerate() {
        let (s, pre) = (k % 2, k < 2);
        // Outwards from the split, a frame's gap from it left for the contact itself.
        let order: Vec<usize> = if pre {
            (0..split.saturating_sub(1)).rev().collect()
        } else {
            (split + 2..obs.len()).collect()
        };
        let order: Vec<usize> = order
            .into_iter()
            .filter(|&i| centre(i, s).is_some())
            .collect();
        if order.len() < SEED {
            continue;
        }
        let mut kept: Vec<usize> = order[..SEED].to_vec();
        let mut misses = 0;
        for &i in &order[SEED..] {
            let pts: Vec<(f64, [f64; 2])> = kept
                .iter()
                .filter_map(|&j| Some((obs[j].time_s, centre(j, s)?)))
                .collect();
            let Some((c, rms)) = parabola(&pts) else {
                break;
            };
            let (t, q) = (obs[i].time_s, centre(i, s).unwrap_or([f64::NAN; 2]));
            let off = (0..2)
                .map(|a| (q[a] - (c[a][0] + c[a][1] * t + c[a][2] * t * t)).abs())
                .fold(0.0, f64::max);
            if off <= 5.0 * rms.max(0.05) {
                kept.push(i);
                misses = 0;
            } else {
                misses += 1;
                if misses >= 3 {
                    break;
                }
            }
        }
        kept.sort_unstable();
        *slot = kept;
    }
    Ok((split, out))
}

/// Coefficients (c0, c1, c2) of u(t) and v(t) = c0 + c1·t + c2·t², and the RMS residual, px.
fn parabola(pts: &[(f64, [f64; 2])]) -> Option<([[f64; 3]; 2], f64)> {
    if pts.len() < 4 {
        return None;
    }
    let a = DMatrix::from_fn(pts.len(), 3, |r, j| pts[r].0.powi(j as i32));
    let svd = a.clone().svd(true, true);
    let mut coef = [[0.0; 3]; 2];
    let mut ss = 0.0;
    for (c, co) in coef.iter_mut().enumerate() {
        let b = DVector::from_fn(pts.len(), |r, _| pts[r].1[c]);
        let x = svd.solve(&b, 1e-12).ok()?;
        ss += (b - &a * &x).norm_squared();
        *co = [x[0], x[1], x[2]];
    }
    Some((coef, (ss / (2 * pts.len()) as f64).sqrt()))
}

/// Least-squares line y = a·x + b through (x, y) pairs, when they span 20 px of x and lie
/// within 1.5 px RMS of it (blobs of clutter paired with spheres do not).
fn line_fit(pairs: &[(f64, f64)]) -> Option<(f64, f64)> {
    if pairs.len() < 6 {
        return None;
    }
    let n = pairs.len() as f64;
    let (mx, my) = (
        pairs.iter().map(|p| p.0).sum::<f64>() / n,
        pairs.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxx: f64 = pairs.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = pairs.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let lo = pairs.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
    let hi = pairs.iter().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max);
    if hi - lo < 20.0 || sxx <= 0.0 {
        return None;
    }
    let (a, b) = (sxy / sxx, my - sxy / sxx * mx);
    let rms = (pairs
        .iter()
        .map(|p| (p.1 - a * p.0 - b).powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    (rms <= 1.5).then_some((a, b))
}

/// A provisional shorthand mirror made to agree with the direct view on x, from
/// u_mirror = a·u_direct + b (matrices and projections are left as given).
fn align_mirror(direct: &ViewGeometry, mirror: &mut ViewGeometry, (a, b): (f64, f64)) {
    let (Some(sd), Some(od), Some(ud)) = (direct.px_per_mm, direct.origin_px, &direct.u_axis)
    else {
        return;
    };
    let (Some(_), Some(om)) = (mirror.px_per_mm, mirror.origin_px.as_mut()) else {
        return;
    };
    // x = sign_d·(u_d − o_d)/s_d, so u_m = a·u_d + b is the mirror with scale |a|·s_d along
    // x, reversed when a·sign_d < 0, and u offset b + a·o_d.
    let sign_d = if ud.starts_with('-') { -1.0 } else { 1.0 };
    om[0] = b + a * od[0];
    mirror.px_per_mm = Some(a.abs() * sd);
    mirror.u_axis = Some(if a * sign_d < 0.0 { "-x" } else { "+x" }.into());
}

/// A view's scale at the world origin, px/mm (the geometric mean of its two image axes').
fn local_scale(v: &ViewGeometry) -> Option<f64> {
    let (m, _) = v.local_affine()?;
    let norm = |r: &[f64; 3]| r.iter().map(|x| x * x).sum::<f64>().sqrt();
    Some((norm(&m[0]) * norm(&m[1])).sqrt())
}

/// Sets a provisional view's scale to `px_per_mm` (a projection is left as given).
fn set_scale(v: &mut ViewGeometry, px_per_mm: f64) {
    let Some(now) = local_scale(v) else { return };
    let k = px_per_mm / now;
    if !k.is_finite() {
        return;
    }
    if let Some(s) = v.px_per_mm.as_mut() {
        *s *= k;
    }
    if let Some(mm) = v.matrix_px_per_mm.as_mut() {
        *mm = mm.map(|r| r.map(|x| x * k));
    }
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

/// The camera's distance 1/κ with its σ, when the fit found perspective: κ beyond 4σ and
/// beyond 1e-4 /mm (a camera nearer than 10 m, whose scale changes by 0.2 % over 20 mm of depth).
fn distance(kappa: Fitted) -> Option<Fitted> {
    (kappa.value.abs() > 4.0 * kappa.sigma && kappa.value.abs() > 1e-4).then(|| Fitted {
        value: 1.0 / kappa.value,
        sigma: kappa.sigma / (kappa.value * kappa.value),
    })
}

/// A view's map as config: a matrix, or where perspective was found the pinhole
/// [[m1 − u0·κ·f, u0], [m2 − v0·κ·f, v0], [−κ·f, 1]] (camera at 1/κ along f).
fn view_geometry(
    region: [u32; 4],
    m: [[f64; 3]; 2],
    origin: [f64; 2],
    kind: ViewKind,
    kappa: Fitted,
) -> ViewGeometry {
    if distance(kappa).is_none() {
        return ViewGeometry::affine(region, m, origin);
    }
    let (k, f) = (kappa.value, facing_of(&m, kind));
    let row = |r: [f64; 3], o: f64| [0, 1, 2].map(|i| r[i] - o * k * f[i]);
    let [a, b] = [row(m[0], origin[0]), row(m[1], origin[1])];
    ViewGeometry {
        region,
        projection: Some([
            [a[0], a[1], a[2], origin[0]],
            [b[0], b[1], b[2], origin[1]],
            [-k * f[0], -k * f[1], -k * f[2], 1.0],
        ]),
        ..Default::default()
    }
}

/// The unit vector from the scene towards a view's camera, from its map's rows (u × v is the
/// line of sight for a camera, reversed by a mirror).
fn facing_of(m: &[[f64; 3]; 2], kind: ViewKind) -> V3 {
    let c = V3::from(m[0]).cross(&V3::from(m[1])).normalize();
    match kind {
        ViewKind::Direct => -c,
        ViewKind::Mirror => c,
    }
}

/// M = s·N·Qᵀ: the nominal mirror rows N = [[sx, 0, 0], [0, 0, f]] (u along ±x, v along ±z)
/// with the view turned by Q, the rotation by `turn` rad about world (x, y, z).
fn mirror_matrix(s: f64, turn: [f64; 3], sx: f64, f: f64) -> [[f64; 3]; 2] {
    let q = nalgebra::Rotation3::from_scaled_axis(V3::from(turn));
    let n = [V3::new(sx, 0.0, 0.0), V3::new(0.0, 0.0, f)];
    n.map(|r| {
        let t = q * r;
        [s * t.x, s * t.y, s * t.z]
    })
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
    /// Inverse camera distance of [direct, mirror], 1/mm.
    kappa: [Fitted; 2],
    mirror: Option<MirrorFit>,
    residual_rms_px: [f64; 2],
}

/// (parameter, σ) of the bundle's priors: the mirror's turns about x, y, z (rad) and the two
/// cameras' 1/distance (1/mm).
const PRIORS: [(usize, f64); 5] = [(3, 0.0873), (4, 0.0873), (5, 0.0873), (7, 0.01), (8, 0.01)];

/// Direct view: M = s·[[cos φ, −sin φ, 0], [−sin φ, −cos φ, 0]] (φ: gravity's image turned
/// from straight down towards +u).
fn direct_matrix(s: f64, phi: f64) -> [[f64; 3]; 2] {
    let (sp, cp) = phi.sin_cos();
    [[s * cp, -s * sp, 0.0], [-s * sp, -s * cp, 0.0]]
}

/// Both views fitted together (a small bundle adjustment): every flight is a ballistic
/// trajectory with g known (x, z straight lines, y a parabola), seen by the direct view through
/// (s_d, φ_d) and by the mirror through its scale, its turn about x, y and z, and o_u. Held: the direct view's origin and
/// the mirror's v offset (the world origin, a choice), the mirror's flips.
#[allow(clippy::too_many_arguments)]
fn fit_bundle(
    obs: &[FrameObs],
    phases: &[Vec<usize>],
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
    let flights: Vec<usize> = (0..phases.len())
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
    // Parameters: s_d, φ_d, s_m, the mirror's turn about x, y, z, o_u, the direct and the
    // mirror camera's inverse distance κ (1/mm; 0 is orthographic), then
    // (x0, vx, y0, vy, z0, vz) per flight.
    let nv = 9;
    let np = nv + 6 * flights.len();
    let mut th = DVector::zeros(np);
    th[0] = start.0;
    th[1] = start.1;
    if let Some(v) = provisional_mirror {
        th[2] = v.px_per_mm;
        th[6] = v.origin_px[0];
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
    // Points left out as outliers (a frame still in contact, a sphere still in its tube at
    // a flight's end) weigh 0.
    let weights = std::cell::RefCell::new(vec![1.0; pts.len()]);
    let residuals = |th: &DVector<f64>| -> DVector<f64> {
        let weights = weights.borrow();
        let md = direct_matrix(th[0], th[1]);
        let mm = mirror_matrix(th[2], [th[3], th[4], th[5]], sx, f);
        let (fd, fm) = (
            facing_of(&md, ViewKind::Direct),
            facing_of(&mm, ViewKind::Mirror),
        );
        let mut r = DVector::zeros(2 * pts.len() + PRIORS.len());
        // Weak priors keep what the flights cannot tell apart sane (and its σ honest): each
        // of the mirror's turns 0 ± 5°, each camera's 1/distance 0 ± 0.01 /mm; a row weighs as
        // an image residual of 0.03 px does.
        for (j, &(c, sigma)) in PRIORS.iter().enumerate() {
            r[2 * pts.len() + j] = th[c] / sigma * 0.03;
        }
        for (i, p) in pts.iter().enumerate() {
            let b = nv + 6 * slot(p.flight);
            let t = p.dt;
            let w = [
                th[b] + th[b + 1] * t,
                th[b + 2] + th[b + 3] * t - 0.5 * g * t * t,
                th[b + 4] + th[b + 5] * t,
            ];
            let (m, o, facing, kappa) = if p.view == 0 {
                (&md, origin_direct, fd, th[7])
            } else {
                (&mm, [th[6], ov], fm, th[8])
            };
            let k = 1.0 / (1.0 - kappa * facing.dot(&V3::from(w)));
            for c in 0..2 {
                r[2 * i + c] = weights[i]
                    * (p.q[c] - (k * (m[c][0] * w[0] + m[c][1] * w[1] + m[c][2] * w[2]) + o[c]));
            }
        }
        r
    };
    // Without a mirror its parameters are held (their columns left out).
    let free: Vec<usize> = (0..np)
        .filter(|&c| with_mirror || !(2..nv).contains(&c))
        .filter(|&c| with_mirror || (c < nv || (c - nv) % 6 < 4))
        .collect();
    // Levenberg–Marquardt: Gauss–Newton steps, damped where they would not lower the cost.
    let mut jac = DMatrix::zeros(2 * pts.len() + PRIORS.len(), free.len());
    for _round in 0..4 {
        let mut lambda = 1e-3;
        for _ in 0..60 {
            let r0 = residuals(&th);
            let cost0 = r0.norm_squared();
            for (jc, &c) in free.iter().enumerate() {
                let h = 1e-6 * th[c].abs().max(1e-4);
                let mut t2 = th.clone();
                t2[c] += h;
                jac.set_column(jc, &((residuals(&t2) - &r0) / h));
            }
            let a = jac.transpose() * &jac;
            let grad = jac.transpose() * &r0;
            let mut moved = None;
            while lambda < 1e12 {
                let mut damped = a.clone();
                for d in 0..damped.nrows() {
                    damped[(d, d)] += lambda * a[(d, d)].max(1e-12);
                }
                let Some(step) = damped.try_inverse().map(|inv| -(inv * &grad)) else {
                    lambda *= 10.0;
                    continue;
                };
                let mut trial = th.clone();
                for (jc, &c) in free.iter().enumerate() {
                    trial[c] += step[jc];
                }
                if residuals(&trial).norm_squared() <= cost0 {
                    th = trial;
                    lambda = (lambda / 10.0).max(1e-9);
                    moved = Some(step.amax());
                    break;
                }
                lambda *= 10.0;
            }
            match moved {
                Some(m) if m > 1e-10 => {}
                _ => break,
            }
        }
        // Robust: points beyond 6σ (σ from the median residual, at least 0.02 px) are left out
        // and the fit repeated, until none is.
        let r = residuals(&th);
        let norms: Vec<f64> = (0..pts.len())
            .map(|i| r[2 * i].hypot(r[2 * i + 1]))
            .collect();
        let mut kept: Vec<f64> = norms
            .iter()
            .zip(weights.borrow().iter())
            .filter(|(_, w)| **w > 0.0)
            .map(|(n, _)| *n)
            .collect();
        kept.sort_by(f64::total_cmp);
        // The median of a 2-D residual's length is 1.1774σ for Gaussian errors.
        let sigma = (kept.get(kept.len() / 2).copied().unwrap_or(0.0) / 1.1774).max(0.02);
        let mut changed = false;
        for (w, n) in weights.borrow_mut().iter_mut().zip(&norms) {
            if *w > 0.0 && *n > 6.0 * sigma {
                *w = 0.0;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    let r0 = residuals(&th);
    for (jc, &c) in free.iter().enumerate() {
        let h = 1e-6 * th[c].abs().max(1e-4);
        let mut t2 = th.clone();
        t2[c] += h;
        jac.set_column(jc, &((residuals(&t2) - &r0) / h));
    }
    let r = residuals(&th);
    let used = 2 * weights.borrow().iter().filter(|w| **w > 0.0).count();
    let dof = (used as f64 - free.len() as f64).max(1.0);
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
            .filter(|(i, p)| p.view == view && weights.borrow()[*i] > 0.0)
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
        kappa: [fitted(7, 1.0), fitted(8, 1.0)],
        mirror: with_mirror.then(|| MirrorFit {
            scale: fitted(2, 1.0),
            scale_from_diameter: Fitted {
                value: f64::NAN,
                sigma: f64::NAN,
            },
            tilt_deg: fitted(3, deg),
            roll_deg: fitted(4, deg),
            yaw_deg: fitted(5, deg),
            origin_u_px: fitted(6, 1.0),
            x_reversed: sx < 0.0,
            residual_rms_px: rms(1),
            points: mirror_points,
            camera_distance_mm: None,
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
            "# impactcam calibrate: {}{}, {} frames. The world origin is the config's (a choice).\n\
             # direct: scale {} from free fall, {} from the diameter, {} used;\n\
             #   roll {} (image direction of gravity); parabola residuals {:.3} px RMS\n",
            self.source,
            if self.recordings > 1 {
                format!(" and {} more recording(s)", self.recordings - 1)
            } else {
                String::new()
            },
            self.frames,
            p(&d.scale_from_free_fall, "px/mm", 4),
            p(&d.scale_from_diameter, "px/mm", 4),
            p(&d.scale, "px/mm", 4),
            p(&d.roll_deg, "deg", 3),
            d.residual_rms_px
        );
        let persp = |d: &Option<Fitted>| match d {
            Some(d) => format!("a pinhole {}", p(d, "mm away", 0)),
            None => "no perspective found (orthographic)".into(),
        };
        out += &format!("#   direct camera: {}\n", persp(&d.camera_distance_mm));
        if let Some(m) = &self.mirror {
            out += &format!("#   mirror camera: {}\n", persp(&m.camera_distance_mm));
            out += &format!(
                "# mirror: scale {} (diameter: {}); turned about x (tilt, twice the mirror's from 45°)\n\
                 #   {}, about y (roll) {}, about z (yaw) {}; x {}; origin u {};\n\
                 #   residuals {:.3} px RMS over {} centres\n",
                p(&m.scale, "px/mm", 4),
                p(&m.scale_from_diameter, "px/mm", 4),
                p(&m.tilt_deg, "deg", 3),
                p(&m.roll_deg, "deg", 3),
                p(&m.yaw_deg, "deg", 3),
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
            if let Some(p) = v.projection {
                let row =
                    |r: [f64; 4]| format!("[{:.6}, {:.6}, {:.9}, {:.4}]", r[0], r[1], r[2], r[3]);
                let row3 =
                    |r: [f64; 4]| format!("[{:.9}, {:.9}, {:.9}, {:.1}]", r[0], r[1], r[2], r[3]);
                out +=
                    &format!(
                    "\n[geometry.{name}]\nregion = [{}, {}, {}, {}]\nprojection = [{}, {}, {}]\n",
                    v.region[0], v.region[1], v.region[2], v.region[3],
                    row(p[0]), row(p[1]), row3(p[2])
                );
                continue;
            }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::tracking::Measurement;

    const G: f64 = 9806.65;

    /// Four ballistic flights (a and b, before and after) seen through the given views with
    /// Gaussian noise on every centre, 25 frames each at 1 kHz: the bundle's input written from
    /// the maps' `project`, not drawn by the simulator.
    fn flights_through(
        views: [&View; 2],
        noise_px: f64,
        seed: u64,
    ) -> (Vec<FrameObs>, Vec<Vec<usize>>) {
        let mut rng = hw_sim::Rng::new(seed);
        let flights = [
            (V3::new(-15.0, 5.0, 1.0), V3::new(800.0, -300.0, 20.0)),
            (V3::new(15.0, 4.0, -1.0), V3::new(-700.0, -350.0, -10.0)),
            (V3::new(-5.0, -6.0, 4.5), V3::new(-400.0, -500.0, 160.0)),
            (V3::new(6.0, -5.0, -4.5), V3::new(600.0, -200.0, -180.0)),
        ];
        let (mut obs, mut phases) = (Vec::new(), vec![Vec::new(); 4]);
        for (k, (p0, v)) in flights.iter().enumerate() {
            for j in 0..25 {
                let t = (j as f64 - 12.0) / 1000.0;
                let p = p0 + v * t + V3::new(0.0, -0.5 * G * t * t, 0.0);
                let mut spheres = [vec![None, None], vec![None, None]];
                for (vi, view) in views.iter().enumerate() {
                    let q = view.project(&p);
                    let c = [
                        q[0] + noise_px * rng.gaussian(),
                        q[1] + noise_px * rng.gaussian(),
                    ];
                    spheres[k % 2][vi] = Some(Measurement {
                        centre_px: c,
                        blob_centroid_px: c,
                        sigma_px: [noise_px; 2],
                        diameter_px: 13.7,
                        markers: Vec::new(),
                    });
                }
                phases[k].push(obs.len());
                obs.push(FrameObs {
                    index: obs.len() as u64,
                    frame_id: obs.len() as u64,
                    time_s: k as f64 * 0.1 + t,
                    spheres,
                    position_mm: [None, None],
                });
            }
        }
        (obs, phases)
    }

    fn within(name: &str, f: Fitted, truth: f64) {
        assert!(
            f.sigma > 0.0 && (f.value - truth).abs() <= 4.0 * f.sigma,
            "{name}: {} ± {} against {truth}",
            f.value,
            f.sigma
        );
    }

    #[test]
    fn the_bundle_finds_a_turned_rig_within_its_uncertainty() {
        let (roll_d, turn_m) = (
            1.2f64.to_radians(),
            [3.5f64, -0.8, 0.6].map(f64::to_radians),
        );
        let kappa = Fitted {
            value: 1.0 / 300.0,
            sigma: 0.0,
        };
        for (perspective, seed) in [(false, 5), (true, 6)] {
            let k = if perspective {
                kappa
            } else {
                Fitted {
                    value: 0.0,
                    sigma: 0.0,
                }
            };
            let (od, om) = ([119.5, 44.0], [121.0, 144.0]);
            let md = direct_matrix(2.1576, roll_d);
            let mm = mirror_matrix(2.1175, turn_m, 1.0, 1.0);
            let direct = View::from_config(
                ViewKind::Direct,
                &view_geometry([0, 0, 240, 96], md, od, ViewKind::Direct, k),
            );
            let mirror = View::from_config(
                ViewKind::Mirror,
                &view_geometry([0, 96, 240, 96], mm, om, ViewKind::Mirror, k),
            );
            let (obs, phases) = flights_through([&direct, &mirror], 0.02, seed);
            // Started from the square rig, 2 % off in scale.
            let provisional = View::from_config(
                ViewKind::Mirror,
                &ViewGeometry::shorthand([0, 96, 240, 96], 2.08, om, "+x", "+z"),
            );
            let b = fit_bundle(
                &obs,
                &phases,
                G,
                0,
                Some(1),
                od,
                (2.11, 0.0),
                Some(&provisional),
            )
            .unwrap();
            let m = b.mirror.unwrap();
            let deg = |x: f64| x.to_degrees();
            within("direct scale", b.direct_scale, 2.1576);
            within("direct roll", b.direct_roll, deg(roll_d));
            within("mirror scale", m.scale, 2.1175);
            within("mirror tilt", m.tilt_deg, deg(turn_m[0]));
            within("mirror roll", m.roll_deg, deg(turn_m[1]));
            within("mirror yaw", m.yaw_deg, deg(turn_m[2]));
            within("mirror origin u", m.origin_u_px, om[0]);
            within("direct 1/distance", b.kappa[0], k.value);
            within("mirror 1/distance", b.kappa[1], k.value);
            assert_eq!(
                distance(b.kappa[1]).is_some(),
                perspective,
                "perspective found"
            );
            assert!(m.residual_rms_px < 0.03, "{}", m.residual_rms_px);
        }
    }
}
