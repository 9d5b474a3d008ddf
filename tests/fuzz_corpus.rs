//! Replays the committed fuzz corpora (`fuzz/corpus/<target>/`) through the same functions the
//! fuzz targets call (`impactcam::fuzzing`), so CI checks every input the fuzzers kept without
//! spending fuzzing time. A panic here is a crash the fuzzer found. See docs/fuzzing.md.

use std::path::{Path, PathBuf};

fn corpus(target: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fuzz/corpus")
        .join(target);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    assert!(!files.is_empty(), "{}: no seed inputs", dir.display());
    files
}

fn replay(target: &str, run: &dyn Fn(&[u8], &Path)) {
    let tmp = tempfile::tempdir().unwrap();
    let files = corpus(target);
    for f in &files {
        let data = std::fs::read(f).unwrap();
        let work = tmp.path().join("work");
        let _ = std::fs::remove_dir_all(&work);
        std::fs::create_dir(&work).unwrap();
        run(&data, &work);
    }
    println!("{target}: {} inputs replayed", files.len());
}

#[test]
fn config_corpus() {
    replay("config", &|d, _| impactcam::fuzzing::config(d));
}

#[test]
fn session_corpus() {
    replay("session", &|d, w| impactcam::fuzzing::session(d, w));
}

#[test]
fn tiff_corpus() {
    replay("tiff", &|d, w| {
        impactcam::fuzzing::tiff(d, &w.join("in.tif"))
    });
}

#[test]
fn tracks_corpus() {
    replay("tracks", &|d, w| {
        impactcam::fuzzing::tracks(d, &w.join("in.csv"))
    });
}

#[test]
fn api_body_corpus() {
    replay("api_body", &|d, _| impactcam::fuzzing::api_body(d));
}

#[test]
fn footage_corpus() {
    replay("footage", &|d, w| impactcam::fuzzing::footage(d, w));
}
