//! `impactcam calibrate`: each view's map found from recordings of collisions, knowing only the
//! spheres' diameter, the frame rate and g. The mirror's edge is found first (`regions`: the
//! config's regions are kept where they keep each view's spheres whole and apart, else replaced
//! by the found ones). The frames are measured with a provisional geometry (those regions, the
//! config's flips, its scales or the blobs'; `provisional`), the flights are
//! found in the direct view's image (`flights`), and both views' maps are fitted to them at once
//! (`bundle`, parametrised in `maps`):
//!
//! - the direct view's scale from free fall (g known; the imaged diameter is the check) and its
//!   roll from the image direction of gravity;
//! - the mirror's scale and its turns about x (tilt), y (roll) and z (yaw) from the x both views
//!   share and from free fall; each camera's distance where perspective shows;
//! - one lens's radial distortion for both views, kept where the flights show it beyond 3σ.
//!
//! What the data cannot give is kept from the config: the world origin (the direct view's
//! `origin_px`, and the mirror's v offset, which sets z = 0), the sign of z in the mirror (which
//! side of the collision the mirror is on), and the views' layout (above each other or side by
//! side, and which side is the direct view). The direct camera's pitch and yaw cannot be told
//! from a change of the flights either: the camera is taken as square, with
//! `DIRECT_SQUARE_DEG` of uncertainty that the analysis carries.

use crate::analysis::geometry::ViewKind;

mod bundle;
mod flights;
pub mod grid;
mod maps;
mod output;
mod provisional;
mod regions;

use crate::analysis::tracking::FrameObs;
use crate::analysis::{self, AnalysisError, FrameSource};
use crate::config::Config;
use bundle::{cut_by_border, fit_bundle, LensFrame};
use flights::{diameter_scale, flights, parabola_acceleration};
use maps::{direct_matrix, distance, mirror_matrix, view_geometry, x_sign};
use provisional::{align_mirror, line_fit, local_scale, set_scale, x_index, MirrorAxes};

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
    /// From both views' flights fitted together, g known.
    pub scale_from_flights: Fitted,
    /// The one used: the flights' and the diameter's weighed by their σ (`combine_scales`), or
    /// the flights' alone where the two disagree.
    pub scale: Fitted,
    /// How far the diameter's scale lay from the flights', in σ of their difference, where
    /// that was beyond `SCALES_AGREE_SIGMA` and the diameter's was left out.
    pub diameter_disagrees_sigma: Option<f64>,
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
    /// The world origin's image coordinate along the mirror's image of x (u; v where
    /// `x_along_v`), px.
    pub origin_x_px: Fitted,
    /// Whether the mirror images world x along v (a camera turned on its side), not u.
    pub x_along_v: bool,
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
    /// How the views' regions were settled: the mirror's edge as found, and whether the
    /// config's regions were kept or replaced.
    pub regions: String,
    pub direct: DirectFit,
    pub mirror: Option<MirrorFit>,
    /// The lens's radial distortion as fitted (k1 at the frame's half-diagonal, about its
    /// centre), and whether it was kept (beyond 3σ) and written into both views.
    pub lens_k1: Fitted,
    pub lens_kept: bool,
    /// The dot grid's fit, where one was given (its k1 is then the one used).
    pub grid: Option<grid::GridFit>,
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
    calibrate_paths(&[path.to_path_buf()], cfg, None)
}

/// As `calibrate_path`, pooling the flights of several recordings of one rig (the first sets
/// the provisional scale; the config is the first session's own when none is given).
/// `grid`: an image of a dot-grid target in the plane of collision (a TIFF, PNG or a session's
/// first frame) and its dots' pitch, mm; the lens is then taken from it.
pub fn calibrate_paths(
    paths: &[std::path::PathBuf],
    cfg: Option<&Config>,
    grid: Option<(&std::path::Path, f64)>,
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
        let grid_image = match grid {
            Some((path, pitch_mm)) => Some((
                grid::read_image(path, cfg.camera.frame_rate_hz)?,
                pitch_mm,
                path.display().to_string(),
            )),
            None => None,
        };
        calibrate(
            &mut refs,
            &cfg,
            grid_image
                .as_ref()
                .map(|(img, p, name)| (img, *p, name.as_str())),
        )
        .map_err(|e| AnalysisError::Input {
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

/// How square to the plane of collision the direct camera is taken to be, deg (one σ about
/// world x and y): what squaring a camera by eye or with a spirit level gives. Free flight cannot
/// measure it (a pitch shears z into y, which a change of trajectory does just as well), so
/// calibrate writes it as the direct view's `turn_uncertainty_deg` about x and y, and the
/// analysis carries it into every estimate. A user who knows better edits the two numbers.
pub const DIRECT_SQUARE_DEG: f64 = 1.0;

/// The measurements of discs seen whole: a disc the other sphere partly hides was fitted on
/// part of its edge, and is off along the line between them by more than its σ says (the
/// analysis widens it by how far such centres' x disagree with the other view's, which needs
/// the maps this is finding). Why: with the direct view's one silhouette of both split after
/// an impact along its axis, its crescent fits entered the free-fall fits and put an
/// independent render's direct scale at 1.13 px/mm instead of 1.96.
fn whole_discs_only(mut obs: Vec<FrameObs>) -> Vec<FrameObs> {
    for f in &mut obs {
        for per_view in &mut f.spheres {
            for m in per_view.iter_mut() {
                if m.as_ref().is_some_and(|m| m.hidden_in_part.is_some()) {
                    *m = None;
                }
            }
        }
    }
    obs
}

/// A scale's σ, %, as the config accepts it: at most 20 (a fit that knows the scale worse, or
/// not at all, says 20 rather than writing a config the analysis would refuse).
fn percent_known(p: f64) -> f64 {
    if p.is_finite() {
        p.abs().min(20.0)
    } else {
        20.0
    }
}

/// A turn's σ, deg, as the config accepts it: at most 10 (as `percent_known`).
fn degrees_known(d: f64) -> f64 {
    if d.is_finite() {
        d.abs().min(10.0)
    } else {
        10.0
    }
}

/// Fits the views' maps from one or more recordings of one rig (the first sets the
/// provisional scale; the flights of all are fitted together).
pub fn calibrate(
    sources: &mut [&mut dyn FrameSource],
    cfg: &Config,
    grid: Option<(&analysis::image::GreyImage, f64, &str)>,
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
    if cfg.geometry.direct.is_none() {
        return Err(CalibrateError::NoDirectView { source_name: name });
    }
    // The regions: the mirror's edge found in the frames; the config's regions are kept when
    // they keep each view's spheres whole and apart, and replaced by the found ones otherwise.
    let (regions, cfg) = {
        let found = regions::survey(src, cfg).map_err(|cause| CalibrateError::Provisional {
            source_name: name.clone(),
            cause,
        })?;
        let typed: Vec<[u32; 4]> = [&cfg.geometry.direct, &cfg.geometry.mirror]
            .into_iter()
            .flatten()
            .map(|v| v.region)
            .collect();
        let mut settled = cfg.clone();
        let note = match &found.split {
            Some(split) if found.separates(&typed) => {
                format!("{}; the config's regions keep each view's spheres whole and apart, and are kept: {typed:?}", split.describe())
            }
            Some(split) => {
                let (w, h) = src.dimensions();
                let (d, m) = split.regions(w, h);
                if let Some(v) = settled.geometry.direct.as_mut() {
                    v.region = d;
                }
                let mirror = match settled.geometry.mirror.as_mut() {
                    Some(v) => {
                        v.region = m;
                        format!("mirror {m:?}")
                    }
                    None => "the config has no [geometry.mirror] for the other side".into(),
                };
                format!(
                    "{}; the config's regions cut through a view's spheres, so these are used: direct {d:?}, {mirror}",
                    split.describe()
                )
            }
            None => "the mirror's edge was not found (no two groups of spheres that share x); the config's regions are kept".into(),
        };
        (note, settled)
    };
    let cfg = &cfg;
    let Some(direct_cfg) = cfg.geometry.direct.clone() else {
        return Err(CalibrateError::NoDirectView { source_name: name });
    };
    // Where the spheres are, before any geometry is trusted: every view's whole blobs.
    let survey =
        analysis::blob_survey(src, cfg, 60).map_err(|cause| CalibrateError::Provisional {
            source_name: name.clone(),
            cause,
        })?;
    let config_views = analysis::geometry::views(cfg);
    let kinds: Vec<ViewKind> = config_views.iter().map(|v| v.kind).collect();
    let di = kinds
        .iter()
        .position(|k| *k == ViewKind::Direct)
        .ok_or_else(|| data("no direct view".into()))?;
    let mi = kinds.iter().position(|k| *k == ViewKind::Mirror);
    // The mirror's x against the direct view's: where each view shows the same number of
    // blobs (one or two), paired in order of each view's image coordinate along x (u, or v on
    // a camera turned on its side: `x_index`); c_mirror = a·c_direct + b gives the mirror's
    // scale along x (and whether it reverses x) and the offset that makes the two x agree, so
    // that the spheres are labelled alike in both views.
    let mirror_line = mi.and_then(|mi| {
        let (kd, km) = (x_index(&config_views[di]), x_index(&config_views[mi]));
        let mut pairs = Vec::new();
        for f in &survey {
            let (mut d, mut m) = (f[di].clone(), f[mi].clone());
            if d.len() != m.len() || d.is_empty() || d.len() > 2 {
                continue;
            }
            d.sort_by(|p, q| p.0[kd].total_cmp(&q.0[kd]));
            m.sort_by(|p, q| p.0[km].total_cmp(&q.0[km]));
            pairs.extend(d.iter().zip(&m).map(|(p, q)| (p.0[kd], q.0[km])));
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
            .map(|(views, obs)| (views, whole_discs_only(obs)))
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
        let o = whole_discs_only(o);
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

    // Direct view: free fall per flight, pooled; whole discs only, as the bundle takes them
    // (`cut_by_border`).
    let mut acc = Vec::new();
    for (k, frames) in phases.iter().enumerate() {
        let pts: Vec<(f64, [f64; 2])> = frames
            .iter()
            .filter_map(|&i| {
                let m = obs[i].spheres[k % 2][di].as_ref()?;
                (!cut_by_border(&views[di], m)).then_some((obs[i].time_s, m.centre_px))
            })
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
    // How much more the flights' accelerations scatter than their σ say (Birge's ratio, at
    // least 1): a disc's centre errs alike from frame to frame as it crosses the light and the
    // pixel grid, which a fit that takes its residuals for independent cannot see, and every
    // scale from the flights' curvature carries it. On 72 hw-sim rigs drawn at random and
    // calibrated (docs/accuracy.md, session 48) the flights' scale was within its σ on 50 %
    // and beyond 3σ on 9, up to 6σ; the diameter's within its σ on 93 %, none beyond 2σ.
    let scatter = scatter_ratio(&acc, [au, av]);
    let scale_from_free_fall = Fitted {
        value: a_norm / g,
        sigma: sa / g * scatter,
    };
    let roll_deg = Fitted {
        value: au.atan2(av).to_degrees(),
        sigma: (sa / a_norm).to_degrees() * scatter,
    };
    let scale_from_diameter = diameter_scale(obs, di, diam)
        .ok_or_else(|| data("no sphere diameter measured in the direct view".into()))?;
    let origin_direct = direct_cfg
        .local_affine()
        .map(|(_, o)| o)
        .ok_or_else(|| data("the direct view's provisional map is incomplete".into()))?;
    let mi = views.iter().position(|v| v.kind == ViewKind::Mirror);
    // One lens for both views, about the frame's centre. Its k1 is kept where the flights show
    // it (beyond 3σ); else the maps are fitted again with none, as a lens-free rig's would be.
    let (width, height) = src.dimensions();
    let frame = LensFrame::of_frame(width, height);
    // A dot grid's lens, where one is given, is held; the flights then fit the rest.
    let grid_fit = match grid {
        Some((img, pitch_mm, grid_name)) => {
            if (img.width, img.height) != (width as usize, height as usize) {
                return Err(data(format!(
                    "the dot grid {grid_name} is {}×{} px, the recording's frames {width}×{height}: they must come from the same camera",
                    img.width, img.height
                )));
            }
            Some(
                grid::fit_grid(img, direct_cfg.region, pitch_mm, frame)
                    .map_err(|e| data(format!("the dot grid {grid_name}: {e}")))?,
            )
        }
        None => None,
    };
    let fit = |lens, held, perspective| {
        fit_bundle(
            obs,
            &phases,
            g,
            di,
            mi,
            origin_direct,
            (scale_from_free_fall.value, roll_deg.value.to_radians()),
            mi.map(|i| &views[i]),
            lens,
            held,
            perspective,
            views,
        )
        .map_err(&data)
    };
    let free = [true; 2];
    let (bundle, with_lens_k1, lens_found) = match &grid_fit {
        Some(gf) => (
            fit(Some(frame), Some(gf.lens_k1.value), free)?,
            gf.lens_k1,
            true,
        ),
        None => {
            let with_lens = fit(Some(frame), None, free)?;
            let k1 = with_lens.lens_k1;
            let found = k1.value.abs() > 3.0 * k1.sigma;
            let bundle = if found {
                with_lens
            } else {
                fit(None, None, free)?
            };
            (bundle, k1, found)
        }
    };
    // A camera whose perspective the flights do not show (`distance`) is written as an affine
    // map, so its maps are fitted again with its 1/distance held at 0, as an orthographic
    // rig's would be. Why: a free 1/distance trades with the scale where the spheres flew away
    // from the world origin's depth, and the scale at the origin it leaves is not the scale an
    // affine map needs there. A defocused side-lit recording (seed 31) came out with 1/distance
    // 0.005 /mm (not beyond 4σ, not kept) and both scales 6 % high: e 0.01 off (docs/accuracy.md,
    // session 47).
    let shows = [0, 1].map(|c| distance(bundle.kappa[c]).is_some());
    let bundle = if shows == [true; 2] {
        bundle
    } else {
        let lens = lens_found.then_some(frame);
        let held = grid_fit.as_ref().map(|gf| gf.lens_k1.value);
        fit(lens, held, shows)?
    };
    // A lens left out (not shown beyond 3σ) is not shown absent either: each map parameter's σ
    // takes in how far it moves with a lens fitted (the same holds otherwise). Why: k1 trades
    // with the mirror's roll and the scale over flights that cover little of the frame; on 72
    // rigs drawn at random, calibrated, a rig through k1 = −0.016 whose lens was left out
    // (−0.021 ± 0.009 found) had its mirror rolled 7.0 ± 1.0° for 0.6°, and z velocities 6σ
    // off (docs/accuracy.md, session 48).
    let bundle = if lens_found {
        bundle
    } else {
        match fit(Some(frame), None, shows) {
            Ok(with_lens) => widened_by(bundle, &with_lens),
            Err(_) => bundle,
        }
    };
    // The whole world scaled by 1/k and every map by k images the same flights (each camera's
    // 1/distance scales with the maps): so the flights fix the mirror's scale against the
    // direct view's far better than either alone, and a better direct scale moves both.
    // Under perspective the imaged diameter is the scale where the spheres flew, 1/(1 − κ·depth)
    // times the map's at the world origin.
    let at_origin = if distance(bundle.kappa[0]).is_some() {
        1.0 - bundle.kappa[0].value * bundle.mean_depth_mm[0]
    } else {
        1.0
    };
    let scale_from_diameter = Fitted {
        value: scale_from_diameter.value * at_origin,
        sigma: scale_from_diameter.sigma * at_origin,
    };
    // The flights' scale and gravity's direction know no better than their accelerations'
    // scatter lets them.
    let scale_from_flights = Fitted {
        value: bundle.direct_scale.value,
        sigma: bundle.direct_scale.sigma * scatter,
    };
    let mut bundle = bundle;
    bundle.direct_roll.sigma *= scatter;
    let (scale, diameter_disagrees_sigma) = combine_scales(scale_from_flights, scale_from_diameter);
    let k = scale.value / bundle.direct_scale.value;
    for kappa in &mut bundle.kappa {
        kappa.value *= k;
        kappa.sigma *= k;
    }
    if let Some(m) = bundle.mirror.as_mut() {
        // Its σ: the ratio's (the part of its own the direct view's does not share) and the
        // direct scale's as used.
        let rel = |f: Fitted| f.sigma / f.value;
        let ratio = (rel(m.scale).powi(2) - rel(bundle.direct_scale).powi(2)).max(0.0);
        m.scale.value *= k;
        m.scale.sigma = m.scale.value * (ratio + rel(scale).powi(2)).sqrt();
    }
    let m_direct = direct_matrix(
        scale.value,
        bundle.direct_roll.value.to_radians(),
        x_sign(&views[di]),
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
    // How well each map is known, for the analysis to carry into its estimates' σ. The direct
    // camera's pitch and yaw are not determined (see the docs): taken as 0 ± DIRECT_SQUARE_DEG.
    if let Some(v) = geometry.direct.as_mut() {
        v.px_per_mm_uncertainty_percent = Some(percent_known(100.0 * scale.sigma / scale.value));
        v.turn_uncertainty_deg = Some([
            DIRECT_SQUARE_DEG,
            DIRECT_SQUARE_DEG,
            degrees_known(bundle.direct_roll.sigma),
        ]);
    }
    let lens_k1 = with_lens_k1;
    let mut mirror = None;
    if let (Some(mi), Some(mut fit)) = (mi, bundle.mirror) {
        let region = cfg
            .geometry
            .mirror
            .as_ref()
            .map(|m| m.region)
            .unwrap_or(views[mi].region);
        let axes = MirrorAxes {
            sx: if fit.x_reversed { -1.0 } else { 1.0 },
            ..MirrorAxes::of(&views[mi])
        };
        let m = mirror_matrix(
            fit.scale.value,
            [fit.tilt_deg.value, fit.roll_deg.value, fit.yaw_deg.value].map(f64::to_radians),
            axes,
        );
        let mut origin = views[mi].origin_px;
        origin[axes.x_along] = fit.origin_x_px.value;
        let mut mirror_geometry =
            view_geometry(region, m, origin, ViewKind::Mirror, bundle.kappa[1]);
        mirror_geometry.px_per_mm_uncertainty_percent =
            Some(percent_known(100.0 * fit.scale.sigma / fit.scale.value));
        mirror_geometry.turn_uncertainty_deg =
            Some([fit.tilt_deg.sigma, fit.roll_deg.sigma, fit.yaw_deg.sigma].map(degrees_known));
        geometry.mirror = Some(mirror_geometry);
        fit.camera_distance_mm = distance(bundle.kappa[1]);
        if let Some(d) = diameter_scale(obs, mi, diam) {
            fit.scale_from_diameter = d;
        }
        mirror = Some(fit);
    }
    // Whether each image is mirrored is the user's to say (no flight tells): kept as given.
    if let Some(v) = geometry.direct.as_mut() {
        v.image_mirrored = direct_cfg.image_mirrored;
    }
    if let Some(v) = geometry.mirror.as_mut() {
        v.image_mirrored = cfg.geometry.mirror.as_ref().and_then(|m| m.image_mirrored);
    }
    if lens_found {
        let lens = frame.lens(lens_k1.value);
        for v in [geometry.direct.as_mut(), geometry.mirror.as_mut()]
            .into_iter()
            .flatten()
        {
            v.lens_k1 = Some(lens.k1);
            v.lens_centre_px = Some(lens.centre_px);
            v.lens_radius_px = Some(lens.radius_px);
        }
    }
    Ok(Calibrated {
        source: name,
        recordings: used,
        frames: obs.len(),
        impact_frame: split_frame,
        regions,
        direct: DirectFit {
            scale_from_free_fall,
            scale_from_diameter,
            scale_from_flights,
            scale,
            diameter_disagrees_sigma,
            roll_deg: bundle.direct_roll,
            residual_rms_px: bundle.residual_rms_px[0],
            camera_distance_mm: distance(bundle.kappa[0]),
        },
        mirror,
        lens_k1,
        lens_kept: lens_found,
        grid: grid_fit,
        geometry,
    })
}

/// `bundle` with each map parameter's σ widened by how far `other` (the same flights fitted
/// under another model) puts it: σ² + Δ². Not the cameras' 1/distance, whose σ decided
/// whether perspective shows and which the maps were written by.
fn widened_by(mut bundle: bundle::Bundle, other: &bundle::Bundle) -> bundle::Bundle {
    let widen = |f: &mut Fitted, o: Fitted| {
        let d = f.value - o.value;
        if d.is_finite() {
            f.sigma = f.sigma.hypot(d);
        }
    };
    widen(&mut bundle.direct_scale, other.direct_scale);
    widen(&mut bundle.direct_roll, other.direct_roll);
    if let (Some(m), Some(o)) = (bundle.mirror.as_mut(), other.mirror.as_ref()) {
        widen(&mut m.scale, o.scale);
        widen(&mut m.tilt_deg, o.tilt_deg);
        widen(&mut m.roll_deg, o.roll_deg);
        widen(&mut m.yaw_deg, o.yaw_deg);
        widen(&mut m.origin_x_px, o.origin_x_px);
    }
    bundle
}

/// Birge's ratio of the flights' accelerations (u, v, px/s², each with its σ per component)
/// about their weighted mean: √(χ²/dof), at least 1 (1 where there is only one).
fn scatter_ratio(acc: &[([f64; 2], f64)], mean: [f64; 2]) -> f64 {
    let chi2: f64 = acc
        .iter()
        .map(|(a, s)| ((a[0] - mean[0]).powi(2) + (a[1] - mean[1]).powi(2)) / (s * s))
        .sum();
    let dof = 2 * acc.len().saturating_sub(1);
    if dof > 0 && chi2.is_finite() {
        (chi2 / dof as f64).sqrt().max(1.0)
    } else {
        1.0
    }
}

/// How far apart, in σ of their difference, the flights' and the diameter's scales may lie and
/// still be weighed together.
pub const SCALES_AGREE_SIGMA: f64 = 3.0;

/// The direct view's scale from the flights (free fall, g known) and from the imaged diameter,
/// weighed by their σ; where they disagree beyond `SCALES_AGREE_SIGMA`, the flights' alone
/// (the diameter's rests on where the disc's model puts its edge, the flights' on g and the
/// frame rate) and how far apart they were. Why both: free fall over the 20–40 frames of a
/// short recording knows the scale to 0.4–2 %, the imaged diameter to 0.3–0.5 % (its σ,
/// `flights::diameter_scale`), and a grazing impact's e moves by about ψ1·0.8 times a scale's
/// error (the contact distance is a diameter in mm): on an independent render at ψ1 = 2.5 the
/// flights' scale alone, 0.8 % off (1.1σ), put e 0.049 off.
///
/// The σ says how far apart the two were, not only their own σ: weighed, it is widened by
/// their difference in σ where that is beyond 1 (the Particle Data Group's scale factor for
/// two measurements); the flights' alone take the difference itself into their σ, since
/// nothing here tells which of the two the look misled. Why: on 72 hw-sim rigs drawn at
/// random and calibrated, a side-lit one's flights put the scale 3.8 % high where its diameter
/// was right, a defocused one's 4.0 % with the diameter 2.1σ from them, and their velocities
/// came out up to 6σ off (docs/accuracy.md, session 48).
fn combine_scales(flights: Fitted, diameter: Fitted) -> (Fitted, Option<f64>) {
    let z = (diameter.value - flights.value) / flights.sigma.hypot(diameter.sigma);
    let usable = |f: Fitted| f.value.is_finite() && f.sigma.is_finite() && f.sigma > 0.0;
    if !(usable(flights) && usable(diameter)) || z.is_nan() {
        return (flights, None);
    }
    if z.abs() > SCALES_AGREE_SIGMA {
        let apart = diameter.value - flights.value;
        return (
            Fitted {
                value: flights.value,
                sigma: flights.sigma.hypot(apart),
            },
            Some(z),
        );
    }
    let (wf, wd) = (flights.sigma.powi(-2), diameter.sigma.powi(-2));
    (
        Fitted {
            value: (wf * flights.value + wd * diameter.value) / (wf + wd),
            sigma: (wf + wd).recip().sqrt() * z.abs().max(1.0),
        },
        None,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fitted(value: f64, sigma: f64) -> Fitted {
        Fitted { value, sigma }
    }

    /// Scales that agree are weighed by their σ, the result knowing more than either where
    /// they lie within 1σ of each other, and its σ widened by their distance in σ beyond; a
    /// diameter's scale beyond 3σ of the flights' is left out, the distance said and taken
    /// into the σ.
    #[test]
    fn the_flights_and_the_diameters_scales_are_weighed_where_they_agree() {
        let (wf, wd) = (0.0178f64.powi(-2), 0.0095f64.powi(-2));
        let weighed = (wf + wd).recip().sqrt();
        let (both, note) = combine_scales(fitted(2.3275, 0.0178), fitted(2.3146, 0.0095));
        assert_eq!(note, None);
        assert!((both.value - (wf * 2.3275 + wd * 2.3146) / (wf + wd)).abs() < 1e-12);
        assert!(both.value > 2.3146 && both.value < 2.3275);
        assert_eq!(both.sigma, weighed, "within 1σ of each other");
        // 2.0σ apart: the same weighing, its σ twice as wide.
        let apart = 2.0 * 0.0178f64.hypot(0.0095);
        let (wide, note) = combine_scales(fitted(2.3146 + apart, 0.0178), fitted(2.3146, 0.0095));
        assert_eq!(note, None);
        assert!((wide.sigma - 2.0 * weighed).abs() < 1e-12, "{}", wide.sigma);
        let (alone, note) = combine_scales(fitted(2.1576, 0.002), fitted(2.10, 0.005));
        assert_eq!(alone.value, 2.1576);
        assert!((alone.sigma - 0.002f64.hypot(2.1576 - 2.10)).abs() < 1e-12);
        let z = note.unwrap();
        assert!(
            (z - (2.10 - 2.1576) / 0.002f64.hypot(0.005)).abs() < 1e-9,
            "{z}"
        );
        // Nothing to weigh: the flights' as they are.
        let (kept, note) = combine_scales(fitted(2.0, 0.01), fitted(f64::NAN, f64::NAN));
        assert_eq!((kept.value, note), (2.0, None));
    }

    /// A lens left out widens each map parameter's σ by how far a lens fitted moves it (here
    /// the mirror's roll, 7° against 0.6°), and leaves the values and the 1/distance alone.
    #[test]
    fn a_lens_left_out_widens_the_maps_by_what_it_would_move() {
        let bundle = |roll_deg: f64, scale: f64| bundle::Bundle {
            direct_scale: fitted(scale, 0.01),
            direct_roll: fitted(0.3, 0.2),
            kappa: [fitted(0.0, 1e-4), fitted(0.001, 2e-4)],
            lens_k1: fitted(0.0, 0.0),
            mirror: Some(MirrorFit {
                scale: fitted(2.1, 0.02),
                scale_from_diameter: fitted(f64::NAN, f64::NAN),
                roll_deg: fitted(roll_deg, 1.0),
                tilt_deg: fitted(-5.0, 0.4),
                yaw_deg: fitted(0.5, 0.3),
                origin_x_px: fitted(120.0, 0.01),
                x_along_v: false,
                x_reversed: false,
                residual_rms_px: 0.04,
                points: 100,
                camera_distance_mm: None,
            }),
            residual_rms_px: [0.04, 0.04],
            mean_depth_mm: [0.0, 0.0],
        };
        let without = bundle(7.0, 2.16);
        let with_lens = bundle(0.6, 2.14);
        let w = widened_by(without, &with_lens);
        let m = w.mirror.as_ref().unwrap();
        assert_eq!(m.roll_deg.value, 7.0);
        assert!(
            (m.roll_deg.sigma - 1.0f64.hypot(6.4)).abs() < 1e-9,
            "{}",
            m.roll_deg.sigma
        );
        assert!((w.direct_scale.sigma - 0.01f64.hypot(0.02)).abs() < 1e-9);
        assert_eq!(
            (m.tilt_deg.sigma, m.yaw_deg.sigma),
            (0.4, 0.3),
            "unmoved: as they were"
        );
        assert_eq!((w.kappa[1].value, w.kappa[1].sigma), (0.001, 2e-4));
    }

    /// The flights' accelerations scattered twice as widely as their σ say widen every scale
    /// from them twice; scattered within their σ, not at all (the ratio is never below 1).
    #[test]
    fn flights_that_scatter_beyond_their_sigma_widen_it() {
        let mean = [0.0, 21_000.0];
        let at = |du: f64, dv: f64| ([mean[0] + du, mean[1] + dv], 100.0);
        // Each flight 2σ off in u and in v: χ² = 4·(2² + 2²) = 32 over 2·(4 − 1) = 6 dof.
        let wide = [
            at(200.0, 200.0),
            at(-200.0, -200.0),
            at(200.0, -200.0),
            at(-200.0, 200.0),
        ];
        let r = scatter_ratio(&wide, mean);
        assert!((r - (32.0f64 / 6.0).sqrt()).abs() < 1e-12, "{r}");
        let tight = [
            at(10.0, -20.0),
            at(-10.0, 20.0),
            at(5.0, 0.0),
            at(-5.0, 0.0),
        ];
        assert_eq!(scatter_ratio(&tight, mean), 1.0);
        assert_eq!(scatter_ratio(&wide[..1], mean), 1.0);
    }

    /// What calibrate writes for how well it knows a map is always a value the config accepts:
    /// the analysis must not refuse the config calibrate printed.
    #[test]
    fn how_well_a_map_is_known_is_written_within_the_configs_bounds() {
        let toml = |p: f64, d: f64| {
            format!(
                "[geometry.direct]\nregion = [0, 0, 240, 96]\npx_per_mm = 2.0\norigin_px = [120.0, 48.0]\nu_axis = \"+x\"\nv_axis = \"-y\"\npx_per_mm_uncertainty_percent = {}\nturn_uncertainty_deg = [0.0, 0.0, {}]\n",
                percent_known(p),
                degrees_known(d)
            )
        };
        for (p, d) in [
            (0.21, 0.088),
            (35.0, 12.0),
            (f64::NAN, f64::INFINITY),
            (-0.3, -0.1),
        ] {
            let t = toml(p, d);
            assert!(Config::from_toml_str(&t, "cal.toml").is_ok(), "{t}");
        }
        assert_eq!(percent_known(0.21), 0.21);
        assert_eq!(degrees_known(f64::NAN), 10.0);
    }
}
