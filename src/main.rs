//! The impactcam command line: parses arguments (their definitions in `cli.rs`), sets up
//! logging and hands each command to `commands`, which calls the library.

mod cli;
mod commands;

use anyhow::Result;
use clap::Parser;
use cli::{Cli, Command, LogFormat};

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

/// One command, run; its exit code.
fn real_main(cli: Cli) -> Result<i32> {
    use commands::{analyze, bench, campaign, files, record};
    match cli.command {
        Command::Run { config, json } => record::run(config, json),
        Command::Capture { config } => record::capture(config),
        Command::Serve { config, listen } => record::serve(config, listen),
        Command::Replay {
            sessions,
            json,
            jobs,
            shard,
        } => analyze::replay(sessions, json, jobs, shard),
        Command::Calibrate {
            paths,
            config,
            out,
            grid,
            grid_pitch_mm,
        } => analyze::calibrate(paths, config, out, grid, grid_pitch_mm),
        Command::Analyze {
            paths,
            tracks,
            config,
            json,
            out,
            overwrite,
            jobs,
            shard,
        } => analyze::analyze(paths, tracks, config, json, out, overwrite, jobs, shard),
        Command::Sweep {
            config,
            tube_angles,
            impact_offsets,
            repeats,
            dir,
        } => campaign::sweep(config, tube_angles, impact_offsets, repeats, dir),
        Command::Fit { paths, json, out } => campaign::fit(paths, json, out),
        Command::Export {
            session,
            out,
            format,
            tiff,
        } => files::export(session, out, format, tiff),
        Command::Import { file, out, config } => files::import(file, out, config),
        Command::Devices => files::devices(),
        Command::Config { action } => files::config(action),
        Command::Bench { what } => bench::bench(what),
    }
}
