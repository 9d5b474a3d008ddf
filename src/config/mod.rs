//! The configuration: one TOML file, fully defaulted, with the embedded default compiled in.
//! This module owns parsing and validation only; every error names the key and what was
//! expected. It never touches hardware, so `impactcam config check` is safe anywhere.

mod geometry;
mod validate;

pub use geometry::{parse_axis, Geometry, ViewGeometry};
pub(crate) use validate::check_geometry;

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The embedded default: simulated camera and relay in the thesis's geometry.
pub const DEFAULT_TOML: &str = include_str!("../../config/default.toml");

#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    // The cause is part of the message, not a `source`: printed once.
    #[error("{path}: cannot read: {cause}")]
    Read {
        path: PathBuf,
        cause: std::io::Error,
    },
    #[error("{origin}: {message}")]
    Parse { origin: String, message: String },
    #[error("{origin}: {message}")]
    Invalid { origin: String, message: String },
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Config {
    #[serde(default)]
    pub camera: CameraConfig,
    #[serde(default)]
    pub trigger: TriggerConfig,
    #[serde(default)]
    pub recording: RecordingConfig,
    #[serde(default = "Geometry::thesis")]
    pub geometry: Geometry,
    #[serde(default)]
    pub spheres: SpheresConfig,
    #[serde(default)]
    pub analysis: AnalysisConfig,
    #[serde(default)]
    pub daemon: DaemonConfig,
    #[serde(default)]
    pub sim: hw_sim::LabConfig,
    /// What the lab writes down about this experiment (campaign, tube angle, notes). It is kept
    /// with the config, so it is stored in the session's manifest (`config.experiment`) by
    /// whatever runs the experiment: `run`, a sweep, or the daemon.
    #[serde(default, skip_serializing_if = "ExperimentLabel::is_empty")]
    pub experiment: ExperimentLabel,
}

/// The lab's label for one experiment; nothing in the analysis reads it.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct ExperimentLabel {
    /// Groups experiments on the page and in `fit`: 1–64 characters of `A-Z a-z 0-9 . _ -` and
    /// spaces.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub campaign: Option<String>,
    /// The tubes' angle as set on the rig (the simulator's angle is `sim.tube_angle_deg`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tube_angle_deg: Option<f64>,
    /// Free text, at most 2000 characters.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub notes: Option<String>,
}

/// Longest `experiment.notes` accepted.
pub const MAX_NOTES_CHARS: usize = 2000;

impl ExperimentLabel {
    pub fn is_empty(&self) -> bool {
        self.campaign.is_none() && self.tube_angle_deg.is_none() && self.notes.is_none()
    }
}

/// Whether `name` is a campaign name: 1–64 characters of `A-Z a-z 0-9 . _ -` and spaces, not
/// starting with a space or a dot.
pub fn is_campaign_name(name: &str) -> bool {
    (1..=64).contains(&name.len())
        && !name.starts_with([' ', '.'])
        && !name.ends_with(' ')
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'.' | b'_' | b'-' | b' '))
}

#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum CameraBackend {
    Sim,
    Aravis,
    V4l,
}

#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
pub enum PixelFormat {
    Mono8,
    Mono16,
}

impl PixelFormat {
    pub fn bytes_per_pixel(self) -> usize {
        match self {
            PixelFormat::Mono8 => 1,
            PixelFormat::Mono16 => 2,
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            PixelFormat::Mono8 => "Mono8",
            PixelFormat::Mono16 => "Mono16",
        }
    }
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct CameraConfig {
    pub backend: CameraBackend,
    /// Device id (Aravis) or path (V4L2); empty = the first camera found.
    pub device: String,
    pub width: u32,
    pub height: u32,
    pub pixel_format: PixelFormat,
    pub frame_rate_hz: f64,
    /// Exposure; None leaves the camera's own setting. The analysis reads it too: a disc that
    /// moved half a pixel or more while the shutter was open is fitted as smeared
    /// (`circle::FirstPassDisc::smear_px`); None, it takes the shutter as short.
    pub exposure_us: Option<f64>,
    /// The gamma the camera encodes its levels with (a level is full scale × (linear light /
    /// full scale)^(1/gamma); 2.2 for an sRGB-like curve); None: linear, as machine-vision
    /// cameras deliver by default. The analysis brings every frame back to linear light by it
    /// (`analysis::linear`); impactcam does not set it on the camera.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gamma: Option<f64>,
    /// How the camera starts each exposure: "free_run" (its own clock), "software" (impactcam
    /// triggers each frame), or "hardware" (a trigger input, `trigger_line`). Aravis only.
    pub trigger_mode: CameraTrigger,
    /// The trigger input for trigger_mode = "hardware", e.g. "Line1".
    pub trigger_line: String,
}

#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum CameraTrigger {
    FreeRun,
    Software,
    Hardware,
}

impl Default for CameraConfig {
    fn default() -> Self {
        CameraConfig {
            backend: CameraBackend::Sim,
            device: String::new(),
            width: 240,
            height: 192,
            pixel_format: PixelFormat::Mono8,
            frame_rate_hz: 1000.0,
            exposure_us: None,
            gamma: None,
            trigger_mode: CameraTrigger::FreeRun,
            trigger_line: "Line1".into(),
        }
    }
}

#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum TriggerBackend {
    /// The simulator's relay: the serial LCUS protocol on a pseudo-terminal.
    Sim,
    /// A USB/serial relay module.
    Serial,
    /// Nothing is fired (footage of something released by hand or by other equipment).
    None,
    /// A line of a Linux GPIO chip (`--features gpio`).
    Gpio,
}

#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum RelayProtocol {
    /// LCUS / CH340 modules: `A0 ch state sum`, 9600 8N1.
    Lcus,
    /// Numato Lab boards: `relay on N\r`, echoed, state read back.
    Numato,
    /// Bytes from `generic_on_hex` / `generic_off_hex`, optional reply `generic_reply_hex`.
    Generic,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct TriggerConfig {
    pub backend: TriggerBackend,
    /// Serial device of the relay module (backend = "serial").
    pub port: String,
    pub protocol: RelayProtocol,
    pub channel: u8,
    pub baud_rate: u32,
    /// How long the relay is held closed to release the spheres.
    pub relay_pulse_ms: f64,
    /// Hard ceiling on any closing of the relay; `relay_pulse_ms` may not exceed it.
    pub relay_pulse_ms_max: f64,
    /// protocol = "generic": bytes that close the relay, hex ("A0 01 01 A2").
    pub generic_on_hex: Option<String>,
    /// protocol = "generic": bytes that open the relay.
    pub generic_off_hex: Option<String>,
    /// protocol = "generic": bytes the module answers after each switch, if it does.
    pub generic_reply_hex: Option<String>,
    /// backend = "gpio": the chip device.
    pub gpio_chip: String,
    /// backend = "gpio": the line offset on the chip.
    pub gpio_line: u32,
    /// backend = "gpio": the relay closes on a low level.
    pub gpio_active_low: bool,
}

impl Default for TriggerConfig {
    fn default() -> Self {
        TriggerConfig {
            backend: TriggerBackend::Sim,
            port: String::new(),
            protocol: RelayProtocol::Lcus,
            channel: 1,
            baud_rate: 9600,
            relay_pulse_ms: 50.0,
            relay_pulse_ms_max: 500.0,
            generic_on_hex: None,
            generic_off_hex: None,
            generic_reply_hex: None,
            gpio_chip: "/dev/gpiochip0".into(),
            gpio_line: 0,
            gpio_active_low: false,
        }
    }
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct RecordingConfig {
    /// Sessions are written under this directory.
    pub dir: PathBuf,
    /// Frames saved per experiment, pre-trigger frames included.
    pub frames: u32,
    /// Frames kept from before the relay fired.
    pub pre_trigger_frames: u32,
    /// Bound on frames held in RAM while the disk catches up.
    pub ram_buffer_mb: u32,
    /// How long to wait for the camera's first frames before refusing to fire.
    pub arm_timeout_ms: u32,
}

impl Default for RecordingConfig {
    fn default() -> Self {
        RecordingConfig {
            dir: PathBuf::from("sessions"),
            frames: 280,
            pre_trigger_frames: 20,
            ram_buffer_mb: 1024,
            arm_timeout_ms: 2000,
        }
    }
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SphereOverride {
    pub diameter_mm: Option<f64>,
    pub mass_g: Option<f64>,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct SpheresConfig {
    pub diameter_mm: f64,
    pub mass_g: f64,
    /// K in I = K m r²: 2/5 for solid spheres (the impulse–spin check, physics.md §8).
    pub inertia_factor: f64,
    pub material: Option<String>,
    pub a: Option<SphereOverride>,
    pub b: Option<SphereOverride>,
}

impl Default for SpheresConfig {
    fn default() -> Self {
        SpheresConfig {
            diameter_mm: 6.35,
            mass_g: 0.295,
            inertia_factor: 0.4,
            material: None,
            a: None,
            b: None,
        }
    }
}

impl SpheresConfig {
    /// (diameter_mm, mass_g) of sphere a (index 0) or b (index 1).
    pub fn sphere(&self, i: usize) -> (f64, f64) {
        let o = if i == 0 { &self.a } else { &self.b };
        let d = o
            .as_ref()
            .and_then(|o| o.diameter_mm)
            .unwrap_or(self.diameter_mm);
        let m = o.as_ref().and_then(|o| o.mass_g).unwrap_or(self.mass_g);
        (d, m)
    }

    /// Distance between the spheres' centres when they touch, mm: the mean of the diameters.
    pub fn contact_mm(&self) -> f64 {
        0.5 * (self.sphere(0).0 + self.sphere(1).0)
    }
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct AnalysisConfig {
    /// Fewer usable frames than this on either side of the impact is an error.
    pub min_frames_per_side: u32,
    /// Gravity used in the ballistic fits, mm/s² along −y.
    pub gravity_mm_s2: f64,
    /// Detection threshold as a fraction of the way from background to the brightest pixel.
    pub threshold_fraction: f64,
    /// Rotation between frames from markers: "kabsch" (optimal) or "thesis" (the 1992
    /// 9-parameter least squares, for comparison).
    pub rotation: RotationMethod,
    /// Diameter of the painted markers; sets the window of their sub-pixel centroid.
    pub marker_diameter_mm: f64,
}

impl Default for AnalysisConfig {
    fn default() -> Self {
        AnalysisConfig {
            min_frames_per_side: 5,
            gravity_mm_s2: hw_sim::GRAVITY_MM_S2,
            threshold_fraction: 0.5,
            rotation: RotationMethod::Kabsch,
            marker_diameter_mm: 1.0,
        }
    }
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct DaemonConfig {
    pub listen: String,
    /// Token required on every route when set (and always off loopback); `IMPACTCAM_TOKEN`
    /// overrides it. At least 16 characters of `A-Z a-z 0-9 - . _ ~ + / =`.
    pub token: Option<String>,
    /// Host names (besides the listening address) that requests may give in `Host`, e.g. the
    /// lab PC's name on the network. Anything else is refused (DNS rebinding).
    pub allowed_hosts: Vec<String>,
}

impl Default for DaemonConfig {
    fn default() -> Self {
        DaemonConfig {
            listen: "127.0.0.1:8620".into(),
            token: None,
            allowed_hosts: Vec::new(),
        }
    }
}

impl Config {
    pub fn default_config() -> Config {
        // The embedded file is tested to parse; a failure here is a build defect, not user input.
        Config::from_toml_str(DEFAULT_TOML, "embedded default")
            .expect("embedded default config is valid")
    }

    pub fn load(path: &Path) -> Result<Config, ConfigError> {
        let cfg = Config::load_unchecked(path)?;
        cfg.validate().map_err(|message| ConfigError::Invalid {
            origin: path.display().to_string(),
            message,
        })?;
        Ok(cfg)
    }

    /// A config file parsed but not yet validated: for footage recorded elsewhere, whose frame
    /// size (and rate, where it states one) the file decides; `for_footage` then validates it.
    pub fn load_unchecked(path: &Path) -> Result<Config, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|cause| ConfigError::Read {
            path: path.into(),
            cause,
        })?;
        Config::parse(&text, &path.display().to_string())
    }

    fn parse(text: &str, origin: &str) -> Result<Config, ConfigError> {
        toml::from_str(text).map_err(|e| ConfigError::Parse {
            origin: origin.into(),
            message: e.message().to_string() + &span_hint(text, e.span()),
        })
    }

    /// This config for footage of `width`×`height` frames (at `frame_rate_hz` where the file
    /// states it): the camera's size and rate replaced by the file's, then validated, so the
    /// regions are checked against the frames they will be read from.
    pub fn for_footage(
        &self,
        width: u32,
        height: u32,
        frame_rate_hz: Option<f64>,
    ) -> Result<Config, String> {
        let mut c = self.clone();
        c.camera.width = width;
        c.camera.height = height;
        if let Some(r) = frame_rate_hz {
            c.camera.frame_rate_hz = r;
        }
        c.validate()?;
        Ok(c)
    }

    pub fn from_toml_str(text: &str, origin: &str) -> Result<Config, ConfigError> {
        let cfg = Config::parse(text, origin)?;
        cfg.validate().map_err(|message| ConfigError::Invalid {
            origin: origin.into(),
            message,
        })?;
        Ok(cfg)
    }

    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).unwrap_or_default()
    }
}

/// How rotations between frames are estimated from markers (`analysis.rotation`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RotationMethod {
    /// Optimal rotation (Kabsch with determinant correction).
    Kabsch,
    /// The thesis's 9-parameter least squares.
    Thesis,
}

/// "A0 01 01 A2" → bytes; None if any token is not a hex byte (`trigger.generic_*_hex`).
pub fn parse_hex(text: &str) -> Option<Vec<u8>> {
    text.split_whitespace()
        .map(|t| u8::from_str_radix(t.trim_start_matches("0x"), 16).ok())
        .collect()
}

/// Most frames one recording may save (a 1000 fps camera's 1000 s).
pub const MAX_FRAMES: u32 = 1_000_000;
/// Largest RAM ring (`recording.ram_buffer_mb`), MiB.
pub const MAX_RAM_BUFFER_MB: u32 = 65_536;
/// Longest wait for the camera's first frames, ms.
pub const MAX_ARM_TIMEOUT_MS: u32 = 600_000;

/// The rule for a daemon token from any source (config or `IMPACTCAM_TOKEN`): long enough not
/// to be guessed, and made of characters that survive a header and a cookie unquoted.
pub fn check_token(t: &str) -> Result<(), String> {
    if t.chars().count() < 16 {
        return Err(format!(
            "too short ({} characters), expected at least 16",
            t.chars().count()
        ));
    }
    if let Some(c) = t
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || "-._~+/=".contains(*c)))
    {
        return Err(format!(
            "contains {c:?}, expected only letters, digits and - . _ ~ + / ="
        ));
    }
    Ok(())
}

fn span_hint(text: &str, span: Option<std::ops::Range<usize>>) -> String {
    match span {
        Some(s) => {
            let line = text[..s.start.min(text.len())].matches('\n').count() + 1;
            format!(" (line {line})")
        }
        None => String::new(),
    }
}

#[cfg(test)]
mod tests;
