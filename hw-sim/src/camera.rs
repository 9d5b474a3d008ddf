//! The simulated camera: frames rendered from the lab's scenario, delivered on the lab clock with
//! frame ids (from 0) and device timestamps (id/fps of the lab clock, mid-exposure). Frames can
//! be lost on demand (ids skip, as with a real camera's lost packets) and the camera can
//! disconnect after a given number of frames.

use crate::config::Pace;
use crate::lab::SimLab;
use crate::render::Renderer;
use crate::rng::Rng;
use std::sync::Arc;
use std::time::Duration;

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SimError {
    #[error("simulated camera disconnected after {0} frames")]
    Disconnected(u64),
}

pub struct SimFrame {
    pub frame_id: u64,
    pub timestamp_ns: u64,
    /// Row-major pixels; 16-bit frames are little-endian.
    pub data: Vec<u8>,
}

pub struct SimCamera {
    lab: Arc<SimLab>,
    renderer: Renderer,
    start_index: Option<u64>,
    next_index: u64,
    delivered: u64,
    rng: Rng,
    /// Preview (setting the rig up): the spheres drawn at rest in view.
    preview: bool,
}

impl SimCamera {
    /// The lab's camera (one lab may have several: each renders the same scenario).
    pub fn new(lab: Arc<SimLab>) -> SimCamera {
        let renderer = Renderer::new(lab.scene.clone(), lab.cfg.clone(), lab.cfg.seed);
        let rng = Rng::new(lab.cfg.seed ^ 0xD409);
        SimCamera {
            lab,
            renderer,
            start_index: None,
            next_index: 0,
            delivered: 0,
            rng,
            preview: false,
        }
    }

    pub fn frame_bytes(&self) -> usize {
        self.renderer.frame_bytes()
    }

    /// Starts (or restarts) streaming: the first frame is the next one due on the lab clock.
    pub fn start(&mut self) {
        let fps = self.lab.scene.frame_rate_hz;
        let idx = (self.lab.clock().now_s() * fps).ceil().max(0.0) as u64;
        self.start_index = Some(idx);
        self.next_index = idx;
    }

    /// Preview on: frames show the spheres held still shortly before impact
    /// (`Scenario::at_rest_in_view`), as a user holds them to set up focus, exposure and
    /// geometry; off (the default): the experiment as it runs.
    pub fn set_preview(&mut self, on: bool) {
        self.preview = on;
    }

    /// Stops streaming: the lab clock no longer waits for this camera (see `clock`).
    pub fn stop(&mut self) {
        self.start_index = None;
        self.lab.clock().release_hold();
    }

    /// Blocks until the next frame is due (real-time pace), renders it and returns it.
    pub fn next_frame(&mut self, buf: Vec<u8>) -> Result<SimFrame, SimError> {
        if self.start_index.is_none() {
            self.start();
        }
        let start = self.start_index.unwrap_or(0);
        if let Some(limit) = self.lab.cfg.disconnect_after_frames {
            if self.delivered >= limit {
                return Err(SimError::Disconnected(self.delivered));
            }
        }
        let fps = self.lab.scene.frame_rate_hz;
        let clock = self.lab.clock().clone();
        loop {
            let idx = self.next_index;
            self.next_index += 1;
            let t = idx as f64 / fps;
            match clock.pace() {
                Pace::RealTime => {
                    let due = clock.epoch() + Duration::from_secs_f64(t);
                    let now = std::time::Instant::now();
                    if due > now {
                        std::thread::sleep(due - now);
                    }
                    // The world waits for the next frame if this one is drawn late.
                    clock.hold_at((idx + 1) as f64 / fps);
                }
                Pace::FreeRun => clock.set_free_run_now(t),
            }
            let frame_id = idx - start;
            let lost = self.lab.cfg.drop_frame_ids.contains(&frame_id)
                || (self.lab.cfg.drop_probability > 0.0
                    && self.rng.uniform() < self.lab.cfg.drop_probability);
            if lost {
                continue;
            }
            let release = self.lab.release_time_s();
            let stage = self.lab.stage();
            let mut data = buf;
            self.renderer
                .set_tube_exits([stage.scenario.tube_exit(0), stage.scenario.tube_exit(1)]);
            if self.preview {
                let sc = &stage.scenario;
                let bodies = sc.at_rest_in_view();
                let markers = [
                    sc.marker_positions(0, &bodies[0]),
                    sc.marker_positions(1, &bodies[1]),
                ];
                self.renderer
                    .render(t, &move |_| (bodies, markers.clone()), &mut data);
            } else {
                self.renderer.render(
                    t,
                    &move |tt| SimLab::bodies_in(&stage.scenario, tt, release),
                    &mut data,
                );
            }
            self.delivered += 1;
            return Ok(SimFrame {
                frame_id,
                timestamp_ns: (t * 1e9).round() as u64,
                data,
            });
        }
    }
}

impl Drop for SimCamera {
    fn drop(&mut self) {
        if self.start_index.is_some() {
            self.lab.clock().release_hold();
        }
    }
}
