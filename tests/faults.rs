//! The fault matrix: `impactcam capture` (and the daemon) against a relay-module emulator on a
//! pseudo-terminal that logs every byte, with one fault injected per row. At the end of each
//! row: whether the relay ever closed, whether it is open now, the session's status, whether
//! its frames read back, leftover temporary files, and the exit code. The matrix is printed.

mod common;

use hw_sim::modules::{Emulator, Kind};
use std::io::{Read, Write};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A config recording from the simulated camera, with the relay on the emulator's port.
fn config(port: &str, recording: &str, trigger: &str) -> String {
    format!(
        "[trigger]\nbackend = \"serial\"\nport = \"{port}\"\nprotocol = \"lcus\"\n{trigger}\n[recording]\ndir = \"sessions\"\n{recording}\n"
    )
}

fn spawn_capture(dir: &Path, cfg: &str) -> Child {
    spawn_capture_env(dir, cfg, &[])
}

fn spawn_capture_env(dir: &Path, cfg: &str, env: &[(&str, &str)]) -> Child {
    std::fs::write(dir.join("c.toml"), cfg).unwrap();
    Command::new(env!("CARGO_BIN_EXE_impactcam"))
        .args(["capture", "--config", "c.toml"])
        .envs(env.iter().copied())
        .current_dir(dir)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

fn signal(child: &Child, sig: &str) {
    assert!(Command::new("kill")
        .args([sig, &child.id().to_string()])
        .status()
        .unwrap()
        .success());
}

/// Waits until the emulator has heard the relay close (the firing), at most 20 s.
fn wait_closed(emu: &Emulator) -> Instant {
    let t0 = Instant::now();
    loop {
        if let Some((at, _)) = emu.switches().iter().find(|(_, closed)| *closed) {
            return *at;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "the relay never closed"
        );
    }
}

struct Row {
    fault: &'static str,
    phase: &'static str,
    fired: bool,
    open_at_end: bool,
    status: String,
    frames_readable: String,
    temp_files: usize,
    exit: String,
}

/// What is on disk and on the wire after a row.
fn observe(
    fault: &'static str,
    phase: &'static str,
    dir: &Path,
    emu: &Emulator,
    exit: Option<i32>,
) -> Row {
    let switches = emu.switches();
    let sessions: Vec<_> = std::fs::read_dir(dir.join("sessions"))
        .map(|d| d.filter_map(|e| e.ok()).map(|e| e.path()).collect())
        .unwrap_or_default();
    let (status, frames_readable, temp_files) = match sessions.as_slice() {
        [] => ("none".to_string(), "-".to_string(), 0),
        [s] => {
            let status = std::fs::read_to_string(s.join("session.json"))
                .ok()
                .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
                .and_then(|m| m["status"].as_str().map(String::from))
                .unwrap_or_else(|| "unreadable".into());
            let readable = match impactcam::session::SessionReader::open(s) {
                Ok(mut r) => {
                    let mut buf = Vec::new();
                    let n = r.frames.len();
                    let ok = (0..n).all(|k| r.read_frame(k, &mut buf).is_ok());
                    format!("{n} {}", if ok { "ok" } else { "UNREADABLE" })
                }
                Err(e) => format!("error: {e}"),
            };
            let temps = std::fs::read_dir(s)
                .unwrap()
                .filter_map(|e| e.ok())
                .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
                .count();
            (status, readable, temps)
        }
        more => (format!("{} sessions", more.len()), "-".into(), 0),
    };
    Row {
        fault,
        phase,
        fired: switches.iter().any(|(_, closed)| *closed),
        open_at_end: switches.last().is_none_or(|(_, closed)| !closed),
        status,
        frames_readable,
        temp_files,
        exit: exit.map_or("signal".into(), |c| c.to_string()),
    }
}

fn print_matrix(rows: &[Row]) {
    println!(
        "\n{:<28} {:<14} {:<6} {:<9} {:<11} {:<22} {:<5} exit",
        "fault", "phase", "fired", "open now", "session", "frames read back", "tmp"
    );
    for r in rows {
        println!(
            "{:<28} {:<14} {:<6} {:<9} {:<11} {:<22} {:<5} {}",
            r.fault,
            r.phase,
            r.fired,
            r.open_at_end,
            r.status,
            r.frames_readable,
            r.temp_files,
            r.exit
        );
    }
}

/// Faults before firing: the relay must never close and nothing may be written.
fn before_firing(fault: &'static str, recording: &str, trigger: &str, port: Option<&str>) -> Row {
    let emu = Emulator::start(Kind::Lcus).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    if fault == "unusable dir (a file)" {
        std::fs::write(tmp.path().join("sessions"), b"x").unwrap();
    }
    let cfg = config(port.unwrap_or(emu.path()), recording, trigger);
    let out = spawn_capture(tmp.path(), &cfg).wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    let lines: Vec<&str> = stderr.lines().filter(|l| l.contains("error")).collect();
    assert_eq!(
        lines.len(),
        1,
        "{fault}: one error line expected:\n{stderr}"
    );
    let mut row = observe(fault, "before firing", tmp.path(), &emu, out.status.code());
    if fault == "unusable dir (a file)" {
        row.status = "none (dir is a file)".into();
    }
    row
}

/// Faults while recording: the relay must be open at the end and the frames kept.
fn while_recording(fault: &'static str, sig: Option<&str>, recording: &str) -> Row {
    let emu = Emulator::start(Kind::Lcus).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let cfg = config(
        emu.path(),
        recording,
        "relay_pulse_ms = 3000.0\nrelay_pulse_ms_max = 5000.0\n",
    );
    let mut child = spawn_capture(tmp.path(), &cfg);
    let fired_at = wait_closed(&emu);
    // Mid-pulse (the pulse lasts 3 s), with frames being written.
    std::thread::sleep(Duration::from_millis(300));
    let mut opened_after: Option<Duration> = None;
    if let Some(sig) = sig {
        signal(&child, sig);
        let killed_at = Instant::now();
        // The relay must open again soon after, whoever opens it.
        let t0 = Instant::now();
        while t0.elapsed() < Duration::from_secs(3) {
            if let Some((at, _)) = emu
                .switches()
                .iter()
                .find(|(at, closed)| !closed && *at > fired_at)
            {
                opened_after = Some(at.saturating_duration_since(killed_at));
                break;
            }
        }
    }
    let status = child.wait().unwrap();
    let row = observe(fault, "mid-pulse", tmp.path(), &emu, status.code());
    if let Some(sig) = sig {
        let opened =
            opened_after.unwrap_or_else(|| panic!("{fault}: relay not opened after {sig}"));
        assert!(
            opened < Duration::from_millis(500),
            "{fault}: relay opened {opened:?} after the signal"
        );
        println!(
            "{fault}: relay opened {:.1} ms after the signal",
            opened.as_secs_f64() * 1e3
        );
    }
    row
}

#[test]
fn fault_matrix() {
    // Before firing.
    let mut rows = vec![
        before_firing(
            "bad config (frames 2^32-1)",
            "frames = 4294967295",
            "",
            None,
        ),
        before_firing("unusable dir (a file)", "", "", None),
        before_firing(
            "disk too small",
            "pre_trigger_frames = 1\nframes = 1000000\n[camera]\nwidth = 2048\nheight = 2048",
            "",
            None,
        ),
        before_firing(
            "relay port gone",
            "",
            "",
            Some("/dev/impactcam-no-such-port"),
        ),
        before_firing(
            "pulse above its maximum",
            "",
            "relay_pulse_ms = 900.0\nrelay_pulse_ms_max = 500.0",
            None,
        ),
    ];
    for r in &rows {
        assert!(!r.fired, "{}: the relay closed", r.fault);
        assert_eq!(r.exit, "1", "{}", r.fault);
        assert!(r.status.starts_with("none"), "{}: {}", r.fault, r.status);
    }
    // While recording.
    let during = [
        (
            "SIGINT",
            Some("-INT"),
            "frames = 5000",
            "incomplete",
            Some(130),
        ),
        (
            "SIGTERM",
            Some("-TERM"),
            "frames = 5000",
            "incomplete",
            Some(130),
        ),
        ("SIGKILL", Some("-KILL"), "frames = 5000", "recording", None),
        (
            "abort (SIGABRT)",
            Some("-ABRT"),
            "frames = 5000",
            "recording",
            None,
        ),
        (
            "camera disconnect",
            None,
            "frames = 400\n[sim]\ndisconnect_after_frames = 200",
            "incomplete",
            Some(1),
        ),
    ];
    for (fault, sig, recording, want_status, want_exit) in during {
        let row = while_recording(fault, sig, recording);
        assert!(row.fired, "{fault}: never fired");
        assert!(row.open_at_end, "{fault}: relay left closed");
        assert_eq!(row.status, want_status, "{fault}");
        assert!(
            row.frames_readable.ends_with(" ok"),
            "{fault}: {}",
            row.frames_readable
        );
        assert_eq!(row.temp_files, 0, "{fault}");
        assert_eq!(
            row.exit,
            want_exit.map_or("signal".into(), |c: i32| c.to_string()),
            "{fault}"
        );
        rows.push(row);
    }
    // A panic in the main process with the relay closed (a debug-build fail point).
    rows.push(panic_mid_pulse());
    // The relay's port vanishes mid-pulse (a USB module unplugged).
    rows.push(port_gone_mid_pulse());
    // A panic in the daemon's experiment with the relay closed (the same fail point).
    rows.push(daemon_panic_mid_pulse());
    // An oversize request to the daemon.
    rows.push(daemon_oversize_request());
    print_matrix(&rows);
}

/// The daemon's experiment panics after firing, mid-pulse: the relay opens at once (the panic
/// raises the daemon's abort flag before it is reported, `trigger::raise_on_panic`), and the
/// daemon stays up.
fn daemon_panic_mid_pulse() -> Row {
    let emu = Emulator::start(Kind::Lcus).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(tmp.path().join("c.toml"), long_pulse_config(emu.path())).unwrap();
    let (mut child, addr) = common::spawn_daemon_env(
        tmp.path(),
        &["--config", "c.toml"],
        None,
        Stdio::null(),
        &[("IMPACTCAM_TEST_PANIC_AFTER_FIRING", "1")],
    );
    let answer = post_experiment(&addr, "{}");
    assert!(answer.starts_with("HTTP/1.1 202"), "{answer}");
    let closed = wait_closed(&emu);
    assert_opened_before_the_pulse_ends("daemon panic", &emu, closed);
    let still_up = child.try_wait().unwrap().is_none();
    signal(&child, "-TERM");
    let status = child.wait().unwrap();
    let mut row = observe("daemon panic", "mid-pulse", tmp.path(), &emu, status.code());
    assert!(still_up && row.fired && row.open_at_end, "daemon panic");
    row.exit = format!("up, then {}", row.exit);
    row
}

/// `{"frames": 4294967295}` to the daemon: a 400, nothing fired, the daemon still up.
fn daemon_oversize_request() -> Row {
    let emu = Emulator::start(Kind::Lcus).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(tmp.path().join("c.toml"), config(emu.path(), "", "")).unwrap();
    let (mut child, addr) =
        common::spawn_daemon(tmp.path(), &["--config", "c.toml"], None, Stdio::null());
    let answer = post_experiment(&addr, r#"{"frames": 4294967295}"#);
    assert!(answer.starts_with("HTTP/1.1 400"), "{answer}");
    assert!(answer.contains("recording.frames"), "{answer}");
    let still_up = child.try_wait().unwrap().is_none();
    signal(&child, "-TERM");
    let status = child.wait().unwrap();
    let mut row = observe(
        "oversize API request",
        "request",
        tmp.path(),
        &emu,
        status.code(),
    );
    assert!(
        still_up && !row.fired && row.status == "none",
        "oversize request"
    );
    row.exit = format!("400, then {}", row.exit);
    row
}

/// The panic rows' config: a 3 s pulse, so that a relay opened well before its end was opened
/// by the panic's path, not by the pulse's timer.
fn long_pulse_config(port: &str) -> String {
    config(
        port,
        "frames = 5000",
        "relay_pulse_ms = 3000.0\nrelay_pulse_ms_max = 5000.0\n",
    )
}

/// Waits (at most 10 s) for the relay to open after it closed at `closed`, prints how long it
/// was held, and asserts that the panic's path opened it, well before the 3 s pulse's end.
/// (The fail point panics 200 ms after firing.)
fn assert_opened_before_the_pulse_ends(what: &str, emu: &Emulator, closed: Instant) {
    let t0 = Instant::now();
    let opened = loop {
        if let Some((at, _)) = emu.switches().iter().find(|(at, c)| !c && *at > closed) {
            break *at;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(10),
            "{what}: the relay never opened"
        );
        std::thread::sleep(Duration::from_millis(5));
    };
    eprintln!(
        "{what}: relay opened {:.1} ms after firing",
        (opened - closed).as_secs_f64() * 1000.0
    );
    assert!(
        opened - closed < Duration::from_millis(1500),
        "{what}: relay held {:?} of a 3 s pulse",
        opened - closed
    );
}

/// `POST /api/experiments` with `body` to the daemon at `addr`: the whole answer.
fn post_experiment(addr: &str, body: &str) -> String {
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    write!(s, "POST /api/experiments HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\nContent-Type: application/json\r\nContent-Length: {}\r\n\r\n{body}", body.len()).unwrap();
    let mut answer = String::new();
    s.read_to_string(&mut answer).unwrap();
    answer
}

/// The main process panics after firing, mid-pulse: the relay opens at once, the session keeps
/// its frames.
fn panic_mid_pulse() -> Row {
    let emu = Emulator::start(Kind::Lcus).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let cfg = long_pulse_config(emu.path());
    let child = spawn_capture_env(
        tmp.path(),
        &cfg,
        &[("IMPACTCAM_TEST_PANIC_AFTER_FIRING", "1")],
    );
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("IMPACTCAM_TEST_PANIC_AFTER_FIRING"),
        "the fail point did not fire:\n{err}"
    );
    let closed = emu.switches().iter().find(|(_, c)| *c).expect("fired").0;
    assert_opened_before_the_pulse_ends("panic", &emu, closed);
    let row = observe("panic", "mid-pulse", tmp.path(), &emu, out.status.code());
    assert!(
        row.open_at_end && row.frames_readable.ends_with(" ok"),
        "panic: {}",
        row.frames_readable
    );
    assert_eq!(row.status, "recording", "a panic cannot finalise");
    row
}

/// The relay's serial port disappears mid-pulse: the recording ends with the relay error as
/// its reason, frames kept, exit 1.
fn port_gone_mid_pulse() -> Row {
    let emu = Emulator::start(Kind::Lcus).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let cfg = config(
        emu.path(),
        "frames = 5000",
        "relay_pulse_ms = 1000.0\nrelay_pulse_ms_max = 5000.0\n",
    );
    let child = spawn_capture(tmp.path(), &cfg);
    wait_closed(&emu);
    std::thread::sleep(Duration::from_millis(200));
    let heard = emu.switches();
    drop(emu); // the module and its port are gone
    let out = child.wait_with_output().unwrap();
    let probe = Emulator::start(Kind::Lcus).unwrap();
    let mut row = observe(
        "relay port gone",
        "mid-pulse",
        tmp.path(),
        &probe,
        out.status.code(),
    );
    row.fired = heard.iter().any(|(_, c)| *c);
    let reason = std::fs::read_dir(tmp.path().join("sessions"))
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| std::fs::read_to_string(e.path().join("session.json")).unwrap_or_default())
        .next()
        .unwrap_or_default();
    assert!(row.fired, "never fired");
    assert_eq!(row.status, "incomplete", "{reason}");
    assert!(
        reason.contains("relay"),
        "the reason must be the relay's: {reason}"
    );
    assert!(
        row.frames_readable.ends_with(" ok"),
        "{}",
        row.frames_readable
    );
    assert_eq!(row.exit, "1");
    row.open_at_end = false; // unknown: the module is gone (unpowered, it opens by itself)
    row
}

/// The disk fills after firing (another writer takes the rest of a 400 MiB tmpfs in a private
/// mount namespace): the frames already reserved are kept, the session ends `failed` with the
/// disk's error, no temporary file is left, the relay is open. Needs root for the namespace.
#[test]
#[ignore = "needs root (a mount namespace with a small tmpfs): scripts/test runs it"]
fn disk_full_after_firing() {
    let emu = Emulator::start(Kind::Lcus).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let cfg = config(emu.path(), "frames = 4000", "relay_pulse_ms = 50.0\n")
        .replace("dir = \"sessions\"", "dir = \"mnt/sessions\"");
    std::fs::write(tmp.path().join("c.toml"), cfg).unwrap();
    std::fs::create_dir(tmp.path().join("mnt")).unwrap();
    // Fill the disk once the recording has started; keep the session's files to read back.
    let script = format!(
        "mount -t tmpfs -o size=400m tmpfs mnt || exit 97; \
         \"{bin}\" capture --config c.toml 2>err.txt & pid=$!; \
         while [ ! -d mnt/sessions ] || [ -z \"$(ls mnt/sessions)\" ]; do sleep 0.01; done; sleep 0.3; \
         dd if=/dev/zero of=mnt/filler bs=1M >/dev/null 2>&1; \
         wait $pid; rc=$?; rm -f mnt/filler; cp -r mnt/sessions sessions; echo $rc > rc.txt",
        bin = env!("CARGO_BIN_EXE_impactcam")
    );
    let out = Command::new("unshare")
        .args(["-m", "sh", "-c", &script])
        .current_dir(tmp.path())
        .output()
        .unwrap();
    assert_ne!(
        out.status.code(),
        Some(97),
        "cannot mount a tmpfs (not root?)"
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let rc: i32 = std::fs::read_to_string(tmp.path().join("rc.txt"))
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    let err = std::fs::read_to_string(tmp.path().join("err.txt")).unwrap_or_default();
    let row = observe("disk full", "after firing", tmp.path(), &emu, Some(rc));
    print_matrix(std::slice::from_ref(&row));
    assert!(row.fired && row.open_at_end, "relay");
    assert_eq!(row.status, "failed", "{err}");
    assert!(err.contains("No space left"), "the disk's own error: {err}");
    assert!(
        row.frames_readable.ends_with(" ok"),
        "{}",
        row.frames_readable
    );
    assert_eq!(row.temp_files, 0);
    assert_eq!(rc, 1);
}
