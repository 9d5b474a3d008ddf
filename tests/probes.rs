//! Bad input as a careless user or a crafted file gives it: every probe must end in exit 1 and
//! one line on stderr that names the file, key or line — never a panic, an abort, or a wrong
//! number with exit 0 — and must leave what was recorded as it was.

mod common;

use common::impactcam;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Asserts exit 1 and exactly one stderr line that contains every one of `named`.
fn refused(what: &str, out: &Output, named: &[&str]) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        out.status.code(),
        Some(1),
        "{what}: exit {:?}\n{err}",
        out.status.code()
    );
    let lines: Vec<&str> = err.lines().collect();
    assert_eq!(lines.len(), 1, "{what}: expected one line:\n{err}");
    for n in named {
        assert!(
            lines[0].contains(n),
            "{what}: {n:?} not named in {:?}",
            lines[0]
        );
    }
    assert!(!err.contains("panicked"), "{what}: {err}");
}

/// A copy of `session` with `file` replaced by what `edit` makes of it.
fn altered(
    tmp: &Path,
    session: &Path,
    name: &str,
    file: &str,
    edit: &dyn Fn(Vec<u8>) -> Vec<u8>,
) -> PathBuf {
    let dir = tmp.join(name);
    std::fs::create_dir_all(&dir).unwrap();
    for e in std::fs::read_dir(session).unwrap() {
        let p = e.unwrap().path();
        std::fs::copy(&p, dir.join(p.file_name().unwrap())).unwrap();
    }
    let bytes = std::fs::read(dir.join(file)).unwrap();
    std::fs::write(dir.join(file), edit(bytes)).unwrap();
    dir
}

fn lines_of(bytes: Vec<u8>) -> Vec<String> {
    String::from_utf8(bytes)
        .unwrap()
        .lines()
        .map(String::from)
        .collect()
}

#[test]
fn crafted_sessions_are_refused_naming_the_file_and_line() {
    let tmp = tempfile::tempdir().unwrap();
    let out = impactcam(tmp.path(), &["run"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let session = common::first_session(tmp.path());
    let s = session.to_str().unwrap();

    // frames.idx: ids out of order around the impact, a timestamp of 2^64-1, a duplicated id.
    let swap = altered(tmp.path(), &session, "swapped", "frames.idx", &|b| {
        let mut l = lines_of(b);
        l.swap(150, 151);
        (l.join("\n") + "\n").into_bytes()
    });
    refused(
        "ids out of order",
        &impactcam(tmp.path(), &["replay", swap.to_str().unwrap()]),
        &["frames.idx", "line 152"],
    );
    let huge = altered(tmp.path(), &session, "huge-ts", "frames.idx", &|b| {
        let mut l = lines_of(b);
        let id = l[100].split(',').next().unwrap().to_string();
        l[100] = format!("{id},18446744073709551615");
        (l.join("\n") + "\n").into_bytes()
    });
    refused(
        "timestamp 2^64-1",
        &impactcam(tmp.path(), &["replay", huge.to_str().unwrap()]),
        &["frames.idx", "line 101"],
    );
    let dup = altered(tmp.path(), &session, "dup", "frames.idx", &|b| {
        let mut l = lines_of(b);
        l.insert(60, l[59].clone());
        (l.join("\n") + "\n").into_bytes()
    });
    refused(
        "duplicated id",
        &impactcam(tmp.path(), &["replay", dup.to_str().unwrap()]),
        &["frames.idx", "line 61"],
    );
    // frames.bin: a header whose width × height × bytes wraps.
    let wrap = altered(tmp.path(), &session, "wrap", "frames.bin", &|mut b| {
        b[8..20].copy_from_slice(&[0xff; 12]);
        b
    });
    refused(
        "header wraps",
        &impactcam(tmp.path(), &["replay", wrap.to_str().unwrap()]),
        &["frames.bin"],
    );
    // session.json: a config without views.
    let noview = altered(tmp.path(), &session, "noview", "session.json", &|b| {
        let mut m: serde_json::Value = serde_json::from_slice(&b).unwrap();
        m["config"]["geometry"] = serde_json::json!({});
        serde_json::to_vec(&m).unwrap()
    });
    refused(
        "no views",
        &impactcam(tmp.path(), &["replay", noview.to_str().unwrap()]),
        &["session.json", "geometry"],
    );

    // analyze with another config never replaces the recorded report.json unless asked.
    let recorded = std::fs::read(session.join("report.json")).unwrap();
    std::fs::write(
        tmp.path().join("other.toml"),
        "[analysis]\nthreshold_fraction = 0.4\n",
    )
    .unwrap();
    refused(
        "analyze --config OTHER",
        &impactcam(tmp.path(), &["analyze", s, "--config", "other.toml"]),
        &["report.json", "--out"],
    );
    assert_eq!(
        std::fs::read(session.join("report.json")).unwrap(),
        recorded
    );
    let out = impactcam(tmp.path(), &["analyze", s]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        std::fs::read(session.join("report.json")).unwrap(),
        recorded,
        "its own config gives the same report"
    );
    let out = impactcam(tmp.path(), &["replay", s]);
    assert_eq!(out.status.code(), Some(0));

    // fit: e = 1e308, a negative uncertainty.
    let mut report: serde_json::Value = serde_json::from_slice(&recorded).unwrap();
    report["e"]["value"] = serde_json::json!(1e308);
    std::fs::write(tmp.path().join("e-huge.json"), report.to_string()).unwrap();
    refused(
        "fit e = 1e308",
        &impactcam(tmp.path(), &["fit", "e-huge.json"]),
        &["e-huge.json", "e.value"],
    );
    let mut report: serde_json::Value = serde_json::from_slice(&recorded).unwrap();
    report["psi1"]["uncertainty"] = serde_json::json!(-0.1);
    std::fs::write(tmp.path().join("neg.json"), report.to_string()).unwrap();
    refused(
        "fit negative σ",
        &impactcam(tmp.path(), &["fit", "neg.json"]),
        &["neg.json", "psi1.uncertainty"],
    );
}

#[test]
fn crafted_files_and_arguments_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let t = tmp.path();
    // A 126-byte TIFF declaring 200000 × 200000.
    let tiff =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus/tiff/declares-200000x200000.tif");
    std::fs::write(t.join("c.toml"), "").unwrap();
    refused(
        "huge TIFF",
        &impactcam(
            t,
            &["analyze", tiff.to_str().unwrap(), "--config", "c.toml"],
        ),
        &["declares-200000x200000.tif", "16384"],
    );
    // A tracks CSV with a NaN cell.
    std::fs::write(
        t.join("nan.csv"),
        "frame,sphere,view,u,v\n0,a,direct,NaN,40\n",
    )
    .unwrap();
    refused(
        "NaN in tracks",
        &impactcam(t, &["analyze", "--tracks", "nan.csv", "--config", "c.toml"]),
        &["nan.csv", "line 2", "finite"],
    );
    // A sweep range of 1e302 values.
    refused(
        "sweep range",
        &impactcam(
            t,
            &["sweep", "--tube-angles", "0:1e300:1e-300", "--dir", "camp"],
        ),
        &["--tube-angles", "at most"],
    );
    // Sizes from a config are bounded before anything is opened.
    std::fs::write(t.join("big.toml"), "[recording]\nframes = 4294967295\n").unwrap();
    refused(
        "config check frames",
        &impactcam(t, &["config", "check", "big.toml"]),
        &["recording.frames", "at most"],
    );
    refused(
        "capture frames",
        &impactcam(t, &["capture", "--config", "big.toml"]),
        &["recording.frames"],
    );
    assert!(!t.join("sessions").exists());
    // A missing file: its cause once.
    let out = impactcam(t, &["replay", "no-such-session"]);
    refused("missing session", &out, &["no-such-session"]);
    let line = String::from_utf8_lossy(&out.stderr).to_string();
    let cause = "does not exist";
    assert!(line.matches(cause).count() <= 1, "{line}");
    let out = impactcam(t, &["config", "check", "missing.toml"]);
    refused("missing config", &out, &["missing.toml"]);
    let line = String::from_utf8_lossy(&out.stderr).to_string();
    assert_eq!(line.matches("No such file").count(), 1, "{line}");
    // Usage errors and a bad log format exit 1 (2 means "replay differs").
    let out = impactcam(t, &["replay"]);
    assert_eq!(out.status.code(), Some(1));
    let out = Command::new(env!("CARGO_BIN_EXE_impactcam"))
        .args(["config", "default"])
        .env("IMPACTCAM_LOG_FORMAT", "xml")
        .output()
        .unwrap();
    refused("bad IMPACTCAM_LOG_FORMAT", &out, &["IMPACTCAM_LOG_FORMAT"]);
}

#[test]
fn logs_are_json_when_asked_and_never_coloured_when_redirected() {
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(tmp.path().join("c.toml"), "[recording]\nframes = 60\n").unwrap();
    let out = impactcam(
        tmp.path(),
        &["--log-format", "json", "capture", "--config", "c.toml"],
    );
    assert!(out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.trim().is_empty());
    for line in err.lines() {
        let v: serde_json::Value =
            serde_json::from_str(line).unwrap_or_else(|e| panic!("not JSON ({e}): {line}"));
        assert!(v["message"].is_string(), "{line}");
    }
    let out = impactcam(tmp.path(), &["capture", "--config", "c.toml"]);
    assert!(out.status.success());
    assert!(
        !String::from_utf8_lossy(&out.stderr).contains('\u{1b}'),
        "ANSI codes in a redirected log"
    );
}

/// A tracks CSV as Tracker or DLTdv export it — a byte-order mark, quoted header cells — gives
/// the same report as the plain file; and a campaign table keeps a source name with a comma.
#[test]
fn csv_with_a_bom_and_quotes_reads_like_plain_csv() {
    let tmp = tempfile::tempdir().unwrap();
    let t = tmp.path();
    let plain = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus/tracks/simulated-collision.csv"),
    )
    .unwrap();
    let (head, rest) = plain.split_once('\n').unwrap();
    let quoted: Vec<String> = head.split(',').map(|c| format!("\"{c}\"")).collect();
    std::fs::write(t.join("plain.csv"), &plain).unwrap();
    std::fs::write(
        t.join("export.csv"),
        format!(
            "\u{feff}{}\r\n{}",
            quoted.join(","),
            rest.replace('\n', "\r\n")
        ),
    )
    .unwrap();
    std::fs::write(t.join("c.toml"), "").unwrap();
    let a = common::run_json(
        t,
        &[
            "analyze",
            "--tracks",
            "plain.csv",
            "--config",
            "c.toml",
            "--json",
        ],
    );
    let b = common::run_json(
        t,
        &[
            "analyze",
            "--tracks",
            "export.csv",
            "--config",
            "c.toml",
            "--json",
        ],
    );
    assert!(a["e"]["value"].is_number(), "{a}");
    assert_eq!(a["e"], b["e"]);
    assert_eq!(a["tracks"], b["tracks"]);

    // A source (the report's file name) with a comma in it survives collisions.csv.
    std::fs::write(t.join("glass, run 3.json"), a.to_string()).unwrap();
    let out = impactcam(t, &["fit", "glass, run 3.json", "--out", "fit"]);
    assert!(out.status.success(), "{}", common::stderr(&out));
    let table = std::fs::read_to_string(t.join("fit/collisions.csv")).unwrap();
    let row = table.lines().nth(1).unwrap();
    assert!(
        row.starts_with("\"glass, run 3.json\","),
        "a source with a comma is quoted: {row}"
    );
}
