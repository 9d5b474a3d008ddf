//! The simulated lab as one object: the staged scenario, the lab clock (which is also the
//! simulated camera's device clock), the relay on its pseudo-terminal, and the ground truth.

use crate::clock::LabClock;
use crate::config::{LabConfig, Scene};
use crate::physics::Body;
use crate::relay::{RelayEvent, RelayLog, SimRelay};
use crate::render::project;
use crate::scenario::Scenario;
use crate::V3;
use serde_json::{json, Value};
use std::sync::{Arc, Mutex, RwLock};

/// What is loaded in the tubes now: the scenario, and the lab time from which a relay closing
/// releases it (closings before belong to earlier experiments).
pub struct Stage {
    pub scenario: Scenario,
    pub solenoid_delay_ms: f64,
    pub staged_at_s: f64,
}

pub struct SimLab {
    /// The lab as opened: noise, drops, disconnects and pace stay as they were at opening.
    pub cfg: LabConfig,
    pub scene: Scene,
    stage: RwLock<Arc<Stage>>,
    clock: Arc<LabClock>,
    log: Arc<Mutex<RelayLog>>,
    relay: SimRelay,
}

impl SimLab {
    pub fn new(cfg: LabConfig, mut scene: Scene) -> Result<Arc<SimLab>, String> {
        let cfg = cfg.with_look_drawn()?;
        // The lab's true mirror view, which the caller's nominal geometry may not match.
        for v in scene.views.iter_mut().filter(|v| v.name == "mirror") {
            v.px_per_mm *= 1.0 + cfg.mirror_scale_error;
            v.origin_px[0] += cfg.mirror_offset_error_px[0];
            v.origin_px[1] += cfg.mirror_offset_error_px[1];
            v.turn_about_x(2.0 * cfg.mirror_tilt_deg.to_radians());
        }
        // The direct camera not square to the plane of collision: turned before the roll (which
        // turns the image about the frame's centre).
        for v in scene.views.iter_mut().filter(|v| v.name == "direct") {
            v.turn_about_x(cfg.direct_pitch_deg.to_radians());
            v.turn_about_y(cfg.direct_yaw_deg.to_radians());
        }
        for v in scene.views.iter_mut() {
            v.distance_mm = cfg.perspective_distance_mm;
        }
        if cfg.lens_k1 != 0.0 {
            let (w, h) = (f64::from(scene.width), f64::from(scene.height));
            let lens = crate::config::Lens {
                k1: cfg.lens_k1,
                centre_px: [(w - 1.0) / 2.0, (h - 1.0) / 2.0],
                radius_px: 0.5 * w.hypot(h),
            };
            for v in scene.views.iter_mut() {
                v.lens = Some(lens);
            }
        }
        if cfg.camera_roll_deg != 0.0 {
            let centre = [
                (f64::from(scene.width) - 1.0) / 2.0,
                (f64::from(scene.height) - 1.0) / 2.0,
            ];
            for v in scene.views.iter_mut() {
                v.roll_about(centre, cfg.camera_roll_deg.to_radians());
            }
        }
        let scenario = Scenario::new(&cfg, &scene.spheres)?;
        let clock = Arc::new(LabClock::new(cfg.pace));
        let log = Arc::new(Mutex::new(RelayLog::default()));
        let relay = SimRelay::spawn(clock.clone(), log.clone())
            .map_err(|e| format!("sim relay: cannot create a pseudo-terminal: {e}"))?;
        let stage = RwLock::new(Arc::new(Stage {
            scenario,
            solenoid_delay_ms: cfg.solenoid_delay_ms,
            staged_at_s: 0.0,
        }));
        Ok(Arc::new(SimLab {
            cfg,
            scene,
            stage,
            clock,
            log,
            relay,
        }))
    }

    /// Loads the spheres again for the next experiment, as a person does between two firings on
    /// a real rig: a new scenario from `cfg`'s experiment keys (tube angle, material, offset…),
    /// released by the next relay closing. Noise, drops and pace stay as opened.
    pub fn restage(&self, cfg: &LabConfig) -> Result<(), String> {
        let cfg = &cfg.with_look_drawn()?;
        let scenario = Scenario::new(cfg, &self.scene.spheres)?;
        let stage = Arc::new(Stage {
            scenario,
            solenoid_delay_ms: cfg.solenoid_delay_ms,
            staged_at_s: self.clock.now_s(),
        });
        *self.stage.write().unwrap_or_else(|p| p.into_inner()) = stage;
        Ok(())
    }

    /// The experiment loaded now.
    pub fn stage(&self) -> Arc<Stage> {
        self.stage.read().unwrap_or_else(|p| p.into_inner()).clone()
    }

    /// Serial device path of the simulated relay module.
    pub fn relay_port(&self) -> &str {
        self.relay.port_path()
    }

    pub fn clock(&self) -> &Arc<LabClock> {
        &self.clock
    }

    /// Relay events since the spheres were last loaded, after the last one before (the state
    /// the relay was in when they were loaded).
    pub fn relay_events(&self) -> Vec<RelayEvent> {
        let since = self.stage().staged_at_s;
        self.log
            .lock()
            .map(|l| {
                let after = l.events.partition_point(|e| e.time_s < since);
                l.events[after.saturating_sub(1)..].to_vec()
            })
            .unwrap_or_default()
    }

    pub fn relay_bad_frames(&self) -> u64 {
        self.log.lock().map(|l| l.bad_frames).unwrap_or(0)
    }

    /// Whether the relay is closed now, as the module sees it.
    pub fn relay_closed(&self) -> bool {
        self.log
            .lock()
            .map(|l| l.events.last().is_some_and(|e| e.closed))
            .unwrap_or(false)
    }

    /// When the solenoids let go, on the lab clock: the first relay closing plus the solenoid
    /// delay. None while the relay has never closed.
    pub fn release_time_s(&self) -> Option<f64> {
        let stage = self.stage();
        self.relay_events()
            .iter()
            .find(|e| e.closed && e.time_s >= stage.staged_at_s)
            .map(|e| e.time_s + stage.solenoid_delay_ms / 1000.0)
    }

    /// Both spheres and their marker positions (world, mm) at lab time t.
    pub fn bodies_at(&self, t: f64, release: Option<f64>) -> ([Body; 2], [Vec<V3>; 2]) {
        Self::bodies_in(&self.stage().scenario, t, release)
    }

    /// As `bodies_at`, for a stage already in hand (the renderer asks many times per frame).
    pub fn bodies_in(sc: &Scenario, t: f64, release: Option<f64>) -> ([Body; 2], [Vec<V3>; 2]) {
        let tau = match release {
            Some(r) => t - r,
            None => -1.0,
        };
        let b = sc.state_at(tau);
        let m = [sc.marker_positions(0, &b[0]), sc.marker_positions(1, &b[1])];
        (b, m)
    }

    /// Ground truth for the given frames (frame id, device timestamp in ns), as JSON.
    pub fn truth(&self, frames: &[(u64, u64)]) -> Value {
        let release = self.release_time_s();
        let stage = self.stage();
        let sc = &stage.scenario;
        let impact_time = release
            .map(|r| r + sc.impact_tau_s)
            .filter(|t| t.is_finite());
        let state = |b: &Body| json!({"position_mm": v(&b.pos_mm), "velocity_mm_s": v(&b.vel_mm_s), "spin_rad_s": v(&b.spin_rad_s)});
        let per_frame: Vec<Value> = frames
            .iter()
            .map(|&(id, ts)| {
                let t = ts as f64 * 1e-9;
                let (bodies, markers) = Self::bodies_in(sc, t, release);
                let spheres: Vec<Value> = (0..2)
                    .map(|i| {
                        let views: serde_json::Map<String, Value> = self
                            .scene
                            .views
                            .iter()
                            .map(|view| {
                                let (u, vv) = project(view, &bodies[i].pos_mm);
                                (view.name.clone(), json!({"centre_px": [u, vv], "diameter_px": 2.0 * crate::render::radius_px(view, &bodies[i].pos_mm, bodies[i].radius_mm)}))
                            })
                            .collect();
                        json!({
                            "centre_mm": v(&bodies[i].pos_mm),
                            "velocity_mm_s": v(&bodies[i].vel_mm_s),
                            "spin_rad_s": v(&bodies[i].spin_rad_s),
                            "views": views,
                            "markers_mm": markers[i].iter().map(v).collect::<Vec<_>>(),
                        })
                    })
                    .collect();
                json!({"frame_id": id, "time_s": t, "spheres": {"a": spheres[0], "b": spheres[1]}})
            })
            .collect();
        let o = sc.outcome.as_ref();
        let mut truth = json!({
            "schema": "hw-sim.truth/1",
            "material": sc.material,
            "relay_events": self.relay_events(),
            "release_time_s": release,
            "tube_exit_time_s": release.map(|r| r + sc.exit_tau_s),
            "impact": {
                "time_s": impact_time,
                "normal": o.map(|o| o.normal),
            },
            "e": o.map(|o| o.e),
            "beta": o.map(|o| o.beta),
            "psi1": o.map(|o| o.psi1),
            "psi2": o.map(|o| o.psi2),
            "branch": o.map(|o| if o.sliding { "sliding" } else { "sticking" }),
            "spheres": {
                "a": {"pre": state(&sc.pre[0]), "post": state(&sc.post[0]), "diameter_mm": 2.0 * sc.pre[0].radius_mm},
                "b": {"pre": state(&sc.pre[1]), "post": state(&sc.post[1]), "diameter_mm": 2.0 * sc.pre[1].radius_mm},
            },
            "frames": per_frame,
        });
        if let Some(look) = &self.cfg.look {
            truth["look"] = json!(look);
        }
        // The exact map of every view as rendered: [u, v] = M·p + origin_px.
        let maps: serde_json::Map<String, Value> = self
            .scene
            .views
            .iter()
            .map(|view| {
                let mut map = match view.projection() {
                    Some(p) => json!({"projection": p}),
                    None => json!({"matrix_px_per_mm": view.matrix_px_per_mm(), "origin_px": view.origin_px}),
                };
                // The map is of the ideal image; a lens then moves every point (`Lens`).
                if let Some(lens) = &view.lens {
                    map["lens"] = json!(lens);
                }
                (view.name.clone(), map)
            })
            .collect();
        truth["geometry"] = Value::Object(maps);
        truth
    }
}

fn v(x: &V3) -> [f64; 3] {
    [x.x, x.y, x.z]
}
