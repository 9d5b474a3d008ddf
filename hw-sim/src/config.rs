//! What the simulated lab is told: `LabConfig` is the `[sim]` section of an impactcam config
//! (the experiment the simulator stages), `Scene` is what the rig looks like (camera frame, views,
//! spheres), filled in by the caller from its own geometry.

use crate::look::Look;
use crate::physics::Material;
use serde::{Deserialize, Serialize};

/// Mains at 50 Hz: a lamp's light peaks twice a cycle.
const DEFAULT_FLICKER_HZ: f64 = 100.0;

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

fn is_one(x: &f64) -> bool {
    *x == 1.0
}

fn is_none_stuck(x: &u32) -> bool {
    *x == 0
}

fn is_default_flicker_hz(x: &f64) -> bool {
    *x == DEFAULT_FLICKER_HZ
}

/// How the simulated camera's clock runs.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Pace {
    /// Frames are delivered when a real camera would deliver them.
    RealTime,
    /// Frames are delivered as fast as they can be rendered; the device clock still advances by
    /// 1/fps per frame, and relay events are stamped on that clock.
    FreeRun,
}

/// The `[sim]` section: the experiment the simulator stages. Every field has a default.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct LabConfig {
    /// Everything random (spin jitter, markers, noise, drops) follows from this seed.
    pub seed: u64,
    /// Material preset: glass, acetate, teflon or steel.
    pub material: String,
    /// Override the preset's normal restitution.
    pub e: Option<f64>,
    /// Override the preset's friction coefficient.
    pub mu: Option<f64>,
    /// Override the preset's sticking tangential restitution.
    pub beta0: Option<f64>,
    /// Both tubes' angle below horizontal; they mirror each other about the vertical.
    pub tube_angle_deg: f64,
    /// Rolling length inside each tube; sets the exit speed (rolling without slip,
    /// a = 5/7 g sin θ).
    pub tube_length_mm: f64,
    /// Free flight from the tube exits to first contact.
    pub flight_time_ms: f64,
    /// In-plane impact parameter as a fraction of the contact distance (0 = head-on). Sets the
    /// obliquity, hence ψ1. With impact_offset² + impact_offset_z² ≥ 1 the spheres miss.
    pub impact_offset: f64,
    /// Out-of-plane impact parameter, same units; makes the contact normal leave the x–y plane.
    pub impact_offset_z: f64,
    /// Magnitude of a small velocity along z given to each sphere at the tube exit.
    pub out_of_plane_velocity_mm_s: f64,
    /// Magnitude of an extra spin about a random axis added to each sphere at the tube exit.
    pub spin_jitter_rad_s: f64,
    /// From relay closing to the solenoid shafts letting the spheres go.
    pub solenoid_delay_ms: f64,
    pub markers_per_sphere: u32,
    pub marker_diameter_mm: f64,
    pub background_grey: f64,
    pub sphere_grey: f64,
    pub marker_grey: f64,
    /// Gaussian read noise, grey levels (8-bit scale).
    pub noise_sigma_grey: f64,
    /// Electrons per grey level for shot noise; 0 disables shot noise.
    pub shot_noise_e_per_grey: f64,
    /// Exposure time; the image is averaged over it (motion blur). 0 = instantaneous.
    pub exposure_ms: f64,
    /// The lamps' flicker (a mains-driven lamp's light rises and falls at twice the mains
    /// frequency; a camera at 1000 fps sees it frame to frame): the light's modulation depth,
    /// per cent of its mean ((max − min)/(max + min), as lighting data sheets give it), on
    /// everything a look lights, ground and spheres alike; 0: steady. Needs a look.
    #[serde(skip_serializing_if = "is_zero")]
    pub flicker_percent: f64,
    /// The flicker's frequency, Hz (100 under 50 Hz mains, 120 under 60 Hz); its phase at the
    /// recording's start follows from the seed.
    #[serde(skip_serializing_if = "is_default_flicker_hz")]
    pub flicker_hz: f64,
    /// The camera's gamma: a level is 255·(linear/255)^(1/gamma), as many cameras encode (2.2
    /// for sRGB-like); 1: linear. Needs a look.
    #[serde(skip_serializing_if = "is_one")]
    pub gamma: f64,
    /// The sensor's defective pixels, stuck at one level in every frame (the first of each pair
    /// at the top of the range, hot; the second at 0, dead), at places drawn from the seed, as
    /// a real sensor has a few. 0: none.
    #[serde(skip_serializing_if = "is_none_stuck")]
    pub stuck_pixels: u32,
    /// Samples per pixel side for anti-aliasing (4 → 16 samples).
    pub supersample: u32,
    /// Samples per pixel side where a sphere's limb or a marker's rim crosses the pixel. A
    /// regular 4×4 grid draws the limb as a staircase of quarter pixels, which moves a disc's
    /// grey-level centre by about 0.005 px (as much as σ = 2 noise does); a real sensor
    /// integrates the light over the whole pixel.
    pub edge_supersample: u32,
    /// Frame ids the camera loses (as a real camera loses packets).
    pub drop_frame_ids: Vec<u64>,
    /// Probability of losing any frame.
    pub drop_probability: f64,
    /// The camera disconnects after delivering this many frames.
    pub disconnect_after_frames: Option<u64>,
    pub pace: Pace,
    /// The real mirror view's magnification differs from the configured one by this fraction
    /// (what a lab gets from an uncalibrated mirror path); the analysis must find it.
    pub mirror_scale_error: f64,
    /// The real mirror view is shifted by this much (u, v) from the configured origin, px.
    pub mirror_offset_error_px: [f64; 2],
    /// The camera is turned about its optical axis by this much, deg (positive turns the image
    /// from +u towards +v): every view's image rotates about the frame's centre.
    pub camera_roll_deg: f64,
    /// The mirror is turned away from 45° about the world x axis by this much, deg: the mirror
    /// view turns by twice the angle (its v axis takes in world y).
    pub mirror_tilt_deg: f64,
    /// The direct view's camera turned about world x (pitch: its v takes in z) and about world
    /// y (yaw: its u takes in z), deg: a camera not square to the plane of collision. The
    /// mirror view is left as `mirror_tilt_deg` and the roll set it (its own turns are the
    /// mirror's).
    pub direct_pitch_deg: f64,
    pub direct_yaw_deg: f64,
    /// Every view becomes a pinhole camera this far from the world origin, mm (the mirror's
    /// virtual camera too); absent: orthographic, as before.
    pub perspective_distance_mm: Option<f64>,
    /// Radial lens distortion of the camera (both views through one lens): the fractional
    /// displacement at the frame's corners, about the frame's centre (negative: barrel); 0:
    /// none.
    pub lens_k1: f64,
    /// How the rig looks (light, surface, paint, clutter, focus); absent = the original render.
    pub look: Option<Look>,
    /// Draw the look at random from this family and the seed (`Look::FAMILIES` or
    /// `Look::EXTRA_FAMILIES`, or "varied"); the drawn look also sets `background_grey`,
    /// `sphere_grey` and `marker_grey`.
    pub look_family: Option<String>,
}

impl Default for LabConfig {
    fn default() -> Self {
        LabConfig {
            seed: 1,
            material: "teflon".into(),
            e: None,
            mu: None,
            beta0: None,
            tube_angle_deg: 30.0,
            tube_length_mm: 40.0,
            flight_time_ms: 60.0,
            impact_offset: 0.35,
            impact_offset_z: 0.05,
            out_of_plane_velocity_mm_s: 15.0,
            spin_jitter_rad_s: 20.0,
            solenoid_delay_ms: 5.0,
            markers_per_sphere: 8,
            marker_diameter_mm: 1.0,
            background_grey: 30.0,
            sphere_grey: 200.0,
            marker_grey: 40.0,
            noise_sigma_grey: 2.0,
            shot_noise_e_per_grey: 0.0,
            exposure_ms: 0.1,
            flicker_percent: 0.0,
            flicker_hz: DEFAULT_FLICKER_HZ,
            gamma: 1.0,
            stuck_pixels: 0,
            supersample: 4,
            edge_supersample: 16,
            drop_frame_ids: Vec::new(),
            drop_probability: 0.0,
            disconnect_after_frames: None,
            pace: Pace::RealTime,
            mirror_scale_error: 0.0,
            mirror_offset_error_px: [0.0, 0.0],
            camera_roll_deg: 0.0,
            mirror_tilt_deg: 0.0,
            direct_pitch_deg: 0.0,
            direct_yaw_deg: 0.0,
            perspective_distance_mm: None,
            lens_k1: 0.0,
            look: None,
            look_family: None,
        }
    }
}

impl LabConfig {
    /// The collision coefficients the lab will use: the preset with any overrides.
    pub fn material(&self) -> Result<Material, String> {
        let mut m = Material::preset(&self.material).ok_or_else(|| {
            format!(
                "sim.material: unknown material {:?}, expected one of {}",
                self.material,
                Material::PRESETS.join(", ")
            )
        })?;
        if let Some(e) = self.e {
            m.e = e;
        }
        if let Some(mu) = self.mu {
            m.mu = mu;
        }
        if let Some(b) = self.beta0 {
            m.beta0 = b;
        }
        Ok(m)
    }

    /// The config with `look_family` replaced by the look it draws from the seed (and that
    /// look's grey levels); unchanged without one.
    pub fn with_look_drawn(&self) -> Result<LabConfig, String> {
        let mut out = self.clone();
        if let Some(family) = out.look_family.take() {
            if self.look.is_some() {
                return Err(
                    "sim.look, sim.look_family: give a look or a family to draw one from, not both"
                        .into(),
                );
            }
            let (look, levels) = Look::draw(&family, self.seed)?;
            out.look = Some(look);
            out.background_grey = levels.background_grey;
            out.sphere_grey = levels.sphere_grey;
            out.marker_grey = levels.marker_grey;
        }
        Ok(out)
    }

    /// Checks every value; the error names the key (`sim.…`) and what was expected.
    pub fn validate(&self) -> Result<(), String> {
        let drawn = self.with_look_drawn()?;
        if let Some(look) = &drawn.look {
            look.validate()?;
        }
        let m = self.material()?;
        let range = |key: &str, v: f64, lo: f64, hi: f64| -> Result<(), String> {
            if v.is_finite() && v >= lo && v <= hi {
                Ok(())
            } else {
                Err(format!(
                    "sim.{key}: {v} is out of range, expected {lo} to {hi}"
                ))
            }
        };
        range("e", m.e, 0.0, 1.0)?;
        range("mu", m.mu, 0.0, 2.0)?;
        range("beta0", m.beta0, -1.0, 1.0)?;
        range("tube_angle_deg", self.tube_angle_deg, 5.0, 80.0)?;
        range("tube_length_mm", self.tube_length_mm, 1.0, 5000.0)?;
        range("flight_time_ms", self.flight_time_ms, 1.0, 1000.0)?;
        range("impact_offset", self.impact_offset, -3.0, 3.0)?;
        range("impact_offset_z", self.impact_offset_z, -3.0, 3.0)?;
        let b2 = self.impact_offset.powi(2) + self.impact_offset_z.powi(2);
        if b2 > 0.995 && b2 < 1.0 {
            return Err("sim.impact_offset, sim.impact_offset_z: a contact this grazing cannot be staged; below 0.995 they collide, from 1 they miss".into());
        }
        range(
            "out_of_plane_velocity_mm_s",
            self.out_of_plane_velocity_mm_s,
            0.0,
            1000.0,
        )?;
        range("spin_jitter_rad_s", self.spin_jitter_rad_s, 0.0, 10000.0)?;
        range("solenoid_delay_ms", self.solenoid_delay_ms, 0.0, 1000.0)?;
        range(
            "markers_per_sphere",
            self.markers_per_sphere as f64,
            0.0,
            12.0,
        )?;
        range("marker_diameter_mm", self.marker_diameter_mm, 0.0, 10.0)?;
        range("background_grey", self.background_grey, 0.0, 255.0)?;
        range("sphere_grey", self.sphere_grey, 0.0, 255.0)?;
        range("marker_grey", self.marker_grey, 0.0, 255.0)?;
        range("noise_sigma_grey", self.noise_sigma_grey, 0.0, 100.0)?;
        range(
            "shot_noise_e_per_grey",
            self.shot_noise_e_per_grey,
            0.0,
            1e6,
        )?;
        range("exposure_ms", self.exposure_ms, 0.0, 100.0)?;
        range("flicker_percent", self.flicker_percent, 0.0, 100.0)?;
        range("flicker_hz", self.flicker_hz, 1.0, 10000.0)?;
        range("gamma", self.gamma, 0.2, 5.0)?;
        range("stuck_pixels", f64::from(self.stuck_pixels), 0.0, 10_000.0)?;
        if self.gamma != 1.0 && drawn.look.is_none() {
            return Err("sim.gamma: a camera's gamma is drawn under a look only (sim.look or sim.look_family)".into());
        }
        if self.flicker_percent > 0.0 && drawn.look.is_none() {
            return Err("sim.flicker_percent: a flickering lamp needs a look (sim.look or sim.look_family); the default render has no lamp to flicker".into());
        }
        range("supersample", self.supersample as f64, 1.0, 16.0)?;
        range("edge_supersample", self.edge_supersample as f64, 1.0, 32.0)?;
        range("drop_probability", self.drop_probability, 0.0, 0.5)?;
        range("mirror_scale_error", self.mirror_scale_error, -0.2, 0.2)?;
        range("camera_roll_deg", self.camera_roll_deg, -10.0, 10.0)?;
        range("lens_k1", self.lens_k1, -0.2, 0.2)?;
        range("mirror_tilt_deg", self.mirror_tilt_deg, -10.0, 10.0)?;
        range("direct_pitch_deg", self.direct_pitch_deg, -10.0, 10.0)?;
        range("direct_yaw_deg", self.direct_yaw_deg, -10.0, 10.0)?;
        if let Some(d) = self.perspective_distance_mm {
            range("perspective_distance_mm", d, 100.0, 1e5)?;
        }
        range(
            "mirror_offset_error_px[0]",
            self.mirror_offset_error_px[0],
            -50.0,
            50.0,
        )?;
        range(
            "mirror_offset_error_px[1]",
            self.mirror_offset_error_px[1],
            -50.0,
            50.0,
        )?;
        Ok(())
    }
}

/// One view of the scene inside the camera frame (orthographic).
#[derive(Clone, Debug, Serialize)]
pub struct ViewSpec {
    pub name: String,
    /// u, v, width, height of the view inside the frame, px.
    pub region: [u32; 4],
    pub px_per_mm: f64,
    /// Image (u, v) of the world origin.
    pub origin_px: [f64; 2],
    /// World unit vector along which image u increases.
    pub u_axis: [f64; 3],
    /// World unit vector along which image v increases.
    pub v_axis: [f64; 3],
    /// World unit vector from the scene towards this view's (virtual) camera: the visible
    /// hemisphere.
    pub facing: [f64; 3],
    /// A pinhole camera this far from the world origin along `facing`, mm (`px_per_mm` is then
    /// the scale on the plane through the origin square to the line of sight); None:
    /// orthographic.
    pub distance_mm: Option<f64>,
    /// The lens's radial distortion, applied after the projection; None: none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lens: Option<Lens>,
}

/// Radial lens distortion about `centre_px`: an ideal image point p lands at
/// c + (p − c)·(1 + k1·r²), r = |p − c| / `radius_px` (the frame's half-diagonal), so `k1` is
/// the fractional displacement at the frame's corners (negative: barrel).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Lens {
    pub k1: f64,
    pub centre_px: [f64; 2],
    pub radius_px: f64,
}

impl Lens {
    /// The scale factor 1 + k1·r² at ideal image point (u, v).
    pub fn factor(&self, u: f64, v: f64) -> f64 {
        let (du, dv) = (u - self.centre_px[0], v - self.centre_px[1]);
        1.0 + self.k1 * (du * du + dv * dv) / (self.radius_px * self.radius_px)
    }

    /// Where the ideal image point (u, v) is recorded.
    pub fn distort(&self, u: f64, v: f64) -> (f64, f64) {
        let f = self.factor(u, v);
        let c = self.centre_px;
        (c[0] + (u - c[0]) * f, c[1] + (v - c[1]) * f)
    }

    /// The ideal image point recorded at (u, v): the inverse of `distort`, by fixed-point
    /// iteration (a contraction for |k1| ≤ 0.2 inside the frame; settled to 1e-9 px).
    pub fn undistort(&self, u: f64, v: f64) -> (f64, f64) {
        let c = self.centre_px;
        let (mut x, mut y) = (u, v);
        for _ in 0..50 {
            let f = self.factor(x, y);
            let (nx, ny) = (c[0] + (u - c[0]) / f, c[1] + (v - c[1]) / f);
            let done = (nx - x).abs() + (ny - y).abs() < 1e-9;
            (x, y) = (nx, ny);
            if done {
                break;
            }
        }
        (x, y)
    }
}

impl ViewSpec {
    /// The pinhole's 3×4 projection, world mm → homogeneous px (DLT convention, p34 = 1);
    /// None for an orthographic view.
    pub fn projection(&self) -> Option<[[f64; 4]; 3]> {
        let d = self.distance_mm?;
        let (s, f, o) = (self.px_per_mm, self.facing, self.origin_px);
        let row = |a: [f64; 3], o: f64| {
            [
                s * a[0] - o * f[0] / d,
                s * a[1] - o * f[1] / d,
                s * a[2] - o * f[2] / d,
                o,
            ]
        };
        Some([
            row(self.u_axis, o[0]),
            row(self.v_axis, o[1]),
            [-f[0] / d, -f[1] / d, -f[2] / d, 1.0],
        ])
    }

    /// [u, v] = M·p + origin_px, M in px per mm.
    pub fn matrix_px_per_mm(&self) -> [[f64; 3]; 2] {
        [
            self.u_axis.map(|x| x * self.px_per_mm),
            self.v_axis.map(|x| x * self.px_per_mm),
        ]
    }

    /// Turns the view's camera about the world x axis by `angle` rad (a tilted mirror turns
    /// its view by twice its own tilt); the world origin keeps its image.
    pub fn turn_about_x(&mut self, angle: f64) {
        if angle == 0.0 {
            return;
        }
        let (s, c) = angle.sin_cos();
        let turn = |a: [f64; 3]| [a[0], c * a[1] - s * a[2], s * a[1] + c * a[2]];
        self.u_axis = turn(self.u_axis);
        self.v_axis = turn(self.v_axis);
        self.facing = turn(self.facing);
    }

    /// Turns the view's camera about the world y axis by `angle` rad (z towards x); the world
    /// origin keeps its image.
    pub fn turn_about_y(&mut self, angle: f64) {
        if angle == 0.0 {
            return;
        }
        let (s, c) = angle.sin_cos();
        let turn = |a: [f64; 3]| [c * a[0] + s * a[2], a[1], -s * a[0] + c * a[2]];
        self.u_axis = turn(self.u_axis);
        self.v_axis = turn(self.v_axis);
        self.facing = turn(self.facing);
    }

    /// Rotates the view's image by `angle` rad about the image point `centre` (a camera rolled
    /// about its optical axis): u' = c + R·(u − c), R = [[cos, −sin], [sin, cos]].
    pub fn roll_about(&mut self, centre: [f64; 2], angle: f64) {
        let (s, c) = angle.sin_cos();
        let (ua, va) = (self.u_axis, self.v_axis);
        self.u_axis = [0, 1, 2].map(|i| c * ua[i] - s * va[i]);
        self.v_axis = [0, 1, 2].map(|i| s * ua[i] + c * va[i]);
        let d = [self.origin_px[0] - centre[0], self.origin_px[1] - centre[1]];
        self.origin_px = [
            centre[0] + c * d[0] - s * d[1],
            centre[1] + s * d[0] + c * d[1],
        ];
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct SphereSpec {
    pub diameter_mm: f64,
    pub mass_g: f64,
}

/// The rig as the caller's geometry describes it.
#[derive(Clone, Debug, Serialize)]
pub struct Scene {
    pub width: u32,
    pub height: u32,
    pub frame_rate_hz: f64,
    /// 8 (Mono8) or 16 (Mono16, little-endian).
    pub bit_depth: u32,
    pub views: Vec<ViewSpec>,
    /// Sphere a (released from the left tube) and sphere b.
    pub spheres: [SphereSpec; 2],
}

#[cfg(test)]
mod tests {
    use super::{LabConfig, Lens, ViewSpec};

    /// The direct view pitched about x and yawed about y: its v then takes in world z by
    /// about −s·sin(pitch) and its u by −s·sin(yaw) (a point 10 mm towards the camera moves by about
    /// 0.75 px per degree at 2.16 px/mm), it still faces its camera (u × v = −facing), and the
    /// keys beyond ±10° are refused by name.
    #[test]
    fn a_pitched_and_yawed_direct_view_sees_z_in_its_image() {
        let mut v = ViewSpec {
            name: "direct".into(),
            region: [0, 0, 240, 96],
            px_per_mm: 2.1576,
            origin_px: [119.5, 44.0],
            u_axis: [1.0, 0.0, 0.0],
            v_axis: [0.0, -1.0, 0.0],
            facing: [0.0, 0.0, 1.0],
            distance_mm: None,
            lens: None,
        };
        let (pitch, yaw) = (2f64.to_radians(), (-1.5f64).to_radians());
        v.turn_about_x(pitch);
        v.turn_about_y(yaw);
        let m = v.matrix_px_per_mm();
        // (yaw turns z towards x, so u = (cos, 0, −sin); the pitch's v row is then turned too)
        assert!((m[0][2] - (-2.1576 * yaw.sin())).abs() < 1e-12, "{m:?}");
        assert!(
            (m[1][2] - (-2.1576 * pitch.sin() * yaw.cos())).abs() < 1e-12,
            "{m:?}"
        );
        let (a, b, f) = (v.u_axis, v.v_axis, v.facing);
        let cross = [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ];
        for i in 0..3 {
            assert!((cross[i] + f[i]).abs() < 1e-12, "{cross:?} vs {f:?}");
        }
        for key in ["direct_pitch_deg", "direct_yaw_deg"] {
            let mut cfg = LabConfig::default();
            match key {
                "direct_pitch_deg" => cfg.direct_pitch_deg = 12.0,
                _ => cfg.direct_yaw_deg = -12.0,
            }
            let err = cfg.validate().expect_err("out of range");
            assert!(err.contains(&format!("sim.{key}")), "{err}");
        }
    }

    #[test]
    fn a_lens_beyond_its_range_is_refused_by_name() {
        for k1 in [0.5, -0.25, f64::NAN] {
            let cfg = LabConfig {
                lens_k1: k1,
                ..LabConfig::default()
            };
            let err = cfg.validate().expect_err("out of range");
            assert!(err.contains("sim.lens_k1"), "{err}");
        }
        let cfg = LabConfig {
            lens_k1: -0.05,
            ..LabConfig::default()
        };
        assert!(cfg.validate().is_ok());
    }

    #[test]
    fn undistort_inverts_distort_across_the_frame() {
        for k1 in [-0.2, -0.05, 0.05, 0.2] {
            let lens = Lens {
                k1,
                centre_px: [119.5, 95.5],
                radius_px: 0.5 * 240f64.hypot(192.0),
            };
            for (u, v) in [(0.0, 0.0), (239.0, 191.0), (119.5, 95.5), (30.0, 150.0)] {
                let (du, dv) = lens.distort(u, v);
                let (bu, bv) = lens.undistort(du, dv);
                assert!(
                    (bu - u).hypot(bv - v) < 1e-6,
                    "k1 {k1}: ({u}, {v}) → ({bu}, {bv})"
                );
            }
        }
    }
}
