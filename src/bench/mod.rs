//! Benchmarks and accuracy reports, printed as ratios or errors against baselines measured in
//! the same run — never asserted on wall-clock time.

pub mod accuracy;
pub mod analysis;
pub mod capture;
pub mod relay;
pub mod rigs;
pub mod saved_as;
pub mod soak;
pub mod validation;

pub use capture::capture;

/// Records one experiment on the simulated lab `cfg` describes; returns the session directory.
pub(crate) fn record_sim(cfg: &crate::config::Config) -> Result<std::path::PathBuf, String> {
    crate::experiment::Rig::open(cfg)
        .map_err(|e| e.to_string())
        .and_then(|mut rig| {
            rig.record(
                cfg,
                std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false)),
                &mut |_| {},
            )
            .map_err(|e| e.to_string())
        })
        .map(|rec| rec.session_dir)
        .map_err(|e| format!("recording: {e}"))
}
