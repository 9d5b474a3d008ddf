//! The Aravis backend against Aravis's own in-process fake GenICam camera (`Fake_1`), through the
//! whole recorder: the issue's example config must record 400 frames with none dropped. The GigE
//! and USB3 interfaces are disabled for `Fake…` devices, so nothing is sent on the network.
#![cfg(feature = "aravis")]

use std::process::Command;

const CONFIG: &str = r#"
[camera]
backend = "aravis"
device = "Fake_1"
width = 320
height = 240
pixel_format = "Mono8"
frame_rate_hz = 500.0

[trigger]
backend = "sim"

[recording]
dir = "sessions"
frames = 400
"#;

#[test]
fn capture_from_the_fake_genicam_camera_records_400_frames_without_drops() {
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(tmp.path().join("fake.toml"), CONFIG).unwrap();
    let check = Command::new(env!("CARGO_BIN_EXE_impactcam"))
        .args(["config", "check", "fake.toml"])
        .current_dir(tmp.path())
        .output()
        .unwrap();
    assert!(
        check.status.success(),
        "{}",
        String::from_utf8_lossy(&check.stderr)
    );
    let out = Command::new(env!("CARGO_BIN_EXE_impactcam"))
        .args(["capture", "--config", "fake.toml"])
        .current_dir(tmp.path())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let session = std::fs::read_dir(tmp.path().join("sessions"))
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(session.join("session.json")).unwrap())
            .unwrap();
    assert_eq!(m["status"], "complete");
    assert_eq!(m["frames_recorded"], 400);
    assert_eq!(m["frames_dropped"], 0);
    assert_eq!(m["camera"]["backend"], "aravis");
    assert_eq!(m["camera"]["width"], 320);
    let reader = impactcam::session::SessionReader::open(&session).unwrap();
    assert_eq!(reader.frames.len(), 400);
    // Device timestamps advance by the frame period (2 ms at 500 Hz).
    let dt: Vec<u64> = reader
        .frames
        .windows(2)
        .map(|w| w[1].timestamp_ns - w[0].timestamp_ns)
        .collect();
    let mean = dt.iter().sum::<u64>() as f64 / dt.len() as f64;
    assert!(
        (mean - 2.0e6).abs() < 0.1e6,
        "mean frame interval {mean} ns"
    );
}
