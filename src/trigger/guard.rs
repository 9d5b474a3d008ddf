//! The relay guard: a child process that owns the relay, so that a crash of the main process —
//! SIGKILL, an OOM kill, an abort — still opens it.
//!
//! The main process (`GuardedRelay`) sends one line per switch on the child's stdin (`close`,
//! `open`) and reads `ok` or `error <message>` back. The child opens the relay:
//! - when its stdin ends, which the kernel makes happen the moment the main process dies,
//!   however it dies (the pipe's write end is close-on-exec and held by no one else);
//! - when the relay has been closed for `relay_pulse_ms_max`, whatever the main process does
//!   (a watchdog of its own, on the child's clock);
//! - before it exits for any reason it can handle.
//!
//! It ignores SIGINT, SIGTERM and SIGHUP: a Ctrl-C reaches the whole process group, and the
//! guard must outlive the main process long enough to open the relay after it. The child is
//! the same executable started with `__relay-guard` as its only argument (see `main.rs`); the
//! main binary names itself with `set_executable`. Where none is set (the library's own unit
//! tests), `Trigger::open` drives the relay in-process.

use super::{Relay, TriggerError, TriggerInfo};
use crate::config::TriggerConfig;
use serde::{Deserialize, Serialize};
use std::io::{BufRead, BufReader, Write};
use std::os::fd::AsRawFd;
use std::path::PathBuf;
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

/// The argument that makes the executable a relay guard.
pub const GUARD_ARG: &str = "__relay-guard";
/// How long the main process waits for the guard to answer a switch.
const ANSWER_TIMEOUT: Duration = Duration::from_secs(3);

static EXECUTABLE: OnceLock<PathBuf> = OnceLock::new();
static JSON_LOGS: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Makes the guard's own messages JSON lines, as the main process logs (`--log-format json`).
pub fn set_json_logs(on: bool) {
    JSON_LOGS.store(on, std::sync::atomic::Ordering::Relaxed);
}

/// Names the executable that runs `guard_main` when started with `GUARD_ARG`.
pub fn set_executable(path: PathBuf) {
    let _ = EXECUTABLE.set(path);
}

pub(crate) fn executable() -> Option<&'static PathBuf> {
    EXECUTABLE.get()
}

/// What the guard is told to open, as the first line on its stdin.
#[derive(Serialize, Deserialize)]
struct Spec {
    trigger: TriggerConfig,
    /// The device to open (the configured port, or the simulator's pseudo-terminal).
    port: String,
    backend: String,
    /// Whether the guard's own messages are JSON lines (`--log-format json`).
    json_logs: bool,
}

/// The main process's side: a `Relay` whose switching happens in the guard.
pub struct GuardedRelay {
    child: Child,
    commands: Option<ChildStdin>,
    answers: BufReader<ChildStdout>,
    info: TriggerInfo,
}

impl GuardedRelay {
    /// Starts the guard, which opens the relay (and sets it open) before answering `ready`
    /// with what the relay says of itself.
    pub fn spawn(
        exe: &std::path::Path,
        trigger: &TriggerConfig,
        port: &str,
        backend: &'static str,
    ) -> Result<GuardedRelay, TriggerError> {
        let fail = |message: String| TriggerError::Open {
            port: port.into(),
            message,
        };
        let mut child = Command::new(exe)
            .arg(GUARD_ARG)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .map_err(|e| {
                fail(format!(
                    "cannot start the relay guard {}: {e}",
                    exe.display()
                ))
            })?;
        let (Some(mut commands), Some(answers)) = (child.stdin.take(), child.stdout.take()) else {
            let _ = child.kill();
            let _ = child.wait();
            return Err(fail("the relay guard has no pipes".into()));
        };
        let spec = Spec {
            trigger: trigger.clone(),
            port: port.into(),
            backend: backend.into(),
            json_logs: JSON_LOGS.load(std::sync::atomic::Ordering::Relaxed),
        };
        let line = serde_json::to_string(&spec).map_err(|e| fail(e.to_string()))?;
        let mut relay = GuardedRelay {
            child,
            commands: None,
            answers: BufReader::new(answers),
            // Until the guard says more.
            info: TriggerInfo {
                backend: backend.into(),
                port: Some(port.into()),
                protocol: None,
                channel: None,
            },
        };
        if let Err(e) = writeln!(commands, "{line}").and_then(|_| commands.flush()) {
            return Err(fail(format!("cannot talk to the relay guard: {e}")));
        }
        relay.commands = Some(commands);
        let answer = relay.answer().map_err(fail)?;
        match answer.strip_prefix("ready ") {
            Some(info) => {
                relay.info = serde_json::from_str(info)
                    .map_err(|e| fail(format!("the relay guard's answer {info:?}: {e}")))?;
                Ok(relay)
            }
            None => Err(fail(
                answer.strip_prefix("error ").unwrap_or(&answer).to_string(),
            )),
        }
    }

    /// The guard's process id (tests kill the main process and watch this one).
    pub fn guard_pid(&self) -> u32 {
        self.child.id()
    }

    /// One answer line, waiting at most `ANSWER_TIMEOUT`.
    fn answer(&mut self) -> Result<String, String> {
        if self.answers.buffer().is_empty()
            && !wait_readable(self.answers.get_ref().as_raw_fd(), ANSWER_TIMEOUT)
        {
            return Err(format!(
                "the relay guard did not answer within {} ms",
                ANSWER_TIMEOUT.as_millis()
            ));
        }
        let mut line = String::new();
        match self.answers.read_line(&mut line) {
            Ok(0) => Err("the relay guard has exited".into()),
            Ok(_) => Ok(line.trim_end().to_string()),
            Err(e) => Err(format!("reading the relay guard: {e}")),
        }
    }
}

impl Relay for GuardedRelay {
    fn set_closed(&mut self, closed: bool) -> Result<(), TriggerError> {
        let port = self.info.port.clone().unwrap_or_default();
        let io = |message: String| TriggerError::Io {
            port: port.clone(),
            message,
        };
        let command = if closed { "close" } else { "open" };
        let Some(commands) = self.commands.as_mut() else {
            return Err(io("the relay guard is gone".into()));
        };
        writeln!(commands, "{command}")
            .and_then(|_| commands.flush())
            .map_err(|e| io(format!("cannot talk to the relay guard: {e}")))?;
        match self.answer().map_err(&io)? {
            a if a == "ok" => Ok(()),
            a => Err(io(a.strip_prefix("error ").unwrap_or(&a).to_string())),
        }
    }

    fn info(&self) -> TriggerInfo {
        self.info.clone()
    }
}

impl Drop for GuardedRelay {
    fn drop(&mut self) {
        // End of input: the guard opens the relay and exits.
        drop(self.commands.take());
        let deadline = Instant::now() + Duration::from_secs(2);
        loop {
            match self.child.try_wait() {
                Ok(Some(_)) | Err(_) => return,
                Ok(None) if Instant::now() > deadline => {
                    let _ = self.child.kill();
                    let _ = self.child.wait();
                    return;
                }
                Ok(None) => std::thread::sleep(Duration::from_millis(2)),
            }
        }
    }
}

/// Whether `fd` has something to read (or has hung up) within `timeout`.
fn wait_readable(fd: i32, timeout: Duration) -> bool {
    let mut p = libc::pollfd {
        fd,
        events: libc::POLLIN,
        revents: 0,
    };
    let ms = timeout.as_millis().min(i32::MAX as u128) as i32;
    // SAFETY: one valid pollfd, for the duration of the call.
    let rc = unsafe { libc::poll(&mut p, 1, ms) };
    rc > 0
}

/// The guard process: returns its exit code. Reads the spec, opens the relay, then obeys
/// commands until its input ends, keeping the relay closed no longer than the configured
/// maximum.
pub fn guard_main() -> i32 {
    // SAFETY: setting signal dispositions to SIG_IGN before any other thread exists.
    unsafe {
        libc::signal(libc::SIGINT, libc::SIG_IGN);
        libc::signal(libc::SIGTERM, libc::SIG_IGN);
        libc::signal(libc::SIGHUP, libc::SIG_IGN);
        libc::signal(libc::SIGPIPE, libc::SIG_IGN);
    }
    let mut input = Lines::default();
    let mut out = std::io::stdout();
    let Some(line) = input.next(Duration::from_secs(10)).ok().flatten() else {
        return 1;
    };
    let spec: Spec = match serde_json::from_str(&line) {
        Ok(s) => s,
        Err(e) => {
            let _ = writeln!(out, "error relay guard: bad spec: {e}");
            return 1;
        }
    };
    let mut relay = match super::open_direct(&spec.trigger, &spec.port, &spec.backend) {
        Ok(r) => r,
        Err(e) => {
            let _ = writeln!(out, "error {e}");
            return 1;
        }
    };
    let max_closed =
        Duration::from_secs_f64(spec.trigger.relay_pulse_ms_max.clamp(0.0, 10_000.0) / 1000.0);
    let info = serde_json::to_string(&relay.info()).unwrap_or_default();
    if writeln!(out, "ready {info}")
        .and_then(|_| out.flush())
        .is_err()
    {
        let _ = open_hard(&mut *relay);
        return 1;
    }
    let mut closed_since: Option<Instant> = None;
    loop {
        // Wait for a command, but not past the watchdog's deadline.
        let wait = match closed_since {
            Some(t) => max_closed.saturating_sub(t.elapsed()),
            None => Duration::from_secs(3600),
        };
        let line = match input.next(wait) {
            Err(()) => break, // end of input: the main process is gone or done
            Ok(None) => {
                // The watchdog: closed for the maximum, whatever the main process thinks.
                if closed_since.is_some() {
                    let _ = open_hard(&mut *relay);
                    closed_since = None;
                    say(
                        spec.json_logs,
                        "relay guard: relay opened after trigger.relay_pulse_ms_max",
                    );
                }
                continue;
            }
            Ok(Some(line)) => line,
        };
        let (result, closed) = match line.trim() {
            "close" => (relay.set_closed(true), true),
            "open" => (relay.set_closed(false), false),
            other => {
                let _ = writeln!(out, "error relay guard: unknown command {other:?}");
                let _ = out.flush();
                continue;
            }
        };
        closed_since = match (closed, closed_since) {
            (true, None) => Some(Instant::now()),
            (true, t) => t,
            (false, _) => None,
        };
        let answer = match result {
            Ok(()) => "ok".to_string(),
            Err(e) => format!("error {e}"),
        };
        if writeln!(out, "{answer}").and_then(|_| out.flush()).is_err() {
            break;
        }
    }
    // The relay is opened whatever state it was left in.
    if !open_hard(&mut *relay) {
        say(spec.json_logs, "relay guard: could not open the relay");
    }
    0
}

/// A line on stderr, as the main process logs (text, or a JSON object).
fn say(json: bool, message: &str) {
    if json {
        eprintln!(
            "{}",
            serde_json::json!({"level": "WARN", "message": message, "process": "relay-guard"})
        );
    } else {
        eprintln!("{message}");
    }
}

/// Lines from stdin (fd 0), read without std's buffering so that a wait can time out.
#[derive(Default)]
struct Lines {
    pending: Vec<u8>,
}

impl Lines {
    /// The next line; Ok(None) when `wait` passed without one; Err at end of input.
    fn next(&mut self, wait: Duration) -> Result<Option<String>, ()> {
        let deadline = Instant::now() + wait;
        loop {
            if let Some(i) = self.pending.iter().position(|&b| b == b'\n') {
                let line: Vec<u8> = self.pending.drain(..=i).collect();
                return Ok(Some(String::from_utf8_lossy(&line).into_owned()));
            }
            if self.pending.len() > 1 << 20 {
                return Err(()); // no sane command is this long
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if !wait_readable(0, left) {
                if Instant::now() >= deadline {
                    return Ok(None);
                }
                continue;
            }
            let mut buf = [0u8; 4096];
            // SAFETY: reading into a local buffer of the given length from fd 0.
            let n = unsafe { libc::read(0, buf.as_mut_ptr().cast(), buf.len()) };
            match n {
                0 => return Err(()),
                n if n < 0 => {
                    if std::io::Error::last_os_error().kind() != std::io::ErrorKind::Interrupted {
                        return Err(());
                    }
                }
                n => self.pending.extend_from_slice(&buf[..n as usize]),
            }
        }
    }
}

/// Opens the relay, retrying a few times: this is the last chance. Whether it answered.
fn open_hard(relay: &mut dyn Relay) -> bool {
    for _ in 0..5 {
        if relay.set_closed(false).is_ok() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    false
}
