//! `impactcam bench validation DIR`: the analysis on recordings from a renderer that is not
//! hw-sim (each a folder with `frames.tif`, `calibration.json`, `centres.csv`, `truth.json`, as
//! the lab's validation set has them), compared with their ground truth. It checks; it tunes
//! nothing: the figures are printed with each estimate's error in units of its own σ, so an
//! uncertainty that does not cover the error shows. A rotated view is given its general map.
//! Each recording is also analysed with the maps `calibrate` finds on it, started from the
//! shorthand an experimenter would type.

use super::saved_as::{write_changed, SavedAs};
use crate::config::{Config, SphereOverride, ViewGeometry};
use serde_json::Value;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// A folder of the bench's own under the system's temporary directory, removed when dropped.
struct TempDir(PathBuf);

impl TempDir {
    fn new() -> Result<TempDir, String> {
        let dir = std::env::temp_dir().join(format!(
            "impactcam-validation-{}-{}",
            std::process::id(),
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_nanos())
        ));
        std::fs::create_dir(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        Ok(TempDir(dir))
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// One recording's comparison, as printed.
struct Row {
    name: String,
    outcome: Result<Figures, String>,
}

#[derive(Default)]
struct Figures {
    /// (quantity, error, error / σ).
    estimates: Vec<(String, f64, f64)>,
    centre_errors_px: Vec<f64>,
    /// Each measured centre's error over its reported σ, per image axis.
    centre_z: Vec<f64>,
    centres_expected: usize,
}

fn num(v: &Value) -> Option<f64> {
    v.as_f64()
}

/// The config an experimenter would write from `calibration.json`, or why there is none.
pub(crate) fn config_from_calibration(cal: &Value) -> Result<Config, String> {
    let mut cfg = Config::default_config();
    let c = &cal["calibration"];
    cfg.camera.width = c["image_width"]
        .as_u64()
        .ok_or("calibration.image_width missing")? as u32;
    cfg.camera.height = c["image_height"]
        .as_u64()
        .ok_or("calibration.image_height missing")? as u32;
    cfg.camera.frame_rate_hz = num(&cal["fps"]).ok_or("fps missing")?;
    // What the experimenter knows of the shutter: the analysis models a disc's smear over it.
    cfg.camera.exposure_us = num(&cal["exposure_s"])
        .filter(|s| *s > 0.0)
        .map(|s| s * 1e6);
    let (da, db) = (
        num(&cal["diameter_a_m"]).ok_or("diameter_a_m missing")? * 1e3,
        num(&cal["diameter_b_m"]).ok_or("diameter_b_m missing")? * 1e3,
    );
    let (ma, mb) = (
        num(&cal["mass_a_kg"]).ok_or("mass_a_kg missing")? * 1e3,
        num(&cal["mass_b_kg"]).ok_or("mass_b_kg missing")? * 1e3,
    );
    cfg.spheres.diameter_mm = da;
    cfg.spheres.mass_g = ma;
    cfg.spheres.b = Some(SphereOverride {
        diameter_mm: Some(db),
        mass_g: Some(mb),
    });
    cfg.analysis.gravity_mm_s2 = num(&cal["gravity_mps2"]).ok_or("gravity_mps2 missing")? * 1e3;
    let view_map = |name: &str| -> Result<ViewGeometry, String> {
        let v = &c[name];
        let rows = v["rows"].as_array().ok_or(format!("{name}.rows missing"))?;
        let (r0, r1) = (
            rows.first().and_then(Value::as_u64).unwrap_or(0) as u32,
            rows.get(1).and_then(Value::as_u64).unwrap_or(0) as u32,
        );
        let region = [0, r0, cfg.camera.width, r1.saturating_sub(r0)];
        // A pinhole view (`scripts/rerender-looks.py --perspective_mm`): "P", 3×4, world metres
        // to homogeneous px; the config's projection takes millimetres.
        if let Some(p) = v.get("P") {
            let at =
                |i: usize, j: usize| num(&p[i][j]).ok_or(format!("{name}.P[{i}][{j}] missing"));
            let mut rows = [[0.0; 4]; 3];
            for (i, row) in rows.iter_mut().enumerate() {
                for (j, x) in row.iter_mut().enumerate() {
                    *x = at(i, j)? / if j < 3 { 1000.0 } else { 1.0 };
                }
            }
            return Ok(ViewGeometry {
                region,
                projection: Some(rows),
                ..Default::default()
            });
        }
        let a = &v["A"];
        let b = &v["b"];
        let origin = [num(&b[0]).unwrap_or(0.0), num(&b[1]).unwrap_or(0.0)];
        // A is px per metre.
        let rows: [[f64; 3]; 2] =
            [0, 1].map(|row| [0, 1, 2].map(|k| num(&a[row][k]).unwrap_or(0.0) / 1000.0));
        let mut axes = Vec::new();
        for r in &rows {
            let (k, big) = r
                .iter()
                .enumerate()
                .max_by(|x, y| x.1.abs().total_cmp(&y.1.abs()))
                .map(|(k, x)| (k, *x))
                .unwrap_or((0, 0.0));
            let rest: f64 = r
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != k)
                .map(|(_, x)| x.abs())
                .sum();
            if big == 0.0 || rest > 1e-6 * big.abs() {
                // A turned view: only the general map describes it.
                return Ok(ViewGeometry::affine(region, rows, origin));
            }
            let axis = format!(
                "{}{}",
                if big > 0.0 { '+' } else { '-' },
                ['x', 'y', 'z'][k]
            );
            axes.push((axis, big.abs()));
        }
        // An aligned view: the shorthand (the scale of u; both rows agree for square pixels).
        Ok(ViewGeometry::shorthand(
            region, axes[0].1, origin, &axes[0].0, &axes[1].0,
        ))
    };
    let view = |name: &str| -> Result<ViewGeometry, String> {
        let mut g = view_map(name)?;
        // Whether the image is mirrored, from the side its camera is on: an unmirrored
        // camera's u × v points away from it (`image_mirrored`; said only where it is not the
        // view's default).
        let towards = &c[name]["view_direction_to_camera"];
        if let (Some((u, v)), Some(d)) = (
            g.local_affine().map(|(m, _)| (m[0], m[1])),
            (0..3)
                .map(|k| num(&towards[k]))
                .collect::<Option<Vec<f64>>>(),
        ) {
            let uxv = [
                u[1] * v[2] - u[2] * v[1],
                u[2] * v[0] - u[0] * v[2],
                u[0] * v[1] - u[1] * v[0],
            ];
            let mirrored = uxv.iter().zip(&d).map(|(a, b)| a * b).sum::<f64>() > 0.0;
            if mirrored != (name == "mirror") {
                g.image_mirrored = Some(mirrored);
            }
        }
        Ok(g)
    };
    cfg.geometry.direct = Some(view("direct")?);
    cfg.geometry.mirror = Some(view("mirror")?);
    cfg.validate()
        .map_err(|e| format!("config from calibration.json: {e}"))?;
    Ok(cfg)
}

fn read_json(path: &Path) -> Result<Value, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))
}

/// Compares one recording's report with its truth.
fn compare(dir: &Path, frames: &Path) -> Result<Figures, String> {
    let cal = read_json(&dir.join("calibration.json"))?;
    let truth = read_json(&dir.join("truth.json"))?;
    let cfg = config_from_calibration(&cal)?;
    let report = crate::experiment::analyze_path(frames, Some(&cfg), &mut |_, _| {})
        .map_err(|e| format!("no result: {e}"))?;
    let report = serde_json::to_value(&report).map_err(|e| e.to_string())?;
    let imp = &truth["impact"];
    let mut f = Figures::default();
    let mut est = |name: &str, got: &Value, want: Option<f64>| {
        if let (Some(v), Some(s), Some(w)) = (num(&got["value"]), num(&got["uncertainty"]), want) {
            f.estimates
                .push((name.into(), v - w, (v - w) / s.max(1e-300)));
        } else if want.is_some() {
            f.estimates.push((name.into(), f64::NAN, f64::NAN));
        }
    };
    est("e", &report["e"], num(&imp["e_effective"]));
    est("psi1", &report["psi1"], num(&imp["psi1"]));
    est("psi2", &report["psi2"], num(&imp["psi2"]));
    est("beta", &report["beta"], num(&imp["beta_effective"]));
    for (name, one, want) in vector_components(&report, imp) {
        est(&name, &one, want);
    }
    // Centres, per frame and view, against centres.csv.
    let csv = std::fs::read_to_string(dir.join("centres.csv")).map_err(|e| e.to_string())?;
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap_or("").split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name);
    let tracks = report["tracks"].as_array().cloned().unwrap_or_default();
    for line in lines {
        let cells: Vec<f64> = line
            .split(',')
            .map(|c| c.parse().unwrap_or(f64::NAN))
            .collect();
        let frame = cells.first().copied().unwrap_or(f64::NAN) as u64;
        let track = tracks.iter().find(|t| t["frame"].as_u64() == Some(frame));
        for s in ["a", "b"] {
            for (view, cu, cv) in [
                ("direct", "x_direct", "y_direct"),
                ("mirror", "x_mirror", "z_mirror"),
            ] {
                let (Some(iu), Some(iv)) = (col(&format!("{s}_{cu}")), col(&format!("{s}_{cv}")))
                else {
                    continue;
                };
                f.centres_expected += 1;
                let got = track.map(|t| &t[s][view]);
                if let Some(g) = got {
                    let c = &g["centre_px"];
                    if let (Some(u), Some(v)) = (num(&c[0]), num(&c[1])) {
                        f.centre_errors_px
                            .push((u - cells[iu]).hypot(v - cells[iv]));
                        let sd = &g["uncertainty_px"];
                        if let (Some(su), Some(sv)) = (num(&sd[0]), num(&sd[1])) {
                            f.centre_z.push((u - cells[iu]) / su.max(1e-300));
                            f.centre_z.push((v - cells[iv]) / sv.max(1e-300));
                        }
                    }
                }
            }
        }
    }
    Ok(f)
}

/// Every velocity and spin component of a report (JSON) beside the truth's `impact`: its name,
/// {value, uncertainty}, and the true value in the report's units.
fn vector_components(report: &Value, imp: &Value) -> Vec<(String, Value, Option<f64>)> {
    let mut out = Vec::new();
    for s in ["a", "b"] {
        for (phase, key, unit) in [
            ("pre", "velocity_pre_mm_s", 1e3),
            ("post", "velocity_post_mm_s", 1e3),
            ("pre", "spin_pre_rad_s", 1.0),
            ("post", "spin_post_rad_s", 1.0),
        ] {
            let field = if key.starts_with("velocity") {
                "velocity_mps"
            } else {
                "spin_radps"
            };
            let got = &report["spheres"][s][key];
            for (k, axis) in ["x", "y", "z"].iter().enumerate() {
                // A 2-D result reports the axis it could not measure as 0 ± 0 (its warning
                // says so): nothing to compare.
                if report["dimensionality"] == "2d" && num(&got["uncertainty"][k]) == Some(0.0) {
                    continue;
                }
                let want = num(&imp[phase][s][field][k]).map(|w| w * unit);
                let one = serde_json::json!({"value": got["value"][k], "uncertainty": got["uncertainty"][k]});
                out.push((format!("{s} {key} {axis}"), one, want));
            }
        }
    }
    out
}

/// The shorthand an experimenter would type for a view (each image axis the world axis it is
/// nearest, the scale of its rows), whether or not it describes the view: where `calibrate`
/// starts from.
fn shorthand_of(g: &ViewGeometry) -> Option<ViewGeometry> {
    let (m, o) = g.local_affine()?;
    let axis = |r: &[f64; 3]| {
        let k = (0..3).max_by(|&a, &b| r[a].abs().total_cmp(&r[b].abs()))?;
        Some(format!(
            "{}{}",
            if r[k] < 0.0 { '-' } else { '+' },
            ['x', 'y', 'z'][k]
        ))
    };
    let norm = |r: &[f64; 3]| r.iter().map(|x| x * x).sum::<f64>().sqrt();
    Some(ViewGeometry {
        image_mirrored: g.image_mirrored,
        ..ViewGeometry::shorthand(
            g.region,
            (norm(&m[0]) * norm(&m[1])).sqrt(),
            o,
            &axis(&m[0])?,
            &axis(&m[1])?,
        )
    })
}

/// What `with_calibrate` gives: e, ψ1, ψ2 as (error, error / σ), and every velocity and spin
/// component's error / σ.
struct WithCalibrate {
    scalars: Vec<(f64, f64)>,
    components: Vec<f64>,
}

/// e, ψ1, ψ2 against the truth (error, error / σ) with the maps `calibrate` finds on the
/// recording itself, started from the shorthand; and every velocity and spin component's
/// error / σ with those maps (what a turn or scale the maps get wrong shows in, and e and ψ
/// do not).
fn with_calibrate(dir: &Path, frames: &Path) -> Result<WithCalibrate, String> {
    let cal = read_json(&dir.join("calibration.json"))?;
    let truth = read_json(&dir.join("truth.json"))?;
    let mut cfg = config_from_calibration(&cal)?;
    cfg.geometry.direct = cfg.geometry.direct.as_ref().and_then(shorthand_of);
    cfg.geometry.mirror = cfg.geometry.mirror.as_ref().and_then(shorthand_of);
    let tiff = frames;
    let (found, _) = crate::calibrate::calibrate_path(tiff, Some(&cfg))
        .map_err(|e| format!("calibrate: {e}"))?;
    cfg.geometry = found.geometry;
    let report = crate::experiment::analyze_path(tiff, Some(&cfg), &mut |_, _| {})
        .map_err(|e| format!("no result: {e}"))?;
    let imp = &truth["impact"];
    let scalars = [
        (&report.e, "e_effective"),
        (&report.psi1, "psi1"),
        (&report.psi2, "psi2"),
    ]
    .iter()
    .map(|(est, key)| match (est, num(&imp[*key])) {
        (Some(e), Some(t)) => (e.value - t, (e.value - t) / e.uncertainty.max(1e-300)),
        _ => (f64::NAN, f64::NAN),
    })
    .collect();
    let json = serde_json::to_value(&report).map_err(|e| e.to_string())?;
    let components = vector_components(&json, imp)
        .into_iter()
        .filter_map(|(_, got, want)| {
            let (v, s, w) = (num(&got["value"])?, num(&got["uncertainty"])?, want?);
            (s > 0.0).then(|| (v - w) / s)
        })
        .collect();
    Ok(WithCalibrate {
        scalars,
        components,
    })
}

/// The comparison over every recording (a folder holding `truth.json`) under `dir`.
/// `saved_as`: how each recording's frames are changed first (`saved_as`; none: as rendered),
/// written to a temporary folder that is removed afterwards.
/// Of errors over their σ (`zs`): the share within ±1σ, %, NaN for none; how many lie beyond
/// 3σ and beyond 5σ.
fn coverage(zs: &[f64]) -> (f64, usize, usize) {
    let within = |k: f64| zs.iter().filter(|z| z.abs() <= k).count();
    let share = if zs.is_empty() {
        f64::NAN
    } else {
        100.0 * within(1.0) as f64 / zs.len() as f64
    };
    (share, zs.len() - within(3.0), zs.len() - within(5.0))
}

pub fn validation(dir: &Path, saved_as: &[SavedAs]) -> Result<String, String> {
    let mut sessions: Vec<_> = std::fs::read_dir(dir)
        .map_err(|e| format!("{}: {e}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("truth.json").is_file())
        .collect();
    sessions.sort();
    if sessions.is_empty() {
        return Err(format!(
            "{}: no recordings (folders with truth.json)",
            dir.display()
        ));
    }
    // The frames each recording is analysed from: its own, or changed into a folder of the
    // bench's own that goes when it is done.
    let changed = if saved_as.is_empty() {
        None
    } else {
        let tmp = TempDir::new()?;
        for p in &sessions {
            let name = p.file_name().map(|n| n.to_os_string()).unwrap_or_default();
            let out = tmp.0.join(name).with_extension("tif");
            write_changed(&p.join("frames.tif"), saved_as, &out)
                .map_err(|e| format!("{}: {e}", p.display()))?;
        }
        Some(tmp)
    };
    let frames_of = |p: &Path| match &changed {
        Some(tmp) => tmp
            .0
            .join(p.file_name().unwrap_or_default())
            .with_extension("tif"),
        None => p.join("frames.tif"),
    };
    let rows: Vec<Row> = sessions
        .iter()
        .map(|p| Row {
            name: p
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
            outcome: compare(p, &frames_of(p)),
        })
        .collect();
    let mut out = String::new();
    let _ = writeln!(
        out,
        "independent recordings under {} (errors against their truth; z = error / reported σ)",
        dir.display()
    );
    if !saved_as.is_empty() {
        let _ = writeln!(out, "frames saved as: {saved_as:?}, in that order");
    }
    let _ = writeln!(
        out,
        "{:<6} {:>9} {:>9} {:>9} {:>9} {:>10} {:>9} {:>8}  its estimate, or why none",
        "", "Δe", "Δψ1", "Δψ2", "Δβ", "centre RMS", "found", "max |z|"
    );
    let mut all_z = Vec::new();
    let mut centre_z: Vec<f64> = Vec::new();
    // Which estimates lie beyond 5σ, named, so that a regression shows where it is.
    let mut far: Vec<String> = Vec::new();
    for r in &rows {
        match &r.outcome {
            Err(e) => {
                let _ = writeln!(
                    out,
                    "{:<6} {:>9} {:>9} {:>9} {:>9} {:>10} {:>9} {:>8}  {e}",
                    r.name, "-", "-", "-", "-", "-", "-", "-"
                );
            }
            Ok(f) => {
                let get = |n: &str| f.estimates.iter().find(|e| e.0 == n).map(|e| e.1);
                let fmt = |v: Option<f64>| {
                    v.filter(|x| x.is_finite())
                        .map_or("null".to_string(), |x| format!("{x:+.4}"))
                };
                let rms = if f.centre_errors_px.is_empty() {
                    f64::NAN
                } else {
                    (f.centre_errors_px.iter().map(|e| e * e).sum::<f64>()
                        / f.centre_errors_px.len() as f64)
                        .sqrt()
                };
                let zs: Vec<f64> = f
                    .estimates
                    .iter()
                    .map(|e| e.2)
                    .filter(|z| z.is_finite())
                    .collect();
                let max_z = zs.iter().fold(0.0f64, |m, z| m.max(z.abs()));
                // Which estimate that is, so that a large one shows where to look.
                let largest = f
                    .estimates
                    .iter()
                    .filter(|e| e.2.is_finite())
                    .max_by(|a, b| a.2.abs().total_cmp(&b.2.abs()))
                    .map_or(String::new(), |e| e.0.clone());
                all_z.extend(zs);
                centre_z.extend(f.centre_z.iter().filter(|z| z.is_finite()));
                far.extend(
                    f.estimates
                        .iter()
                        .filter(|e| e.2.abs() > 5.0)
                        .map(|e| format!("  {} {}: error {:+.4} ({:+.1}σ)", r.name, e.0, e.1, e.2)),
                );
                let _ = writeln!(
                    out,
                    "{:<6} {:>9} {:>9} {:>9} {:>9} {:>7.3} px {:>4}/{:<4} {:>8.1}  {largest}",
                    r.name,
                    fmt(get("e")),
                    fmt(get("psi1")),
                    fmt(get("psi2")),
                    fmt(get("beta")),
                    rms,
                    f.centre_errors_px.len(),
                    f.centres_expected,
                    max_z
                );
            }
        }
    }
    let _ = writeln!(
        out,
        "\nwith the maps `impactcam calibrate` finds on each recording, started from the shorthand (the diameter, frame rate, g, regions known):"
    );
    let _ = writeln!(
        out,
        "{:<6} {:>16} {:>16} {:>16}",
        "", "Δe (z)", "Δψ1 (z)", "Δψ2 (z)"
    );
    let mut calibrated_components: Vec<f64> = Vec::new();
    for p in &sessions {
        let name = p
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        match with_calibrate(p, &frames_of(p)) {
            Ok(WithCalibrate {
                scalars: v,
                components,
            }) => {
                calibrated_components.extend(components);
                let cell = |(e, z): (f64, f64)| {
                    if e.is_finite() {
                        format!("{e:+.4} ({z:+.1})")
                    } else {
                        "null".into()
                    }
                };
                let _ = writeln!(
                    out,
                    "{name:<6} {:>16} {:>16} {:>16}",
                    cell(v[0]),
                    cell(v[1]),
                    cell(v[2])
                );
            }
            Err(e) => {
                let _ = writeln!(out, "{name:<6} {e}");
            }
        }
    }
    let (within1, beyond3, beyond5) = coverage(&calibrated_components);
    let _ = writeln!(
        out,
        "with those maps, of {} velocity and spin components with a σ: {within1:.0} % within ±1σ, {beyond3} beyond 3σ, {beyond5} beyond 5σ",
        calibrated_components.len(),
    );
    let (within1, beyond3, beyond5) = coverage(&centre_z);
    let _ = writeln!(
        out,
        "centres' σ, every measured centre and image axis ({} values): {within1:.1} % within ±1σ (68.3 % if honest), {beyond3} beyond 3σ, {beyond5} beyond 5σ",
        centre_z.len(),
    );
    let analysed = rows.iter().filter(|r| r.outcome.is_ok()).count();
    let covered = all_z.iter().filter(|z| z.abs() <= 1.0).count();
    let beyond5 = all_z.iter().filter(|z| z.abs() > 5.0).count();
    let _ = writeln!(
        out,
        "{analysed} of {} recordings gave a result; of their {} estimates with a σ, {:.0} % within ±1σ (55–80 % is honest) and {beyond5} beyond 5σ",
        rows.len(),
        all_z.len(),
        if all_z.is_empty() { f64::NAN } else { 100.0 * covered as f64 / all_z.len() as f64 }
    );
    for line in far {
        let _ = writeln!(out, "{line}");
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::config_from_calibration;
    use serde_json::json;

    /// A view's "P" (world metres to homogeneous px) becomes the config's projection in
    /// millimetres, taking the place of A and b; a P short of an entry is an error naming it.
    #[test]
    fn a_pinhole_views_p_becomes_its_projection_in_millimetres() {
        let view = |rows: [u64; 2], p: serde_json::Value| {
            json!({
                "rows": rows,
                "A": [[2610.0, 0.0, 0.0], [0.0, -2610.0, 0.0]],
                "b": [175.0, 51.0],
                "view_direction_to_camera": [0.0, 0.0, 1.0],
                "P": p,
            })
        };
        let p_direct = json!([
            [2610.0, 0.0, -583.3, 175.0],
            [0.0, -2610.0, -170.0, 51.0],
            [0.0, 0.0, -3.333, 1.0]
        ]);
        let p_mirror = json!([
            [2540.0, -590.0, 0.0, 176.0],
            [0.0, -560.0, 2540.0, 168.0],
            [0.0, -3.333, 0.0, 1.0]
        ]);
        let cal = |p_mirror: serde_json::Value| {
            json!({
                "fps": 1000.0, "exposure_s": 0.0001,
                "diameter_a_m": 0.00635, "diameter_b_m": 0.00635,
                "mass_a_kg": 0.000335, "mass_b_kg": 0.000335, "gravity_mps2": 9.81,
                "calibration": {
                    "image_width": 240, "image_height": 192,
                    "direct": view([0, 96], p_direct.clone()),
                    "mirror": {
                        "rows": [96, 192], "A": [[2540.0, 0.0, 0.0], [0.0, 0.0, 2540.0]],
                        "b": [176.0, 168.0], "view_direction_to_camera": [0.0, 1.0, 0.0],
                        "P": p_mirror,
                    },
                },
            })
        };
        let cfg = config_from_calibration(&cal(p_mirror.clone())).expect("a valid config");
        let direct = cfg.geometry.direct.expect("a direct view");
        let p = direct.projection.expect("the direct view is a pinhole");
        assert_eq!(direct.matrix_px_per_mm, None);
        assert_eq!(direct.origin_px, None);
        assert!((p[0][0] - 2.610).abs() < 1e-12 && (p[2][2] + 0.003333).abs() < 1e-12);
        assert_eq!((p[0][3], p[1][3], p[2][3]), (175.0, 51.0, 1.0));
        let mut short = p_mirror;
        short[1] = json!([0.0, -560.0, 2540.0]);
        let err = config_from_calibration(&cal(short)).expect_err("P short of an entry");
        assert!(err.contains("mirror.P[1][3]"), "{err}");
    }
}
