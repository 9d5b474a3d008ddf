//! Commands that drive the rig: `run` (record and analyse), `capture` (record only) and
//! `serve` (the daemon).

use super::{abort_flag, interrupted_or, load_config};
use anyhow::Result;
use impactcam::experiment;
use impactcam::summary::{progress_printer, report_text, Status};
use std::path::PathBuf;

/// `impactcam run`: one experiment recorded and analysed.
pub(crate) fn run(config: Option<PathBuf>, json: bool) -> Result<i32> {
    let cfg = load_config(config.as_deref())?;
    let abort = abort_flag();
    let mut status = Status::new();
    let result = experiment::run(&cfg, abort, &mut progress_printer(&mut status));
    let (rec, report) = match result {
        Ok(r) => r,
        Err(e) => return interrupted_or(e),
    };
    status.line(&format!("analysed {} frames", report.quality.frames_total));
    if json {
        print!("{}", experiment::report_json(&report));
    } else {
        print!("{}", report_text(&report));
        println!("session     {}", rec.session_dir.display());
        println!(
            "report      {}",
            rec.session_dir.join("report.json").display()
        );
    }
    Ok(0)
}

/// `impactcam capture`: one experiment recorded, not analysed; exit 1 if the session is
/// incomplete.
pub(crate) fn capture(config: Option<PathBuf>) -> Result<i32> {
    let cfg = load_config(config.as_deref())?;
    let abort = abort_flag();
    let mut status = Status::new();
    let result = experiment::capture(&cfg, abort, &mut progress_printer(&mut status));
    match result {
        Ok(rec) => {
            println!(
                "session {} ({:?}): {} frames recorded, {} dropped",
                rec.session_dir.display(),
                rec.status,
                rec.frames_recorded,
                rec.frames_dropped
            );
            Ok(if rec.status == impactcam::session::Status::Complete {
                0
            } else {
                1
            })
        }
        Err(e) => interrupted_or(e),
    }
}

/// `impactcam serve`: the daemon and its lab page, on the config's address unless `--listen`.
pub(crate) fn serve(config: Option<PathBuf>, listen: Option<String>) -> Result<i32> {
    let cfg = load_config(config.as_deref())?;
    let listen = listen.unwrap_or_else(|| cfg.daemon.listen.clone());
    impactcam::daemon::serve(cfg, &listen, &mut |addr| {
        println!("listening on http://{addr}");
        use std::io::Write;
        let _ = std::io::stdout().flush();
    })?;
    Ok(0)
}
