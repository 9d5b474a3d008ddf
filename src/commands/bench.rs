//! `impactcam bench …`: each benchmark's arguments checked, then the library's bench run and its
//! table printed.

use crate::cli::BenchWhat;
use anyhow::{bail, Result};

/// Runs the benchmark `what` names.
pub(crate) fn bench(what: BenchWhat) -> Result<i32> {
    match what {
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
        BenchWhat::Validation { dir, saved_as } => {
            print!(
                "{}",
                impactcam::bench::validation::validation(&dir, &saved_as)
                    .map_err(anyhow::Error::msg)?
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
    }
}
