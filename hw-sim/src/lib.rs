//! hw-sim — the sphere-collision lab in software.
//!
//! It owns everything a real rig would provide to impactcam, and nothing of impactcam itself:
//! the physics of two spheres rolling down tubes and colliding in free flight (Walton's rough
//! inelastic operator), the rendering of the direct and 45°-mirror views with markers, shading,
//! blur and noise, a camera that delivers those frames with ids and device timestamps, and a relay
//! module on a pseudo-terminal that speaks the LCUS serial protocol. The simulated lab learns that
//! the relay closed only through that pseudo-terminal, so the simulated experiment exercises the
//! same serial code path as a real relay.
//!
//! Ground truth (centres, spins, markers, impact, e, β, ψ) is derived from the same scenario that
//! drives the rendering, so accuracy can be measured exactly. This crate must never depend on
//! impactcam.

pub mod camera;
pub mod clock;
pub mod config;
pub mod grid;
pub mod lab;
pub mod lcus;
pub mod look;
pub mod modules;
pub mod physics;
pub mod pty;
pub mod relay;
pub mod render;
mod rng;
pub mod scenario;

pub use camera::{SimCamera, SimError, SimFrame};
pub use config::{LabConfig, Lens, Pace, Scene, SphereSpec, ViewSpec};
pub use grid::{render_grid, GridTarget};
pub use lab::SimLab;
pub use look::{Look, MarkerPaint, SurfaceKind, ViewLook};
pub use physics::{Material, Outcome};
pub use rng::Rng;
pub use scenario::Scenario;

/// Standard gravity in mm/s², along −y in world coordinates.
pub const GRAVITY_MM_S2: f64 = 9806.65;

pub type V3 = nalgebra::Vector3<f64>;
