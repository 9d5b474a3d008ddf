//! impactcam — sphere-collision experiments end to end: arm a high-speed camera, fire the relay
//! that releases two spheres, record the frames, and measure the collision (e, and with spin,
//! β, ψ1, ψ2). See docs/ARCHITECTURE.md for the map.

pub mod analysis;
pub mod batch;
pub mod bench;
pub mod calibrate;
pub mod camera;
pub mod campaign;
pub mod config;
pub mod daemon;
pub mod experiment;
pub mod figures;
pub mod footage;
pub mod fuzzing;
pub mod recorder;
pub mod session;
pub mod summary;
pub mod trigger;
