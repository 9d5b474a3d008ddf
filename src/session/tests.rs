use super::*;
use crate::config::PixelFormat;
use std::fs::OpenOptions;

fn info() -> CameraInfo {
    CameraInfo {
        backend: "test".into(),
        device: "t".into(),
        width: 4,
        height: 3,
        pixel_format: PixelFormat::Mono8,
        frame_rate_hz: 100.0,
    }
}

fn trig() -> ManifestTrigger {
    ManifestTrigger::new(
        &TriggerInfo {
            backend: "none".into(),
            port: None,
            protocol: None,
            channel: None,
        },
        10.0,
    )
}

#[test]
fn a_crash_mid_write_keeps_the_whole_frames_before_it() {
    let tmp = tempfile::tempdir().unwrap();
    let cfg = Config::default_config();
    let mut w = SessionWriter::create(tmp.path(), &info(), trig(), &cfg).unwrap();
    for k in 0..3u64 {
        w.append(
            FrameMeta {
                frame_id: k,
                timestamp_ns: k * 10,
            },
            &[k as u8; 12],
        )
        .unwrap();
    }
    let dir = w.dir().to_path_buf();
    drop(w); // as if killed: never finished
             // The fourth frame's index line made it, its pixels only half; a fifth line is cut short.
    let mut f = OpenOptions::new()
        .append(true)
        .open(dir.join("frames.bin"))
        .unwrap();
    f.write_all(&[9u8; 6]).unwrap();
    let mut i = OpenOptions::new()
        .append(true)
        .open(dir.join("frames.idx"))
        .unwrap();
    i.write_all(b"3,30\n4,4").unwrap();
    let mut r = SessionReader::open(&dir).unwrap();
    assert_eq!(r.manifest.status, Status::Recording);
    assert!(!r.is_complete());
    assert_eq!(r.frames.len(), 3);
    assert_eq!(r.frames_truncated, 1);
    let mut buf = Vec::new();
    r.read_frame(2, &mut buf).unwrap();
    assert_eq!(buf, vec![2u8; 12]);
}

#[test]
fn finished_session_round_trips() {
    let tmp = tempfile::tempdir().unwrap();
    let cfg = Config::default_config();
    let mut w = SessionWriter::create(tmp.path(), &info(), trig(), &cfg).unwrap();
    w.append(
        FrameMeta {
            frame_id: 7,
            timestamp_ns: 70,
        },
        &[1u8; 12],
    )
    .unwrap();
    assert!(w
        .append(
            FrameMeta {
                frame_id: 8,
                timestamp_ns: 80
            },
            &[1u8; 11]
        )
        .is_err());
    let dir = w.finish(Status::Complete, None).unwrap();
    let r = SessionReader::open(&dir).unwrap();
    assert!(r.is_complete());
    assert_eq!(
        r.frames,
        vec![FrameMeta {
            frame_id: 7,
            timestamp_ns: 70
        }]
    );
    assert_eq!(r.config(), &cfg);
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

#[test]
fn a_batch_indexes_the_frames_before_one_that_fails() {
    let tmp = tempfile::tempdir().unwrap();
    let cfg = Config::default_config();
    let mut w = SessionWriter::create(tmp.path(), &info(), trig(), &cfg).unwrap();
    let meta = |k: u64| FrameMeta {
        frame_id: k,
        timestamp_ns: k * 10,
    };
    let (good, short) = ([5u8; 12], [6u8; 11]);
    w.append_batch(&[(meta(0), &good[..]), (meta(1), &good[..])])
        .unwrap();
    let err = w
        .append_batch(&[
            (meta(2), &good[..]),
            (meta(3), &short[..]),
            (meta(4), &good[..]),
        ])
        .unwrap_err();
    assert!(err.to_string().contains("frame 3 has 11 bytes"), "{err}");
    let dir = w.finish(Status::Failed, None).unwrap();
    let r = SessionReader::open(&dir).unwrap();
    assert_eq!(r.frames, vec![meta(0), meta(1), meta(2)]);
    assert_eq!(r.manifest.frames_recorded, 3);
}

#[test]
fn the_daemon_token_is_not_written_into_a_session() {
    let tmp = tempfile::tempdir().unwrap();
    let mut cfg = Config::default_config();
    cfg.daemon.token = Some("a-secret-token-0123456789".into());
    let w = SessionWriter::create(tmp.path(), &info(), trig(), &cfg).unwrap();
    let dir = w.finish(Status::Complete, None).unwrap();
    for file in ["config.toml", "session.json"] {
        let text = std::fs::read_to_string(dir.join(file)).unwrap();
        assert!(!text.contains("a-secret-token"), "{file} holds the token");
    }
}
