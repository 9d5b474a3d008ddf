//! Benchmarks and accuracy reports, printed as ratios or errors against baselines measured in
//! the same run — never asserted on wall-clock time.

pub mod accuracy;
pub mod analysis;
pub mod capture;
pub mod relay;
pub mod rigs;
pub mod soak;
pub mod validation;

pub use capture::capture;
