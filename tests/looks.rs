//! Whole experiments on the simulator under looks other than its default, and on a collision
//! whose spheres pass in front of each other in the direct view: the analysis gives a result,
//! within its stated uncertainty, on each family a real rig shows (backlit, cluttered, side-lit,
//! shiny). Before the backdrop, the lamp-following disc model and the per-side edge levels, the
//! backlit and cluttered ones gave no result at all; before the mirror view's x checked the
//! direct view's labels, the out-of-plane collision gave "no impact found".

mod common;

use std::path::Path;

/// Runs one experiment in `dir` with the config `toml` and returns (report, truth).
fn run_config(dir: &Path, toml: &str) -> (serde_json::Value, serde_json::Value) {
    std::fs::write(dir.join("sim.toml"), toml).unwrap();
    let report = common::run_json(dir, &["run", "--config", "sim.toml", "--json"]);
    let truth = common::read_json(&common::first_session(dir).join("truth.json"));
    (report, truth)
}

/// Runs one experiment with `sim.look_family = family` and returns (report, truth).
fn run(dir: &Path, family: &str, seed: u64) -> (serde_json::Value, serde_json::Value) {
    let (report, truth) = run_config(
        dir,
        &format!("[sim]\nseed = {seed}\nlook_family = \"{family}\"\n"),
    );
    assert_eq!(
        truth["look"]["family"], family,
        "the look was drawn as asked"
    );
    (report, truth)
}

#[test]
fn every_kind_of_rig_gives_e_within_its_uncertainty() {
    // Backlit seed 3 is a pure silhouette; seed 5 has a lamp in front too, so its dark spheres
    // show faint dots (before markers were looked for the right way up in an inverted view,
    // its ψ1 was null).
    for (family, seed) in [
        ("backlit", 3),
        ("backlit", 5),
        ("cluttered", 4),
        ("side_lit", 5),
        ("specular", 6),
    ] {
        let t = tempfile::tempdir().unwrap();
        let (report, truth) = run(t.path(), family, seed);
        let e = report["e"]["value"].as_f64().expect("e measured");
        let sigma = report["e"]["uncertainty"].as_f64().expect("σ(e)");
        let true_e = truth["e"].as_f64().unwrap();
        assert!(
            (e - true_e).abs() < 0.01 && (e - true_e).abs() < 5.0 * sigma,
            "{family}: e {e:.4} ± {sigma:.4}, truth {true_e:.4}"
        );
        if family == "backlit" {
            let warnings = &report["quality"]["warnings"];
            let warned = warnings.as_array().is_some_and(|w| {
                w.iter()
                    .any(|x| x.as_str().is_some_and(|s| s.contains("backlit")))
            });
            assert!(warned, "a backlit view is reported as such: {warnings}");
        }
        if (family, seed) == ("backlit", 5) {
            assert_eq!(
                truth["look"]["backlit_front_light"], true,
                "backlit seed 5 is drawn with a lamp in front"
            );
        }
        let markers_seen = family != "backlit" || truth["look"]["backlit_front_light"] == true;
        if !markers_seen {
            assert!(
                report["psi1"].is_null(),
                "{family} seed {seed}: no dots are drawn on a silhouette, so no ψ1: {}",
                report["psi1"]
            );
        } else {
            // Markers are seen: ψ1 is measured and within 5σ.
            let psi1 = report["psi1"]["value"].as_f64().expect("ψ1 measured");
            let s = report["psi1"]["uncertainty"].as_f64().expect("σ(ψ1)");
            let t1 = truth["psi1"].as_f64().unwrap();
            assert!(
                (psi1 - t1).abs() < 5.0 * s,
                "{family} seed {seed}: ψ1 {psi1:.4} ± {s:.4}, truth {t1:.4}"
            );
        }
    }
}

/// A contact normal nearly along z: the spheres overlap in the direct view through the impact
/// and come out of it on the sides they did not go in on, while the mirror view sees them
/// apart throughout.
#[test]
fn spheres_that_pass_in_front_of_each_other_keep_their_names() {
    let t = tempfile::tempdir().unwrap();
    let (report, truth) = run_config(
        t.path(),
        "[sim]\nseed = 11\nimpact_offset = 0.1\nimpact_offset_z = 0.95\n",
    );
    // Names swapped after the impact would put e far off (the post-impact velocities exchanged);
    // ψ1 here is 3.5, with σ 0.02–0.04 from run to run (the simulated release follows the
    // relay's wall-clock timing), so its absolute bound is wider: 0.05 failed at 2.4σ in CI.
    for (key, bound) in [("e", 0.05), ("psi1", 0.15), ("psi2", 0.15)] {
        assert_near_truth(&report, &truth, key, bound);
    }
}

/// The report's `key` is measured, within 5σ of the truth and within `bound` of it.
fn assert_near_truth(report: &serde_json::Value, truth: &serde_json::Value, key: &str, bound: f64) {
    let warnings = &report["quality"]["warnings"];
    let v = report[key]["value"]
        .as_f64()
        .unwrap_or_else(|| panic!("{key} measured: {warnings}"));
    let s = report[key]["uncertainty"].as_f64().unwrap();
    let tv = truth[key].as_f64().unwrap();
    assert!(
        (v - tv).abs() < 5.0 * s && (v - tv).abs() < bound,
        "{key}: {v:.4} ± {s:.4}, truth {tv:.4}"
    );
}

/// A contact normal 45° out of the view's plane, towards the direct camera: after the impact the
/// spheres separate mostly along the direct camera's axis, one partly hiding the other in the
/// direct view for the rest of the recording, while the mirror sees them apart. Only the direct
/// view measures y. Before the direct view's one silhouette was split by the mirror's x, that
/// whole phase had no y: the report was 2-D, with no spin, ψ1, ψ2 or β (as on an independent
/// render, validation v03). (hw-sim's default look: on a side-lit draw of the same rig the
/// spheres leave the direct view's region apart late enough that y was measured before too;
/// the split on side-lit spheres is `tracking::tests`' synthetic pair.)
#[test]
fn spheres_one_behind_the_other_in_the_direct_view_after_the_impact_keep_their_y() {
    let t = tempfile::tempdir().unwrap();
    let (report, truth) = run_config(
        t.path(),
        "[sim]\nseed = 11\nimpact_offset = 0.05\nimpact_offset_z = 0.7\n",
    );
    let warnings = &report["quality"]["warnings"];
    assert_eq!(report["dimensionality"], "3d", "{warnings}");
    for key in ["e", "psi1", "psi2", "beta"] {
        assert_near_truth(&report, &truth, key, 0.05);
    }
    // y after the impact, from the direct view's discs one behind the other.
    for s in ["a", "b"] {
        let v = report["spheres"][s]["velocity_post_mm_s"]["value"][1]
            .as_f64()
            .unwrap();
        let sd = report["spheres"][s]["velocity_post_mm_s"]["uncertainty"][1]
            .as_f64()
            .unwrap();
        let tv = truth["spheres"][s]["post"]["velocity_mm_s"][1]
            .as_f64()
            .unwrap();
        assert!(
            sd > 0.0 && (v - tv).abs() < 5.0 * sd,
            "{s}'s y velocity after: {v:.1} ± {sd:.1} mm/s, truth {tv:.1}"
        );
    }
}

/// Tube ends and a ruler in view (the cluttered family): the spheres leave their tubes in front
/// of the tube ends and cross the ruler, hiding what stands behind them. Where, by the truth,
/// both are out of their tubes, wholly inside a view and apart, both are measured and their
/// centres hold. Before a disc's fit knew what it hides, this experiment gave centre RMS 0.083
/// px and one centre 1.18 px off (0.020 and 0.108 after; 99.3 % of such frames measured).
#[test]
fn spheres_in_front_of_tube_ends_and_a_ruler_are_measured_where_they_are() {
    let t = tempfile::tempdir().unwrap();
    let (report, truth) = run(t.path(), "cluttered", 4);
    let (clear, both, errors) = centres_where_apart(&report, &truth);
    assert!(
        clear > 100,
        "{clear} frames with both spheres clear of the tubes and apart"
    );
    let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
    let worst = errors.iter().cloned().fold(0.0, f64::max);
    assert!(
        both as f64 >= 0.98 * clear as f64 && rms < 0.04 && worst < 0.3,
        "both measured in {both} of {clear} frames; centre RMS {rms:.4} px, worst {worst:.3} px"
    );
}

/// Over the frames where, by the truth, both spheres are out of their tubes, wholly inside a
/// view (the default config's regions) and apart: how many such view-frames there are, in
/// how many both were measured, and each measured centre's distance from the truth, px.
fn centres_where_apart(
    report: &serde_json::Value,
    truth: &serde_json::Value,
) -> (usize, usize, Vec<f64>) {
    // The default config's views: [x, y, width, height].
    let regions = [
        ("direct", [0.0, 0.0, 240.0, 96.0]),
        ("mirror", [0.0, 96.0, 240.0, 96.0]),
    ];
    let exit_s = truth["tube_exit_time_s"]
        .as_f64()
        .unwrap_or(f64::NEG_INFINITY);
    let tracks = report["tracks"].as_array().expect("tracks");
    let (mut clear, mut both, mut errors) = (0, 0, Vec::new());
    for f in truth["frames"].as_array().expect("truth frames") {
        if f["time_s"].as_f64().unwrap() < exit_s {
            continue;
        }
        let track = tracks.iter().find(|t| t["frame_id"] == f["frame_id"]);
        for (view, [rx, ry, rw, rh]) in regions {
            let disc = |s: &str| {
                let v = &f["spheres"][s]["views"][view];
                let c = &v["centre_px"];
                [
                    c[0].as_f64().unwrap(),
                    c[1].as_f64().unwrap(),
                    v["diameter_px"].as_f64().unwrap() / 2.0,
                ]
            };
            let (a, b) = (disc("a"), disc("b"));
            let inside = |d: [f64; 3]| {
                d[0] - d[2] > rx + 1.0
                    && d[0] + d[2] < rx + rw - 2.0
                    && d[1] - d[2] > ry + 1.0
                    && d[1] + d[2] < ry + rh - 2.0
            };
            if !(inside(a) && inside(b) && (a[0] - b[0]).hypot(a[1] - b[1]) > a[2] + b[2] + 1.0) {
                continue;
            }
            clear += 1;
            let got = |s: &str| {
                let c = &track?[s][view]["centre_px"];
                Some([c[0].as_f64()?, c[1].as_f64()?])
            };
            if got("a").is_some() && got("b").is_some() {
                both += 1;
            }
            for (s, d) in [("a", a), ("b", b)] {
                if let Some(c) = got(s) {
                    errors.push((c[0] - d[0]).hypot(c[1] - d[1]));
                }
            }
        }
    }
    (clear, both, errors)
}

/// A sensor with 400 stuck pixels (hw-sim's `stuck_pixels`: half hot at 255, half dead at 0,
/// about 1 % of the frame; a side-lit look): the pixels are found and said, and the centres
/// hold as on a clean sensor. A stuck pixel on a disc's ring is a residual the size of the
/// sphere's contrast in every frame that brings the edge over it; before the backdrop found
/// them this experiment gave centre RMS 0.074 px and one centre 0.54 px off (after: 0.022 and
/// 0.075, 0.024 and 0.118 in another run; hw-sim records in real time, so runs differ). Until
/// the backdrop behind a stuck pixel was taken from its neighbours, a hot one read as a tube
/// end's edge, and in one run of four (and in CI) sphere b went unmeasured in 4 of 136
/// view-frames; now 136–138 of 136–138 in four runs.
#[test]
fn a_sensors_stuck_pixels_are_left_out() {
    let t = tempfile::tempdir().unwrap();
    let (report, truth) = run_config(
        t.path(),
        "[sim]\nseed = 7\nlook_family = \"side_lit\"\nstuck_pixels = 400\n",
    );
    let warnings = report["quality"]["warnings"].to_string();
    assert!(warnings.contains("stuck pixel(s)"), "{warnings}");
    let (clear, both, errors) = centres_where_apart(&report, &truth);
    assert!(clear > 100, "{clear} view-frames with both spheres apart");
    let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
    let worst = errors.iter().cloned().fold(0.0, f64::max);
    assert!(
        both as f64 >= 0.98 * clear as f64 && rms < 0.04 && worst < 0.3,
        "both measured in {both} of {clear} frames; centre RMS {rms:.4} px, worst {worst:.3} px"
    );
}

/// After this impact the spheres' x come together while their y part, so the mirror sees one
/// partly behind the other for a dozen frames or more: each is measured from its part of the
/// shared silhouette (the outline split in two, or the grey-level fit of a crescent). Under the
/// side lamp of this look those centres were up to 0.6 px off with a claimed σ of 0.02–0.04
/// px, 8–25σ, and two of them put a's z velocity after the impact 7σ off. Their σ now holds
/// what the shared x shows of their error: every one within 5σ of the truth.
#[test]
fn discs_the_other_sphere_partly_hides_carry_their_error_in_their_sigma() {
    let t = tempfile::tempdir().unwrap();
    let (report, truth) = run_config(
        t.path(),
        "[sim]\nseed = 3124\nlook_family = \"varied\"\ntube_angle_deg = 50.0\nimpact_offset = 0.85\nimpact_offset_z = 0.05\n",
    );
    let frames = truth["frames"].as_array().expect("truth frames");
    let xy = |v: &serde_json::Value| [v[0].as_f64().unwrap(), v[1].as_f64().unwrap()];
    let mut hidden = 0;
    let mut worst: f64 = 0.0;
    for f in report["tracks"].as_array().expect("tracks") {
        let k = f["frame"].as_u64().unwrap() as usize;
        let tv = &frames[k]["spheres"];
        let ca = xy(&tv["a"]["views"]["mirror"]["centre_px"]);
        let cb = xy(&tv["b"]["views"]["mirror"]["centre_px"]);
        let r = tv["a"]["views"]["mirror"]["diameter_px"].as_f64().unwrap() / 2.0
            + tv["b"]["views"]["mirror"]["diameter_px"].as_f64().unwrap() / 2.0;
        // Overlapping by half a pixel or more, by the truth.
        if (ca[0] - cb[0]).hypot(ca[1] - cb[1]) > r - 0.5 {
            continue;
        }
        for s in ["a", "b"] {
            let m = &f[s]["mirror"];
            if m.is_null() {
                continue;
            }
            hidden += 1;
            let (c, sigma) = (xy(&m["centre_px"]), xy(&m["uncertainty_px"]));
            let truth_c = xy(&tv[s]["views"]["mirror"]["centre_px"]);
            for i in 0..2 {
                worst = worst.max(((c[i] - truth_c[i]) / sigma[i]).abs());
            }
        }
    }
    assert!(hidden >= 4, "only {hidden} partly hidden discs measured");
    assert!(worst < 5.0, "a partly hidden disc's centre {worst:.1}σ off");
}

/// Seed 1104's rig (tube 10°, offset 0.85): after the impact sphere a is half hidden by b in the
/// mirror, so its z velocity is fitted on a few poor frames (45–92 mm/s off with σ 27–67 mm/s
/// over five recordings of this rig, with the phases fitted apart; the relay's timing varies
/// from one recording to the next). Momentum across the impact ties it to the three phases
/// measured well: over ten recordings 0.4–8 mm/s off, σ 1.5–20 mm/s (20 where b's z after is
/// as poorly measured as a's, and then nothing can lend a its z). So: within 20 mm/s and 5σ,
/// and e within 3σ(e) of the truth.
#[test]
fn a_phase_the_mirror_hardly_sees_takes_its_velocity_from_momentum() {
    let t = tempfile::tempdir().unwrap();
    let (report, truth) = run_config(
        t.path(),
        "[sim]\nseed = 1104\nlook_family = \"varied\"\nmaterial = \"teflon\"\ntube_angle_deg = 10.0\nimpact_offset = 0.85\nimpact_offset_z = 0.05\npace = \"free_run\"\n[recording]\nframes = 400\npre_trigger_frames = 10\n",
    );
    let v = &report["spheres"]["a"]["velocity_post_mm_s"];
    let z = v["value"][2].as_f64().expect("a post vz");
    let sigma_z = v["uncertainty"][2].as_f64().expect("a post σ vz");
    let true_z = truth["spheres"]["a"]["post"]["velocity_mm_s"][2]
        .as_f64()
        .expect("true a post vz");
    assert!(
        (z - true_z).abs() < 20.0 && (z - true_z).abs() < 5.0 * sigma_z,
        "a after the impact, z: {:+.2} ± {sigma_z:.2} mm/s off",
        z - true_z
    );
    let e = report["e"]["value"].as_f64().expect("e");
    let sigma_e = report["e"]["uncertainty"].as_f64().expect("σ(e)");
    let true_e = truth["e"].as_f64().expect("true e");
    assert!(
        (e - true_e).abs() < 3.0 * sigma_e,
        "e {e:.4} ± {sigma_e:.4}, truth {true_e:.4}"
    );
}

/// Seed 4112's rig (defocused: blur σ 1.2 px, so no dot is found and none masked): where the
/// blurred discs come near each other or the view's border, their fits find radii 0.4–0.6 px
/// off and centres up to 1 px off, claiming 0.1 px; before each centre's σ took in its radius's
/// stray from its neighbours' (`radius_misfit`), 26–31 % of this rig's centres were within ±1σ
/// and 10–12 % beyond 5σ, over eleven recordings (they differ by the relay's timing); after,
/// 58–64 % and 2.4–3.8 %. (Its velocities were out by up to 11σ in y and, once in CI, 9σ in x;
/// with runs of such misfits in their σ, `phases::stray_velocity`, within 4.3σ over 46
/// recordings, but only 44 % within ±1σ — docs/accuracy.md.)
#[test]
fn a_defocused_rigs_centres_carry_their_radius_misfit_in_their_sigma() {
    let t = tempfile::tempdir().unwrap();
    let (report, truth) = run_config(
        t.path(),
        "[sim]\nseed = 4112\nlook_family = \"varied\"\nmaterial = \"teflon\"\ntube_angle_deg = 30.0\nimpact_offset = 0.3\nimpact_offset_z = 0.05\npace = \"free_run\"\n[recording]\nframes = 400\npre_trigger_frames = 10\n",
    );
    let frames = truth["frames"].as_array().expect("truth frames");
    let mut z = Vec::new();
    for f in report["tracks"].as_array().expect("tracks") {
        let k = f["frame"].as_u64().expect("frame") as usize;
        for s in ["a", "b"] {
            for v in ["direct", "mirror"] {
                let m = &f[s][v];
                if m.is_null() {
                    continue;
                }
                let true_px = &frames[k]["spheres"][s]["views"][v]["centre_px"];
                for axis in 0..2 {
                    let err = m["centre_px"][axis].as_f64().expect("centre")
                        - true_px[axis].as_f64().expect("true centre");
                    let sigma = m["uncertainty_px"][axis].as_f64().expect("σ");
                    z.push(err.abs() / sigma);
                }
            }
        }
    }
    assert!(z.len() > 1000, "{} centre components", z.len());
    let share =
        |keep: &dyn Fn(f64) -> bool| z.iter().filter(|&&x| keep(x)).count() as f64 / z.len() as f64;
    let (within, beyond5) = (share(&|x| x <= 1.0), share(&|x| x > 5.0));
    assert!(
        within > 0.5 && beyond5 < 0.06,
        "{:.1} % within ±1σ, {:.1} % beyond 5σ",
        100.0 * within,
        100.0 * beyond5
    );
}
