//! Centres digitised in other software (DLTdv, Tracker, …) as a CSV, turned into the same
//! per-frame observations the image analysis produces, so the fits, impact and e are computed
//! the same way. Columns (header required, any order, extra columns ignored):
//!
//! | column | meaning |
//! |---|---|
//! | `frame` | frame number (integer) |
//! | `sphere` | `a` or `b` |
//! | `view` | `direct` or `mirror` (as in the config's `[geometry]`) |
//! | `u`, `v` | image position of the sphere centre, px, pixel centres at integers (ImageJ coordinates − 0.5) |
//! | `time_s` | optional: the frame's time; without it frame k is at k / `camera.frame_rate_hz` |
//!
//! Without markers there is no spin: ψ1, ψ2 and β are null and the report says so.

use super::geometry::{View, ViewKind};
use super::report::Source;
use super::tracking::{FrameObs, Measurement};
use super::{AnalysisError, Input};
use std::collections::BTreeMap;
use std::path::Path;

fn err(path: &Path, message: String) -> AnalysisError {
    AnalysisError::Input {
        source_name: path.display().to_string(),
        message,
    }
}

pub fn read(
    path: &Path,
    views: &[View],
    frame_rate_hz: f64,
) -> Result<(Input, Vec<FrameObs>), AnalysisError> {
    let text = std::fs::read_to_string(path).map_err(|e| err(path, format!("cannot read: {e}")))?;
    // Exports from Tracker or DLTdv may start with a byte-order mark and quote their cells.
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(true)
        .flexible(true)
        .trim(csv::Trim::All)
        .from_reader(text.trim_start_matches('\u{feff}').as_bytes());
    let header = reader
        .headers()
        .map_err(|e| err(path, format!("header line: {e}")))?
        .clone();
    if header.iter().all(|c| c.is_empty()) {
        return Err(err(path, "empty file, expected a header line".into()));
    }
    let cols: Vec<String> = header.iter().map(|c| c.to_lowercase()).collect();
    let col = |name: &str| cols.iter().position(|c| c == name);
    let need = |name: &str| {
        col(name).ok_or_else(|| {
            err(
                path,
                format!("no column {name:?}, expected frame,sphere,view,u,v[,time_s]"),
            )
        })
    };
    let (cf, cs, cv, cu, cvv) = (
        need("frame")?,
        need("sphere")?,
        need("view")?,
        need("u")?,
        need("v")?,
    );
    let ct = col("time_s");
    let mut frames: BTreeMap<u64, FrameObs> = BTreeMap::new();
    for record in reader.records() {
        let record = record.map_err(|e| err(path, e.to_string()))?;
        if record.iter().all(|c| c.is_empty()) {
            continue;
        }
        let line = record.position().map_or(0, |p| p.line());
        let at = |i: usize| record.get(i).unwrap_or("");
        let bad = |what: &str| err(path, format!("line {line}: {what}"));
        let frame: u64 = at(cf)
            .parse()
            .map_err(|_| bad(&format!("frame {:?} is not a whole number", at(cf))))?;
        let s = match at(cs) {
            "a" | "A" => 0,
            "b" | "B" => 1,
            other => return Err(bad(&format!("sphere {other:?}, expected a or b"))),
        };
        let kind = match at(cv) {
            "direct" => ViewKind::Direct,
            "mirror" => ViewKind::Mirror,
            other => return Err(bad(&format!("view {other:?}, expected direct or mirror"))),
        };
        let vi = views.iter().position(|v| v.kind == kind).ok_or_else(|| {
            bad(&format!(
                "view {} is not in the config's [geometry]",
                kind.name()
            ))
        })?;
        let number = |name: &str, i: usize| -> Result<f64, AnalysisError> {
            at(i)
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| bad(&format!("{name} {:?} is not a finite number", at(i))))
        };
        let u = number("u", cu)?;
        let v = number("v", cvv)?;
        let time_s = match ct {
            Some(i) if !at(i).is_empty() => number("time_s", i)?,
            _ => frame as f64 / frame_rate_hz,
        };
        let f = frames.entry(frame).or_insert_with(|| FrameObs {
            index: 0,
            frame_id: frame,
            time_s,
            spheres: [vec![None; views.len()], vec![None; views.len()]],
            position_mm: [None, None],
        });
        // Not estimated by the digitising software: null in the report.
        f.spheres[s][vi] = Some(Measurement {
            centre_px: [u, v],
            blob_centroid_px: [u, v],
            sigma_px: [f64::NAN, f64::NAN],
            diameter_px: f64::NAN,
            edge_width_px: f64::NAN,
            markers: Vec::new(),
            hidden_in_part: None,
            radius_stray_px: 0.0,
            sigma_common_px: 0.0,
        });
    }
    if frames.is_empty() {
        return Err(err(path, "no data rows".into()));
    }
    let obs: Vec<FrameObs> = frames
        .into_values()
        .enumerate()
        .map(|(i, mut f)| {
            f.index = i as u64;
            f
        })
        .collect();
    let info = Source {
        kind: "tracks".into(),
        name: path
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default(),
        frames: obs.len() as u64,
        frame_rate_hz,
        timestamps: if ct.is_some() {
            "time_s column".into()
        } else {
            "frame / camera.frame_rate_hz".into()
        },
        trigger_frame: None,
        first_frame_number: None,
        exposure_s: None,
    };
    Ok((Input { info, warnings: vec!["centres were digitised elsewhere: their uncertainties and the sphere diameters are not known per frame".into()], frames_dropped: 0, first_pass_spins: [None; 4], settle_handedness: false, handedness_doubt: None }, obs))
}
