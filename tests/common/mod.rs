//! Helpers shared by the integration tests: running the binary, reading what it wrote, and
//! starting a daemon.
#![allow(dead_code)]

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};

/// Runs `impactcam args…` in `dir`, with no log format or token from the environment.
pub fn impactcam(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_impactcam"))
        .args(args)
        .current_dir(dir)
        .env_remove("IMPACTCAM_LOG_FORMAT")
        .env_remove("IMPACTCAM_TOKEN")
        .output()
        .expect("impactcam binary runs")
}

/// stderr as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Runs `impactcam args…`, which must succeed, and parses its stdout as JSON.
pub fn run_json(dir: &Path, args: &[&str]) -> serde_json::Value {
    let out = impactcam(dir, args);
    assert!(out.status.success(), "{args:?}: {}", stderr(&out));
    serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("{args:?}: stdout is not JSON ({e})"))
}

/// The first (in tests: the only) session directory under `dir/sessions`.
pub fn first_session(dir: &Path) -> PathBuf {
    std::fs::read_dir(dir.join("sessions"))
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path()
}

/// A JSON file, parsed.
pub fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// `impactcam serve --listen 127.0.0.1:0 args…` in `dir` (stderr to `stderr`): the child and
/// the address it printed ("127.0.0.1:PORT").
pub fn spawn_daemon(
    dir: &Path,
    args: &[&str],
    token: Option<&str>,
    stderr: Stdio,
) -> (Child, String) {
    spawn_daemon_env(dir, args, token, stderr, &[])
}

/// `spawn_daemon` with `env` set in the daemon's environment (a fail point).
pub fn spawn_daemon_env(
    dir: &Path,
    args: &[&str],
    token: Option<&str>,
    stderr: Stdio,
    env: &[(&str, &str)],
) -> (Child, String) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_impactcam"));
    cmd.args(["serve", "--listen", "127.0.0.1:0"])
        .args(args)
        .envs(env.iter().copied())
        .current_dir(dir)
        .env_remove("IMPACTCAM_LOG_FORMAT")
        .stdout(Stdio::piped())
        .stderr(stderr);
    match token {
        Some(t) => cmd.env("IMPACTCAM_TOKEN", t),
        None => cmd.env_remove("IMPACTCAM_TOKEN"),
    };
    let mut child = cmd.spawn().expect("impactcam serve starts");
    let mut line = String::new();
    BufReader::new(child.stdout.take().expect("stdout piped"))
        .read_line(&mut line)
        .expect("the daemon prints its address");
    let addr = line
        .trim()
        .strip_prefix("listening on http://")
        .unwrap_or_else(|| panic!("daemon printed {line:?}"))
        .to_string();
    (child, addr)
}
