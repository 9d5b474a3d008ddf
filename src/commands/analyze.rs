//! Commands that analyse what was recorded: `replay`, `analyze` (one input or a batch, sharded
//! for a cluster's array job) and `calibrate`.

use super::deliver;
use anyhow::{bail, Context, Result};
use impactcam::config::Config;
use impactcam::experiment;
use impactcam::summary::{report_text, Status};
use std::path::{Path, PathBuf};

/// `impactcam replay`: one session analysed again and compared with its recorded report (exit 2
/// if it differs), or many (`replay_batch`).
pub(crate) fn replay(
    sessions: Vec<PathBuf>,
    json: bool,
    jobs: Option<u16>,
    shard: Option<impactcam::batch::Shard>,
) -> Result<i32> {
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
        Some(r) if r == text => Status::new().line("replay: identical to the recorded report.json"),
        Some(_) => {
            Status::new().line("replay: DIFFERS from the recorded report.json");
            return Ok(2);
        }
        None => Status::new().line("replay: the session has no report.json to compare with"),
    }
    Ok(0)
}

/// `impactcam calibrate`: the `[geometry]` TOML (and its figure) from recordings of flights.
pub(crate) fn calibrate(
    paths: Vec<PathBuf>,
    config: Option<PathBuf>,
    out: Option<PathBuf>,
    grid: Option<PathBuf>,
    grid_pitch_mm: Option<f64>,
) -> Result<i32> {
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

/// `impactcam analyze`: one input (`analyze_one`) or a batch of sessions (`analyze_batch`).
#[allow(clippy::too_many_arguments)]
pub(crate) fn analyze(
    paths: Vec<PathBuf>,
    tracks: Option<PathBuf>,
    config: Option<PathBuf>,
    json: bool,
    out: Option<PathBuf>,
    overwrite: bool,
    jobs: Option<u16>,
    shard: Option<impactcam::batch::Shard>,
) -> Result<i32> {
    let jobs = jobs.map_or(0, usize::from);
    let single = match paths.as_slice() {
        [] => None,
        [one] if shard.is_none() && impactcam::footage::is_one_input(one) => Some(one.clone()),
        _ => {
            if json || out.is_some() {
                bail!("--json and --out: one input only (a batch writes each session's report.json into it)");
            }
            return analyze_batch(&paths, config.as_deref(), overwrite, shard, jobs);
        }
    };
    impactcam::analysis::set_threads(jobs);
    analyze_one(single, tracks, config, json, out, overwrite)
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
fn analyze_one(
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
            return deliver(&report, &out_dir.join(format!("{stem}.report.json")), json);
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
