//! The command line as a user meets it: the README's first command on a fresh directory,
//! replay, analyze of exported TIFF stacks, config commands, and bad input.

mod common;

use common::{impactcam, stderr};
use serde_json::Value;
use std::path::{Path, PathBuf};

fn only_session(dir: &Path) -> PathBuf {
    let mut sessions: Vec<PathBuf> = std::fs::read_dir(dir.join("sessions"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(sessions.len(), 1, "{sessions:?}");
    sessions.pop().unwrap()
}

fn json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Files anywhere below `dir` that look like a result.
fn results_below(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if p.file_name().unwrap().to_string_lossy().contains("report") {
                out.push(p);
            }
        }
    }
    out
}

#[test]
fn run_on_the_embedded_default_measures_e_and_replays_exactly() {
    let tmp = tempfile::tempdir().unwrap();
    let out = impactcam(tmp.path(), &["run"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("e ") && text.contains("mm/s") && text.contains("±"),
        "{text}"
    );
    let session = only_session(tmp.path());
    let report = json(&session.join("report.json"));
    let truth = json(&session.join("truth.json"));
    assert_eq!(report["schema"], "impactcam.report/1");
    let e = report["e"]["value"].as_f64().unwrap();
    let e_true = truth["e"].as_f64().unwrap();
    assert!((e - e_true).abs() < 0.02, "e {e} vs true {e_true}");
    let t = report["impact"]["time_s"]["value"].as_f64().unwrap();
    let t_true = truth["impact"]["time_s"].as_f64().unwrap();
    assert!((t - t_true).abs() < 0.2e-3, "impact {t} vs true {t_true}");
    // The relay was set open when the module was opened, closed once, and opened again within
    // the configured bounds, as the simulated module saw it on its serial line.
    let events = truth["relay_events"].as_array().unwrap();
    let states: Vec<bool> = events
        .iter()
        .map(|e| e["closed"].as_bool().unwrap())
        .collect();
    assert_eq!(states, vec![false, true, false]);
    let held_s = events[2]["time_s"].as_f64().unwrap() - events[1]["time_s"].as_f64().unwrap();
    // Seen through the pseudo-terminal each edge arrives a little late (by up to a few ms, not
    // always equally), so the lower bound has slack; the maximum pulse is the hard bound.
    assert!(
        (0.035..0.500).contains(&held_s),
        "relay held {held_s} s; pulse 50 ms, max 500 ms"
    );
    let manifest = json(&session.join("session.json"));
    assert_eq!(manifest["status"], "complete");
    assert_eq!(manifest["frames_recorded"], 280);
    assert_eq!(manifest["frames_dropped"], 0);

    let replay = impactcam(tmp.path(), &["replay", session.to_str().unwrap(), "--json"]);
    assert!(replay.status.success(), "{}", stderr(&replay));
    assert_eq!(
        replay.stdout,
        std::fs::read(session.join("report.json")).unwrap()
    );
    // The same bits whatever the number of threads: one (no work done ahead at all), two and
    // five (frames fitted ahead on other threads, in chunks that end elsewhere).
    for jobs in ["1", "2", "5"] {
        let again = impactcam(
            tmp.path(),
            &[
                "replay",
                session.to_str().unwrap(),
                "--json",
                "--jobs",
                jobs,
            ],
        );
        assert!(again.status.success(), "--jobs {jobs}: {}", stderr(&again));
        assert!(
            again.stdout == replay.stdout,
            "--jobs {jobs}: the report differs from the recorded one"
        );
    }
}

#[test]
fn a_run_that_never_fires_the_relay_finds_no_collision() {
    // With the trigger disconnected from the simulated lab the spheres are never released.
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(
        tmp.path().join("c.toml"),
        "[trigger]\nbackend = \"none\"\n[recording]\nframes = 60\n",
    )
    .unwrap();
    let out = impactcam(tmp.path(), &["run", "--config", "c.toml"]);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("never both measured"),
        "{}",
        stderr(&out)
    );
    assert!(results_below(tmp.path()).is_empty());
}

#[test]
fn exported_tiff_stacks_analyse_like_the_session_8_and_16_bit() {
    for format in ["Mono8", "Mono16"] {
        let tmp = tempfile::tempdir().unwrap();
        let cfg = format!("[camera]\npixel_format = \"{format}\"\n");
        std::fs::write(tmp.path().join("c.toml"), &cfg).unwrap();
        let out = impactcam(tmp.path(), &["run", "--config", "c.toml", "--json"]);
        assert!(out.status.success(), "{}", stderr(&out));
        let session = only_session(tmp.path());
        let from_session: Value = serde_json::from_slice(&out.stdout).unwrap();
        let exp = impactcam(
            tmp.path(),
            &["export", session.to_str().unwrap(), "--tiff", "stack.tif"],
        );
        assert!(exp.status.success(), "{}", stderr(&exp));
        let an = impactcam(
            tmp.path(),
            &[
                "analyze",
                "stack.tif",
                "--config",
                "c.toml",
                "--json",
                "--out",
                "out",
            ],
        );
        assert!(an.status.success(), "{}", stderr(&an));
        let from_tiff: Value = serde_json::from_slice(&an.stdout).unwrap();
        assert_eq!(from_tiff["source"]["kind"], "tiff");
        assert!(tmp.path().join("out/report.json").exists());
        // Without device timestamps frame k is at k/fps: same e, impact shifted by the first
        // frame's timestamp.
        let (e1, e2) = (
            from_session["e"]["value"].as_f64().unwrap(),
            from_tiff["e"]["value"].as_f64().unwrap(),
        );
        assert!((e1 - e2).abs() < 1e-9, "{format}: {e1} vs {e2}");
    }
}

#[test]
fn config_commands() {
    let tmp = tempfile::tempdir().unwrap();
    let out = impactcam(tmp.path(), &["config", "default"]);
    assert!(out.status.success());
    std::fs::write(tmp.path().join("d.toml"), &out.stdout).unwrap();
    let check = impactcam(tmp.path(), &["config", "check", "d.toml"]);
    assert!(check.status.success(), "{}", stderr(&check));
    assert!(String::from_utf8_lossy(&check.stdout).contains("valid"));
}

fn assert_clean_failure(dir: &Path, args: &[&str], must_name: &[&str]) {
    let out = impactcam(dir, args);
    assert!(!out.status.success(), "{args:?} succeeded");
    let err = stderr(&out);
    assert_eq!(
        err.trim().lines().count(),
        1,
        "{args:?}: expected one line, got:\n{err}"
    );
    for m in must_name {
        assert!(err.contains(m), "{args:?}: {err:?} does not name {m:?}");
    }
    assert!(!err.contains("panicked"), "{err}");
    assert!(results_below(dir).is_empty(), "{args:?} wrote a result");
}

#[test]
fn bad_input_gets_one_line_naming_the_problem() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    std::fs::write(d.join("typo.toml"), "[camera]\nfram_rate_hz = 1000.0\n").unwrap();
    assert_clean_failure(
        d,
        &["config", "check", "typo.toml"],
        &["typo.toml", "fram_rate_hz"],
    );
    assert_clean_failure(
        d,
        &["run", "--config", "typo.toml"],
        &["typo.toml", "fram_rate_hz"],
    );
    std::fs::write(d.join("neg.toml"), "[camera]\nframe_rate_hz = -1000.0\n").unwrap();
    assert_clean_failure(
        d,
        &["run", "--config", "neg.toml"],
        &["neg.toml", "camera.frame_rate_hz"],
    );
    assert!(
        !d.join("sessions").exists(),
        "a bad config must not create sessions"
    );

    std::fs::write(d.join("ok.toml"), "").unwrap();
    // An RGB TIFF.
    {
        let f = std::fs::File::create(d.join("rgb.tif")).unwrap();
        let mut enc = tiff::encoder::TiffEncoder::new(f).unwrap();
        enc.write_image::<tiff::encoder::colortype::RGB8>(4, 4, &[0u8; 48])
            .unwrap();
    }
    assert_clean_failure(
        d,
        &["analyze", "rgb.tif", "--config", "ok.toml"],
        &["rgb.tif", "greyscale"],
    );
    // A truncated TIFF: a valid 240×192 stack cut in half.
    {
        let mut buf = std::io::Cursor::new(Vec::new());
        let mut enc = tiff::encoder::TiffEncoder::new(&mut buf).unwrap();
        for _ in 0..3 {
            enc.write_image::<tiff::encoder::colortype::Gray8>(240, 192, &vec![30u8; 240 * 192])
                .unwrap();
        }
        let bytes = buf.into_inner();
        std::fs::write(d.join("cut.tif"), &bytes[..bytes.len() / 2]).unwrap();
    }
    assert_clean_failure(
        d,
        &["analyze", "cut.tif", "--config", "ok.toml"],
        &["cut.tif"],
    );
    assert_clean_failure(
        d,
        &["bench", "accuracy", "--repeat", "0"],
        &["--repeat", "at least 1"],
    );
    // An empty session directory.
    std::fs::create_dir(d.join("empty")).unwrap();
    assert_clean_failure(d, &["replay", "empty"], &["empty", "session"]);
    assert_clean_failure(
        d,
        &["analyze", "empty", "--config", "ok.toml"],
        &["empty", "session"],
    );
}

#[test]
fn centres_digitised_elsewhere_give_e_from_a_tracks_csv() {
    let tmp = tempfile::tempdir().unwrap();
    let out = impactcam(tmp.path(), &["run", "--json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let report: Value = serde_json::from_slice(&out.stdout).unwrap();
    let session = only_session(tmp.path());
    let truth = json(&session.join("truth.json"));
    // A digitiser's export: the true centres rounded to 0.01 px, in ImageJ-free pixel coordinates.
    let mut csv = String::from("frame,sphere,view,u,v,time_s\n");
    for f in truth["frames"].as_array().unwrap() {
        for s in ["a", "b"] {
            for view in ["direct", "mirror"] {
                let c = &f["spheres"][s]["views"][view]["centre_px"];
                let (u, v) = (c[0].as_f64().unwrap(), c[1].as_f64().unwrap());
                // Only what a person would click: spheres inside their view.
                let inside = if view == "direct" {
                    (8.0..232.0).contains(&u) && (8.0..88.0).contains(&v)
                } else {
                    (8.0..232.0).contains(&u) && (104.0..184.0).contains(&v)
                };
                let time = f["time_s"].as_f64().unwrap();
                let impact = truth["impact"]["time_s"].as_f64().unwrap();
                // Nor while the two overlap around the impact.
                if inside && (time - impact).abs() > 0.003 {
                    csv.push_str(&format!(
                        "{},{s},{view},{:.2},{:.2},{}\n",
                        f["frame_id"], u, v, time
                    ));
                }
            }
        }
    }
    std::fs::write(tmp.path().join("tracks.csv"), csv).unwrap();
    std::fs::write(tmp.path().join("c.toml"), "").unwrap();
    let an = impactcam(
        tmp.path(),
        &[
            "analyze",
            "--tracks",
            "tracks.csv",
            "--config",
            "c.toml",
            "--json",
        ],
    );
    assert!(an.status.success(), "{}", stderr(&an));
    let r: Value = serde_json::from_slice(&an.stdout).unwrap();
    assert_eq!(r["source"]["kind"], "tracks");
    let e = r["e"]["value"].as_f64().unwrap();
    assert!((e - truth["e"].as_f64().unwrap()).abs() < 0.01, "e {e}");
    assert!(
        r["psi1"].is_null()
            && r["quality"]["warnings"]
                .to_string()
                .contains("spin not measured")
    );
    assert!((e - report["e"]["value"].as_f64().unwrap()).abs() < 0.02);
    assert!(tmp.path().join("tracks.report.json").exists());

    let bad = tempfile::tempdir().unwrap();
    std::fs::write(bad.path().join("c.toml"), "").unwrap();
    std::fs::write(bad.path().join("bad.csv"), "frame,sphere,u,v\n1,a,3,4\n").unwrap();
    assert_clean_failure(
        bad.path(),
        &["analyze", "--tracks", "bad.csv", "--config", "c.toml"],
        &["bad.csv", "view"],
    );
}

#[test]
fn every_shipped_config_passes_config_check() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("config");
    let mut n = 0;
    for e in std::fs::read_dir(&dir).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "toml") {
            let out = impactcam(&dir, &["config", "check", p.to_str().unwrap()]);
            assert!(out.status.success(), "{}: {}", p.display(), stderr(&out));
            n += 1;
        }
    }
    assert!(n >= 3);
}

/// Many sessions at once: `replay` and `analyze` over a sessions directory on two threads,
/// `--shard i/n` taking every n-th, and a session that cannot be analysed named on its own line
/// without stopping the others.
#[test]
fn sessions_in_a_batch_are_replayed_and_analysed_and_sharded() {
    let tmp = tempfile::tempdir().unwrap();
    for _ in 0..2 {
        let out = impactcam(tmp.path(), &["run"]);
        assert!(out.status.success(), "{}", stderr(&out));
    }
    let replay = impactcam(tmp.path(), &["replay", "sessions", "--jobs", "2"]);
    assert!(replay.status.success(), "{}", stderr(&replay));
    let text = String::from_utf8_lossy(&replay.stdout);
    assert!(
        text.contains("replayed 2 session(s)") && text.contains("2 identical"),
        "{text}"
    );
    assert_eq!(stderr(&replay).matches(": identical").count(), 2);

    // The two shards of two take one session each, and not the same one.
    let mut taken = Vec::new();
    for shard in ["0/2", "1/2"] {
        let out = impactcam(tmp.path(), &["replay", "sessions", "--shard", shard]);
        assert!(out.status.success(), "{}", stderr(&out));
        let err = stderr(&out);
        let line = err
            .lines()
            .find(|l| l.contains(": identical"))
            .unwrap_or("")
            .to_string();
        assert!(err.contains("1 of 2 sessions"), "{err}");
        taken.push(line);
    }
    assert_ne!(taken[0], taken[1]);
    let bad = impactcam(tmp.path(), &["replay", "sessions", "--shard", "2/2"]);
    assert!(!bad.status.success());
    assert!(stderr(&bad).contains("i/n"), "{}", stderr(&bad));

    // A session whose frames are gone: named with its error; the other's report is written.
    let mut sessions: Vec<PathBuf> = std::fs::read_dir(tmp.path().join("sessions"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    sessions.sort();
    std::fs::remove_file(sessions[0].join("report.json")).unwrap();
    std::fs::remove_file(sessions[1].join("report.json")).unwrap();
    std::fs::write(sessions[1].join("frames.bin"), b"").unwrap();
    let out = impactcam(tmp.path(), &["analyze", "sessions", "--jobs", "2"]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let err = stderr(&out);
    let name1 = sessions[1]
        .file_name()
        .unwrap()
        .to_string_lossy()
        .to_string();
    assert!(
        err.lines()
            .any(|l| l.contains(&name1) && l.contains("error")),
        "{err}"
    );
    assert!(sessions[0].join("report.json").is_file());
    assert!(!sessions[1].join("report.json").exists());
}
