//! Campaign commands: `sweep` (experiments over a grid of tube angles and offsets, then the
//! fit) and `fit` (e, μ, β0 over many reports).

use super::{abort_flag, load_config};
use anyhow::{bail, Context, Result};
use impactcam::summary::Status;
use std::path::PathBuf;

/// `impactcam sweep`: a campaign of experiments, then its fit.
pub(crate) fn sweep(
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
pub(crate) fn fit(paths: Vec<PathBuf>, json: bool, out: Option<PathBuf>) -> Result<i32> {
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
