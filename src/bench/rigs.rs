//! `impactcam bench rigs`: the analysis on non-ideal rigs drawn at random — the camera rolled
//! up to ±2°, the mirror tilted up to ±3° from 45°, the direct camera pitched and yawed up to
//! ±1.5° (not square to the plane of collision), every other rig seen in perspective from
//! 300 mm, every third through a lens of radial distortion up to ±3 % at the frame's corners,
//! each with a look drawn from all families ("varied") — and each recording analysed
//! three ways: with the rig's exact map (from the simulator's truth), with the maps `calibrate`
//! finds on that same recording, and with the shorthand geometry, which does not describe the
//! rig and must say so. Errors are against the simulator's truth; z = error / reported σ.

use crate::analysis::source::SessionSource;
use crate::analysis::{self, report::Report};
use crate::config::{Config, Geometry, ViewGeometry};
use crate::session::SessionReader;
use serde_json::Value;
use std::fmt::Write;
use std::path::Path;

/// One rig and what each way of analysing it gave: (Δe, Δψ1, Δψ2) with σ, or why not.
struct RigResult {
    roll_deg: f64,
    tilt_deg: f64,
    pitch_yaw_deg: [f64; 2],
    distance_mm: Option<f64>,
    lens_k1: f64,
    look: String,
    exact: Result<[Option<(f64, f64)>; 3], String>,
    calibrated: Result<[Option<(f64, f64)>; 3], String>,
    /// Every velocity component's (error, σ), mm/s, with the exact map and with calibrate's:
    /// a turn of the world calibrate cannot see shows here, not in e or ψ.
    velocities: [Vec<(f64, f64)>; 2],
    /// The lens calibrate fitted: k1, its σ, and whether it was kept.
    calibrated_k1: Option<(f64, f64, bool)>,
    /// Whether the shorthand's report warned, and its Δe with σ.
    shorthand: Option<(bool, Option<(f64, f64)>)>,
}

/// The rig's exact `[geometry]` from the truth the simulator wrote.
fn exact_geometry(cfg: &Config, truth: &Value) -> Result<Geometry, String> {
    let view = |name: &str, region: [u32; 4]| -> Result<ViewGeometry, String> {
        let g = &truth["geometry"][name];
        let num = |v: &Value| {
            v.as_f64()
                .ok_or(format!("truth.json geometry.{name}: not a number"))
        };
        if g["projection"].is_array() {
            let mut p = [[0.0; 4]; 3];
            for (r, row) in p.iter_mut().enumerate() {
                for (c, x) in row.iter_mut().enumerate() {
                    *x = num(&g["projection"][r][c])?;
                }
            }
            return Ok(ViewGeometry {
                region,
                projection: Some(p),
                ..Default::default()
            });
        }
        let mut m = [[0.0; 3]; 2];
        for (r, row) in m.iter_mut().enumerate() {
            for (c, x) in row.iter_mut().enumerate() {
                *x = num(&g["matrix_px_per_mm"][r][c])?;
            }
        }
        let o = [num(&g["origin_px"][0])?, num(&g["origin_px"][1])?];
        Ok(ViewGeometry::affine(region, m, o))
    };
    // The lens the simulator drew the view through, if any.
    let with_lens = |name: &str, mut v: ViewGeometry| -> Result<ViewGeometry, String> {
        let l = &truth["geometry"][name]["lens"];
        if l.is_object() {
            let num = |v: &Value| {
                v.as_f64()
                    .ok_or(format!("truth.json geometry.{name}.lens: not a number"))
            };
            v.lens_k1 = Some(num(&l["k1"])?);
            v.lens_centre_px = Some([num(&l["centre_px"][0])?, num(&l["centre_px"][1])?]);
            v.lens_radius_px = Some(num(&l["radius_px"])?);
        }
        Ok(v)
    };
    let view = |name: &str, region| view(name, region).and_then(|v| with_lens(name, v));
    let region = |v: &Option<ViewGeometry>| v.as_ref().map(|g| g.region).unwrap_or([0; 4]);
    Ok(Geometry {
        direct: Some(view("direct", region(&cfg.geometry.direct))?),
        mirror: Some(view("mirror", region(&cfg.geometry.mirror))?),
    })
}

fn analyse(session: &Path, cfg: &Config) -> Result<Report, String> {
    let reader = SessionReader::open(session).map_err(|e| e.to_string())?;
    analysis::analyze(&mut SessionSource::new(reader), cfg, &mut |_, _| {})
        .map_err(|e| e.to_string())
}

fn errors(r: &Report, truth: &Value) -> [Option<(f64, f64)>; 3] {
    let one = |est: &Option<analysis::report::Scalar>, key: &str| {
        est.as_ref()
            .zip(truth[key].as_f64())
            .map(|(e, t)| (e.value - t, e.uncertainty))
    };
    [one(&r.e, "e"), one(&r.psi1, "psi1"), one(&r.psi2, "psi2")]
}

/// Each sphere's velocity before and after the impact, every component: (error, σ), mm/s.
fn velocity_errors(r: &Report, truth: &Value) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    for (got, name) in [(&r.spheres.a, "a"), (&r.spheres.b, "b")] {
        for (v, phase) in [
            (&got.velocity_pre_mm_s, "pre"),
            (&got.velocity_post_mm_s, "post"),
        ] {
            let want = &truth["spheres"][name][phase]["velocity_mm_s"];
            for i in 0..3 {
                if let Some(t) = want[i].as_f64() {
                    out.push((v.value[i] - t, v.uncertainty[i]));
                }
            }
        }
    }
    out
}

fn geometry_warned(r: &Report) -> bool {
    r.quality
        .warnings
        .iter()
        .any(|w| w.contains("matrix_px_per_mm"))
}

fn run_rig(seed: u64, dir: &Path) -> Result<RigResult, String> {
    let mut rng = hw_sim::Rng::new(0x5249_4753 ^ seed);
    let roll = 4.0 * rng.uniform() - 2.0;
    let tilt = 6.0 * rng.uniform() - 3.0;
    let pitch_yaw = [0, 1].map(|_| 3.0 * rng.uniform() - 1.5);
    let distance = (seed % 2 == 1).then_some(300.0);
    let lens_k1 = if seed % 3 == 2 {
        0.06 * rng.uniform() - 0.03
    } else {
        0.0
    };
    let mut cfg = Config::default_config();
    cfg.recording.dir = dir.to_path_buf();
    cfg.sim.seed = seed;
    cfg.sim.look_family = Some("varied".into());
    cfg.sim.camera_roll_deg = roll;
    cfg.sim.mirror_tilt_deg = tilt;
    cfg.sim.direct_pitch_deg = pitch_yaw[0];
    cfg.sim.direct_yaw_deg = pitch_yaw[1];
    cfg.sim.perspective_distance_mm = distance;
    cfg.sim.lens_k1 = lens_k1;
    let session = super::record_sim(&cfg)?;
    let result = (|| {
        let truth: Value = std::fs::read_to_string(session.join("truth.json"))
            .map_err(|e| e.to_string())
            .and_then(|t| serde_json::from_str(&t).map_err(|e| e.to_string()))?;
        let look = truth["look"]["family"]
            .as_str()
            .unwrap_or("default")
            .to_string();
        let shorthand = analyse(&session, &cfg)
            .ok()
            .map(|r| (geometry_warned(&r), errors(&r, &truth)[0]));
        let mut exact_cfg = cfg.clone();
        exact_cfg.geometry = exact_geometry(&cfg, &truth)?;
        let mut velocities: [Vec<(f64, f64)>; 2] = Default::default();
        let exact = analyse(&session, &exact_cfg).map(|r| {
            velocities[0] = velocity_errors(&r, &truth);
            errors(&r, &truth)
        });
        let mut calibrated_k1 = None;
        let calibrated = crate::calibrate::calibrate_path(&session, Some(&cfg))
            .map_err(|e| e.to_string())
            .and_then(|(cal, _)| {
                calibrated_k1 = Some((cal.lens_k1.value, cal.lens_k1.sigma, cal.lens_kept));
                let mut c = cfg.clone();
                c.geometry = cal.geometry;
                analyse(&session, &c)
            })
            .map(|r| {
                velocities[1] = velocity_errors(&r, &truth);
                errors(&r, &truth)
            });
        Ok(RigResult {
            roll_deg: roll,
            tilt_deg: tilt,
            pitch_yaw_deg: pitch_yaw,
            distance_mm: distance,
            lens_k1,
            look,
            exact,
            calibrated,
            velocities,
            calibrated_k1,
            shorthand,
        })
    })();
    let _ = std::fs::remove_dir_all(&session);
    result
}

/// Runs `n` rigs and returns the table and its summary.
pub fn rigs(n: usize, dir: &Path) -> String {
    let results: Vec<Result<RigResult, String>> =
        (0..n as u64).map(|i| run_rig(1000 + i, dir)).collect();
    let mut out = format!(
        "{n} non-ideal rigs (roll ±2°, mirror tilt ±3°, direct camera's pitch and yaw ±1.5°, every other one a pinhole at 300 mm, every third through a lens of k1 up to ±0.03; varied looks), each analysed with its exact map, with the maps calibrate finds on it, and with the shorthand\n"
    );
    let _ = writeln!(
        out,
        "{:>3} {:>6} {:>6} {:>11} {:>6} {:>7} {:<10} | {:>16} {:>8} {:>8} | {:>16} {:>8} {:>8} {:>17} | shorthand Δe (z)",
        "#",
        "roll°",
        "tilt°",
        "pitch/yaw°",
        "D mm",
        "k1",
        "look",
        "exact Δe (z)",
        "Δψ1",
        "Δψ2",
        "calib. Δe (z)",
        "Δψ1",
        "Δψ2",
        "calib. k1 (kept)",
    );
    let cell = |x: &Option<(f64, f64)>| match x {
        Some((e, _)) => format!("{e:+.4}"),
        None => "null".into(),
    };
    let e_cell = |x: &Option<(f64, f64)>| match x {
        Some((e, s)) => format!("{e:+.4} ({:+.1})", e / s),
        None => "null".into(),
    };
    for (i, r) in results.iter().enumerate() {
        let r = match r {
            Ok(r) => r,
            Err(e) => {
                let _ = writeln!(out, "{i:>3} failed: {e}");
                continue;
            }
        };
        let side = |x: &Result<[Option<(f64, f64)>; 3], String>| match x {
            Ok(v) => format!(
                "{:>16} {:>8} {:>8}",
                e_cell(&v[0]),
                cell(&v[1]),
                cell(&v[2])
            ),
            Err(e) => format!(
                "{:>34}",
                format!("no result: {}", e.chars().take(22).collect::<String>())
            ),
        };
        let _ = writeln!(
            out,
            "{i:>3} {:>+6.2} {:>+6.2} {:>11} {:>6} {:>7} {:<10} | {} | {} {:>17} | {}",
            r.roll_deg,
            r.tilt_deg,
            format!("{:+.2}/{:+.2}", r.pitch_yaw_deg[0], r.pitch_yaw_deg[1]),
            r.distance_mm
                .map(|d| format!("{d:.0}"))
                .unwrap_or_else(|| "-".into()),
            if r.lens_k1 != 0.0 {
                format!("{:+.4}", r.lens_k1)
            } else {
                "-".into()
            },
            r.look,
            side(&r.exact),
            side(&r.calibrated),
            match r.calibrated_k1 {
                Some((k, s, kept)) => format!("{k:+.4}±{s:.4}{}", if kept { " *" } else { "  " }),
                None => "-".into(),
            },
            match r.shorthand {
                Some((warned, e)) => format!(
                    "{} {}",
                    if warned { "warned" } else { "SILENT" },
                    e_cell(&e)
                ),
                None => "no result".into(),
            }
        );
    }
    for (name, pick) in [("exact map", 0usize), ("calibrated", 1)] {
        let sets: Vec<&[Option<(f64, f64)>; 3]> = results
            .iter()
            .filter_map(|r| r.as_ref().ok())
            .filter_map(|r| {
                if pick == 0 {
                    r.exact.as_ref().ok()
                } else {
                    r.calibrated.as_ref().ok()
                }
            })
            .collect();
        let es: Vec<(f64, f64)> = sets.iter().filter_map(|v| v[0]).collect();
        let psis: Vec<f64> = sets
            .iter()
            .flat_map(|v| [v[1], v[2]])
            .flatten()
            .map(|x| x.0.abs())
            .collect();
        let all: Vec<(f64, f64)> = sets
            .iter()
            .flat_map(|v| v.iter().flatten().copied())
            .collect();
        let mut abs_e: Vec<f64> = es.iter().map(|x| x.0.abs()).collect();
        abs_e.sort_by(f64::total_cmp);
        let frac = |v: &[f64], b: f64| {
            if v.is_empty() {
                f64::NAN
            } else {
                100.0 * v.iter().filter(|x| **x < b).count() as f64 / v.len() as f64
            }
        };
        let within1 = all.iter().filter(|(e, s)| e.abs() <= *s).count();
        let beyond5 = all.iter().filter(|(e, s)| e.abs() > 5.0 * s).count();
        let vel: Vec<(f64, f64)> = results
            .iter()
            .filter_map(|r| r.as_ref().ok())
            .flat_map(|r| r.velocities[pick].iter().copied())
            .collect();
        let vel_within1 = vel.iter().filter(|(e, s)| e.abs() <= *s).count();
        let vel_beyond = |k: f64| vel.iter().filter(|(e, s)| e.abs() > k * s).count();
        let _ = writeln!(
            out,
            "{name}: {} of {n} gave e; |Δe| median {:.4}, max {:.4}, {:.0} % within 0.01; |Δψ| {:.0} % within 0.05; of {} estimates {:.0} % within ±1σ, {beyond5} beyond 5σ; of {} velocity components {:.0} % within ±1σ, {} beyond 3σ, {} beyond 5σ",
            es.len(),
            abs_e.get(abs_e.len() / 2).copied().unwrap_or(f64::NAN),
            abs_e.last().copied().unwrap_or(f64::NAN),
            frac(&abs_e, 0.01),
            frac(&psis, 0.05),
            all.len(),
            if all.is_empty() { f64::NAN } else { 100.0 * within1 as f64 / all.len() as f64 },
            vel.len(),
            if vel.is_empty() { f64::NAN } else { 100.0 * vel_within1 as f64 / vel.len() as f64 },
            vel_beyond(3.0),
            vel_beyond(5.0),
        );
    }
    let short: Vec<(bool, Option<(f64, f64)>)> = results
        .iter()
        .filter_map(|r| r.as_ref().ok()?.shorthand)
        .collect();
    let mut abs_e: Vec<f64> = short
        .iter()
        .filter_map(|s| s.1)
        .map(|e| e.0.abs())
        .collect();
    abs_e.sort_by(f64::total_cmp);
    let beyond5 = short
        .iter()
        .filter_map(|s| s.1)
        .filter(|(e, s)| e.abs() > 5.0 * s)
        .count();
    let _ = writeln!(
        out,
        "shorthand: {} of {} analysed warned that the geometry does not describe the rig; |Δe| median {:.4}, max {:.4}, {beyond5} beyond 5σ",
        short.iter().filter(|s| s.0).count(),
        short.len(),
        abs_e.get(abs_e.len() / 2).copied().unwrap_or(f64::NAN),
        abs_e.last().copied().unwrap_or(f64::NAN),
    );
    out
}
