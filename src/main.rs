//! The impactcam command line: parses arguments (their definitions in `cli.rs`) and calls the
//! library.

mod cli;

use anyhow::{bail, Context, Result};
use clap::Parser;
use cli::{BenchWhat, Cli, Command, ConfigAction, LogFormat};
use impactcam::config::Config;
use impactcam::experiment;
use impactcam::summary::{progress_printer, report_text, Status};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

fn load_config(path: Option<&Path>) -> Result<Config> {
    Ok(match path {
        Some(p) => Config::load(p)?,
        None => Config::default_config(),
    })
}

fn abort_flag() -> Arc<AtomicBool> {
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

fn main() {
    // The relay guard is this executable started by the trigger (see trigger::guard).
    if std::env::args_os()
        .nth(1)
        .is_some_and(|a| a == impactcam::trigger::guard::GUARD_ARG)
    {
        std::process::exit(impactcam::trigger::guard::guard_main());
    }
    match std::env::current_exe() {
        Ok(exe) => impactcam::trigger::guard::set_executable(exe),
        Err(e) => {
            eprintln!("error: cannot find this executable to start the relay guard: {e}");
            std::process::exit(1);
        }
    }
    // Usage errors exit 1 like every other error; 2 is kept for "replay differs".
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            let _ = e.print();
            std::process::exit(if e.use_stderr() { 1 } else { 0 });
        }
    };
    let format = match cli.log_format {
        Some(f) => f,
        None => match std::env::var("IMPACTCAM_LOG_FORMAT").as_deref() {
            Ok("json") => LogFormat::Json,
            Ok("human") | Ok("") | Err(_) => LogFormat::Human,
            Ok(other) => {
                eprintln!("error: IMPACTCAM_LOG_FORMAT={other:?}: expected \"human\" or \"json\"");
                std::process::exit(1);
            }
        },
    };
    use std::io::IsTerminal;
    // Colour codes only for a person at a terminal, never into a redirected log.
    let logs = tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .with_target(false);
    match format {
        LogFormat::Human => logs.init(),
        LogFormat::Json => {
            logs.json().flatten_event(true).init();
            impactcam::summary::set_json_progress(true);
            impactcam::trigger::guard::set_json_logs(true);
        }
    }
    match real_main(cli) {
        Ok(code) => std::process::exit(code),
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::exit(1);
        }
    }
}

/// Exit 130 for a recording the user interrupted (relay released, session kept), else the error.
fn interrupted_or(e: experiment::ExperimentError) -> Result<i32> {
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
fn deliver(report: &impactcam::analysis::report::Report, target: &Path, json: bool) -> Result<i32> {
    impactcam::session::write_atomic(target, experiment::report_json(report).as_bytes())?;
    if json {
        print!("{}", experiment::report_json(report));
    } else {
        print!("{}", report_text(report));
        println!("report      {}", target.display());
    }
    Ok(0)
}

fn real_main(cli: Cli) -> Result<i32> {
    match cli.command {
        Command::Run { config, json } => {
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
        Command::Capture { config } => {
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
        Command::Replay {
            sessions,
            json,
            jobs,
            shard,
        } => {
            let jobs = jobs.map_or(0, usize::from);
            let session = match sessions.as_slice() {
                [one] if shard.is_none() && impactcam::batch::is_session(one) => one.clone(),
                _ if json => bail!("--json: one session only (a batch prints a line per session)"),
                _ => return replay_batch(&sessions, shard, jobs),
            };
            impactcam::analysis::set_threads(jobs);
            let report = experiment::analyze_session(&session, None, &mut |_, _| {})?;
            let text = experiment::report_json(&report);
            let recorded = std::fs::read_to_string(session.join("report.json")).ok();
            if json {
                print!("{text}");
            } else {
                print!("{}", report_text(&report));
            }
            match recorded {
                Some(r) if r == text => {
                    Status::new().line("replay: identical to the recorded report.json")
                }
                Some(_) => {
                    Status::new().line("replay: DIFFERS from the recorded report.json");
                    return Ok(2);
                }
                None => {
                    Status::new().line("replay: the session has no report.json to compare with")
                }
            }
            Ok(0)
        }
        Command::Calibrate {
            paths,
            config,
            out,
            grid,
            grid_pitch_mm,
        } => {
            let cfg = config.as_deref().map(Config::load).transpose()?;
            let grid = match (grid.as_deref(), grid_pitch_mm) {
                (Some(g), Some(p)) if p.is_finite() && (0.1..=1000.0).contains(&p) => Some((g, p)),
                (Some(_), Some(p)) => {
                    anyhow::bail!("--grid-pitch-mm: {p} is out of range, expected 0.1 to 1000 (mm between the grid's dots)")
                }
                (Some(_), None) => {
                    anyhow::bail!("--grid needs --grid-pitch-mm (mm between the grid's dots)")
                }
                (None, _) => None,
            };
            let (cal, png) = impactcam::calibrate::calibrate_paths(&paths, cfg.as_ref(), grid)?;
            let text = cal.toml();
            match out {
                Some(o) => {
                    impactcam::session::write_atomic(&o, text.as_bytes())?;
                    let p = o.with_extension("png");
                    impactcam::session::write_atomic(&p, &png)?;
                    println!("geometry    {}\nfigure      {}", o.display(), p.display());
                }
                None => print!("{text}"),
            }
            Ok(0)
        }
        Command::Analyze {
            paths,
            tracks,
            config,
            json,
            out,
            overwrite,
            jobs,
            shard,
        } => {
            let jobs = jobs.map_or(0, usize::from);
            let single = match paths.as_slice() {
                [] => None,
                [one] if shard.is_none() && impactcam::footage::is_one_input(one) => {
                    Some(one.clone())
                }
                _ => {
                    if json || out.is_some() {
                        bail!("--json and --out: one input only (a batch writes each session's report.json into it)");
                    }
                    return analyze_batch(&paths, config.as_deref(), overwrite, shard, jobs);
                }
            };
            impactcam::analysis::set_threads(jobs);
            analyze_command(single, tracks, config, json, out, overwrite)
        }
        Command::Serve { config, listen } => {
            let cfg = load_config(config.as_deref())?;
            let listen = listen.unwrap_or_else(|| cfg.daemon.listen.clone());
            impactcam::daemon::serve(cfg, &listen, &mut |addr| {
                println!("listening on http://{addr}");
                use std::io::Write;
                let _ = std::io::stdout().flush();
            })?;
            Ok(0)
        }
        Command::Sweep {
            config,
            tube_angles,
            impact_offsets,
            repeats,
            dir,
        } => sweep_command(config, tube_angles, impact_offsets, repeats, dir),
        Command::Fit { paths, json, out } => fit_command(paths, json, out),
        Command::Export {
            session,
            out,
            format,
            tiff,
        } => {
            use impactcam::footage::import::ExportFormat;
            let (format, out) = match (tiff, format, out) {
                (Some(t), _, _) => (ExportFormat::Tiff, t),
                (None, Some(f), Some(o)) => (
                    match f {
                        cli::ExportFormatArg::Tiff => ExportFormat::Tiff,
                        cli::ExportFormatArg::Mraw => ExportFormat::Mraw,
                        cli::ExportFormatArg::Fmf => ExportFormat::Fmf,
                    },
                    o,
                ),
                _ => bail!("give --format tiff|mraw|fmf and the file to write (or --tiff OUT.tif)"),
            };
            let done = impactcam::footage::import::export(&session, format, &out)?;
            let n = done.frames;
            if let Some(c) = &done.caveat {
                eprintln!("warning: {c}");
            }
            if format == ExportFormat::Mraw {
                println!(
                    "wrote {n} frames to {} and {}",
                    out.with_extension("mraw").display(),
                    out.with_extension("cih").display()
                );
            } else {
                println!("wrote {n} frames to {}", out.display());
            }
            Ok(0)
        }
        Command::Import { file, out, config } => {
            let cfg = config.as_deref().map(Config::load_unchecked).transpose()?;
            let done = impactcam::footage::import::import(&file, &out, cfg.as_ref())?;
            println!(
                "imported {} frames ({}, {}×{} px, {} frames/s) into {}",
                done.frames,
                done.kind,
                done.width,
                done.height,
                done.frame_rate_hz,
                done.session.display()
            );
            Ok(0)
        }
        Command::Devices => {
            println!("cameras:");
            for line in impactcam::camera::list() {
                println!("  {line}");
            }
            println!("serial ports (relay modules):");
            match serialport::available_ports() {
                Ok(ports) if ports.is_empty() => println!("  none found"),
                Ok(ports) => {
                    for p in ports {
                        println!("  {}  {:?}", p.port_name, p.port_type);
                    }
                }
                Err(e) => println!("  cannot list: {e}"),
            }
            Ok(0)
        }
        Command::Config { action } => match action {
            ConfigAction::Check { file } => {
                let cfg = Config::load(&file)?;
                println!(
                    "{}: valid ({} camera {}×{} {} at {} Hz, {} trigger)",
                    file.display(),
                    format!("{:?}", cfg.camera.backend).to_lowercase(),
                    cfg.camera.width,
                    cfg.camera.height,
                    cfg.camera.pixel_format.name(),
                    cfg.camera.frame_rate_hz,
                    format!("{:?}", cfg.trigger.backend).to_lowercase()
                );
                Ok(0)
            }
            ConfigAction::Default => {
                print!("{}", impactcam::config::DEFAULT_TOML);
                Ok(0)
            }
        },
        Command::Bench { what } => match what {
            BenchWhat::Capture { frames, dir } => {
                if frames < 10 {
                    bail!("--frames: {frames} is too few, expected at least 10");
                }
                print!("{}", impactcam::bench::capture(frames, &dir)?);
                Ok(0)
            }
            BenchWhat::Soak { experiments, dir } => {
                let tmp = dir.join(format!(".impactcam-soak-{}", std::process::id()));
                let result = impactcam::bench::soak::soak(experiments, &tmp);
                let _ = std::fs::remove_dir_all(&tmp);
                print!("{}", result.map_err(anyhow::Error::msg)?);
                Ok(0)
            }
            BenchWhat::Relay { pulses, pulse_ms } => {
                if pulses == 0 || !(pulse_ms > 0.0 && pulse_ms <= 500.0) {
                    bail!("--pulses must be at least 1 and --pulse-ms between 0 and 500");
                }
                print!(
                    "{}",
                    impactcam::bench::relay::relay(pulses, pulse_ms).map_err(anyhow::Error::msg)?
                );
                Ok(0)
            }
            BenchWhat::Analysis {
                experiments,
                validation,
                opencv,
                dir,
            } => {
                if experiments == 0 && validation.is_none() {
                    bail!("--experiments 0 without --validation times nothing");
                }
                let tmp = dir.join(format!(".impactcam-bench-analysis-{}", std::process::id()));
                let result = impactcam::bench::analysis::analysis(
                    experiments,
                    validation.as_deref(),
                    opencv.as_deref(),
                    &tmp,
                );
                let _ = std::fs::remove_dir_all(&tmp);
                print!("{}", result.map_err(anyhow::Error::msg)?);
                Ok(0)
            }
            BenchWhat::Rigs { experiments, dir } => {
                if experiments == 0 {
                    bail!("--experiments: 0 runs nothing, expected at least 1");
                }
                print!("{}", impactcam::bench::rigs::rigs(experiments, &dir));
                Ok(0)
            }
            BenchWhat::Validation { dir } => {
                print!(
                    "{}",
                    impactcam::bench::validation::validation(&dir).map_err(anyhow::Error::msg)?
                );
                Ok(0)
            }
            BenchWhat::Accuracy {
                quick,
                repeat,
                looks,
                exposure_ms,
                flicker_percent,
                dir,
                keep,
                sessions,
            } => {
                if !sessions.is_empty() {
                    let found = impactcam::batch::sessions(&sessions)?;
                    print!(
                        "{}",
                        impactcam::bench::accuracy::accuracy_of_sessions(&found)
                    );
                    return Ok(0);
                }
                if repeat == 0 {
                    bail!("--repeat: 0 runs nothing, expected at least 1");
                }
                let looks = (looks != "default").then_some(looks);
                if let Some(l) = &looks {
                    hw_sim::Look::draw(l, 0).map_err(|e| {
                        anyhow::anyhow!("--looks: {}", e.trim_start_matches("sim.look_family: "))
                    })?;
                }
                if let Some(ms) = exposure_ms {
                    if !(ms.is_finite() && (0.0..=100.0).contains(&ms)) {
                        bail!("--exposure-ms: {ms} is out of range, expected 0 to 100 (ms the shutter is open)");
                    }
                }
                if let Some(p) = flicker_percent {
                    if !(p.is_finite() && (0.0..=100.0).contains(&p)) {
                        bail!("--flicker-percent: {p} is out of range, expected 0 to 100 (per cent of the lamps' mean light)");
                    }
                    if looks.is_none() {
                        bail!("--flicker-percent: needs --looks other than default (hw-sim's default render has no lamp to flicker)");
                    }
                }
                let text = impactcam::bench::accuracy::accuracy(
                    quick,
                    repeat,
                    looks.as_deref(),
                    exposure_ms,
                    flicker_percent,
                    &dir,
                    keep,
                );
                print!("{text}");
                Ok(0)
            }
        },
    }
}

/// Prints the shard's share when there is one.
fn say_plan(plan: &impactcam::batch::Plan, shard: Option<impactcam::batch::Shard>) {
    if let Some(s) = shard {
        Status::new().line(&format!(
            "shard {}/{}: {} of {} sessions",
            s.index,
            s.count,
            plan.sessions.len(),
            plan.found
        ));
    }
}

/// `impactcam replay` of many sessions: a line per session as it finishes; exit 2 if any
/// differs, 1 if any could not be analysed.
fn replay_batch(
    paths: &[PathBuf],
    shard: Option<impactcam::batch::Shard>,
    jobs: usize,
) -> Result<i32> {
    use impactcam::batch::ReplayOutcome;
    let plan = impactcam::batch::plan(paths, shard, jobs)?;
    say_plan(&plan, shard);
    let total = plan.sessions.len();
    let outcomes = impactcam::batch::run(
        &plan.sessions,
        plan.jobs,
        impactcam::batch::replay_one,
        |s, o, k| eprintln!("[{k}/{total}] {}: {o}", s.display()),
    );
    let count = |f: &dyn Fn(&ReplayOutcome) -> bool| outcomes.iter().filter(|o| f(o)).count();
    let differ = count(&|o| *o == ReplayOutcome::Differs);
    let failed = count(&|o| matches!(o, ReplayOutcome::Failed(_)));
    println!(
        "replayed {total} session(s) on {} thread(s): {} identical, {differ} differ, {} without a recorded report, {failed} failed",
        plan.jobs,
        count(&|o| *o == ReplayOutcome::Identical),
        count(&|o| *o == ReplayOutcome::NoRecord),
    );
    Ok(if differ > 0 {
        2
    } else if failed > 0 {
        1
    } else {
        0
    })
}

/// `impactcam analyze` of many sessions: each one's report.json written into it, a line per
/// session as it finishes; exit 1 if any failed.
fn analyze_batch(
    paths: &[PathBuf],
    config: Option<&Path>,
    overwrite: bool,
    shard: Option<impactcam::batch::Shard>,
    jobs: usize,
) -> Result<i32> {
    let given = config.map(Config::load).transpose()?;
    let plan = impactcam::batch::plan(paths, shard, jobs)?;
    if given.is_some() && !overwrite {
        if let Some(s) = plan
            .sessions
            .iter()
            .find(|s| s.join("report.json").exists())
        {
            bail!(
                "{}: the session's recorded report.json would be replaced by one from another --config; give --overwrite to replace the recorded reports",
                s.display()
            );
        }
    }
    say_plan(&plan, shard);
    let total = plan.sessions.len();
    let outcomes = impactcam::batch::run(
        &plan.sessions,
        plan.jobs,
        |s| impactcam::batch::analyze_one(s, given.as_ref()),
        |s, o, k| match o {
            Ok(()) => eprintln!("[{k}/{total}] {}: report.json written", s.display()),
            Err(e) => eprintln!("[{k}/{total}] {}: error: {e}", s.display()),
        },
    );
    let failed = outcomes.iter().filter(|o| o.is_err()).count();
    println!(
        "analysed {total} session(s) on {} thread(s): {} report(s) written, {failed} failed",
        plan.jobs,
        total - failed
    );
    Ok(if failed > 0 { 1 } else { 0 })
}

/// `impactcam analyze`: a session, a TIFF stack or a tracks CSV; the report beside the input
/// or in `--out`.
fn analyze_command(
    path: Option<PathBuf>,
    tracks: Option<PathBuf>,
    config: Option<PathBuf>,
    json: bool,
    out: Option<PathBuf>,
    overwrite: bool,
) -> Result<i32> {
    // Footage decides its own frame size and rate: the config is validated against them once
    // the file is open (`experiment::analyze_path`); for --tracks, as it stands.
    let given = config.as_deref().map(Config::load_unchecked).transpose()?;
    if tracks.is_some() {
        if let (Some(c), Some(p)) = (&given, &config) {
            c.validate()
                .map_err(|m| anyhow::anyhow!("{}: {m}", p.display()))?;
        }
    }
    let needs_config = || {
        anyhow::anyhow!("--config: missing, expected the config that describes this footage (a session uses its own; a TIFF stack or --tracks needs one)")
    };
    let path = match (path, tracks) {
        (Some(p), _) => p,
        (None, Some(t)) => {
            let cfg = given.ok_or_else(needs_config)?;
            let report = impactcam::analysis::analyze_tracks(&t, &cfg)?;
            let out_dir = out.unwrap_or_else(|| {
                t.parent()
                    .map(Path::to_path_buf)
                    .unwrap_or_else(|| PathBuf::from("."))
            });
            std::fs::create_dir_all(&out_dir)
                .with_context(|| format!("{}: cannot create", out_dir.display()))?;
            let stem = t
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
            let target = out_dir.join(format!("{stem}.report.json"));
            impactcam::session::write_atomic(&target, experiment::report_json(&report).as_bytes())?;
            if json {
                print!("{}", experiment::report_json(&report));
            } else {
                print!("{}", report_text(&report));
                println!("report      {}", target.display());
            }
            return Ok(0);
        }
        (None, None) => bail!("give a session, a TIFF stack, or --tracks FILE.csv"),
    };
    if path.is_dir()
        && out.is_none()
        && given.is_some()
        && !overwrite
        && path.join("report.json").exists()
    {
        bail!(
            "{}: the session's recorded report.json would be replaced by one from another --config; give --out DIR, or --overwrite to replace it",
            path.display()
        );
    }
    if !path.is_dir() && given.is_none() {
        return Err(needs_config());
    }
    let report = experiment::analyze_path(&path, given.as_ref(), &mut |_, _| {})?;
    let out_dir = match out {
        Some(d) => d,
        None if path.is_dir() => path.clone(),
        None => path
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_else(|| PathBuf::from(".")),
    };
    std::fs::create_dir_all(&out_dir)
        .with_context(|| format!("{}: cannot create", out_dir.display()))?;
    let target = if path.is_dir() || out_dir != path.parent().unwrap_or(Path::new("")) {
        out_dir.join("report.json")
    } else {
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        out_dir.join(format!("{stem}.report.json"))
    };
    deliver(&report, &target, json)
}

/// `impactcam sweep`: a campaign of experiments, then its fit.
fn sweep_command(
    config: Option<PathBuf>,
    tube_angles: String,
    impact_offsets: Option<String>,
    repeats: u32,
    dir: Option<PathBuf>,
) -> Result<i32> {
    let cfg = load_config(config.as_deref())?;
    let angles = impactcam::campaign::parse_range(&tube_angles, "--tube-angles")
        .map_err(anyhow::Error::msg)?;
    let offsets = match &impact_offsets {
        Some(t) => Some(
            impactcam::campaign::parse_range(t, "--impact-offsets").map_err(anyhow::Error::msg)?,
        ),
        None => None,
    };
    if repeats == 0 {
        bail!("--repeats: 0 is not allowed, expected 1 or more");
    }
    let dir =
        dir.unwrap_or_else(|| PathBuf::from("campaigns").join(impactcam::session::utc_stamp().0));
    let abort = abort_flag();
    let mut status = Status::new();
    let (_, f) = impactcam::campaign::sweep(
        &cfg,
        &dir,
        &angles,
        offsets.as_deref(),
        repeats,
        abort,
        &mut |m| status.line(m),
    )?;
    print!("{}", impactcam::campaign::fit_text(&f));
    println!(
        "campaign    {} (fit.json, collisions.csv, psi.svg, report.html)",
        dir.display()
    );
    Ok(0)
}

/// `impactcam fit`: e, μ, β0 over many reports.
fn fit_command(paths: Vec<PathBuf>, json: bool, out: Option<PathBuf>) -> Result<i32> {
    let mut skipped = Vec::new();
    let mut collisions = impactcam::campaign::load(&paths, &mut skipped)?;
    for s in &skipped {
        Status::new().line(&format!("skipped: {s}"));
    }
    if collisions.is_empty() {
        bail!("no collision with a measured e among the given reports");
    }
    let f = impactcam::campaign::fit::fit(&mut collisions);
    if let Some(out) = out {
        std::fs::create_dir_all(&out)
            .with_context(|| format!("{}: cannot create", out.display()))?;
        impactcam::campaign::write_outputs(&out, &collisions, &f, "")?;
    }
    if json {
        println!(
            "{}",
            serde_json::to_string_pretty(&impactcam::campaign::fit_json(&f))?
        );
    } else {
        print!("{}", impactcam::campaign::fit_text(&f));
    }
    Ok(0)
}
