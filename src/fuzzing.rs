//! The inputs a user or a file can hand impactcam, as functions of raw bytes, for the fuzz
//! targets in `fuzz/` and for the test that replays their committed corpora
//! (`tests/fuzz_corpus.rs`). Each must return (an error is fine) and never panic, abort or
//! allocate by a size it has not checked.

use crate::config::Config;
use std::path::Path;

/// A config file's text.
pub fn config(data: &[u8]) {
    if let Ok(text) = std::str::from_utf8(data) {
        if let Ok(cfg) = Config::from_toml_str(text, "fuzz.toml") {
            // A config that validates gives views whose maps can be used: project a point and
            // read it back through every view, alone and both together.
            let views = crate::analysis::geometry::views(&cfg);
            let p = crate::analysis::geometry::V3::new(3.0, -7.0, 1.5);
            let mut seen = Vec::new();
            for v in &views {
                let px = v.project(&p);
                let _ = v.solve(px, Some(&p));
                let _ = v.local_at(&p);
                seen.push((v, px));
            }
            let _ = crate::analysis::geometry::triangulate(&seen, &p);
        }
    }
}

/// A session directory: `data` is split at the first two `\0\0\0` marks into session.json,
/// frames.idx and frames.bin, written into `dir`, opened, and every frame read.
pub fn session(data: &[u8], dir: &Path) {
    let mut parts = split3(data);
    let (manifest, index, frames) = (parts.0, parts.1, std::mem::take(&mut parts.2));
    if std::fs::write(dir.join("session.json"), manifest).is_err()
        || std::fs::write(dir.join("frames.idx"), index).is_err()
        || std::fs::write(dir.join("frames.bin"), frames).is_err()
    {
        return;
    }
    if let Ok(mut r) = crate::session::SessionReader::open(dir) {
        let mut buf = Vec::new();
        for k in 0..r.frames.len() {
            let _ = r.read_frame(k, &mut buf);
        }
    }
}

/// A TIFF file, written to `path`, opened as a stack and every page read.
pub fn tiff(data: &[u8], path: &Path) {
    if std::fs::write(path, data).is_ok() {
        if let Ok(mut stack) = crate::footage::tiff_stack::TiffStack::open(path, Some(1000.0)) {
            use crate::footage::FrameFile;
            let mut buf = Vec::new();
            for k in 0..stack.len() {
                let _ = stack.read(k, &mut buf);
            }
        }
    }
}

/// Another camera's file (`footage`): the first byte picks the format — 0 a Photron header and
/// its frames (split at the first `\0\0\0`), 1 a cine, 2 an FMF, 3 a numbered image — the rest
/// is written into `dir`, opened by content, and its first 64 frames read.
pub fn footage(data: &[u8], dir: &Path) {
    let Some((&kind, rest)) = data.split_first() else {
        return;
    };
    let written = match kind % 4 {
        0 => {
            let at = rest.windows(3).position(|w| w == b"\0\0\0");
            let (cih, mraw) = match at {
                Some(i) => (&rest[..i], &rest[i + 3..]),
                None => (rest, &[][..]),
            };
            std::fs::write(dir.join("in.cih"), cih)
                .and_then(|_| std::fs::write(dir.join("in.mraw"), mraw))
                .map(|_| dir.join("in.cih"))
        }
        1 => std::fs::write(dir.join("in.cine"), rest).map(|_| dir.join("in.cine")),
        2 => std::fs::write(dir.join("in.fmf"), rest).map(|_| dir.join("in.fmf")),
        // Named as an image; what it is, its content decides.
        _ => std::fs::write(dir.join("f_0001.png"), rest).map(|_| dir.join("f_0001.png")),
    };
    let Ok(path) = written else { return };
    if let Ok(mut f) = crate::footage::open(&path, Some(1000.0)) {
        let mut buf = Vec::new();
        for k in 0..f.len().min(64) {
            let _ = f.meta(k);
            let _ = f.read(k, &mut buf);
        }
    }
}

/// A tracks CSV, written to `path` and analysed with the default config.
pub fn tracks(data: &[u8], path: &Path) {
    if std::fs::write(path, data).is_ok() {
        let cfg = Config::default_config();
        if let Ok(report) = crate::analysis::analyze_tracks(path, &cfg) {
            // Whatever it prints is a number or says it is not measured, never NaN.
            let text = crate::summary::report_text(&report);
            assert!(!text.contains("NaN"), "{text}");
        }
    }
}

/// A request body for `POST /api/experiments`.
pub fn api_body(data: &[u8]) {
    let _ = crate::daemon::experiment_config(data, &Config::default_config());
}

fn split3(data: &[u8]) -> (&[u8], &[u8], Vec<u8>) {
    let mark = b"\0\0\0";
    let find = |d: &[u8]| d.windows(3).position(|w| w == mark);
    match find(data) {
        Some(i) => {
            let rest = &data[i + 3..];
            match find(rest) {
                Some(j) => (&data[..i], &rest[..j], rest[j + 3..].to_vec()),
                None => (&data[..i], rest, Vec::new()),
            }
        }
        None => (data, &[], Vec::new()),
    }
}
