//! Measurement against the simulator's ground truth: the accuracy goals that hold, the thesis
//! baseline beaten on the same frames, and what happens when the data cannot give a quantity.

mod common;

use impactcam::bench::accuracy::{self, rms, stats};
use std::path::Path;

#[test]
fn quick_sweep_meets_the_accuracy_goals_and_beats_the_thesis() {
    let tmp = tempfile::tempdir().unwrap();
    let results: Vec<_> = accuracy::sweep(true)
        .into_iter()
        .map(|c| {
            let r = accuracy::run_case(&c, tmp.path(), true);
            (c, r)
        })
        .collect();
    for (c, r) in &results {
        assert!(r.failed.is_none(), "{c:?}: {:?}", r.failed);
    }
    let all = |f: &dyn Fn(&accuracy::CaseResult) -> Vec<f64>| {
        results.iter().flat_map(|(_, r)| f(r)).collect::<Vec<f64>>()
    };
    let centres = all(&|r| r.centre_err_px.clone());
    assert!(rms(&centres) <= 0.1, "centre RMS {} px", rms(&centres));
    let thesis_centres = all(&|r| r.thesis_centre_err_px.clone());
    assert!(rms(&thesis_centres) > 3.0 * rms(&centres));
    let e = all(&|r| r.e.map(|x| x.0).into_iter().collect());
    assert_eq!(e.len(), 4);
    assert!(
        stats(&e).unwrap().0 <= 0.01 && stats(&e).unwrap().2 <= 0.03,
        "{e:?}"
    );
    for key in ["psi1", "psi2"] {
        let v = all(&|r| {
            if key == "psi1" { r.psi1 } else { r.psi2 }
                .map(|x| x.0)
                .into_iter()
                .collect()
        });
        assert!(
            v.len() >= 2,
            "{key} measured in only {} experiments",
            v.len()
        );
        assert!(stats(&v).unwrap().0 <= 0.05, "{key}: {v:?}");
    }
    let vel = all(&|r| r.vel_rel.clone());
    assert!(stats(&vel).unwrap().0 <= 0.01, "{vel:?}");
    let rot = all(&|r| r.rot_err_deg.clone());
    let rot_thesis = all(&|r| r.thesis_rot_err_deg.clone());
    assert!(
        stats(&rot).unwrap().0 < 0.5 * stats(&rot_thesis).unwrap().0,
        "Kabsch {:?} vs LS9 {:?}",
        stats(&rot),
        stats(&rot_thesis)
    );
    // The goal is 0.5° on the full sweep (docs/accuracy.md); four experiments scatter more.
    // Before the markers' shading, coverage and foreshortening were fixed the median was 0.69°.
    assert!(
        stats(&rot).unwrap().0 <= 0.6,
        "rotation per pair {:?}",
        stats(&rot)
    );
    // Dot centres unbiased from the middle of the disc to the limb (they were pulled 0.05 px
    // inwards near the limb and pushed 0.04 px outwards near the middle).
    let markers: Vec<(f64, f64, f64)> = results
        .iter()
        .flat_map(|(_, r)| r.marker_err_px.iter().copied())
        .collect();
    for (lo, hi) in [(0.0, 0.4), (0.4, 0.8)] {
        let radial: Vec<f64> = markers
            .iter()
            .filter(|m| m.0 >= lo && m.0 < hi)
            .map(|m| m.2)
            .collect();
        let mean = radial.iter().sum::<f64>() / radial.len().max(1) as f64;
        assert!(
            radial.len() > 100 && mean.abs() < 0.025,
            "dots at ρ/R {lo}–{hi}: mean radial error {mean:+.3} px over {}",
            radial.len()
        );
    }
    let thesis_e = all(&|r| r.thesis_e.into_iter().collect());
    assert!(stats(&thesis_e).unwrap().0 > stats(&e).unwrap().0);

    // `bench accuracy --sessions`: a kept recording analysed again gives the table it gave when
    // it was recorded (one of the four, to keep the suite short), all but the time it took.
    let kept = impactcam::batch::sessions(&[tmp.path().to_path_buf()]).unwrap();
    assert_eq!(kept.len(), 4, "--keep keeps every recording");
    let seed_of = |dir: &Path| {
        impactcam::session::SessionReader::open(dir)
            .ok()
            .map(|r| r.config().sim.seed)
    };
    let first = &results[0].0;
    let again = kept
        .iter()
        .find(|d| seed_of(d) == Some(first.seed))
        .expect("the first case's recording");
    let untimed = |t: String| {
        t.lines()
            .filter(|l| !l.starts_with("analysis time"))
            .collect::<Vec<_>>()
            .join("\n")
    };
    let recorded = [(first.clone(), results.into_iter().next().unwrap().1)];
    assert_eq!(
        untimed(accuracy::accuracy_of_sessions(std::slice::from_ref(again))),
        untimed(accuracy::table(&recorded))
    );
}

fn run(dir: &Path, toml: &str, extra: &[&str]) -> std::process::Output {
    std::fs::write(dir.join("c.toml"), toml).unwrap();
    let mut args = vec!["run", "--config", "c.toml", "--json"];
    args.extend_from_slice(extra);
    common::impactcam(dir, &args)
}

#[test]
fn without_markers_spins_are_null_with_a_warning_and_e_is_still_measured() {
    let tmp = tempfile::tempdir().unwrap();
    let out = run(tmp.path(), "[sim]\nmarkers_per_sphere = 0\n", &[]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(r["e"]["value"].as_f64().is_some());
    for k in ["psi1", "psi2", "beta", "branch_hint"] {
        assert!(r[k].is_null(), "{k} = {}", r[k]);
    }
    assert!(r["spheres"]["a"]["spin_pre_rad_s"].is_null());
    assert!(r["quality"]["warnings"]
        .to_string()
        .contains("spin not measured"));
}

#[test]
fn one_view_gives_2d_results_flagged_as_such() {
    let tmp = tempfile::tempdir().unwrap();
    let toml = "[geometry.direct]\nregion = [0, 0, 240, 96]\npx_per_mm = 2.1576\norigin_px = [119.5, 44.0]\nu_axis = \"+x\"\nv_axis = \"-y\"\n";
    let out = run(tmp.path(), toml, &[]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(r["dimensionality"], "2d");
    assert!(r["quality"]["warnings"].to_string().contains("2-D"));
    let e = r["e"]["value"].as_f64().unwrap();
    assert!((e - 0.9).abs() < 0.03, "2-D e {e}");
}

/// A shallow tube (15°): the spheres roll slowly, and hw-sim's 280-frame recording ends about
/// 16 ms before they meet. The error says the impact is not in the recording, and which way
/// to move it, not that a phase has too few frames (before session 48: "only 0 usable frame(s)
/// of sphere a before the impact", even from the true centres).
#[test]
fn a_recording_that_ends_before_the_impact_says_so() {
    let err = failed_without_a_report("[sim]\ntube_angle_deg = 15.0\n");
    assert!(
        err.contains("no impact found") && err.contains("after the recording ends"),
        "{err}"
    );
}

/// Runs one experiment with `toml`, which must fail and leave no report: its stderr.
fn failed_without_a_report(toml: &str) -> String {
    let tmp = tempfile::tempdir().unwrap();
    let out = run(tmp.path(), toml, &[]);
    assert!(!out.status.success());
    let session = common::first_session(tmp.path());
    assert!(!session.join("report.json").exists());
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn spheres_that_never_touch_are_no_impact_and_no_report() {
    // An impact parameter of 1.6 contact distances: they fly past each other.
    let err = failed_without_a_report("[sim]\nimpact_offset = 1.6\n");
    assert!(err.contains("no impact found"), "{err}");
    assert_eq!(
        err.trim().lines().last().map(|l| l.starts_with("error:")),
        Some(true),
        "{err}"
    );
}

#[test]
fn thesis_rotation_is_available_for_comparison() {
    let tmp = tempfile::tempdir().unwrap();
    let out = run(tmp.path(), "[analysis]\nrotation = \"thesis\"\n", &[]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(r["e"]["value"].as_f64().is_some());
}

#[test]
fn the_mirror_scale_and_offset_are_refined_from_the_redundant_x() {
    let tmp = tempfile::tempdir().unwrap();
    let out = run(
        tmp.path(),
        "[sim]\nmirror_scale_error = 0.03\nmirror_offset_error_px = [2.0, 0.0]\n",
        &[],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let c = &r["quality"]["calibration"];
    assert_eq!(c["refined"], true, "{c}");
    let s0 = c["mirror_px_per_mm_config"].as_f64().unwrap();
    let s1 = c["mirror_px_per_mm_refined"].as_f64().unwrap();
    assert!((s1 / s0 - 1.03).abs() < 0.005, "scale {s0} -> {s1}");
    let du = c["mirror_origin_u_px_refined"].as_f64().unwrap()
        - c["mirror_origin_u_px_config"].as_f64().unwrap();
    assert!((du - 2.0).abs() < 0.3, "offset change {du} px");
    // The whole origin: moved along u (the image of x here), not along v.
    let origin = |key: &str| c[key][1].as_f64().unwrap_or(f64::NAN);
    assert_eq!(
        origin("mirror_origin_px_refined"),
        origin("mirror_origin_px_config")
    );
    assert_eq!(
        c["mirror_origin_px_refined"][0], c["mirror_origin_u_px_refined"],
        "{c}"
    );
    assert!(
        c["residual_rms_mm_after"].as_f64().unwrap()
            < 0.3 * c["mirror_minus_direct_x_rms_mm"].as_f64().unwrap(),
        "{c}"
    );
    assert!((r["e"]["value"].as_f64().unwrap() - 0.9).abs() < 0.02);
}

/// A slow head-on impact (10°), where the two discs touch in the direct view for a few frames
/// and are one silhouette there: those frames, the ones nearest the contact, are measured, each
/// disc fitted from where it was heading (alone, or with its neighbour where their rings meet),
/// and within a tenth of a pixel of the truth. Whether a frame falls while the discs touch
/// depends on the frame clock's phase at the impact, which the relay's timing on a busy machine
/// sets; so the experiment is repeated until one does (every run is checked in full).
#[test]
fn touching_spheres_in_the_direct_view_are_measured() {
    for _attempt in 0..5 {
        if touching_frames_measured_in_one_run() > 0 {
            return;
        }
    }
    panic!("in five runs no frame with the discs touching: the test shows nothing");
}

/// Runs one simulated experiment with `toml` and returns its session's report and truth.
fn recorded_report_and_truth(toml: &str) -> (serde_json::Value, serde_json::Value) {
    let tmp = tempfile::tempdir().unwrap();
    let out = run(tmp.path(), toml, &[]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let session = common::first_session(tmp.path());
    let read = |name: &str| -> serde_json::Value {
        serde_json::from_slice(&std::fs::read(session.join(name)).unwrap()).unwrap()
    };
    (read("report.json"), read("truth.json"))
}

/// One run of `touching_spheres_in_the_direct_view_are_measured`: every frame within 3 of
/// the impact is measured in the direct view, within 0.1 px; returns how many of them show the
/// discs touching (less than 0.5 px apart).
fn touching_frames_measured_in_one_run() -> usize {
    let (report, truth) = recorded_report_and_truth("[recording]\nframes = 400\npre_trigger_frames = 10\n[sim]\ntube_angle_deg = 10.0\nimpact_offset = 0.05\nseed = 7\n");
    let impact = report["impact"]["frame"].as_i64().unwrap();
    let merged: Vec<&serde_json::Value> = report["quality"]["unmeasured"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|u| u["view"] == "direct" && (u["frame"].as_i64().unwrap() - impact).abs() <= 3)
        .collect();
    assert!(
        merged.is_empty(),
        "unmeasured next to the impact: {merged:?}"
    );
    let truth_frames: Vec<&serde_json::Value> =
        truth["frames"].as_array().unwrap().iter().collect();
    let mut touching = 0;
    for t in report["tracks"].as_array().unwrap() {
        if (t["frame"].as_i64().unwrap() - impact).abs() > 3 {
            continue;
        }
        let tf = truth_frames
            .iter()
            .find(|f| f["frame_id"] == t["frame_id"])
            .unwrap();
        let centre = |s: &str| -> [f64; 2] {
            let c = &tf["spheres"][s]["views"]["direct"]["centre_px"];
            [c[0].as_f64().unwrap(), c[1].as_f64().unwrap()]
        };
        let (ta, tb) = (centre("a"), centre("b"));
        let gap = (ta[0] - tb[0]).hypot(ta[1] - tb[1]) - 6.35 * 2.1576;
        if gap < 0.5 {
            touching += 1;
        }
        for (s, truth_c) in [("a", ta), ("b", tb)] {
            let m = &t[s]["direct"]["centre_px"];
            let (u, v) = (m[0].as_f64().unwrap(), m[1].as_f64().unwrap());
            let err = (u - truth_c[0]).hypot(v - truth_c[1]);
            assert!(
                err < 0.1,
                "frame {}: {s} {err:.3} px off (gap {gap:.2} px)",
                t["frame"]
            );
        }
    }
    touching
}

/// After an oblique impact (65°, offset 0.85) the two spheres slide behind each other in the
/// mirror: one silhouette, split into two circles. Where the spheres are 4–7.5 px apart the
/// mirror's centres are within 0.03 px RMS of the truth: from 5 px apart both discs are
/// refitted on the grey levels with the front one hiding the back one (the outline's circles
/// alone came out 0.046–0.049 px RMS, drifting as the overlap grew, which a line fit took for a
/// z velocity 4–5σ off).
#[test]
fn spheres_behind_each_other_in_the_mirror_are_measured_on_their_grey_levels() {
    let (report, truth) = recorded_report_and_truth("[recording]\nframes = 400\npre_trigger_frames = 10\n[sim]\ntube_angle_deg = 65.0\nimpact_offset = 0.85\nseed = 1129\n");
    let impact = report["impact"]["frame"].as_i64().unwrap();
    let truth_frames: Vec<&serde_json::Value> =
        truth["frames"].as_array().unwrap().iter().collect();
    let mut errors = Vec::new();
    for t in report["tracks"].as_array().unwrap() {
        if t["frame"].as_i64().unwrap() <= impact {
            continue;
        }
        let tf = truth_frames
            .iter()
            .find(|f| f["frame_id"] == t["frame_id"])
            .unwrap();
        let centre = |s: &str| -> Option<[f64; 2]> {
            let c = &tf["spheres"][s]["views"]["mirror"]["centre_px"];
            Some([c[0].as_f64()?, c[1].as_f64()?])
        };
        let (Some(ta), Some(tb)) = (centre("a"), centre("b")) else {
            continue;
        };
        let apart = (ta[0] - tb[0]).hypot(ta[1] - tb[1]);
        if !(4.0..=7.5).contains(&apart) {
            continue;
        }
        for (s, truth_c) in [("a", ta), ("b", tb)] {
            let m = &t[s]["mirror"]["centre_px"];
            if let (Some(u), Some(v)) = (m[0].as_f64(), m[1].as_f64()) {
                errors.push((u - truth_c[0]).hypot(v - truth_c[1]));
            }
        }
    }
    assert!(
        errors.len() >= 4,
        "only {} mirror centres with the spheres 4–7.5 px apart after the impact",
        errors.len()
    );
    let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
    assert!(
        rms < 0.03,
        "split silhouettes in the mirror {rms:.3} px from the truth: {errors:?}"
    );
}

/// Two spheres passing at different depths overlap in the direct view from the impact on, so
/// only the mirror sees them afterwards (the lab's validation recording v03 is such a case).
/// Centres given as a tracks CSV: the direct view's stop at the impact. The result is 2-D (x and
/// z, y lost with a warning) with the right e, not "no usable frames".
#[test]
fn spheres_the_direct_view_loses_after_impact_give_a_2d_result() {
    let cfg = impactcam::config::Config::default_config();
    let views = impactcam::analysis::geometry::views(&cfg);
    let r = cfg.spheres.sphere(0).0 / 2.0;
    let g = cfg.analysis.gravity_mm_s2;
    let n = nalgebra::Vector3::new(0.68, 0.0, -0.733).normalize();
    let (va, vb) = (
        nalgebra::Vector3::new(900.0, 150.0, 0.0),
        nalgebra::Vector3::new(-980.0, 150.0, -66.0),
    );
    let e = 0.9;
    let gn = (va - vb).dot(&n);
    let (va2, vb2) = (va - 0.5 * (1.0 + e) * gn * n, vb + 0.5 * (1.0 + e) * gn * n);
    let t_c = 0.0194;
    let mut csv = String::from("frame,sphere,view,u,v\n");
    // Deterministic sub-pixel jitter, as a digitiser's.
    let mut seed = 12345u64;
    let mut jitter = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((seed >> 33) as f64 / (1u64 << 31) as f64 - 0.5) * 0.04
    };
    for k in 0..40 {
        let t = k as f64 / cfg.camera.frame_rate_hz;
        let dt = t - t_c;
        for (name, side, v_pre, v_post) in [("a", -1.0, va, va2), ("b", 1.0, vb, vb2)] {
            let v = if dt < 0.0 { v_pre } else { v_post };
            let p = n * (side * r) + v * dt - nalgebra::Vector3::new(0.0, 0.5 * g * dt * dt, 0.0);
            for view in &views {
                if view.kind.name() == "direct" && dt > 0.0 {
                    continue;
                }
                let px = view.project(&p);
                csv += &format!(
                    "{k},{name},{},{},{}\n",
                    view.kind.name(),
                    px[0] + jitter(),
                    px[1] + jitter()
                );
            }
        }
    }
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("t.csv"), csv).unwrap();
    let report = impactcam::analysis::analyze_tracks(&dir.path().join("t.csv"), &cfg).unwrap();
    assert_eq!(report.dimensionality, "2d");
    assert!(
        report
            .quality
            .warnings
            .iter()
            .any(|w| w.starts_with("y was not measured")),
        "{:?}",
        report.quality.warnings
    );
    let got = report.e.unwrap();
    assert!(
        (got.value - e).abs() < 0.01 && (got.value - e).abs() < 4.0 * got.uncertainty + 0.002,
        "e = {} ± {}",
        got.value,
        got.uncertainty
    );
}
