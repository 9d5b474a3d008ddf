//! The report contract (`report.json`, schema "impactcam.report/1"): what users' scripts read.
//! Every estimate is `{"value", "uncertainty"}` (one standard deviation, same shape); a quantity
//! the data cannot give is null, with a warning in `quality.warnings` saying why.

use serde::{Deserialize, Serialize};

pub const REPORT_SCHEMA: &str = "impactcam.report/1";

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Estimate<T> {
    pub value: T,
    pub uncertainty: T,
}

pub type Scalar = Estimate<f64>;
pub type Vector = Estimate<[f64; 3]>;

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Report {
    pub schema: String,
    pub software: Software,
    pub source: Source,
    /// "3d" with both views, "2d" when only one view is configured (z unknown).
    pub dimensionality: String,
    pub impact: Impact,
    /// Contact normal at impact, unit vector from a to b.
    pub normal: Vector,
    pub e: Option<Scalar>,
    pub beta: Option<Scalar>,
    pub psi1: Option<Scalar>,
    pub psi2: Option<Scalar>,
    pub branch_hint: Option<String>,
    pub spheres: Spheres,
    pub tracks: Vec<TrackFrame>,
    pub quality: Quality,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Software {
    pub name: String,
    pub version: String,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Source {
    /// "session", "tracks", or the file's format: "tiff", "mraw", "cine", "fmf", "sequence".
    pub kind: String,
    /// Session id or file name (not a path, so a moved session replays identically).
    pub name: String,
    pub frames: u64,
    pub frame_rate_hz: f64,
    /// Whether frame times come from device timestamps or from frame numbers / frame rate.
    pub timestamps: String,
    /// Footage from another camera: the index (in the file) of its trigger frame, where the
    /// file records one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trigger_frame: Option<i64>,
    /// Footage from another camera: its number of the first frame, relative to the trigger
    /// (negative before it), where the file records it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub first_frame_number: Option<i64>,
    /// Footage from another camera: the exposure it records, s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exposure_s: Option<f64>,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Impact {
    /// First contact on the camera clock, s: where the pre-impact trajectories reach contact
    /// distance.
    pub time_s: Scalar,
    /// Index (in this recording) of the frame nearest the impact.
    pub frame: u64,
    /// Cross-check: least-squares intersection of the pre- and post-impact separation lines, s.
    pub time_intersection_s: f64,
    pub contact_distance_mm: f64,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Spheres {
    pub a: SphereResult,
    pub b: SphereResult,
}

/// One sphere's spin change as its markers show it and as the contact impulse implies it
/// (physics.md §8).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct SpinCheck {
    /// ω after − ω before from the markers, rad/s (null where either was not measured).
    pub delta_spin_markers_rad_s: Option<Vector>,
    /// (1/(K r)) n × Δv, rad/s.
    pub delta_spin_impulse_rad_s: Vector,
    /// χ² of their difference over their combined covariance (null without both).
    pub chi2: Option<f64>,
    pub dof: u32,
    /// Where `spin_post_rad_s` comes from: "markers and impulse", "impulse", or "markers".
    pub spin_post_from: String,
    /// The factor both spins' covariances were scaled by, as σ (1 where the check passed);
    /// where it failed, the disagreement r was then added to each as r rᵀ.
    pub uncertainty_inflated_by: f64,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct SphereResult {
    /// Centre at the impact time from the pre-impact ballistic fit, mm (absent from reports
    /// written before it was added; the schema's other fields are unchanged).
    #[serde(default)]
    pub position_impact_mm: Option<Vector>,
    /// Velocity at the impact time from the pre-impact ballistic fit, mm/s.
    pub velocity_pre_mm_s: Vector,
    pub velocity_post_mm_s: Vector,
    pub spin_pre_rad_s: Option<Vector>,
    pub spin_post_rad_s: Option<Vector>,
    /// Measured silhouette diameter per view, px (median over frames, with its spread).
    pub diameter_px: ViewValues,
    /// The impulse–spin cross-check (absent from reports written before it was added, and
    /// where the velocities are 2-D).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spin_check: Option<SpinCheck>,
    /// Markers tracked, per frame of `tracks` (empty until marker tracking exists).
    pub markers_tracked: Vec<u32>,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct ViewValues {
    #[serde(deserialize_with = "scalar_nan_if_null")]
    pub direct: Option<Scalar>,
    #[serde(deserialize_with = "scalar_nan_if_null")]
    pub mirror: Option<Scalar>,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct TrackFrame {
    /// Index in the recording.
    pub frame: u64,
    pub frame_id: u64,
    pub time_s: f64,
    pub a: Option<SphereTrack>,
    pub b: Option<SphereTrack>,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct SphereTrack {
    pub direct: Option<ViewTrack>,
    pub mirror: Option<ViewTrack>,
    /// World centre, mm; a coordinate no view measured in this frame is null.
    pub centre_mm: [Option<f64>; 3],
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct ViewTrack {
    /// Sub-pixel centre (u, v), full-frame pixel coordinates.
    pub centre_px: [f64; 2],
    /// Null where the digitising software gave none (a tracks CSV): read back as NaN.
    #[serde(deserialize_with = "nan_if_null_2")]
    pub uncertainty_px: [f64; 2],
    #[serde(deserialize_with = "nan_if_null")]
    pub diameter_px: f64,
    /// Markers found inside the disc (sub-pixel image positions), lifted to 3-D for spin.
    pub markers_px: Vec<[f64; 2]>,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Quality {
    pub frames_total: u64,
    pub frames_dropped: u64,
    pub frames_used_pre: PerSphere<u64>,
    pub frames_used_post: PerSphere<u64>,
    /// RMS distance of the measured centres from the fitted trajectories, mm.
    pub fit_residual_rms_mm: FitResiduals,
    /// Mirror-view x minus direct-view x over frames seen in both, mm.
    pub calibration: Option<Calibration>,
    /// Frames/views where a sphere could not be measured, and why.
    pub unmeasured: Vec<Unmeasured>,
    pub warnings: Vec<String>,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct PerSphere<T> {
    pub a: T,
    pub b: T,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct FitResiduals {
    pub a_pre: f64,
    pub a_post: f64,
    pub b_pre: f64,
    pub b_post: f64,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Calibration {
    /// Sphere centres seen in both views.
    pub frames: u64,
    /// Mirror-view x minus direct-view x with the config's geometry, mm.
    pub mirror_minus_direct_x_mean_mm: f64,
    pub mirror_minus_direct_x_rms_mm: f64,
    /// Whether the mirror's scale and offset were refined from the redundant x (needs ≥ 10
    /// centres over ≥ 3 mm of x).
    pub refined: bool,
    pub mirror_px_per_mm_config: f64,
    pub mirror_px_per_mm_refined: f64,
    /// The mirror's origin's u, px (kept as it was first written; `mirror_origin_px_*` give
    /// both image coordinates).
    pub mirror_origin_u_px_config: f64,
    pub mirror_origin_u_px_refined: f64,
    /// The mirror's origin [u, v], px, as the config gives it and as refined. The refinement
    /// moves it along the image of world x, which is v on a camera turned on its side and
    /// both axes on a rolled one (a general map): the u fields alone do not say what changed
    /// there. Absent from reports written before session 48.
    #[serde(default)]
    pub mirror_origin_px_config: Option<[f64; 2]>,
    #[serde(default)]
    pub mirror_origin_px_refined: Option<[f64; 2]>,
    /// Mirror x minus direct x after refinement, mm.
    pub residual_mean_mm_after: f64,
    pub residual_rms_mm_after: f64,
    /// How mirror x minus direct x (after refinement) changes with the world y and z, mm per
    /// mm: zero for a right geometry; a rolled view the map does not describe shows here.
    #[serde(default)]
    pub residual_per_mm_of_y: Option<Scalar>,
    #[serde(default)]
    pub residual_per_mm_of_z: Option<Scalar>,
    /// Free fall as each view measures it on its own axes (pooled over the flights): −g along
    /// y and 0 along x and z for a right geometry; a turned or mis-scaled view shows here.
    #[serde(default)]
    pub free_fall: Vec<FreeFall>,
    /// The geometry's parameters whose uncertainty the config gives, each with the step the
    /// analysis was re-run with and what that step changed e by; every estimate's uncertainty
    /// includes these changes (`geometry_sigma`). Empty for a config that gives none.
    #[serde(default)]
    pub geometry_uncertainty: Vec<GeometryTerm>,
}

/// One parameter of the configured geometry and what its uncertainty does.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct GeometryTerm {
    /// The config key, e.g. "geometry.direct.turn_uncertainty_deg[2]" (the camera's roll).
    pub parameter: String,
    /// The step the analysis was re-run with: rad for a turn, a fraction for a scale.
    pub step: f64,
    /// |change of e| that step made (null where e was not measured both ways).
    pub e_change: Option<f64>,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct FreeFall {
    pub view: String,
    /// "x", "y" or "z".
    pub axis: String,
    pub acceleration_mm_s2: Scalar,
    pub expected_mm_s2: f64,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Unmeasured {
    pub frame: u64,
    pub view: String,
    pub reason: String,
}

/// serde writes a NaN as null; reading it back gives the NaN again (not an error).
fn nan_if_null<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

fn nan_if_null_2<'de, D: serde::Deserializer<'de>>(d: D) -> Result<[f64; 2], D::Error> {
    let v = <[Option<f64>; 2]>::deserialize(d)?;
    Ok(v.map(|x| x.unwrap_or(f64::NAN)))
}

fn scalar_nan_if_null<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<Scalar>, D::Error> {
    let v = Option::<Estimate<Option<f64>>>::deserialize(d)?;
    Ok(v.map(|e| Estimate {
        value: e.value.unwrap_or(f64::NAN),
        uncertainty: e.uncertainty.unwrap_or(f64::NAN),
    }))
}
