//! What each command does once its arguments are parsed: load what it names, call the library,
//! print the outcome and choose the exit code. One module per group of commands; `main.rs`
//! only parses and dispatches.

pub(crate) mod analyze;
pub(crate) mod bench;
pub(crate) mod campaign;
pub(crate) mod files;
pub(crate) mod record;

use anyhow::Result;
use impactcam::config::Config;
use impactcam::experiment;
use impactcam::summary::{report_text, Status};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// The config at `path`, checked; the built-in default without one.
pub(crate) fn load_config(path: Option<&Path>) -> Result<Config> {
    Ok(match path {
        Some(p) => Config::load(p)?,
        None => Config::default_config(),
    })
}

/// Set by Ctrl-C, and raised by a panic (the relay is released either way).
pub(crate) fn abort_flag() -> Arc<AtomicBool> {
    let abort = Arc::new(AtomicBool::new(false));
    let a = abort.clone();
    // If the handler cannot be installed, Ctrl-C kills the process; the relay pulse is short and
    // the relay module is opened again on the next start.
    if let Err(e) = ctrlc::set_handler(move || a.store(true, Ordering::SeqCst)) {
        tracing::warn!("cannot install the Ctrl-C handler: {e}");
    }
    impactcam::trigger::raise_on_panic(abort.clone());
    abort
}

/// Exit 130 for a recording the user interrupted (relay released, session kept), else the error.
pub(crate) fn interrupted_or(e: experiment::ExperimentError) -> Result<i32> {
    match e {
        experiment::ExperimentError::Record(impactcam::recorder::RecordError::Interrupted(dir)) => {
            Status::new().line(&format!(
                "interrupted: relay released; session {} marked incomplete",
                dir.display()
            ));
            Ok(130)
        }
        e => Err(e.into()),
    }
}

/// Writes a report and prints it (JSON or summary).
pub(crate) fn deliver(
    report: &impactcam::analysis::report::Report,
    target: &Path,
    json: bool,
) -> Result<i32> {
    impactcam::session::write_atomic(target, experiment::report_json(report).as_bytes())?;
    if json {
        print!("{}", experiment::report_json(report));
    } else {
        print!("{}", report_text(report));
        println!("report      {}", target.display());
    }
    Ok(0)
}
