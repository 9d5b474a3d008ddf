//! Analysis: pure functions from recorded frames to a report. It never touches hardware — it
//! reads sessions or TIFF stacks — which is what makes `replay` exact: the same frames and the
//! same config give the same report, bit for bit.
//!
//! Pipeline: segment each view → sub-pixel circles (`circle`) → a/b labels and world centres
//! (`tracking`) → ballistic fits before/after, impact, normal, e with uncertainties
//! (`kinematics`) → `report`. Imperfect footage gives a report with warnings and a list of the
//! frames that could not be measured; it fails only when no honest result exists (no spheres,
//! no impact, too few frames).

pub mod circle;
pub mod detect;
pub mod geometry;
pub mod image;
pub mod kinematics;
pub mod markers;
pub mod report;
pub mod rotation;
pub mod spin;
pub mod thesis;
pub mod tracking;
pub mod tracks;

use crate::config::Config;
use crate::session::tiff::TiffStack;
use crate::session::{FrameMeta, SessionError, SessionReader};
use circle::DotMask;
use geometry::{View, ViewKind};
use image::GreyImage;
use kinematics::{derive, uncertainties, Fits, ImpactError, Series, SideFit, Spins, V3};
use nalgebra::Rotation3;
use report::*;
use rotation::SpinFit;
use tracking::{DotMasks, FrameObs};

#[derive(Debug, thiserror::Error)]
pub enum AnalysisError {
    #[error(transparent)]
    Session(#[from] SessionError),
    #[error("{source_name}: {message}")]
    Input {
        source_name: String,
        message: String,
    },
    #[error("{source_name}: no impact found: {message}")]
    NoImpact {
        source_name: String,
        message: String,
    },
}

/// Frames to analyse, from a session or from footage recorded elsewhere.
pub trait FrameSource {
    fn source(&self) -> Source;
    fn len(&self) -> usize;
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    fn meta(&self, i: usize) -> FrameMeta;
    fn read(&mut self, i: usize, img: &mut GreyImage) -> Result<(), AnalysisError>;
    fn frames_dropped(&self) -> u64;
    fn dimensions(&self) -> (u32, u32);
    /// Things about the input a reader of the report must know.
    fn warnings(&self) -> Vec<String>;
}

pub struct SessionSource {
    pub reader: SessionReader,
    buf: Vec<u8>,
}

impl SessionSource {
    pub fn new(reader: SessionReader) -> Self {
        SessionSource {
            reader,
            buf: Vec::new(),
        }
    }
}

impl FrameSource for SessionSource {
    fn source(&self) -> Source {
        Source {
            kind: "session".into(),
            name: self.reader.manifest.id.clone(),
            frames: self.reader.frames.len() as u64,
            frame_rate_hz: self.reader.manifest.camera.frame_rate_hz,
            timestamps: "device".into(),
        }
    }
    fn len(&self) -> usize {
        self.reader.frames.len()
    }
    fn meta(&self, i: usize) -> FrameMeta {
        self.reader.frames[i]
    }
    fn read(&mut self, i: usize, img: &mut GreyImage) -> Result<(), AnalysisError> {
        self.reader.read_frame(i, &mut self.buf)?;
        img.load(
            &self.buf,
            self.reader.width as usize,
            self.reader.height as usize,
            self.reader.bytes_per_pixel,
        );
        Ok(())
    }
    fn frames_dropped(&self) -> u64 {
        crate::session::count_gaps(&self.reader.frames)
    }
    fn dimensions(&self) -> (u32, u32) {
        (self.reader.width, self.reader.height)
    }
    fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        if !self.reader.is_complete() {
            w.push(format!(
                "session status is {:?}{}: analysed the {} frames that were written",
                self.reader.manifest.status,
                self.reader
                    .manifest
                    .reason
                    .as_ref()
                    .map(|r| format!(" ({r})"))
                    .unwrap_or_default(),
                self.reader.frames.len()
            ));
        }
        if self.reader.frames_truncated > 0 {
            w.push(format!(
                "{} frame(s) listed in the index were cut short on disk and ignored",
                self.reader.frames_truncated
            ));
        }
        w
    }
}

pub struct TiffSource {
    stack: TiffStack,
    meta: Vec<FrameMeta>,
    frame_rate_hz: f64,
}

impl TiffSource {
    pub fn new(stack: TiffStack, frame_rate_hz: f64) -> Self {
        let meta = stack.meta(frame_rate_hz);
        TiffSource {
            stack,
            meta,
            frame_rate_hz,
        }
    }
}

impl FrameSource for TiffSource {
    fn source(&self) -> Source {
        Source {
            kind: "tiff".into(),
            name: self
                .stack
                .path
                .file_name()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default(),
            frames: self.stack.frames.len() as u64,
            frame_rate_hz: self.frame_rate_hz,
            timestamps: "frame number / camera.frame_rate_hz".into(),
        }
    }
    fn len(&self) -> usize {
        self.stack.frames.len()
    }
    fn meta(&self, i: usize) -> FrameMeta {
        self.meta[i]
    }
    fn read(&mut self, i: usize, img: &mut GreyImage) -> Result<(), AnalysisError> {
        img.load(
            &self.stack.frames[i],
            self.stack.width as usize,
            self.stack.height as usize,
            self.stack.bytes_per_pixel,
        );
        Ok(())
    }
    fn frames_dropped(&self) -> u64 {
        0
    }
    fn dimensions(&self) -> (u32, u32) {
        (self.stack.width, self.stack.height)
    }
    fn warnings(&self) -> Vec<String> {
        Vec::new()
    }
}

/// Per-sphere coordinate series (x, y, z) in world mm over the given frames, built from the
/// views: y from the direct view, z from the mirror, x from the direct view when there is one
/// (the mirror's x is the calibration check).
fn series(obs: &[FrameObs], views: &[View], s: usize, frames: &[usize]) -> [Series; 3] {
    let mut out: [Series; 3] = [Vec::new(), Vec::new(), Vec::new()];
    let has_direct = views.iter().any(|v| v.kind == ViewKind::Direct);
    for f in frames.iter().map(|&k| &obs[k]) {
        for (vi, view) in views.iter().enumerate() {
            let Some(m) = &f.spheres[s][vi] else { continue };
            for (axis, val) in view.unproject(m.centre_px) {
                if axis == 0 && has_direct && view.kind != ViewKind::Direct {
                    continue;
                }
                out[axis].push((f.time_s, val));
            }
        }
    }
    out
}

/// Frames of one flight phase of sphere `s` (before or after `split`, more than `guard` away):
/// only the time span in which the primary view (direct, when configured) saw it, because the
/// other view may still see the sphere rolling in its tube, where free flight does not hold.
fn side_frames(obs: &[FrameObs], s: usize, pre: bool, split: f64, guard: f64) -> Vec<usize> {
    let on_side = |t: f64| {
        if pre {
            t < split - guard
        } else {
            t > split + guard
        }
    };
    let seen = || {
        obs.iter()
            .filter(|f| on_side(f.time_s) && f.spheres[s][0].is_some())
            .map(|f| f.time_s)
    };
    let lo = seen().fold(f64::INFINITY, f64::min);
    let hi = seen().fold(f64::NEG_INFINITY, f64::max);
    (0..obs.len())
        .filter(|&k| on_side(obs[k].time_s) && obs[k].time_s >= lo && obs[k].time_s <= hi)
        .collect()
}

/// [a pre, b pre, a post, b post]
fn phases(obs: &[FrameObs], split: f64, guard: f64) -> [Vec<usize>; 4] {
    [(0, true), (1, true), (0, false), (1, false)]
        .map(|(s, pre)| side_frames(obs, s, pre, split, guard))
}

/// The frames of each phase in which the sphere flies freely: starting from the 15 frames next
/// to the impact, frames further away are taken one by one while they lie on the ballistic
/// trajectory fitted so far (within 4σ of its prediction, σ from the residuals and the
/// extrapolation); three misses in a row end the phase. Before that, a sphere seen still
/// rolling in its tube (its vertical acceleration there is a fraction of g) bent the fit.
fn flight_phases(
    obs: &[FrameObs],
    views: &[View],
    split: f64,
    guard: f64,
    g: f64,
) -> [Vec<usize>; 4] {
    let ph = phases(obs, split, guard);
    [0, 1, 2, 3].map(|k| free_flight(obs, views, k % 2, &ph[k], k < 2, g))
}

fn free_flight(
    obs: &[FrameObs],
    views: &[View],
    s: usize,
    frames: &[usize],
    pre: bool,
    g: f64,
) -> Vec<usize> {
    const SEED: usize = 15;
    if frames.len() <= SEED + 2 {
        return frames.to_vec();
    }
    let order: Vec<usize> = if pre {
        frames.iter().rev().copied().collect()
    } else {
        frames.to_vec()
    };
    let t_ref = obs[order[0]].time_s;
    let gravity = [0.0, -g, 0.0];
    let mut kept: Vec<usize> = order[..SEED].to_vec();
    let mut fit = SideFit::fit(&series(obs, views, s, &kept), t_ref, g);
    let mut misses = 0;
    for &k in &order[SEED..] {
        let one = series(obs, views, s, &[k]);
        let tau = obs[k].time_s - t_ref;
        let on_track = (0..3).all(|axis| {
            let Some(l) = &fit.axes[axis] else {
                return true;
            };
            one[axis].iter().all(|&(_, x)| {
                let predicted = l.p0 + l.v * tau + 0.5 * gravity[axis] * tau * tau;
                let extrapolation =
                    l.cov[(0, 0)] + 2.0 * tau * l.cov[(0, 1)] + tau * tau * l.cov[(1, 1)];
                let sigma = (l.rms * l.rms + extrapolation.max(0.0)).sqrt().max(0.005);
                (x - predicted).abs() <= 4.0 * sigma
            })
        });
        if on_track {
            kept.push(k);
            misses = 0;
            fit = SideFit::fit(&series(obs, views, s, &kept), t_ref, g);
        } else {
            misses += 1;
            if misses >= 3 {
                break;
            }
        }
    }
    kept.sort_unstable();
    kept
}

/// The four ballistic fits for a given split.
fn fit_all(obs: &[FrameObs], views: &[View], t_ref: f64, split: f64, guard: f64, g: f64) -> Fits {
    let ph = flight_phases(obs, views, split, guard, g);
    let mut fits = [0, 1, 2, 3].map(|k| SideFit::fit(&series(obs, views, k % 2, &ph[k]), t_ref, g));
    keep_common_axes(&mut fits);
    fits
}

/// Markers lifted again about the sphere's centre on its fitted trajectory instead of the
/// frame's own circle fit: the trajectory, fitted over every frame of the phase, is several
/// times more precise than one frame's circle, and an error of the centre moves every marker of
/// the frame alike, which the rotation between two frames takes for a turn. Frames where the
/// trajectory and the circle disagree by more than 0.3 px keep their own centre.
fn relift_on_trajectories(
    obs: &[FrameObs],
    views: &[View],
    fits: &Fits,
    ph: &[Vec<usize>; 4],
    split: f64,
    g: f64,
    radii: [f64; 2],
) -> Vec<FrameObs> {
    let mut out = obs.to_vec();
    for (k, frames) in ph.iter().enumerate() {
        let s = k % 2;
        if fits[k].axes.iter().any(|a| a.is_none()) {
            continue;
        }
        for &i in frames {
            let Some(f) = out.get_mut(i) else { continue };
            let (p, _) = kinematics::pos_vel(&fits[k], f.time_s - split, g);
            for (vi, view) in views.iter().enumerate() {
                let Some(m) = f.spheres[s][vi].as_mut() else {
                    continue;
                };
                let c = view.project(&p);
                if (c[0] - m.centre_px[0]).hypot(c[1] - m.centre_px[1]) > 0.3 {
                    continue;
                }
                m.markers = m
                    .markers
                    .iter()
                    .filter_map(|mk| markers::lift(view, mk.centre_px, c, radii[s]))
                    .collect();
            }
        }
    }
    out
}

/// Drops a world axis from all four fits unless every one of them measured it, and says which
/// axes went. A coordinate that no view saw for one sphere in one phase (in the mirror the two
/// spheres can hide each other from the impact to the end of the recording) must not enter the
/// collision as a zero velocity: the collision is then analysed in the axes all four share.
fn keep_common_axes(fits: &mut Fits) -> Vec<usize> {
    let mut dropped = Vec::new();
    for i in 0..3 {
        let present = fits.iter().filter(|f| f.axes[i].is_some()).count();
        if present > 0 && present < fits.len() {
            for f in fits.iter_mut() {
                f.axes[i] = None;
            }
            dropped.push(i);
        }
    }
    dropped
}

/// Which of [a pre, b pre, a post, b post] measured no position along world axis `i`.
fn phases_missing_axis(
    obs: &[FrameObs],
    views: &[View],
    split: f64,
    guard: f64,
    g: f64,
    i: usize,
) -> Vec<&'static str> {
    let ph = flight_phases(obs, views, split, guard, g);
    let names = ["a before", "b before", "a after", "b after"];
    (0..4)
        .filter(|&k| series(obs, views, k % 2, &ph[k])[i].is_empty())
        .map(|k| names[k])
        .collect()
}

/// Analyses any frame source with the given config.
pub fn analyze(
    src: &mut dyn FrameSource,
    cfg: &Config,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Report, AnalysisError> {
    analyze_detailed(src, cfg, progress).map(|(r, _)| r)
}

/// The intermediate results behind a report, for accuracy studies and the thesis baseline.
pub struct Details {
    pub views: Vec<View>,
    pub obs: Vec<FrameObs>,
    /// Impact time on the source's clock, s.
    pub impact_time_s: f64,
    /// Frame indices of [a pre, b pre, a post, b post].
    pub phases: [Vec<usize>; 4],
    /// Spin measurements of [a pre, b pre, a post, b post].
    pub spins: Vec<spin::SpinMeasurement>,
}

pub fn analyze_detailed(
    src: &mut dyn FrameSource,
    cfg: &Config,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(Report, Details), AnalysisError> {
    let info = src.source();
    let input_err = |message: String| AnalysisError::Input {
        source_name: info.name.clone(),
        message,
    };
    if src.is_empty() {
        return Err(input_err("no frames to analyse".into()));
    }
    let (w, h) = src.dimensions();
    let views = geometry::views(cfg);
    for v in &views {
        let [x, y, vw, vh] = v.region;
        if x + vw > w || y + vh > h {
            return Err(input_err(format!(
                "geometry.{}.region {:?} does not fit the {w}×{h} frames",
                v.kind.name(),
                v.region
            )));
        }
    }
    // Two passes over the frames, each counted as half of the progress: the first finds the
    // markers and spins, the second measures the circles again without the dots that the
    // spins put on each rim.
    let (obs, unmeasured) =
        tracking::measure_all(src, &views, cfg, &DotMasks::new(), &mut |i, n| {
            progress(i / 2, n)
        })?;
    let (warnings, frames_dropped) = (src.warnings(), src.frames_dropped());
    let input = || Input {
        info: info.clone(),
        warnings: warnings.clone(),
        frames_dropped,
    };
    let first = analyze_observations(input(), obs, unmeasured, views.clone(), cfg)?;
    let dots = rim_dots(&first.1, cfg);
    if dots.is_empty() {
        progress(src.len(), src.len());
        return Ok(first);
    }
    let (obs, unmeasured) = tracking::measure_all(src, &views, cfg, &dots, &mut |i, n| {
        progress((n + i) / 2, n)
    })?;
    analyze_observations(input(), obs, unmeasured, views, cfg)
}

/// Markers a fit of the grey levels near the edge must leave out (`circle::profile_fit`): every
/// marker found in any frame of a sphere's flight, in either view, carried with the fitted
/// spins to each other frame of that flight, and kept where it lies on the rim band of a view.
/// A dot within a pixel of the limb darkens the edge too little to be rejected as an outlier,
/// and moves the centre by a slowly changing few hundredths of a pixel as the sphere turns; the
/// markers finder does not reach there (53°), but the other view sees the same dot near its own
/// centre, and other frames saw it before it reached the limb — before the impact for a dot on
/// the rim after it, since the orientation is continuous through the impact and only ω changes
/// there. A carried dot's mask grows by the drift its spin's uncertainty allows, and a dot is
/// not carried further than `MAX_DRIFT_PX` of drift. Without a spin, only the same frame's
/// other view is used.
fn rim_dots(details: &Details, cfg: &Config) -> DotMasks {
    const MAX_DRIFT_PX: f64 = 0.5;
    let dot_r_mm = cfg.analysis.marker_diameter_mm / 2.0;
    let t_c = details.impact_time_s;
    let mut out = DotMasks::new();
    for s in 0..2 {
        let spin = |k: usize| details.spins.get(k).and_then(|m| m.fit.as_ref());
        let (before, after) = (spin(s), spin(s + 2));
        let carry = |t0: f64, t1: f64| carry_orientation(t0, t1, t_c, before, after);
        let radius_mm = cfg.spheres.sphere(s).0 / 2.0;
        let behind_limb = -(dot_r_mm / radius_mm).min(1.0).sin();
        let frames: Vec<usize> = details.phases[s]
            .iter()
            .chain(&details.phases[s + 2])
            .copied()
            .collect();
        for &i in &frames {
            let fi = &details.obs[i];
            for (vi, view) in details.views.iter().enumerate() {
                let Some(m) = &fi.spheres[s][vi] else {
                    continue;
                };
                let dot_px = dot_r_mm * view.px_per_mm;
                let radius_px = radius_mm * view.px_per_mm;
                let inner_px = m.diameter_px / 2.0
                    - circle::PROFILE_BAND_PX
                    - dot_px
                    - DotMask::MARGIN_PX
                    - MAX_DRIFT_PX;
                let mut masks: Vec<DotMask> = Vec::new();
                for &j in &frames {
                    let fj = &details.obs[j];
                    let Some((turn, sigma_rad)) = carry(fj.time_s, fi.time_s) else {
                        continue;
                    };
                    let drift_px = sigma_rad * radius_px;
                    if drift_px > MAX_DRIFT_PX {
                        continue;
                    }
                    for d in fj.spheres[s].iter().flatten().flat_map(|mj| &mj.markers) {
                        let rel = turn * d.rel_mm;
                        if rel.normalize().dot(&view.facing) < behind_limb {
                            continue;
                        }
                        let off = [
                            view.px_per_mm * view.u_axis.dot(&rel),
                            view.px_per_mm * view.v_axis.dot(&rel),
                        ];
                        if off[0].hypot(off[1]) < inner_px {
                            continue;
                        }
                        let c = [m.centre_px[0] + off[0], m.centre_px[1] + off[1]];
                        let seen = masks
                            .iter()
                            .any(|q| (q.centre_px[0] - c[0]).hypot(q.centre_px[1] - c[1]) < 0.3);
                        if !seen {
                            masks.push(DotMask::around(c, dot_px + drift_px));
                        }
                    }
                }
                if !masks.is_empty() {
                    out.entry((fi.index as usize, vi))
                        .or_default()
                        .extend(masks);
                }
            }
        }
    }
    out
}

/// The turn of a sphere from time t0 to t1, s, and its angle's σ, rad: with the spin fitted
/// before the impact (at t_c) on that side of it, after it on the other, and both in turn
/// across it — the orientation is continuous through the impact; only ω changes there. None
/// where a spin the carry needs was not measured.
fn carry_orientation(
    t0: f64,
    t1: f64,
    t_c: f64,
    before: Option<&SpinFit>,
    after: Option<&SpinFit>,
) -> Option<(Rotation3<f64>, f64)> {
    let within = |a: f64, b: f64| -> Option<(Rotation3<f64>, f64)> {
        let fit = if a.max(b) <= t_c { before } else { after }?;
        let dt = b - a;
        let sigma = fit.cov.trace().max(0.0).sqrt() * dt.abs();
        Some((Rotation3::from_scaled_axis(fit.omega * dt), sigma))
    };
    if t0 == t1 {
        return Some((Rotation3::identity(), 0.0));
    }
    if (t0 - t_c) * (t1 - t_c) >= 0.0 {
        return within(t0, t1);
    }
    let (first, e0) = within(t0, t_c)?;
    let (second, e1) = within(t_c, t1)?;
    Some((second * first, e0 + e1))
}

/// Analyses centres digitised elsewhere (see `tracks` for the CSV columns).
pub fn analyze_tracks(path: &std::path::Path, cfg: &Config) -> Result<Report, AnalysisError> {
    let views = geometry::views(cfg);
    let (input, obs) = tracks::read(path, &views, cfg.camera.frame_rate_hz)?;
    analyze_observations(input, obs, Vec::new(), views, cfg).map(|(r, _)| r)
}

/// What the analysis needs to know about its input besides the measurements.
pub struct Input {
    pub info: Source,
    pub warnings: Vec<String>,
    pub frames_dropped: u64,
}

/// Everything after per-frame measurement: calibration, fits, impact, spins, the report. Also
/// the entry point for centres digitised elsewhere (`tracks`).
pub fn analyze_observations(
    input: Input,
    obs: Vec<FrameObs>,
    unmeasured: Vec<Unmeasured>,
    views: Vec<View>,
    cfg: &Config,
) -> Result<(Report, Details), AnalysisError> {
    let Input {
        info,
        warnings: input_warnings,
        frames_dropped,
    } = input;
    let input_err = |message: String| AnalysisError::Input {
        source_name: info.name.clone(),
        message,
    };
    let mut views = views;
    let calibration = calibrate_mirror(&obs, &mut views);
    let g = cfg.analysis.gravity_mm_s2;
    let contact_mm = 0.5 * (cfg.spheres.sphere(0).0 + cfg.spheres.sphere(1).0);
    let period = 1.0 / info.frame_rate_hz;
    let primary = 0; // views[0] is direct when present, else the mirror

    // Initial split: the frame where a and b are seen closest together in the primary view.
    let mut closest: Option<(f64, f64)> = None;
    for f in &obs {
        if let (Some(a), Some(b)) = (&f.spheres[0][primary], &f.spheres[1][primary]) {
            let d = (a.centre_px[0] - b.centre_px[0]).hypot(a.centre_px[1] - b.centre_px[1]);
            if closest.is_none_or(|(_, dd)| d < dd) {
                closest = Some((f.time_s, d));
            }
        }
    }
    let Some((mut split, _)) = closest else {
        return Err(input_err(format!(
            "spheres a and b were never both measured in the {} view ({} frames; see the geometry and threshold settings)",
            views[primary].kind.name(),
            obs.len()
        )));
    };
    let min_side = cfg.analysis.min_frames_per_side as usize;
    let radii = [cfg.spheres.sphere(0).0 / 2.0, cfg.spheres.sphere(1).0 / 2.0];
    for _ in 0..8 {
        let fits = fit_all(&obs, &views, split, split, 0.5 * period, g);
        for (k, side) in fits.iter().enumerate() {
            let n = side.axes[0].map(|l| l.n).unwrap_or(0);
            if n < min_side {
                let which = ["a before", "b before", "a after", "b after"][k];
                return Err(input_err(format!(
                    "only {n} usable frame(s) of sphere {which} the impact, need analysis.min_frames_per_side = {min_side}"
                )));
            }
        }
        let d = match derive(&fits, None, radii, contact_mm, g) {
            Ok(d) => d,
            Err(ImpactError::NoContact { closest_mm }) => {
                return Err(AnalysisError::NoImpact {
                    source_name: info.name.clone(),
                    message: format!(
                        "the spheres' trajectories come no closer than {closest_mm:.2} mm, but contact is at {contact_mm:.2} mm"
                    ),
                })
            }
            Err(ImpactError::NotApproaching) => {
                return Err(AnalysisError::NoImpact {
                    source_name: info.name.clone(),
                    message: "the spheres are not approaching each other before the closest frame".into(),
                })
            }
        };
        let new_split = split + d.tau_c;
        let moved = (new_split - split).abs();
        split = new_split;
        if moved < 1e-7 {
            break;
        }
    }
    // Final fits referenced at the impact time, so p0 and v are the state at impact.
    let fits = fit_all(&obs, &views, split, split, 0.5 * period, g);
    let mut warnings = input_warnings;

    // Spins, one constant vector per sphere and flight phase.
    let method = cfg.analysis.rotation;
    let ph = flight_phases(&obs, &views, split, 0.5 * period, g);
    let obs_spin = relift_on_trajectories(&obs, &views, &fits, &ph, split, g, radii);
    let measured: Vec<spin::SpinMeasurement> = (0..4)
        .map(|k| spin::measure(&obs_spin, &ph[k], k % 2, method))
        .collect();
    let phase_names = ["a before", "b before", "a after", "b after"];
    let missing: Vec<&str> = (0..4)
        .filter(|&k| measured[k].fit.is_none())
        .map(|k| phase_names[k])
        .collect();
    let spin_fits: Option<[&SpinFit; 4]> = match [0, 1, 2, 3].map(|k| measured[k].fit.as_ref()) {
        [Some(a), Some(b), Some(c), Some(d)] => Some([a, b, c, d]),
        _ => None,
    };
    let spins = if let Some(f) = spin_fits {
        Some(Spins {
            omega: f.map(|f| f.omega),
            cov: f.map(|f| f.cov),
        })
    } else {
        warnings.push(format!(
            "spin not measured for sphere {} the impact (too few markers tracked over too few frames): spins there, beta, psi1, psi2 and branch_hint are null",
            missing.join(", ")
        ));
        None
    };
    let impact_err = |e: ImpactError| AnalysisError::NoImpact {
        source_name: info.name.clone(),
        message: format!("{e:?}"),
    };
    let d = derive(
        &fits,
        spins.as_ref().map(|s| &s.omega),
        radii,
        contact_mm,
        g,
    )
    .map_err(impact_err)?;
    let sd = combined_uncertainties(
        &obs, &views, &ph, &fits, spin_fits, radii, contact_mm, split, g,
    )
    .map_err(impact_err)?;
    let t_c = split + d.tau_c;

    // Axes some view measures, but not for every sphere in every phase: dropped by fit_all.
    let seen_axes: Vec<usize> = (0..3)
        .filter(|&i| {
            views
                .iter()
                .any(|v| v.unproject([0.0, 0.0]).iter().any(|(axis, _)| *axis == i))
        })
        .collect();
    let lost_axes: Vec<usize> = seen_axes
        .iter()
        .copied()
        .filter(|&i| fits.iter().all(|f| f.axes[i].is_none()))
        .collect();
    let three_d = views.len() == 2 && lost_axes.is_empty();
    if views.len() < 2 {
        warnings.push(format!(
            "only the {} view is configured: results are 2-D (the missing coordinate is taken as constant)",
            views[0].kind.name()
        ));
    }
    for &i in &lost_axes {
        let missing = phases_missing_axis(&obs, &views, split, 0.5 * period, g, i);
        warnings.push(format!(
            "{} was not measured for sphere {} the impact (in the mirror view the spheres hide each other): results are 2-D, without {}",
            ["x", "y", "z"][i],
            missing.join(", "),
            ["x", "y", "z"][i]
        ));
    }
    let dropped = frames_dropped;
    if dropped > 0 {
        warnings.push(format!(
            "{dropped} frame(s) were dropped by the camera (gaps in frame ids)"
        ));
    }
    let dt_check = (d.tau_intersection - d.tau_contact_distance).abs();
    if dt_check > 2.0 * period {
        warnings.push(format!(
            "impact time from contact distance and from the trajectory intersection differ by {:.3} ms: check spheres.diameter_mm and px_per_mm",
            dt_check * 1e3
        ));
    }

    let est3 = |v: V3, s: V3| Estimate {
        value: [v.x, v.y, v.z],
        uncertainty: [s.x, s.y, s.z],
    };
    let impact_frame = obs
        .iter()
        .min_by(|p, q| (p.time_s - t_c).abs().total_cmp(&(q.time_s - t_c).abs()))
        .map(|f| f.index)
        .unwrap_or(0);
    // 3-D RMS distance of the centres from the fitted trajectory.
    let rms = |f: &SideFit| {
        f.axes
            .iter()
            .flatten()
            .map(|l| l.rms * l.rms)
            .sum::<f64>()
            .sqrt()
    };
    let diameters = |s: usize, kind: ViewKind| -> Option<Scalar> {
        let vi = views.iter().position(|v| v.kind == kind)?;
        let mut ds: Vec<f64> = obs
            .iter()
            .filter_map(|f| f.spheres[s][vi].as_ref().map(|m| m.diameter_px))
            .collect();
        if ds.is_empty() {
            return None;
        }
        ds.sort_by(f64::total_cmp);
        let med = ds[ds.len() / 2];
        let mut dev: Vec<f64> = ds.iter().map(|x| (x - med).abs()).collect();
        dev.sort_by(f64::total_cmp);
        let sigma = 1.4826 * dev[dev.len() / 2];
        Some(Estimate {
            value: med,
            uncertainty: sigma / (ds.len() as f64).sqrt(),
        })
    };
    let tracked_frames: Vec<usize> = obs
        .iter()
        .filter(|f| f.spheres.iter().any(|s| s.iter().any(|m| m.is_some())))
        .map(|f| f.index as usize)
        .collect();
    let position_at_impact = |s: usize| {
        let p = kinematics::pos_vel(&fits[s], d.tau_c, g).0;
        let sd = |i: usize| {
            fits[s].axes[i]
                .map(|l| l.cov[(0, 0)].max(0.0).sqrt())
                .unwrap_or(0.0)
        };
        Estimate {
            value: [p.x, p.y, p.z],
            uncertainty: [sd(0), sd(1), sd(2)],
        }
    };
    let sphere = |s: usize| SphereResult {
        position_impact_mm: Some(position_at_impact(s)),
        velocity_pre_mm_s: est3(d.velocities[s], sd.velocities[s]),
        velocity_post_mm_s: est3(d.velocities[2 + s], sd.velocities[2 + s]),
        spin_pre_rad_s: measured[s].fit.as_ref().map(spin_estimate),
        spin_post_rad_s: measured[2 + s].fit.as_ref().map(spin_estimate),
        diameter_px: ViewValues {
            direct: diameters(s, ViewKind::Direct),
            mirror: diameters(s, ViewKind::Mirror),
        },
        markers_tracked: tracked_frames
            .iter()
            .map(|&k| {
                measured[s]
                    .markers_per_frame
                    .get(&k)
                    .or_else(|| measured[2 + s].markers_per_frame.get(&k))
                    .copied()
                    .unwrap_or(0)
            })
            .collect(),
    };
    let tracks: Vec<TrackFrame> = obs
        .iter()
        .filter(|f| f.spheres.iter().any(|s| s.iter().any(|m| m.is_some())))
        .map(|f| {
            let one = |s: usize| -> Option<SphereTrack> {
                let per_view = |kind: ViewKind| {
                    let vi = views.iter().position(|v| v.kind == kind)?;
                    f.spheres[s][vi].as_ref().map(|m| ViewTrack {
                        centre_px: m.centre_px,
                        uncertainty_px: m.sigma_px,
                        diameter_px: m.diameter_px,
                        markers_px: m.markers.iter().map(|k| k.centre_px).collect(),
                    })
                };
                let (direct, mirror) = (per_view(ViewKind::Direct), per_view(ViewKind::Mirror));
                if direct.is_none() && mirror.is_none() {
                    return None;
                }
                let mut centre: [Option<f64>; 3] = [None; 3];
                for (vi, view) in views.iter().enumerate().rev() {
                    if let Some(m) = &f.spheres[s][vi] {
                        for (axis, val) in view.unproject(m.centre_px) {
                            centre[axis] = Some(val);
                        }
                    }
                }
                Some(SphereTrack {
                    direct,
                    mirror,
                    centre_mm: centre,
                })
            };
            TrackFrame {
                frame: f.index,
                frame_id: f.frame_id,
                time_s: f.time_s,
                a: one(0),
                b: one(1),
            }
        })
        .collect();
    let used = |k: usize| fits[k].axes[0].map(|l| l.n as u64).unwrap_or(0);
    let report = Report {
        schema: REPORT_SCHEMA.into(),
        software: Software {
            name: "impactcam".into(),
            version: env!("CARGO_PKG_VERSION").into(),
        },
        source: info,
        dimensionality: if three_d { "3d" } else { "2d" }.into(),
        impact: Impact {
            time_s: Estimate {
                value: t_c,
                uncertainty: sd.tau_c,
            },
            frame: impact_frame,
            time_intersection_s: split + d.tau_intersection,
            contact_distance_mm: contact_mm,
        },
        normal: est3(d.normal, sd.normal),
        e: Some(Estimate {
            value: d.e,
            uncertainty: sd.e,
        }),
        beta: d
            .beta
            .zip(sd.beta)
            .map(|(value, uncertainty)| Estimate { value, uncertainty }),
        psi1: d
            .psi1
            .zip(sd.psi1)
            .map(|(value, uncertainty)| Estimate { value, uncertainty }),
        psi2: d
            .psi2
            .zip(sd.psi2)
            .map(|(value, uncertainty)| Estimate { value, uncertainty }),
        branch_hint: d.psi2.zip(sd.psi2).and_then(|(v, u)| branch_hint(v, u)),
        spheres: Spheres {
            a: sphere(0),
            b: sphere(1),
        },
        tracks,
        quality: Quality {
            frames_total: obs.len() as u64,
            frames_dropped: dropped,
            frames_used_pre: PerSphere {
                a: used(0),
                b: used(1),
            },
            frames_used_post: PerSphere {
                a: used(2),
                b: used(3),
            },
            fit_residual_rms_mm: FitResiduals {
                a_pre: rms(&fits[0]),
                b_pre: rms(&fits[1]),
                a_post: rms(&fits[2]),
                b_post: rms(&fits[3]),
            },
            calibration,
            unmeasured,
            warnings,
        },
    };
    Ok((
        report,
        Details {
            views,
            obs,
            impact_time_s: t_c,
            phases: ph,
            spins: measured,
        },
    ))
}

/// One-sigma uncertainties of everything derived. Propagating the fit covariances assumes each
/// frame's error is independent and alike; a frame that pulls a fit (a centre biased by the
/// neighbouring sphere just before contact, say) breaks that. So the kinematic variance is the
/// mean of the propagated one and a leave-one-frame-out jackknife of the whole derivation; the
/// spin part is added from the spin fits' per-frame influences (`spin_variance`).
#[allow(clippy::too_many_arguments)]
fn combined_uncertainties(
    obs: &[FrameObs],
    views: &[View],
    ph: &[Vec<usize>; 4],
    fits: &Fits,
    spins: Option<[&SpinFit; 4]>,
    radii: [f64; 2],
    contact_mm: f64,
    split: f64,
    g: f64,
) -> Result<kinematics::Derived, ImpactError> {
    let omega = spins.map(|f| f.map(|f| f.omega));
    // The trajectories' part, with the spins held at their estimates.
    let spins_held = omega.map(|omega| Spins {
        omega,
        cov: [nalgebra::Matrix3::zeros(); 4],
    });
    let kin = uncertainties(fits, spins_held.as_ref(), radii, contact_mm, g)?;
    let omega = omega.as_ref();
    let mut frames: Vec<usize> = ph.iter().flatten().copied().collect();
    frames.sort_unstable();
    frames.dedup();
    let mut reps: Vec<Vec<f64>> = Vec::new();
    for &k in &frames {
        let without: [Vec<usize>; 4] =
            [0, 1, 2, 3].map(|j| ph[j].iter().copied().filter(|&f| f != k).collect());
        let fk: Fits =
            [0, 1, 2, 3].map(|j| SideFit::fit(&series(obs, views, j % 2, &without[j]), split, g));
        let mut fk = fk;
        keep_common_axes(&mut fk);
        if let Ok(d) = derive(&fk, omega, radii, contact_mm, g) {
            reps.push(d.to_vec());
        }
    }
    let vk = kin.to_vec();
    let spin_var = match (spins, omega) {
        (Some(measured), Some(omega)) => {
            spin_variance(fits, omega, measured, radii, contact_mm, g)?
        }
        _ => vec![0.0; vk.len()],
    };
    let n = reps.len() as f64;
    let mut out = vk.clone();
    for i in 0..vk.len() {
        let jk = (n >= 3.0 && reps.iter().all(|r| r.len() == vk.len())).then(|| {
            let mean = reps.iter().map(|r| r[i]).sum::<f64>() / n;
            ((n - 1.0) / n * reps.iter().map(|r| (r[i] - mean).powi(2)).sum::<f64>()).sqrt()
        });
        // Two estimates of one variance, the fits' covariance and the jackknife over frames:
        // their mean. The larger of the two, as before, is biased high by the choosing, and
        // once the rim dots were masked it covered e 79–87 % of the time in the bench.
        let kinematic = match jk {
            Some(jk) => (vk[i].powi(2) + jk.powi(2)) / 2.0,
            None => vk[i].powi(2),
        };
        out[i] = (kinematic + spin_var[i]).sqrt();
    }
    Ok(kinematics::Derived::from_vec(&kin, &out))
}

/// The variance the spins give each derived quantity, from the spin fits' influences of each
/// frame taken together: one frame's errors move both spheres' spins of that phase at once,
/// and β and ψ combine the two. Propagating each spin's covariance on its own would leave
/// that covariance out (on the bench it changed β's σ by a few per cent either way).
fn spin_variance(
    fits: &Fits,
    omega: &[V3; 4],
    measured: [&SpinFit; 4],
    radii: [f64; 2],
    contact_mm: f64,
    g: f64,
) -> Result<Vec<f64>, ImpactError> {
    let mut frames: Vec<usize> = measured
        .iter()
        .flat_map(|m| m.frame_influence.iter().map(|(f, _)| *f))
        .collect();
    frames.sort_unstable();
    frames.dedup();
    let len = derive(fits, Some(omega), radii, contact_mm, g)?
        .to_vec()
        .len();
    let mut var = vec![0.0; len];
    for f in frames {
        let step: [V3; 4] = [0, 1, 2, 3].map(|k| {
            measured[k]
                .frame_influence
                .iter()
                .find(|(frame, _)| *frame == f)
                .map_or(V3::zeros(), |(_, d)| *d)
        });
        let moved = |sign: f64| {
            let w = [0, 1, 2, 3].map(|k| omega[k] + sign * step[k]);
            derive(fits, Some(&w), radii, contact_mm, g)
                .ok()
                .map(|d| d.to_vec())
                .filter(|v| v.len() == len)
        };
        // Central differences: the influence terms are small, and β is smooth in the spins.
        if let (Some(up), Some(down)) = (moved(1.0), moved(-1.0)) {
            for i in 0..len {
                var[i] += ((up[i] - down[i]) / 2.0).powi(2);
            }
        }
    }
    Ok(var)
}

fn spin_estimate(f: &SpinFit) -> Vector {
    let s = |i: usize| f.cov[(i, i)].max(0.0).sqrt();
    Estimate {
        value: [f.omega.x, f.omega.y, f.omega.z],
        uncertainty: [s(0), s(1), s(2)],
    }
}

/// Which Walton branch the data suggest, from the sign of ψ2 alone: sliding keeps the slip's
/// direction (ψ2 > 0 unless just above the break point), sticking with β0 > 0 reverses it. Null
/// when ψ2 is within two standard deviations of zero.
fn branch_hint(psi2: f64, sigma: f64) -> Option<String> {
    if psi2.abs() <= 2.0 * sigma {
        None
    } else if psi2 > 0.0 {
        Some("sliding".into())
    } else {
        Some("sticking".into())
    }
}

/// Pairs (direct x, mirror x) in mm of every sphere measured in both views of a frame.
fn x_pairs(obs: &[FrameObs], views: &[View]) -> Option<Vec<(f64, f64)>> {
    let di = views.iter().position(|v| v.kind == ViewKind::Direct)?;
    let mi = views.iter().position(|v| v.kind == ViewKind::Mirror)?;
    let x = |vi: usize, px: [f64; 2]| {
        views[vi]
            .unproject(px)
            .iter()
            .find(|(a, _)| *a == 0)
            .map(|(_, x)| *x)
    };
    Some(
        obs.iter()
            .flat_map(|f| {
                (0..2).filter_map(move |s| {
                    Some((f.spheres[s][di].as_ref()?, f.spheres[s][mi].as_ref()?))
                })
            })
            .filter_map(|(d, m)| Some((x(di, d.centre_px)?, x(mi, m.centre_px)?)))
            .collect(),
    )
}

fn residual_stats(pairs: &[(f64, f64)]) -> (f64, f64) {
    let n = pairs.len().max(1) as f64;
    let mean = pairs.iter().map(|(d, m)| m - d).sum::<f64>() / n;
    let rms = (pairs.iter().map(|(d, m)| (m - d).powi(2)).sum::<f64>() / n).sqrt();
    (mean, rms)
}

/// Refines the mirror view's scale and u-offset from the x coordinate both views see
/// (physics.md §5, minimum calibration): x_mirror = a·x_direct + b over the whole recording.
/// With the config's scale s and offset u0, the true ones are a·s and u0 + sign·b·s. Applied
/// only when the fit is well conditioned (≥ 10 pairs over ≥ 3 mm of x); always reported.
fn calibrate_mirror(obs: &[FrameObs], views: &mut [View]) -> Option<Calibration> {
    let pairs = x_pairs(obs, views)?;
    if pairs.is_empty() {
        return None;
    }
    let (mean_before, rms_before) = residual_stats(&pairs);
    let mi = views.iter().position(|v| v.kind == ViewKind::Mirror)?;
    let config_scale = views[mi].px_per_mm;
    let config_origin_u = views[mi].origin_px[0];
    let n = pairs.len() as f64;
    let (mx, my) = (
        pairs.iter().map(|p| p.0).sum::<f64>() / n,
        pairs.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxx: f64 = pairs.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = pairs.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let lo = pairs.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
    let hi = pairs.iter().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max);
    let refined = pairs.len() >= 10 && hi - lo >= 3.0 && sxx > 0.0;
    let (mut mean_after, mut rms_after) = (mean_before, rms_before);
    if refined {
        let a = sxy / sxx;
        let b = my - a * mx;
        let sign = views[mi].u_axis.x.signum();
        views[mi].px_per_mm = a * config_scale;
        views[mi].origin_px[0] = config_origin_u + sign * b * config_scale;
        let after = x_pairs(obs, views)?;
        (mean_after, rms_after) = residual_stats(&after);
    }
    Some(Calibration {
        frames: pairs.len() as u64,
        mirror_minus_direct_x_mean_mm: mean_before,
        mirror_minus_direct_x_rms_mm: rms_before,
        refined,
        mirror_px_per_mm_config: config_scale,
        mirror_px_per_mm_refined: views[mi].px_per_mm,
        mirror_origin_u_px_config: config_origin_u,
        mirror_origin_u_px_refined: views[mi].origin_px[0],
        residual_mean_mm_after: mean_after,
        residual_rms_mm_after: rms_after,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_axis_missing_in_one_phase_is_dropped_from_all_four() {
        let times: Vec<f64> = (0..10).map(|k| k as f64 * 1e-3).collect();
        let line = |v: f64| -> kinematics::Series { times.iter().map(|&t| (t, v * t)).collect() };
        let full = [line(100.0), line(-200.0), line(5.0)];
        let no_z = [line(100.0), line(-200.0), Vec::new()];
        let mut fits: Fits = [
            SideFit::fit(&full, 0.0, 0.0),
            SideFit::fit(&full, 0.0, 0.0),
            SideFit::fit(&no_z, 0.0, 0.0),
            SideFit::fit(&full, 0.0, 0.0),
        ];
        assert!(fits[0].axes[2].is_some());
        assert_eq!(keep_common_axes(&mut fits), vec![2]);
        assert!(fits
            .iter()
            .all(|f| f.axes[2].is_none() && f.axes[0].is_some()));
        // Nothing to drop when every phase has every axis it had.
        assert!(keep_common_axes(&mut fits).is_empty());
    }

    /// A sphere seen rolling down its tube (vertical acceleration a fifth of g) for 30 frames,
    /// then flying for 40 before the impact: only the flight is kept for the fit.
    #[test]
    fn frames_still_in_the_tube_are_left_out_of_the_flight() {
        use crate::analysis::tracking::Measurement;
        let cfg = Config::default_config();
        let views = geometry::views(&cfg);
        let g = cfg.analysis.gravity_mm_s2;
        let dt = 1e-3;
        let exit = 30;
        // Positions and velocities at the tube exit, then ballistic.
        let (p_exit, v_exit) = (V3::new(-40.0, 20.0, 0.0), V3::new(400.0, -300.0, 0.0));
        let obs: Vec<FrameObs> = (0..70)
            .map(|k| {
                let tau = (k as f64 - exit as f64) * dt;
                let a = if k < exit { 0.2 * g } else { g };
                let p = p_exit + v_exit * tau + V3::new(0.0, -0.5 * a * tau * tau, 0.0);
                let m = |vi: usize| {
                    Some(Measurement {
                        centre_px: views[vi].project(&p),
                        blob_centroid_px: views[vi].project(&p),
                        sigma_px: [0.02, 0.02],
                        diameter_px: 13.7,
                        markers: Vec::new(),
                    })
                };
                FrameObs {
                    index: k as u64,
                    frame_id: k as u64,
                    time_s: k as f64 * dt,
                    spheres: [vec![m(0), m(1)], vec![None, None]],
                }
            })
            .collect();
        let all: Vec<usize> = (0..70).collect();
        let kept = free_flight(&obs, &views, 0, &all, true, g);
        assert!(
            kept.first()
                .is_some_and(|&f| (exit - 2..=exit + 1).contains(&f))
                && kept.len() >= 38,
            "kept frames {:?}..{:?} ({})",
            kept.first(),
            kept.last(),
            kept.len()
        );
    }

    /// A dot seen before the impact is carried to a frame after it by the spin before the
    /// impact up to it and the spin after it from there; its σ grows with both; and it is not
    /// carried across where the spin on the far side is unknown.
    #[test]
    fn dots_are_carried_through_the_impact_with_both_spins() {
        let fit = |w: V3, sigma: f64| SpinFit {
            omega: w,
            cov: nalgebra::Matrix3::identity() * (sigma * sigma / 3.0),
            pairs: 10,
            frame_influence: Vec::new(),
        };
        let (before, after) = (
            fit(V3::new(0.0, 0.0, 200.0), 1.0),
            fit(V3::new(50.0, 0.0, 120.0), 2.0),
        );
        let (t_c, t0, t1) = (0.100, 0.090, 0.104);
        let (turn, sigma) = carry_orientation(t0, t1, t_c, Some(&before), Some(&after)).unwrap();
        let expected = Rotation3::from_scaled_axis(after.omega * 0.004)
            * Rotation3::from_scaled_axis(before.omega * 0.010);
        assert!((turn.matrix() - expected.matrix()).norm() < 1e-12);
        assert!(
            (sigma - (1.0 * 0.010 + 2.0 * 0.004)).abs() < 1e-12,
            "{sigma}"
        );
        // Back again: the inverse turn.
        let (back, _) = carry_orientation(t1, t0, t_c, Some(&before), Some(&after)).unwrap();
        assert!(((back * turn).matrix() - nalgebra::Matrix3::identity()).norm() < 1e-12);
        // One spin of the pair was not measured: only its own side is reachable.
        assert!(carry_orientation(t0, t1, t_c, Some(&before), None).is_none());
        assert!(carry_orientation(t0, 0.095, t_c, Some(&before), None).is_some());
    }

    /// One frame that turns both spheres' spins after the impact by opposite amounts leaves
    /// R_a·ω_a + R_b·ω_b, and so β, unchanged: the spins' variance of β must see that, where
    /// propagating each spin's covariance on its own would not. The same turn in the same
    /// direction doubles β's change.
    #[test]
    fn spins_moved_by_the_same_frame_are_propagated_together() {
        let g = 9806.65;
        let radius = 3.0;
        // Oblique along x, slipping along y: g_t ≠ 0, t along y, n along x.
        let times = |sign: f64| -> Vec<f64> { (1..15).map(|k| sign * k as f64 * 1e-3).collect() };
        let side = |p0: V3, v: V3, ts: &[f64]| {
            let line = |i: usize| -> Series {
                let gi = if i == 1 { -g } else { 0.0 };
                ts.iter()
                    .map(|&t| (t, p0[i] + v[i] * t + 0.5 * gi * t * t))
                    .collect()
            };
            SideFit::fit(&[line(0), line(1), line(2)], 0.0, g)
        };
        let (va, vb) = (V3::new(500.0, 100.0, 0.0), V3::new(-500.0, -100.0, 0.0));
        let (va2, vb2) = (V3::new(-450.0, 60.0, 0.0), V3::new(450.0, -60.0, 0.0));
        let (pa, pb) = (V3::new(-radius, 0.0, 0.0), V3::new(radius, 0.0, 0.0));
        let fits: Fits = [
            side(pa, va, &times(-1.0)),
            side(pb, vb, &times(-1.0)),
            side(pa, va2, &times(1.0)),
            side(pb, vb2, &times(1.0)),
        ];
        let omega = [
            V3::new(0.0, 0.0, -80.0),
            V3::new(0.0, 0.0, 90.0),
            V3::new(0.0, 0.0, -60.0),
            V3::new(0.0, 0.0, 70.0),
        ];
        let fit = |influence: Vec<(usize, V3)>| SpinFit {
            omega: V3::zeros(),
            cov: nalgebra::Matrix3::zeros(),
            pairs: 10,
            frame_influence: influence,
        };
        let still = fit(Vec::new());
        let turn = V3::new(0.0, 0.0, 2.0);
        let beta_var = |a_post: &SpinFit, b_post: &SpinFit| {
            let v = spin_variance(
                &fits,
                &omega,
                [&still, &still, a_post, b_post],
                [radius; 2],
                2.0 * radius,
                g,
            )
            .unwrap();
            v[v.len() - 1]
        };
        let (only_a, opposite, same) = (
            beta_var(&fit(vec![(20, turn)]), &still),
            beta_var(&fit(vec![(20, turn)]), &fit(vec![(20, -turn)])),
            beta_var(&fit(vec![(20, turn)]), &fit(vec![(20, turn)])),
        );
        assert!(only_a > 1e-6, "one spin turned must move β: {only_a}");
        assert!(
            opposite < 1e-9 * only_a,
            "opposite turns cancel: {opposite} against {only_a}"
        );
        assert!(
            (same / only_a - 4.0).abs() < 1e-3,
            "same turns add: {same} against {only_a}"
        );
        // Different frames are independent: their variances add.
        let apart = beta_var(&fit(vec![(20, turn)]), &fit(vec![(21, -turn)]));
        assert!(
            (apart / only_a - 2.0).abs() < 1e-3,
            "{apart} against {only_a}"
        );
    }
}
