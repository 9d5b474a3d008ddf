//! One experiment, end to end: open the rig (camera + trigger, or the simulated lab behind
//! both), record, analyse, write the report. This is what `run` and `capture` call, and what the
//! daemon will call; it owns the order of things, not any of the things.

use crate::analysis::{self, report::Report, AnalysisError, SessionSource};
use crate::camera::{self, Camera, CameraError};
use crate::config::{CameraBackend, Config, TriggerBackend};
use crate::recorder::{self, Progress, RecordError, Recording};
use crate::session::{write_atomic, SessionError, SessionReader, Status};
use crate::trigger::{Trigger, TriggerError};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

#[derive(Debug, thiserror::Error)]
pub enum ExperimentError {
    #[error("simulated lab: {0}")]
    Sim(String),
    #[error(transparent)]
    Camera(#[from] CameraError),
    #[error(transparent)]
    Trigger(#[from] TriggerError),
    #[error(transparent)]
    Record(#[from] RecordError),
    #[error(transparent)]
    Analysis(#[from] AnalysisError),
    #[error(transparent)]
    Session(#[from] SessionError),
    #[error(
        "recording in {dir} ended early ({reason}); its frames are kept but it was not analysed"
    )]
    Incomplete { dir: PathBuf, reason: String },
}

/// What an experiment reports as it goes.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    Recorder(Progress),
    Analysing {
        frames_done: usize,
        frames_total: usize,
    },
}

/// The devices of one experiment.
pub struct Rig {
    pub lab: Option<Arc<hw_sim::SimLab>>,
    pub camera: Box<dyn Camera>,
    pub trigger: Trigger,
}

impl Rig {
    pub fn open(cfg: &Config) -> Result<Rig, ExperimentError> {
        let needs_lab =
            cfg.camera.backend == CameraBackend::Sim || cfg.trigger.backend == TriggerBackend::Sim;
        let lab = if needs_lab {
            Some(
                hw_sim::SimLab::new(cfg.sim.clone(), analysis::geometry::sim_scene(cfg))
                    .map_err(ExperimentError::Sim)?,
            )
        } else {
            None
        };
        let camera = camera::open(cfg, lab.as_ref())?;
        let trigger = Trigger::open(cfg, lab.as_ref().map(|l| l.relay_port()))?;
        Ok(Rig {
            lab,
            camera,
            trigger,
        })
    }
}

/// Arm, fire, record; no analysis.
pub fn capture(
    cfg: &Config,
    abort: Arc<AtomicBool>,
    on_event: &mut dyn FnMut(Event),
) -> Result<Recording, ExperimentError> {
    let rig = Rig::open(cfg)?;
    capture_with(rig, cfg, abort, on_event)
}

pub fn capture_with(
    rig: Rig,
    cfg: &Config,
    abort: Arc<AtomicBool>,
    on_event: &mut dyn FnMut(Event),
) -> Result<Recording, ExperimentError> {
    let Rig {
        lab,
        camera,
        trigger,
    } = rig;
    let rec = recorder::record(camera, &trigger, cfg, abort, &mut |p| {
        on_event(Event::Recorder(p))
    })?;
    drop(trigger);
    drop(lab);
    Ok(rec)
}

/// Record and analyse; the report is written into the session.
pub fn run(
    cfg: &Config,
    abort: Arc<AtomicBool>,
    on_event: &mut dyn FnMut(Event),
) -> Result<(Recording, Report), ExperimentError> {
    let rec = capture(cfg, abort, on_event)?;
    if rec.status != Status::Complete {
        return Err(ExperimentError::Incomplete {
            dir: rec.session_dir.clone(),
            reason: rec.reason.clone().unwrap_or_else(|| "unknown".into()),
        });
    }
    let report = analyze_session(&rec.session_dir, None, &mut |done, total| {
        on_event(Event::Analysing {
            frames_done: done,
            frames_total: total,
        })
    })?;
    write_report(&rec.session_dir, &report)?;
    Ok((rec, report))
}

/// Analyses a recorded session with its own config snapshot (or `cfg` when given).
pub fn analyze_session(
    dir: &Path,
    cfg: Option<&Config>,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Report, ExperimentError> {
    let reader = SessionReader::open(dir)?;
    let cfg = cfg.cloned().unwrap_or_else(|| reader.config().clone());
    let mut src = SessionSource::new(reader);
    Ok(analysis::analyze(&mut src, &cfg, progress)?)
}

pub fn report_json(report: &Report) -> String {
    // Serialising plain structs of numbers and strings cannot fail.
    serde_json::to_string_pretty(report).unwrap_or_default() + "\n"
}

pub fn write_report(dir: &Path, report: &Report) -> Result<PathBuf, ExperimentError> {
    let path = dir.join("report.json");
    write_atomic(&path, report_json(report).as_bytes())?;
    Ok(path)
}
