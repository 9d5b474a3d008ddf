//! Campaigns on the simulator: a sweep over both Walton branches recovers the material's e, μ
//! and β0 inside their intervals; sweeps resume; the fit says what it cannot estimate.

use impactcam::campaign::{self, fit};
use impactcam::config::Config;
use std::process::Command;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

fn glass() -> Config {
    Config::from_toml_str("[sim]\nmaterial = \"glass\"\n", "glass").unwrap()
}

#[test]
fn a_sweep_over_both_branches_recovers_glass() {
    let tmp = tempfile::tempdir().unwrap();
    let offsets = [0.1, 0.2, 0.3, 0.45, 0.55, 0.65, 0.75, 0.85];
    let (collisions, f) = campaign::sweep(
        &glass(),
        tmp.path(),
        &[30.0, 45.0],
        Some(&offsets),
        1,
        Arc::new(AtomicBool::new(false)),
        &mut |_| {},
    )
    .unwrap();
    assert_eq!(collisions.len(), 16);
    let with_psi = collisions.iter().filter(|c| c.psi1.is_some()).count();
    assert!(
        with_psi >= 12,
        "spin measured in only {with_psi} collisions"
    );
    let (e, mu, beta0) = (f.e.unwrap(), f.mu.unwrap(), f.beta0.unwrap());
    assert!((e.value - 0.97).abs() < 0.01, "e {e:?}");
    assert!((mu.value - 0.092).abs() < 0.05 * 0.092, "mu {mu:?}");
    assert!((beta0.value - 0.44).abs() < 0.05, "beta0 {beta0:?}");
    // A 95 % interval misses the truth one run in twenty by design, and the simulator's
    // collisions differ run to run (the release follows the relay's wall-clock timing): the true
    // β0 = 0.44 fell 0.0013 outside [0.4172, 0.4387] in one CI run. So each parameter is checked
    // at twice its interval's half-width on the side the truth lies (about 3.9σ): that fails when
    // an interval is wrong (too narrow, or around a biased value), not when a run is unlucky.
    // The interval's own coverage is tested in campaign::fit (β0 covered in 94 % of 300).
    for (name, est, truth) in [("e", &e, 0.97), ("mu", &mu, 0.092), ("beta0", &beta0, 0.44)] {
        let half = if truth < est.value {
            est.value - est.ci95[0]
        } else {
            est.ci95[1] - est.value
        };
        assert!(
            (est.value - truth).abs() <= 2.0 * half,
            "{name}: {truth} more than twice the 95 % half-width ({half:.5}) from {:.5} {:?}",
            est.value,
            est.ci95
        );
    }
    for file in [
        "fit.json",
        "collisions.csv",
        "psi.svg",
        "report.html",
        "campaign.json",
    ] {
        assert!(tmp.path().join(file).exists(), "{file}");
    }
    let csv = std::fs::read_to_string(tmp.path().join("collisions.csv")).unwrap();
    assert_eq!(csv.lines().count(), 17);
    assert!(csv.starts_with("source,tube_angle_deg,e,e_sigma,psi1"));
    // The command line reads the same campaign.
    let out = Command::new(env!("CARGO_BIN_EXE_impactcam"))
        .args(["fit", "--json", tmp.path().to_str().unwrap()])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for k in ["e", "mu", "beta0", "psi1_break"] {
        assert!(
            j[k]["value"].as_f64().is_some() && j[k]["uncertainty"].as_f64().is_some(),
            "{k}: {}",
            j[k]
        );
    }
    assert_eq!(j["collisions"].as_array().unwrap().len(), 16);
}

#[test]
fn a_sweep_resumes_without_repeating_finished_experiments() {
    let tmp = tempfile::tempdir().unwrap();
    let run = || {
        campaign::sweep(
            &glass(),
            tmp.path(),
            &[30.0],
            Some(&[0.2, 0.6]),
            1,
            Arc::new(AtomicBool::new(false)),
            &mut |_| {},
        )
        .unwrap()
    };
    run();
    let sessions = || {
        std::fs::read_dir(tmp.path().join("sessions"))
            .unwrap()
            .count()
    };
    assert_eq!(sessions(), 2);
    let mut said = Vec::new();
    campaign::sweep(
        &glass(),
        tmp.path(),
        &[30.0],
        Some(&[0.2, 0.6]),
        1,
        Arc::new(AtomicBool::new(false)),
        &mut |m| said.push(m.to_string()),
    )
    .unwrap();
    assert_eq!(sessions(), 2, "nothing recorded again");
    assert!(
        said[0].contains("2 of 2 experiments already done"),
        "{said:?}"
    );
}

#[test]
fn one_branch_only_gives_what_it_can_and_says_why() {
    let tmp = tempfile::tempdir().unwrap();
    // All sticking: small obliquities only.
    let (_, f) = campaign::sweep(
        &glass(),
        tmp.path(),
        &[30.0],
        Some(&[0.05, 0.15, 0.25]),
        1,
        Arc::new(AtomicBool::new(false)),
        &mut |_| {},
    )
    .unwrap();
    assert!(f.e.is_some());
    assert!(
        f.mu.is_none(),
        "mu cannot come from the sticking branch alone"
    );
    assert!(
        f.messages.iter().any(|m| m.starts_with("mu:")),
        "{:?}",
        f.messages
    );
}

#[test]
fn too_few_points_and_mixed_inputs_are_refused_clearly() {
    let mut none: Vec<fit::Collision> = Vec::new();
    let f = fit::fit(&mut none);
    assert!(f.e.is_none() && f.mu.is_none());
    assert!(
        f.messages.iter().any(|m| m.contains("need at least 3")),
        "{:?}",
        f.messages
    );

    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(
        tmp.path().join("old.json"),
        r#"{"schema": "impactcam.report/0", "e": null}"#,
    )
    .unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_impactcam"))
        .args(["fit", "old.json"])
        .current_dir(tmp.path())
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("old.json") && err.contains("schema"), "{err}");

    // Two materials in one fit.
    let a = tmp.path().join("a");
    let b = tmp.path().join("b");
    campaign::sweep(
        &glass(),
        &a,
        &[30.0],
        None,
        1,
        Arc::new(AtomicBool::new(false)),
        &mut |_| {},
    )
    .unwrap();
    let acetate = Config::from_toml_str("[sim]\nmaterial = \"acetate\"\n", "acetate").unwrap();
    campaign::sweep(
        &acetate,
        &b,
        &[30.0],
        None,
        1,
        Arc::new(AtomicBool::new(false)),
        &mut |_| {},
    )
    .unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_impactcam"))
        .args(["fit", a.to_str().unwrap(), b.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("different materials"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The campaign on rigs that do not look like the simulator's default: a side-lit glass rig
/// and a shiny (specular) teflon rig, each one look drawn from its family for the whole
/// campaign, as a real rig keeps its lamps. e within 0.01, μ within 5 %, β0 within 0.05.
#[test]
fn sweeps_on_a_side_lit_and_a_shiny_rig_recover_their_materials() {
    for (material, look, e0, mu0, beta00) in [
        ("glass", "side_lit", 0.97, 0.092, 0.44),
        ("teflon", "specular", 0.90, 0.10, 0.30),
    ] {
        let tmp = tempfile::tempdir().unwrap();
        let cfg = Config::from_toml_str(
            &format!("[sim]\nmaterial = \"{material}\"\nlook_family = \"{look}\"\nseed = 5\n"),
            material,
        )
        .unwrap();
        let offsets = [0.1, 0.2, 0.3, 0.45, 0.55, 0.65, 0.75, 0.85];
        let (_, f) = campaign::sweep(
            &cfg,
            tmp.path(),
            &[30.0, 45.0],
            Some(&offsets),
            1,
            Arc::new(AtomicBool::new(false)),
            &mut |_| {},
        )
        .unwrap();
        let (e, mu, beta0) = (f.e.unwrap(), f.mu.unwrap(), f.beta0.unwrap());
        assert!((e.value - e0).abs() < 0.01, "{material}, {look}: e {e:?}");
        assert!(
            (mu.value - mu0).abs() < 0.05 * mu0,
            "{material}, {look}: mu {mu:?}"
        );
        assert!(
            (beta0.value - beta00).abs() < 0.05,
            "{material}, {look}: beta0 {beta0:?}"
        );
    }
}
