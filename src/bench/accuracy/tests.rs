use super::table::coverage_text;
use super::*;

/// Repetitions keep the geometry and change the seed, so pooled figures rest on
/// independent experiments, and the first repetition is the plain sweep.
#[test]
fn repetitions_are_the_same_sweep_with_new_seeds() {
    let once = sweep(false);
    let thrice = repeated_sweep(false, 3);
    assert_eq!(thrice.len(), 3 * once.len());
    let mut seeds: Vec<u64> = thrice.iter().map(|c| c.seed).collect();
    seeds.sort_unstable();
    seeds.dedup();
    assert_eq!(seeds.len(), thrice.len(), "every experiment its own seed");
    for (k, chunk) in thrice.chunks(once.len()).enumerate() {
        for (c, base) in chunk.iter().zip(&once) {
            assert_eq!(
                (
                    c.tube_angle_deg,
                    c.impact_offset,
                    c.width,
                    c.noise_sigma_grey
                ),
                (
                    base.tube_angle_deg,
                    base.impact_offset,
                    base.width,
                    base.noise_sigma_grey
                )
            );
            assert_eq!(c.seed, base.seed + 1000 * k as u64);
        }
    }
    assert_eq!(coverage_text(&[0.5, -2.0, 0.9, 3.0]), "50 % ± 25 % of 4");
}

/// Varied cases point their impact offset any way round the line of approach (so some
/// contact normals lean far towards the direct camera), keep its size, and read back as
/// that size; the default look keeps the sweep's in-plane offset exactly.
#[test]
fn varied_cases_offset_the_impact_out_of_the_views_plane_too() {
    let dir = Path::new(".");
    let mut leaning = 0;
    for mut c in sweep(false).into_iter().filter(|c| c.impact_offset >= 0.6) {
        let plain = case_config(&c, dir);
        assert_eq!(plain.sim.impact_offset, c.impact_offset);
        assert_eq!(
            plain.sim.impact_offset_z,
            Config::default_config().sim.impact_offset_z
        );
        assert_eq!(case_of(&plain).impact_offset, c.impact_offset);
        c.looks = Some("varied".into());
        let varied = case_config(&c, dir);
        let (b1, b2) = (varied.sim.impact_offset, varied.sim.impact_offset_z);
        assert!((b1.hypot(b2) - c.impact_offset).abs() < 1e-12);
        assert!((case_of(&varied).impact_offset - c.impact_offset).abs() < 1e-12);
        if b2.abs() > 0.5 * c.impact_offset {
            leaning += 1;
        }
    }
    assert!(leaning >= 3, "{leaning} normals leaning out of the plane");
}

/// The "never > 0.03" goal is judged on the data the issue states it for: the σ = 4 and
/// 640×480 runs do not count there, however large their errors.
/// A grazing case (50°, offset 0.97) at noise σ `noise` and frame width `width` (240×192 or
/// 640×480), for the goals' lines.
fn sized_case(seed: u64, noise: f64, width: u32) -> Case {
    Case {
        tube_angle_deg: 50.0,
        impact_offset: 0.97,
        noise_sigma_grey: noise,
        width,
        height: if width == 240 { 192 } else { 480 },
        seed,
        looks: None,
        exposure_ms: None,
        flicker_percent: None,
    }
}

#[test]
fn e_on_the_goals_data_leaves_out_the_other_noise_and_sizes() {
    let case = |seed: u64, noise: f64, width: u32, de: f64| {
        let c = sized_case(seed, noise, width);
        let r = CaseResult {
            e: Some((de, 0.01)),
            ..Default::default()
        };
        (c, r)
    };
    let results = vec![
        case(1, 2.0, 240, 0.010),
        case(2, 2.0, 240, -0.041),
        case(3, 2.0, 240, 0.002),
        case(4, 4.0, 240, 0.090),
        case(5, 2.0, 640, -0.080),
    ];
    let text = table(&results);
    let line = text
        .lines()
        .find(|l| l.starts_with("e on the goals' data"))
        .expect("the goals' line is printed");
    assert_eq!(
            line,
            "e on the goals' data (240×192, σ = 2 grey levels; 3 experiments): median |Δe| 0.0100, max 0.0410 (seed 2, 50°, offset 0.97); 1 above 0.03"
        );
}

/// The ψ and β goals' line: β counted only where the true ψ1 is 0.2 or more (a β 2.6 off
/// at ψ1 = 0.03 is not a miss), ψ everywhere, both on the goals' data only.
#[test]
fn psi_and_beta_on_the_goals_data_count_beta_only_where_psi1_says_something() {
    let case = |seed: u64, width: u32, psi1: f64, dpsi: f64, dbeta: f64| {
        let c = sized_case(seed, 2.0, width);
        let r = CaseResult {
            psi1: Some((dpsi, 0.01)),
            psi2: Some((-dpsi, 0.01)),
            beta: Some((dbeta, 0.01)),
            true_psi1: psi1,
            ..Default::default()
        };
        (c, r)
    };
    let results = vec![
        case(1, 240, 0.03, 0.01, 2.6),
        case(2, 240, 0.8, 0.12, 0.2),
        case(3, 240, 1.5, 0.02, 0.05),
        case(4, 640, 1.5, 0.5, 0.9),
    ];
    assert_eq!(
            table::spin_goals_line(&results),
            "ψ, β on the goals' data (3 experiments with a spin): max |Δψ1| 0.1200, 1 above 0.1; max |Δψ2| 0.1200, 1 above 0.1; |Δβ| where the true ψ1 ≥ 0.2 (2): max 0.2000, 1 above 0.15"
        );
}

/// The spin count says apart how many experiments' frames show no dot at all (a backlit
/// silhouette), counts the measured spins over the rest too, and counts a spin reported
/// where no dot was drawn; with every experiment showing dots it is the plain count.
#[test]
fn the_spin_count_sets_apart_experiments_that_show_no_dot() {
    let case = |spin: bool, no_dots_seen: bool| CaseResult {
        psi1: spin.then_some((0.0, 0.01)),
        no_dots_seen,
        ..Default::default()
    };
    let results = [
        case(true, false),
        case(true, false),
        case(false, false),
        case(false, true),
        case(true, true),
    ];
    let all: Vec<&CaseResult> = results.iter().collect();
    assert_eq!(
        table::spin_count_line(&all),
        "spin measured in 3 of 5 experiments (ψ, β need all four phases); in 2 of the 3 whose frames show dots (2 show none: backlit silhouettes or no markers; a spin reported in 1 of those)"
    );
    assert_eq!(
        table::spin_count_line(&all[..3]),
        "spin measured in 2 of 3 experiments (ψ, β need all four phases)"
    );
}

/// `--looks varied` reports every family it drew, and pooled: a family dropped from the
/// draw or from the table fails here.
#[test]
fn every_look_family_gets_its_row() {
    let mut drawn: Vec<String> = (0..200u64)
        .map(|seed| hw_sim::Look::draw("varied", seed).expect("varied").0.family)
        .collect();
    drawn.sort();
    drawn.dedup();
    assert_eq!(drawn.len(), hw_sim::Look::FAMILIES.len());
    let results: Vec<(Case, CaseResult)> = drawn
        .iter()
        .enumerate()
        .map(|(k, f)| {
            let c = Case {
                tube_angle_deg: 30.0,
                impact_offset: 0.3,
                noise_sigma_grey: 2.0,
                width: 240,
                height: 192,
                seed: k as u64,
                looks: Some("varied".into()),
                exposure_ms: None,
                flicker_percent: None,
            };
            let r = CaseResult {
                look_family: f.clone(),
                e: Some((0.001, 0.01)),
                ..Default::default()
            };
            (c, r)
        })
        .collect();
    let text = table::by_look(&results);
    for f in hw_sim::Look::FAMILIES.iter().chain(["pooled"].iter()) {
        assert!(
            text.lines().any(|l| l.split_whitespace().next() == Some(f)),
            "no row for {f}:\n{text}"
        );
    }
}
