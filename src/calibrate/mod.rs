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
//! Each parameter is written with its σ, widened where the flights say it is known worse than
//! their own fit claims (`sigma`).
//!
//! What the data cannot give is kept from the config: the world origin (the direct view's
//! `origin_px`, and the mirror's v offset, which sets z = 0), the sign of z in the mirror (which
//! side of the collision the mirror is on), and the views' layout (above each other or side by
//! side, and which side is the direct view). The direct camera's pitch and yaw cannot be told
//! from a change of the flights either: the camera is taken as square, with
//! `DIRECT_SQUARE_DEG` of uncertainty that the analysis carries.

use crate::analysis::geometry::ViewKind;

mod bundle;
mod checked;
mod flights;
pub mod grid;
mod maps;
mod output;
mod provisional;
mod regions;
mod sigma;

use crate::analysis::tracking::FrameObs;
use crate::analysis::{self, AnalysisError, FrameSource};
use crate::config::Config;
use bundle::{fit_bundle, LensFrame};
use flights::{diameter_scale, flights, free_fall, FreeFall};
use maps::{direct_matrix, distance, mirror_matrix, view_geometry, x_sign};
use provisional::{first_flights, flight_views, line_fit, x_index, MirrorAxes};
pub use sigma::SCALES_AGREE_SIGMA;
use sigma::{combine_scales, degrees_known, percent_known, widened_by};

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
    /// Why a lens the flights showed was not kept after all: the maps fitted with it would be
    /// refused by the config's reader (`checked`).
    pub lens_refused: Option<String>,
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

/// Fits the views' maps from one or more recordings of one rig (the first sets the
/// provisional scale; the flights of all are fitted together). The geometry is checked as the
/// config's reader checks it: a map the analysis would refuse is never written. Where a lens the
/// flights show gives such maps, they are fitted again without it (`lens_refused` says why);
/// where they are refused even so, an error names the key.
pub fn calibrate(
    sources: &mut [&mut dyn FrameSource],
    cfg: &Config,
    grid: Option<(&analysis::image::GreyImage, f64, &str)>,
) -> Result<Calibrated, CalibrateError> {
    let first = calibrate_once(sources, cfg, grid, true)?;
    checked::settled(first, grid.is_some(), || {
        calibrate_once(sources, cfg, grid, false)
    })
}

/// `calibrate`'s fit; `lens_from_flights`: whether a lens the flights show (beyond 3σ) is kept.
fn calibrate_once(
    sources: &mut [&mut dyn FrameSource],
    cfg: &Config,
    grid: Option<(&analysis::image::GreyImage, f64, &str)>,
    lens_from_flights: bool,
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
    let (regions, cfg) =
        regions::settle(src, cfg).map_err(|cause| CalibrateError::Provisional {
            source_name: name.clone(),
            cause,
        })?;
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
    let (cfg, (views, obs, split_frame, phases)) =
        first_flights(src, cfg, &direct_cfg, &survey, di, mirror_line).map_err(data)?;
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
        let (_, ph) =
            flights(&o, flight_views(&views, di)).map_err(|message| CalibrateError::Data {
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

    // Direct view: free fall per flight, pooled (whole discs only, as the bundle takes them).
    let FreeFall {
        scale: scale_from_free_fall,
        roll_deg,
        scatter,
    } = free_fall(obs, views, &phases, di, g).ok_or_else(|| {
        data(
            "no flight of 6 frames or more in the direct view: free fall cannot be measured".into(),
        )
    })?;
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
            let found = lens_from_flights && k1.value.abs() > 3.0 * k1.sigma;
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
    // (Not where a lens was shown and its maps refused (`checked`): those maps are no
    // measure of how far a real lens would move these.)
    let bundle = if lens_found || !lens_from_flights {
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
            views[di].mirrored,
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
            view_geometry(region, m, origin, views[mi].mirrored, bundle.kappa[1]);
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
        lens_refused: None,
        grid: grid_fit,
        geometry,
    })
}
