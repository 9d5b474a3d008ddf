//! Campaigns: many experiments fitted together. This module owns the sweep (a series of
//! experiments over tube angles, resumable), loading reports for the fit, and the campaign's
//! outputs (CSV table, ψ2–ψ1 plot as SVG, HTML report). The physics of the fit is in `fit`.

pub mod fit;
pub mod plot;

use crate::analysis::report::{Report, REPORT_SCHEMA};
use crate::config::{CameraBackend, Config};
use crate::experiment::{self, ExperimentError};
use crate::session::{write_atomic, SessionReader};
use fit::{CampaignFit, Collision};
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

#[derive(Debug, thiserror::Error)]
pub enum CampaignError {
    #[error("{path}: {message}")]
    Input { path: PathBuf, message: String },
    #[error("{0}")]
    Mixed(String),
    #[error(transparent)]
    Experiment(#[from] ExperimentError),
}

fn input(path: &Path, message: impl Into<String>) -> CampaignError {
    CampaignError::Input {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// What identifies the material of a collision: reports of different materials must not be
/// fitted together.
fn material_key(cfg: &Config) -> String {
    let (da, ma) = cfg.spheres.sphere(0);
    let (db, mb) = cfg.spheres.sphere(1);
    let material = match (&cfg.spheres.material, cfg.camera.backend) {
        (Some(m), _) => m.clone(),
        (None, CameraBackend::Sim) => format!("sim:{}", cfg.sim.material),
        (None, _) => "unnamed".into(),
    };
    format!("{material} a {da} mm {ma} g, b {db} mm {mb} g")
}

fn collision_from(report: Report, source: String, cfg: Option<&Config>) -> Option<Collision> {
    let e = report.e.clone()?;
    Some(Collision {
        source,
        // The angle the lab wrote down, else the simulator's own.
        tube_angle_deg: cfg.and_then(|c| {
            c.experiment
                .tube_angle_deg
                .or((c.camera.backend == CameraBackend::Sim).then_some(c.sim.tube_angle_deg))
        }),
        e: e.value,
        e_sigma: e.uncertainty,
        psi1: report.psi1.as_ref().map(|x| x.value),
        psi1_sigma: report.psi1.as_ref().map(|x| x.uncertainty),
        psi2: report.psi2.as_ref().map(|x| x.value),
        psi2_sigma: report.psi2.as_ref().map(|x| x.uncertainty),
        beta: report.beta.as_ref().map(|x| x.value),
        beta_sigma: report.beta.as_ref().map(|x| x.uncertainty),
        class: None,
        outlier: false,
        report,
    })
}

fn read_report(path: &Path) -> Result<Report, CampaignError> {
    let text =
        std::fs::read_to_string(path).map_err(|e| input(path, format!("cannot read: {e}")))?;
    let v: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| input(path, format!("not JSON: {e}")))?;
    match v.get("schema").and_then(|s| s.as_str()) {
        Some(REPORT_SCHEMA) => {}
        Some(other) => {
            return Err(input(
                path,
                format!("report schema {other:?} cannot be fitted with {REPORT_SCHEMA:?}"),
            ))
        }
        None => return Err(input(path, "not an impactcam report (no schema field)")),
    }
    let report: Report = serde_json::from_value(v)
        .map_err(|e| input(path, format!("not a valid {REPORT_SCHEMA} report: {e}")))?;
    check_report_numbers(&report).map_err(|m| input(path, m))?;
    Ok(report)
}

/// The numbers a fit uses, finite and in range: e in [0, 2] (a measured e may pass 1 by its
/// noise, never by 2), ψ and β finite, every uncertainty finite and ≥ 0.
fn check_report_numbers(r: &Report) -> Result<(), String> {
    let check = |key: &str, value: f64, sigma: f64, range: Option<(f64, f64)>| {
        if !value.is_finite() || range.is_some_and(|(lo, hi)| !(lo..=hi).contains(&value)) {
            let want = range.map_or("a finite number".to_string(), |(lo, hi)| {
                format!("a number in [{lo}, {hi}]")
            });
            return Err(format!(
                "{key}.value: {value} is out of range, expected {want}"
            ));
        }
        if !(sigma.is_finite() && sigma >= 0.0) {
            return Err(format!(
                "{key}.uncertainty: {sigma} is out of range, expected a finite number ≥ 0"
            ));
        }
        Ok(())
    };
    if let Some(e) = &r.e {
        check("e", e.value, e.uncertainty, Some((0.0, 2.0)))?;
    }
    for (key, x) in [("psi1", &r.psi1), ("psi2", &r.psi2), ("beta", &r.beta)] {
        if let Some(x) = x {
            check(key, x.value, x.uncertainty, None)?;
        }
    }
    Ok(())
}

/// Collisions from report files, session directories, or campaign directories (their
/// `sessions/`). Sessions without a report are skipped and said so in `skipped`.
pub fn load(paths: &[PathBuf], skipped: &mut Vec<String>) -> Result<Vec<Collision>, CampaignError> {
    let mut out = Vec::new();
    let mut materials: Vec<(String, PathBuf)> = Vec::new();
    // A stack: reversed so that the collisions come out in the order given.
    let mut queue: Vec<PathBuf> = paths.iter().rev().cloned().collect();
    while let Some(p) = queue.pop() {
        if p.is_dir() && p.join("sessions").is_dir() {
            let mut inner: Vec<PathBuf> = std::fs::read_dir(p.join("sessions"))
                .map_err(|e| input(&p, e.to_string()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .collect();
            inner.sort();
            queue.extend(inner.into_iter().rev());
            continue;
        }
        let (report_path, cfg) = if p.is_dir() {
            let cfg = SessionReader::open(&p)
                .map(|r| r.manifest.config)
                .map_err(|e| input(&p, e.to_string()))?;
            (p.join("report.json"), Some(cfg))
        } else {
            (p.clone(), None)
        };
        if p.is_dir() && !report_path.exists() {
            skipped.push(format!("{}: no report.json (not analysed)", p.display()));
            continue;
        }
        let report = read_report(&report_path)?;
        if let Some(cfg) = &cfg {
            let key = material_key(cfg);
            if let Some((other, other_path)) = materials.iter().find(|(k, _)| *k != key) {
                return Err(CampaignError::Mixed(format!(
                    "reports from different materials cannot be fitted together: {} is {key}, {} is {other}",
                    p.display(),
                    other_path.display()
                )));
            }
            materials.push((key, p.clone()));
        }
        let name = p
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        match collision_from(report, name, cfg.as_ref()) {
            Some(c) => out.push(c),
            None => skipped.push(format!("{}: the report has no e", p.display())),
        }
    }
    Ok(out)
}

/// The sessions directly under `dir` whose manifest puts them in `campaign`
/// (`config.experiment.campaign`), in name order, with their labels; at most `max` looked at.
pub fn sessions_in_campaign(
    dir: &Path,
    campaign: &str,
    max: usize,
) -> Vec<(PathBuf, crate::config::ExperimentLabel)> {
    let mut found: Vec<_> = labelled_sessions(dir, max)
        .into_iter()
        .filter(|(_, l)| l.campaign.as_deref() == Some(campaign))
        .collect();
    found.sort_by(|a, b| a.0.cmp(&b.0));
    found
}

/// (session directory, its label) for each session directly under `dir` that belongs to a
/// campaign, at most `max` sessions looked at (newest names first).
pub fn labelled_sessions(dir: &Path, max: usize) -> Vec<(PathBuf, crate::config::ExperimentLabel)> {
    let mut sessions: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|entries| {
            entries
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| crate::batch::is_session(p))
                .collect()
        })
        .unwrap_or_default();
    sessions.sort_unstable_by(|a, b| b.cmp(a));
    sessions.truncate(max);
    sessions
        .into_iter()
        .filter_map(|p| {
            // Only the label is wanted: the manifest is read as JSON, not validated as a whole.
            let text = std::fs::read_to_string(p.join("session.json")).ok()?;
            let v: serde_json::Value = serde_json::from_str(&text).ok()?;
            let label: crate::config::ExperimentLabel =
                serde_json::from_value(v["config"]["experiment"].clone()).ok()?;
            label.campaign.is_some().then_some((p, label))
        })
        .collect()
}

/// The per-collision table as CSV (one row per experiment), quoted where a cell needs it (a
/// source name with a comma).
pub fn csv(collisions: &[Collision]) -> String {
    let mut header: Vec<String> = [
        "source",
        "tube_angle_deg",
        "e",
        "e_sigma",
        "psi1",
        "psi1_sigma",
        "psi2",
        "psi2_sigma",
        "beta",
        "beta_sigma",
        "class",
        "outlier",
    ]
    .map(String::from)
    .to_vec();
    for sphere in ["a", "b"] {
        for q in [
            "velocity_pre_mm_s",
            "velocity_post_mm_s",
            "spin_pre_rad_s",
            "spin_post_rad_s",
        ] {
            for c in ["x", "y", "z"] {
                header.push(format!("{sphere}_{q}_{c}"));
                header.push(format!("{sphere}_{q}_{c}_sigma"));
            }
        }
    }
    let mut w = csv::Writer::from_writer(Vec::new());
    // Writing into memory cannot fail; a row that somehow did is left out, not half-written.
    let _ = w.write_record(&header);
    let opt = |v: Option<f64>| v.map(|x| format!("{x}")).unwrap_or_default();
    for c in collisions {
        let mut row = vec![
            c.source.clone(),
            opt(c.tube_angle_deg),
            format!("{}", c.e),
            format!("{}", c.e_sigma),
            opt(c.psi1),
            opt(c.psi1_sigma),
            opt(c.psi2),
            opt(c.psi2_sigma),
            opt(c.beta),
            opt(c.beta_sigma),
            c.class.clone().unwrap_or_default(),
            c.outlier.to_string(),
        ];
        for sp in [&c.report.spheres.a, &c.report.spheres.b] {
            for est in [
                Some(&sp.velocity_pre_mm_s),
                Some(&sp.velocity_post_mm_s),
                sp.spin_pre_rad_s.as_ref(),
                sp.spin_post_rad_s.as_ref(),
            ] {
                for i in 0..3 {
                    row.push(opt(est.map(|e| e.value[i])));
                    row.push(opt(est.map(|e| e.uncertainty[i])));
                }
            }
        }
        let _ = w.write_record(&row);
    }
    String::from_utf8(w.into_inner().unwrap_or_default()).unwrap_or_default()
}

fn est_text(name: &str, e: &Option<fit::FitEstimate>) -> String {
    match e {
        Some(e) => format!(
            "{name:<11} {:.4} ± {:.4}  (95 % interval {:.4} to {:.4})",
            e.value, e.uncertainty, e.ci95[0], e.ci95[1]
        ),
        None => format!("{name:<11} not estimated"),
    }
}

/// The fit as a readable table.
pub fn fit_text(f: &CampaignFit) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "{}", est_text("e", &f.e));
    if let Some(sp) = f.e_spread {
        let _ = writeln!(
            s,
            "{:<11} {sp:.4} (standard deviation of the per-collision e)",
            "e spread"
        );
    }
    if let Some(t) = &f.e_trend_per_psi1 {
        let _ = writeln!(
            s,
            "{:<11} {:.4} ± {:.4} per unit ψ1",
            "e trend", t.value, t.uncertainty
        );
    }
    let _ = writeln!(s, "{}", est_text("mu", &f.mu));
    let _ = writeln!(s, "{}", est_text("beta0", &f.beta0));
    let _ = writeln!(s, "{}", est_text("psi1_break", &f.psi1_break));
    if let Some(t) = &f.sliding_slope {
        let _ = writeln!(
            s,
            "{:<11} {:.3} ± {:.3} (free slope of the sliding points; 1 if Walton's model holds)",
            "slope", t.value, t.uncertainty
        );
    }
    let _ = writeln!(
        s,
        "\n{:<28} {:>6} {:>16} {:>16} {:>16} {:>10} ",
        "collision", "tube°", "e", "psi1", "psi2", "class"
    );
    let pm = |e: &Option<crate::analysis::report::Estimate<f64>>| {
        e.as_ref()
            .map(|e| format!("{:.3} ± {:.3}", e.value, e.uncertainty))
            .unwrap_or_else(|| "—".into())
    };
    for c in &f.collisions {
        let _ = writeln!(
            s,
            "{:<28} {:>6} {:>16} {:>16} {:>16} {:>10} {}",
            c.source,
            c.tube_angle_deg.map(|a| format!("{a}")).unwrap_or_default(),
            format!("{:.4} ± {:.4}", c.e.value, c.e.uncertainty),
            pm(&c.psi1),
            pm(&c.psi2),
            c.class.clone().unwrap_or_else(|| "—".into()),
            if c.outlier { "OUTLIER" } else { "" }
        );
    }
    for m in &f.messages {
        let _ = writeln!(s, "note: {m}");
    }
    s
}

/// The campaign report as one HTML page: the fit, the plot, the table, the config.
pub fn html(f: &CampaignFit, svg: &str, config_toml: &str) -> String {
    let esc = |t: &str| {
        t.replace('&', "&amp;")
            .replace('<', "&lt;")
            .replace('>', "&gt;")
    };
    format!(
        "<!doctype html><html><head><meta charset=\"utf-8\"><title>impactcam campaign</title>\
         <style>body{{font-family:sans-serif;max-width:960px;margin:2em auto}}pre{{background:#f4f4f4;padding:1em}}</style></head><body>\
         <h1>impactcam campaign</h1><h2>Fit</h2><pre>{}</pre><h2>ψ2 against ψ1</h2>{svg}<h2>Config</h2><pre>{}</pre></body></html>\n",
        esc(&fit_text(f)),
        esc(config_toml)
    )
}

/// Writes fit.json, collisions.csv, psi.svg and report.html into `dir`.
pub fn write_outputs(
    dir: &Path,
    collisions: &[Collision],
    f: &CampaignFit,
    config_toml: &str,
) -> Result<(), CampaignError> {
    let (svg, png) = plot::psi_plot(collisions, f);
    write_atomic(&dir.join("psi.png"), &png).map_err(|e| input(dir, e.to_string()))?;
    // One trajectory and one residual figure per experiment.
    let plots = dir.join("plots");
    std::fs::create_dir_all(&plots).map_err(|e| input(&plots, e.to_string()))?;
    let g = crate::config::AnalysisConfig::default().gravity_mm_s2;
    for c in collisions {
        for (kind, (svg_t, png_t)) in [
            (
                "trajectory",
                crate::figures::trajectory::trajectory_plot(&c.report, g),
            ),
            (
                "residuals",
                crate::figures::trajectory::residual_plot(&c.report, g),
            ),
        ] {
            write_atomic(
                &plots.join(format!("{}-{kind}.svg", c.source)),
                svg_t.as_bytes(),
            )
            .map_err(|e| input(&plots, e.to_string()))?;
            write_atomic(&plots.join(format!("{}-{kind}.png", c.source)), &png_t)
                .map_err(|e| input(&plots, e.to_string()))?;
        }
    }
    let io = |p: &Path, e: crate::session::SessionError| input(p, e.to_string());
    let json = serde_json::to_string_pretty(&fit_json(f)).unwrap_or_default();
    write_atomic(&dir.join("fit.json"), json.as_bytes()).map_err(|e| io(dir, e))?;
    write_atomic(&dir.join("collisions.csv"), csv(collisions).as_bytes())
        .map_err(|e| io(dir, e))?;
    write_atomic(&dir.join("psi.svg"), svg.as_bytes()).map_err(|e| io(dir, e))?;
    write_atomic(
        &dir.join("report.html"),
        html(f, &svg, config_toml).as_bytes(),
    )
    .map_err(|e| io(dir, e))?;
    Ok(())
}

/// The `fit --json` document: e, mu, beta0, psi1_break as estimate objects, plus the rows.
pub fn fit_json(f: &CampaignFit) -> serde_json::Value {
    serde_json::to_value(f).unwrap_or_default()
}

/// One planned experiment of a sweep.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct SweepEntry {
    pub tube_angle_deg: f64,
    pub impact_offset: Option<f64>,
    pub repeat: u32,
    pub session: Option<String>,
    /// "pending", "done", "failed"
    pub status: String,
    pub error: Option<String>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SweepPlan {
    pub schema: String,
    pub entries: Vec<SweepEntry>,
}

/// Most values a sweep range may give (a campaign of more is a typo).
pub const MAX_RANGE_VALUES: usize = 10_000;

/// Parses "a:b:step" (inclusive) or a single value.
pub fn parse_range(text: &str, what: &str) -> Result<Vec<f64>, String> {
    let parts: Vec<&str> = text.split(':').collect();
    let num = |s: &str| {
        s.trim()
            .parse::<f64>()
            .map_err(|_| format!("{what}: {s:?} is not a number, expected a or a:b:step"))
    };
    match parts.as_slice() {
        [a] => {
            let a = num(a)?;
            if !a.is_finite() {
                return Err(format!("{what}: {text:?} expected a finite number"));
            }
            Ok(vec![a])
        }
        [a, b, step] => {
            let (a, b, step) = (num(a)?, num(b)?, num(step)?);
            if !(a.is_finite() && b.is_finite() && step.is_finite()) || step <= 0.0 || b < a {
                return Err(format!(
                    "{what}: {text:?} expected a:b:step with finite a ≤ b and step > 0"
                ));
            }
            let steps = ((b - a) / step + 1e-9).floor();
            if steps.is_nan() || steps >= MAX_RANGE_VALUES as f64 {
                return Err(format!(
                    "{what}: {text:?} gives {steps:.0} values, expected at most {MAX_RANGE_VALUES}"
                ));
            }
            let n = steps as usize;
            Ok((0..=n).map(|k| a + step * k as f64).collect())
        }
        _ => Err(format!("{what}: {text:?} expected a or a:b:step")),
    }
}

/// Runs (or resumes) a sweep in `dir`; completed experiments are kept and skipped.
pub fn sweep(
    cfg: &Config,
    dir: &Path,
    angles: &[f64],
    offsets: Option<&[f64]>,
    repeats: u32,
    abort: Arc<AtomicBool>,
    say: &mut dyn FnMut(&str),
) -> Result<(Vec<Collision>, CampaignFit), CampaignError> {
    std::fs::create_dir_all(dir.join("sessions")).map_err(|e| input(dir, e.to_string()))?;
    let plan_path = dir.join("campaign.json");
    let mut plan = if plan_path.exists() {
        let text =
            std::fs::read_to_string(&plan_path).map_err(|e| input(&plan_path, e.to_string()))?;
        let p: SweepPlan = serde_json::from_str(&text)
            .map_err(|e| input(&plan_path, format!("not a campaign plan: {e}")))?;
        say(&format!(
            "resuming: {} of {} experiments already done",
            p.entries.iter().filter(|e| e.status == "done").count(),
            p.entries.len()
        ));
        p
    } else {
        let mut entries = Vec::new();
        for &a in angles {
            for o in offsets
                .map(|o| o.iter().map(|x| Some(*x)).collect::<Vec<_>>())
                .unwrap_or_else(|| vec![None])
            {
                for r in 0..repeats {
                    entries.push(SweepEntry {
                        tube_angle_deg: a,
                        impact_offset: o,
                        repeat: r,
                        session: None,
                        status: "pending".into(),
                        error: None,
                    });
                }
            }
        }
        SweepPlan {
            schema: "impactcam.campaign/1".into(),
            entries,
        }
    };
    let save = |plan: &SweepPlan| {
        write_atomic(
            &plan_path,
            serde_json::to_string_pretty(plan)
                .unwrap_or_default()
                .as_bytes(),
        )
        .map_err(|e| input(&plan_path, e.to_string()))
    };
    save(&plan)?;
    let total = plan.entries.len();
    for k in 0..total {
        if plan.entries[k].status == "done" {
            continue;
        }
        if abort.load(std::sync::atomic::Ordering::Relaxed) {
            say("interrupted: the campaign can be resumed with the same --dir");
            break;
        }
        let entry = plan.entries[k].clone();
        let mut c = cfg.clone();
        c.recording.dir = dir.join("sessions");
        c.sim.tube_angle_deg = entry.tube_angle_deg;
        c.experiment.tube_angle_deg = Some(entry.tube_angle_deg);
        if let Some(o) = entry.impact_offset {
            c.sim.impact_offset = o;
        }
        // Each experiment of a simulated sweep is a different throw of the same lab.
        c.sim.seed = cfg.sim.seed.wrapping_add(k as u64 * 7919);
        if c.camera.backend != CameraBackend::Sim {
            say(&format!(
                "set the tubes to {}° (experiment {}/{total})",
                entry.tube_angle_deg,
                k + 1
            ));
        }
        say(&format!(
            "experiment {}/{total}: tube {}°{} repeat {}",
            k + 1,
            entry.tube_angle_deg,
            entry
                .impact_offset
                .map(|o| format!(", offset {o}"))
                .unwrap_or_default(),
            entry.repeat + 1
        ));
        match experiment::run(&c, abort.clone(), &mut |_| {}) {
            Ok((rec, report)) => {
                let e = report
                    .e
                    .as_ref()
                    .map(|e| format!("e = {:.4} ± {:.4}", e.value, e.uncertainty))
                    .unwrap_or_default();
                say(&format!("  done: {} {e}", rec.session_dir.display()));
                plan.entries[k].session = rec
                    .session_dir
                    .file_name()
                    .map(|s| s.to_string_lossy().into_owned());
                plan.entries[k].status = "done".into();
                plan.entries[k].error = None;
            }
            Err(e) => {
                say(&format!("  failed: {e}"));
                plan.entries[k].status = "failed".into();
                plan.entries[k].error = Some(e.to_string());
            }
        }
        save(&plan)?;
    }
    let mut skipped = Vec::new();
    let mut collisions = load(&[dir.to_path_buf()], &mut skipped)?;
    let f = fit::fit(&mut collisions);
    write_outputs(dir, &collisions, &f, &cfg.to_toml())?;
    Ok((collisions, f))
}
