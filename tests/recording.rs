//! Recording against the simulated lab through the real serial path: the relay is released on
//! every path, firing needs live frames, drops are counted, and nothing written is lost when the
//! process is killed or interrupted.

use impactcam::camera::{Camera, CameraError, CameraInfo, Frame};
use impactcam::config::{Config, PixelFormat};
use impactcam::experiment::Rig;
use impactcam::recorder::{self, RecordError};
use impactcam::session::{SessionReader, Status};
use std::path::Path;
use std::process::Command;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::{Duration, Instant};

fn config(dir: &Path, extra: &str) -> Config {
    let text = format!("[recording]\ndir = {:?}\n{extra}", dir.join("sessions"));
    Config::from_toml_str(&text, "test config").unwrap()
}

fn relay_states(lab: &hw_sim::SimLab) -> Vec<bool> {
    // The module's view arrives over a pseudo-terminal; give the last bytes time to land.
    std::thread::sleep(Duration::from_millis(50));
    lab.relay_events().iter().map(|e| e.closed).collect()
}

/// Records with `extra` config against the simulated lab and returns the error and what the
/// relay module heard.
fn record_expecting_error(dir: &Path, extra: &str) -> (RecordError, Vec<bool>) {
    let text = format!("[recording]\ndir = {dir:?}\n{extra}");
    let cfg = Config::from_toml_str(&text, "test config").unwrap();
    let mut rig = Rig::open(&cfg).unwrap();
    let lab = rig.lab.clone().unwrap();
    let r = recorder::record(
        &mut rig.camera,
        &rig.trigger,
        &cfg,
        Arc::new(AtomicBool::new(false)),
        &mut |_| {},
    );
    (
        r.err().expect("the recording must be refused"),
        relay_states(&lab),
    )
}

#[test]
fn an_unusable_session_dir_fires_nothing_and_leaves_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    // recording.dir is a file; is under /proc; is on a disk too small for the recording.
    std::fs::write(tmp.path().join("file"), b"not a directory").unwrap();
    let cases = [
        ("a file", tmp.path().join("file"), "", "recording.dir"),
        (
            "under /proc",
            "/proc/impactcam-sessions".into(),
            "",
            "recording.dir",
        ),
        (
            "too small a disk",
            tmp.path().join("sessions"),
            "pre_trigger_frames = 1\nframes = 1000000\n[camera]\nwidth = 2048\nheight = 2048\n",
            "MiB free",
        ),
    ];
    for (what, dir, extra, named) in cases {
        let (e, relay) = record_expecting_error(&dir, extra);
        assert!(matches!(e, RecordError::Preflight(_)), "{what}: {e}");
        let text = e.to_string();
        assert!(
            text.contains(named) && text.contains("relay not fired"),
            "{what}: {text}"
        );
        // The module only ever heard "open" (sent when the port was opened).
        assert!(
            relay.iter().all(|closed| !closed),
            "{what}: relay heard {relay:?}"
        );
    }
    // No half-written session was left.
    let left: Vec<_> = std::fs::read_dir(tmp.path().join("sessions"))
        .map(|d| d.filter_map(|e| e.ok()).map(|e| e.path()).collect())
        .unwrap_or_default();
    assert!(left.is_empty(), "{left:?}");
}

#[test]
fn camera_disconnect_ends_the_recording_cleanly_with_frames_kept() {
    let tmp = tempfile::tempdir().unwrap();
    let cfg = config(tmp.path(), "[sim]\ndisconnect_after_frames = 100\n");
    let mut rig = Rig::open(&cfg).unwrap();
    let lab = rig.lab.clone().unwrap();
    let rec = recorder::record(
        &mut rig.camera,
        &rig.trigger,
        &cfg,
        Arc::new(AtomicBool::new(false)),
        &mut |_| {},
    )
    .unwrap();
    assert_eq!(rec.status, Status::Incomplete);
    assert!(
        rec.reason.as_deref().unwrap_or("").contains("disconnected"),
        "{:?}",
        rec.reason
    );
    let reader = SessionReader::open(&rec.session_dir).unwrap();
    assert_eq!(reader.manifest.status, Status::Incomplete);
    // 100 delivered, of which up to 20 were pre-trigger frames discarded while arming.
    assert!(
        reader.frames.len() >= 20 && reader.frames.len() <= 100,
        "{}",
        reader.frames.len()
    );
    assert_eq!(reader.frames.len() as u64, reader.manifest.frames_recorded);
    assert!(!*relay_states(&lab).last().unwrap());
}

#[test]
fn dropped_frames_are_counted_from_frame_ids() {
    let tmp = tempfile::tempdir().unwrap();
    let cfg = config(tmp.path(), "[sim]\ndrop_frame_ids = [60, 61, 150]\n");
    let mut rig = Rig::open(&cfg).unwrap();
    let rec = recorder::record(
        &mut rig.camera,
        &rig.trigger,
        &cfg,
        Arc::new(AtomicBool::new(false)),
        &mut |_| {},
    )
    .unwrap();
    assert_eq!(rec.status, Status::Complete);
    assert_eq!(rec.frames_dropped, 3);
    let reader = SessionReader::open(&rec.session_dir).unwrap();
    assert_eq!(reader.manifest.frames_dropped, 3);
    assert_eq!(reader.frames.len(), 280);
    let ids: Vec<u64> = reader.frames.iter().map(|f| f.frame_id).collect();
    assert!(!ids.contains(&60) && !ids.contains(&150));
}

/// A camera that never delivers a frame.
struct DeadCamera;

impl Camera for DeadCamera {
    fn info(&self) -> CameraInfo {
        CameraInfo {
            backend: "dead".into(),
            device: "none".into(),
            width: 8,
            height: 8,
            pixel_format: PixelFormat::Mono8,
            frame_rate_hz: 100.0,
        }
    }
    fn start(&mut self) -> Result<(), CameraError> {
        Ok(())
    }
    fn next_frame(&mut self, _buf: Vec<u8>) -> Result<Frame, CameraError> {
        std::thread::sleep(Duration::from_millis(20));
        Err(CameraError::Disconnected("no signal".into()))
    }
    fn stop(&mut self) -> Result<(), CameraError> {
        Ok(())
    }
}

#[test]
fn firing_is_refused_unless_frames_flow() {
    let tmp = tempfile::tempdir().unwrap();
    let cfg = config(tmp.path(), "arm_timeout_ms = 300\n");
    let rig = Rig::open(&cfg).unwrap();
    let lab = rig.lab.clone().unwrap();
    let r = recorder::record(
        &mut Some(Box::new(DeadCamera) as Box<dyn impactcam::camera::Camera>),
        &rig.trigger,
        &cfg,
        Arc::new(AtomicBool::new(false)),
        &mut |_| {},
    );
    let err = r.err().expect("must refuse");
    assert!(err.to_string().contains("relay not fired"), "{err}");
    assert_eq!(
        relay_states(&lab),
        vec![false],
        "the relay must never have closed"
    );
    assert!(
        !tmp.path().join("sessions").exists(),
        "no session for an experiment that never ran"
    );
}

#[test]
fn no_drops_in_real_time_into_ram() {
    for (w, h, fps, frames) in [(240, 192, 1000.0, 300), (640, 480, 2000.0, 600)] {
        let tmp = tempfile::tempdir().unwrap();
        let mut cfg = config(tmp.path(), "");
        cfg.camera.width = w;
        cfg.camera.height = h;
        cfg.camera.frame_rate_hz = fps;
        let rig = Rig::open(&cfg).unwrap();
        let queue = cfg.recording.ram_buffer_mb as usize * 1024 * 1024 / (w * h) as usize;
        let stats = recorder::stream_to_ram(rig.camera.unwrap(), frames, queue).unwrap();
        assert_eq!(stats.frames_received, frames as u64);
        assert_eq!(stats.frames_lost_queue, 0, "{w}×{h}@{fps}");
        assert_eq!(stats.frames_missing_ids, 0, "{w}×{h}@{fps}");
    }
}

fn wait_for_index_lines(sessions: &Path, n: usize, timeout: Duration) -> std::path::PathBuf {
    let t0 = Instant::now();
    loop {
        if let Ok(mut rd) = std::fs::read_dir(sessions) {
            if let Some(Ok(e)) = rd.next() {
                let idx = e.path().join("frames.idx");
                if std::fs::read_to_string(&idx)
                    .map(|t| t.lines().count() > n)
                    .unwrap_or(false)
                {
                    return e.path();
                }
            }
        }
        assert!(
            t0.elapsed() < timeout,
            "capture did not write {n} frames in {timeout:?}"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[test]
fn a_killed_capture_keeps_every_frame_written() {
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(tmp.path().join("long.toml"), "[recording]\nframes = 5000\n").unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_impactcam"))
        .args(["capture", "--config", "long.toml"])
        .current_dir(tmp.path())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // Past the impact (about frame 240), well before the end.
    let session = wait_for_index_lines(&tmp.path().join("sessions"), 320, Duration::from_secs(20));
    child.kill().unwrap(); // SIGKILL: no chance to finalise anything
    child.wait().unwrap();
    let reader = SessionReader::open(&session).unwrap();
    assert_eq!(
        reader.manifest.status,
        Status::Recording,
        "the manifest was never finalised"
    );
    assert!(
        reader.frames.len() >= 320,
        "{} frames readable",
        reader.frames.len()
    );
    // Every readable frame is whole and in order.
    assert!(reader
        .frames
        .windows(2)
        .all(|w| w[1].frame_id > w[0].frame_id));
    let out = Command::new(env!("CARGO_BIN_EXE_impactcam"))
        .args(["replay", session.to_str().unwrap(), "--json"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let warnings = report["quality"]["warnings"].to_string();
    assert!(warnings.contains("Recording"), "{warnings}");
    assert!(report["e"]["value"].as_f64().is_some());
}

#[test]
fn ctrl_c_mid_capture_releases_the_relay_and_marks_the_session_incomplete() {
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(tmp.path().join("long.toml"), "[recording]\nframes = 5000\n").unwrap();
    let child = Command::new(env!("CARGO_BIN_EXE_impactcam"))
        .args(["capture", "--config", "long.toml"])
        .current_dir(tmp.path())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let session = wait_for_index_lines(&tmp.path().join("sessions"), 30, Duration::from_secs(20));
    // SIGINT while the relay pulse (50 ms) may still be on.
    let ok = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(ok.success());
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(130));
    let reader = SessionReader::open(&session).unwrap();
    assert_eq!(reader.manifest.status, Status::Incomplete);
    assert!(reader
        .manifest
        .reason
        .as_deref()
        .unwrap_or("")
        .contains("interrupted"));
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(session.join("truth.json")).unwrap())
            .unwrap();
    let last = truth["relay_events"]
        .as_array()
        .unwrap()
        .last()
        .unwrap()
        .clone();
    assert_eq!(last["closed"], false, "relay left closed: {truth:?}");
}
