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

/// The devices of an experiment: opened once, and kept by a daemon from one experiment to the
/// next (`record` borrows them).
///
/// Fields drop in this order: the trigger first (its guard opens the relay while the port,
/// the simulator's pseudo-terminal included, is still there), then the camera, then the lab.
pub struct Rig {
    pub trigger: Trigger,
    /// None once an acquisition thread died with it: the rig must be reopened.
    pub camera: Option<Box<dyn Camera>>,
    pub lab: Option<Arc<hw_sim::SimLab>>,
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
            camera: Some(camera),
            trigger,
        })
    }

    /// Arm, fire, record; no analysis. In the simulated lab the spheres are first loaded again
    /// with `cfg`'s experiment keys (`[sim]`), as a person reloads the tubes on a real rig.
    pub fn record(
        &mut self,
        cfg: &Config,
        abort: Arc<AtomicBool>,
        on_event: &mut dyn FnMut(Event),
    ) -> Result<Recording, ExperimentError> {
        if let Some(lab) = &self.lab {
            lab.restage(&cfg.sim).map_err(ExperimentError::Sim)?;
        }
        let result = recorder::record(&mut self.camera, &self.trigger, cfg, abort, &mut |p| {
            on_event(Event::Recorder(p))
        });
        // The simulator knows what really happened: its truth goes beside the frames, for
        // every session that holds frames (an interrupted one too).
        let dir = match &result {
            Ok(rec) => Some(rec.session_dir.as_path()),
            Err(RecordError::Interrupted(dir)) => Some(dir.as_path()),
            Err(_) => None,
        };
        if let (Some(lab), Some(dir)) = (&self.lab, dir) {
            write_truth(lab, dir)?;
        }
        Ok(result?)
    }
}

/// `truth.json`: the simulated lab's ground truth for the frames the session holds.
fn write_truth(lab: &hw_sim::SimLab, dir: &Path) -> Result<(), ExperimentError> {
    let reader = SessionReader::open(dir)?;
    let pairs: Vec<(u64, u64)> = reader
        .frames
        .iter()
        .map(|m| (m.frame_id, m.timestamp_ns))
        .collect();
    // The relay module hears us over a pseudo-terminal: let the last switch arrive before its
    // log goes into the truth.
    std::thread::sleep(std::time::Duration::from_millis(20));
    let text = serde_json::to_string_pretty(&lab.truth(&pairs)).unwrap_or_default();
    write_atomic(&dir.join("truth.json"), text.as_bytes())?;
    Ok(())
}

impl ExperimentError {
    /// Whether the devices may be in a bad state after this error, so that a daemon should
    /// close and reopen them before the next experiment (a disconnect, a relay that stopped
    /// answering). Analysis and bad-input errors leave the rig as it was.
    pub fn rig_suspect(&self) -> bool {
        match self {
            ExperimentError::Sim(_)
            | ExperimentError::Camera(_)
            | ExperimentError::Trigger(_)
            | ExperimentError::Incomplete { .. } => true,
            ExperimentError::Record(RecordError::Session(_)) => false,
            ExperimentError::Record(RecordError::Interrupted(_)) => false,
            ExperimentError::Record(_) => true,
            ExperimentError::Analysis(_) | ExperimentError::Session(_) => false,
        }
    }
}

/// Opens the rig, arms, fires, records; no analysis.
pub fn capture(
    cfg: &Config,
    abort: Arc<AtomicBool>,
    on_event: &mut dyn FnMut(Event),
) -> Result<Recording, ExperimentError> {
    Rig::open(cfg)?.record(cfg, abort, on_event)
}

/// Opens the rig, records and analyses; the report is written into the session.
pub fn run(
    cfg: &Config,
    abort: Arc<AtomicBool>,
    on_event: &mut dyn FnMut(Event),
) -> Result<(Recording, Report), ExperimentError> {
    run_on(&mut Rig::open(cfg)?, cfg, abort, on_event)
}

/// Records on an open rig and analyses; the report is written into the session.
pub fn run_on(
    rig: &mut Rig,
    cfg: &Config,
    abort: Arc<AtomicBool>,
    on_event: &mut dyn FnMut(Event),
) -> Result<(Recording, Report), ExperimentError> {
    let rec = rig.record(cfg, abort, on_event)?;
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

/// Analyses a session or footage recorded elsewhere at `path` (`analysis::source::open`), with
/// `cfg` when given, else the session's own recorded config. For footage, `cfg` may be
/// unvalidated (`Config::load_unchecked`): it is fitted to the file's frame size and, where the
/// file states one, its frame rate, and validated against them.
pub fn analyze_path(
    path: &Path,
    cfg: Option<&Config>,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Report, ExperimentError> {
    let mut src = analysis::source::open(path, cfg.map(|c| c.camera.frame_rate_hz))?;
    let cfg = match cfg {
        Some(c) if src.recorded_config().is_none() => {
            let (w, h) = src.dimensions();
            let rate = src.source().frame_rate_hz;
            c.for_footage(w, h, Some(rate))
                .map_err(|message| AnalysisError::Input {
                    source_name: path.display().to_string(),
                    message: format!("the config does not suit this footage ({w}×{h} px at {rate} frames/s): {message}"),
                })?
        }
        Some(c) => {
            c.validate().map_err(|message| AnalysisError::Input {
                source_name: path.display().to_string(),
                message: format!("the config: {message}"),
            })?;
            c.clone()
        }
        None => src
            .recorded_config()
            .cloned()
            .ok_or_else(|| AnalysisError::Input {
                source_name: path.display().to_string(),
                message: "no config: give --config".into(),
            })?,
    };
    Ok(analysis::analyze(src.as_mut(), &cfg, progress)?)
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
