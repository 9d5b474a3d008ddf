//! The accuracy bench's figures: summary statistics and coverage of the errors, and the table
//! printed per family of cases, for impactcam and the thesis side by side.

use super::*;

/// (median, 95th percentile, max) of absolute values.
pub fn stats(v: &[f64]) -> Option<(f64, f64, f64)> {
    let mut a: Vec<f64> = v
        .iter()
        .map(|x| x.abs())
        .filter(|x| x.is_finite())
        .collect();
    if a.is_empty() {
        return None;
    }
    a.sort_by(f64::total_cmp);
    let q = |p: f64| a[((a.len() - 1) as f64 * p).round() as usize];
    Some((q(0.5), q(0.95), a[a.len() - 1]))
}

pub fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

/// Fraction of |z| ≤ 1.
pub fn coverage(z: &[f64]) -> f64 {
    z.iter().filter(|x| x.abs() <= 1.0).count() as f64 / z.len().max(1) as f64
}

/// "74 % ± 4 % of 136": the coverage with its binomial standard error, in per cent.
pub(super) fn coverage_text(z: &[f64]) -> String {
    let p = coverage(z);
    let se = (p * (1.0 - p) / z.len().max(1) as f64).sqrt();
    format!("{:.0} % ± {:.0} % of {}", 100.0 * p, 100.0 * se, z.len())
}

pub fn table(results: &[(Case, CaseResult)]) -> String {
    let mut s = String::new();
    let ok: Vec<&CaseResult> = results
        .iter()
        .map(|(_, r)| r)
        .filter(|r| r.failed.is_none())
        .collect();
    let _ = writeln!(
        s,
        "impactcam bench accuracy — {} simulated experiments, {} analysed",
        results.len(),
        ok.len()
    );
    let sticking = ok.iter().filter(|r| r.true_branch == "sticking").count();
    let psi_max = ok.iter().map(|r| r.true_psi1).fold(0.0, f64::max);
    let _ = writeln!(
        s,
        "true branches: {sticking} sticking, {} sliding; true ψ1 from 0 to {psi_max:.2}",
        ok.len() - sticking
    );
    for (c, r) in results {
        if let Some(f) = &r.failed {
            let _ = writeln!(
                s,
                "  not analysed: seed {}, look {}, tube {}°, offset {:.2}, σ {}, {}×{}: {f}",
                c.seed,
                r.look_family,
                c.tube_angle_deg,
                c.impact_offset,
                c.noise_sigma_grey,
                c.width,
                c.height
            );
        }
    }
    let _ = writeln!(
        s,
        "\nper experiment (estimate − truth; velocity: worst phase, % of |v|; centre: worst frame):"
    );
    let _ = writeln!(
        s,
        "{:>5} {:<10} {:>6} {:>6} {:>4} {:>9} {:>7} {:>8} {:>7} {:>8} {:>8} {:>8} {:>7} {:>9}",
        "seed",
        "look",
        "tube°",
        "offset",
        "σ",
        "size",
        "ψ1 true",
        "Δe",
        "σ(e)",
        "Δψ1",
        "Δψ2",
        "Δβ",
        "v %",
        "centre px"
    );
    for (c, r) in results.iter().filter(|(_, r)| r.failed.is_none()) {
        let f = |x: Option<(f64, f64)>| {
            x.map(|v| format!("{:>8.4}", v.0))
                .unwrap_or_else(|| format!("{:>8}", "—"))
        };
        let worst = r.centre_err_px.iter().copied().fold(0.0, f64::max);
        let worst_v = r.vel_rel.iter().copied().fold(0.0, f64::max);
        let _ = writeln!(
            s,
            "{:>5} {:<10} {:>6} {:>6.2} {:>4} {:>9} {:>7.3} {} {:>7.4} {} {} {} {:>7.3} {:>9.3}",
            c.seed,
            r.look_family,
            c.tube_angle_deg,
            c.impact_offset,
            c.noise_sigma_grey,
            format!("{}×{}", c.width, c.height),
            r.true_psi1,
            f(r.e),
            r.e.map(|e| e.1).unwrap_or(f64::NAN),
            f(r.psi1),
            f(r.psi2),
            f(r.beta),
            100.0 * worst_v,
            worst
        );
    }
    let col = |v: Vec<f64>| {
        stats(&v)
            .map(|(m, p, x)| format!("{m:>9.4} {p:>9.4} {x:>9.4}"))
            .unwrap_or_else(|| format!("{:>29}", "—"))
    };
    let all =
        |f: &dyn Fn(&CaseResult) -> Vec<f64>| ok.iter().flat_map(|r| f(r)).collect::<Vec<f64>>();
    let _ = writeln!(
        s,
        "\n{:<36} {:>29}   {:>29}",
        "error against truth", "impactcam: median p95 max", "thesis: median p95 max"
    );
    let rows: Vec<(&str, Vec<f64>, Vec<f64>)> = vec![
        (
            "centre, px",
            all(&|r| r.centre_err_px.clone()),
            all(&|r| r.thesis_centre_err_px.clone()),
        ),
        (
            "rotation per pair (≥4 markers), °",
            all(&|r| r.rot_err_deg.clone()),
            all(&|r| r.thesis_rot_err_deg.clone()),
        ),
        (
            "e",
            all(&|r| r.e.map(|x| x.0).into_iter().collect()),
            all(&|r| r.thesis_e.into_iter().collect()),
        ),
        (
            "ψ1",
            all(&|r| r.psi1.map(|x| x.0).into_iter().collect()),
            all(&|r| r.thesis_psi1.into_iter().collect()),
        ),
        (
            "ψ2",
            all(&|r| r.psi2.map(|x| x.0).into_iter().collect()),
            all(&|r| r.thesis_psi2.into_iter().collect()),
        ),
        (
            "β",
            all(&|r| r.beta.map(|x| x.0).into_iter().collect()),
            all(&|r| r.thesis_beta.into_iter().collect()),
        ),
        (
            "velocity |Δv|/|v|",
            all(&|r| r.vel_rel.clone()),
            all(&|r| r.thesis_vel_rel.clone()),
        ),
        (
            "spin |Δω|, rad/s",
            all(&|r| r.spin_err.clone()),
            all(&|r| r.thesis_spin_err.clone()),
        ),
    ];
    for (name, a, b) in rows {
        let _ = writeln!(s, "{name:<36} {}   {}", col(a), col(b));
    }
    let _ = writeln!(
        s,
        "\ncentre RMS, every measured centre (discs cut by a view's border included): {:.4} px (thesis integer centres {:.4} px)",
        rms(&all(&|r| r.centre_err_px.clone())),
        rms(&all(&|r| r.thesis_centre_err_px.clone()))
    );
    let centre_z = all(&|r| r.centre_z.clone());
    let share = |keep: &dyn Fn(f64) -> bool| {
        100.0 * centre_z.iter().filter(|z| keep(z.abs())).count() as f64
            / centre_z.len().max(1) as f64
    };
    let _ = writeln!(
        s,
        "centre σ, every measured centre and image axis ({} values): {:.1} % within ±1σ (68.3 % if honest), {:.2} % beyond 3σ (0.27 %), {:.2} % beyond 5σ",
        centre_z.len(),
        share(&|z| z <= 1.0),
        share(&|z| z > 3.0),
        share(&|z| z > 5.0)
    );
    let markers: Vec<(f64, f64, f64)> = results
        .iter()
        .flat_map(|(_, r)| r.marker_err_px.iter().copied())
        .collect();
    let _ = writeln!(
        s,
        "marker position (relative to its disc centre), by distance from the disc centre ρ/R:"
    );
    for (lo, hi) in [(0.0, 0.4), (0.4, 0.6), (0.6, 0.7), (0.7, 0.8)] {
        let sel: Vec<&(f64, f64, f64)> = markers.iter().filter(|m| m.0 >= lo && m.0 < hi).collect();
        if sel.is_empty() {
            continue;
        }
        let abs: Vec<f64> = sel.iter().map(|m| m.1).collect();
        let mean_radial = sel.iter().map(|m| m.2).sum::<f64>() / sel.len() as f64;
        let _ = writeln!(
            s,
            "  {lo:.1}–{hi:.1}: median error {:.3} px, mean radial error {mean_radial:+.3} px (+ outwards), {} markers",
            stats(&abs).map(|x| x.0).unwrap_or(f64::NAN),
            sel.len()
        );
    }
    // The goal "never > 0.03" against what the data allow: where the reported σ(e) is itself
    // above 0.015, the measurement says it cannot promise 0.03.
    let tight: Vec<f64> = ok
        .iter()
        .filter_map(|r| r.e)
        .filter(|e| e.1 <= 0.015)
        .map(|e| e.0)
        .collect();
    let loose = ok
        .iter()
        .filter_map(|r| r.e)
        .filter(|e| e.1 > 0.015)
        .count();
    let worst_z = ok
        .iter()
        .filter_map(|r| r.e)
        .map(|e| (e.0 / e.1).abs())
        .fold(0.0, f64::max);
    let _ = writeln!(
        s,
        "e where σ(e) ≤ 0.015 ({} experiments): max |Δe| {:.4}; {loose} with σ(e) > 0.015; largest |Δe|/σ(e) {worst_z:.2}",
        tight.len(),
        tight.iter().fold(0.0f64, |m, x| m.max(x.abs()))
    );
    // The goals are stated for 240×192 frames with noise σ = 2 grey levels; the σ = 4
    // and 640×480 runs are there to show the method holds beyond them.
    let on_goal_data: Vec<(&Case, f64)> = results
        .iter()
        .filter(|(c, r)| on_goals_data(c, r))
        .filter_map(|(c, r)| r.e.map(|e| (c, e.0.abs())))
        .collect();
    if let Some((worst, max)) = on_goal_data
        .iter()
        .copied()
        .max_by(|a, b| a.1.total_cmp(&b.1))
    {
        let mut errs: Vec<f64> = on_goal_data.iter().map(|x| x.1).collect();
        errs.sort_by(f64::total_cmp);
        let _ = writeln!(
            s,
            "e on the goals' data (240×192, σ = 2 grey levels; {} experiments): median |Δe| {:.4}, max {max:.4} (seed {}, {}°, offset {:.2}); {} above 0.03",
            errs.len(),
            errs[errs.len() / 2],
            worst.seed,
            worst.tube_angle_deg,
            worst.impact_offset,
            errs.iter().filter(|x| **x > 0.03).count()
        );
    }
    let _ = writeln!(s, "{}", spin_goals_line(results));
    let _ = writeln!(s, "{}", spin_count_line(&ok));
    let z = all(&|r| r.z.clone());
    let _ = writeln!(
        s,
        "coverage of ±1σ, all {} reported components (e, ψ1, ψ2, β, v, ω): {:.1} %",
        z.len(),
        100.0 * coverage(&z)
    );
    for (name, pick) in [("e", 0usize), ("ψ1", 1), ("ψ2", 2), ("β", 3)] {
        let zz = all(&|r| {
            [r.e, r.psi1, r.psi2, r.beta][pick]
                .map(|(e, u)| e / u)
                .into_iter()
                .collect()
        });
        let _ = writeln!(s, "  {name}: {}", coverage_text(&zz));
    }
    for (name, zz) in [
        ("velocity components", all(&|r| r.z_velocity.clone())),
        ("spin components", all(&|r| r.z_spin.clone())),
    ] {
        let _ = writeln!(s, "  {name}: {}", coverage_text(&zz));
    }
    let beyond5 = z.iter().filter(|x| x.abs() > 5.0).count();
    let worst = z.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let _ = writeln!(
        s,
        "beyond 5σ: {beyond5} of {} reported components (largest |error|/σ {worst:.1})",
        z.len()
    );
    for (c, r) in results {
        for line in &r.beyond_5_sigma {
            let _ = writeln!(s, "  seed {} ({}): {line}", c.seed, r.look_family);
        }
    }
    s.push_str(&by_look(results));
    let (at, rt, nf) = ok.iter().fold((0.0, 0.0, 0usize), |a, r| {
        (
            a.0 + r.analysis_time.as_secs_f64(),
            a.1 + r.read_time.as_secs_f64(),
            a.2 + r.frames_analysed,
        )
    });
    if nf > 0 {
        let _ = writeln!(
            s,
            "analysis time: {:.1} ms per 40 frames on one core ({:.0}× the time to read the same frames from disk)",
            at / nf as f64 * 40.0 * 1e3,
            at / rt.max(1e-12)
        );
    }
    s
}

/// The figures per look family (the family each experiment drew), then pooled: the goals of
/// the measurement are stated per family for the centres' bias and pooled for the rest.
pub(super) fn by_look(results: &[(Case, CaseResult)]) -> String {
    let mut s = String::new();
    let mut families: Vec<&str> = results
        .iter()
        .map(|(_, r)| r.look_family.as_str())
        .collect();
    families.sort_unstable();
    families.dedup();
    let _ = writeln!(
        s,
        "\nper look family (centre RMS and bias, and detection, over the frames where both spheres are wholly in a view and apart; z = error/σ over e, ψ, β, v, ω):"
    );
    let _ = writeln!(
        s,
        "{:<10} {:>5} {:>9} {:>11} {:>15} {:>10} {:>9} {:>9} {:>6} {:>9} {:>5}",
        "look",
        "runs",
        "analysed",
        "centre RMS",
        "bias u, v px",
        "detected",
        "med |Δe|",
        "max |Δe|",
        "spin",
        "±1σ",
        ">5σ"
    );
    let mut rows: Vec<(&str, Vec<&CaseResult>)> = families
        .iter()
        .map(|f| {
            (
                *f,
                results
                    .iter()
                    .filter(|(_, r)| r.look_family == *f)
                    .map(|(_, r)| r)
                    .collect(),
            )
        })
        .collect();
    if families.len() > 1 {
        rows.push(("pooled", results.iter().map(|(_, r)| r).collect()));
    }
    for (name, rs) in rows {
        let ok: Vec<&&CaseResult> = rs.iter().filter(|r| r.failed.is_none()).collect();
        let uv: Vec<[f64; 2]> = ok
            .iter()
            .flat_map(|r| r.centre_err_uv.iter().copied())
            .collect();
        // The RMS over the same centres as the bias, as the heading says: where both spheres
        // are wholly in the view and apart. (Until session 36 this column took every measured
        // centre, discs cut by the view's border among them: 0.0706 px pooled on session 35's
        // 190 varied-look recordings, where the centres it names gave 0.0496 px.)
        let centres: Vec<f64> = uv.iter().map(|e| e[0].hypot(e[1])).collect();
        let mean = |i: usize| uv.iter().map(|e| e[i]).sum::<f64>() / uv.len().max(1) as f64;
        let (fr, fm) = ok.iter().fold((0, 0), |a, r| {
            (a.0 + r.apart_frames, a.1 + r.apart_measured)
        });
        let de: Vec<f64> = ok.iter().filter_map(|r| r.e.map(|e| e.0)).collect();
        let z: Vec<f64> = ok.iter().flat_map(|r| r.z.iter().copied()).collect();
        let centre = if centres.is_empty() {
            format!("{:>11} {:>15}", "—", "—")
        } else {
            format!(
                "{:>8.4} px {:>+7.4} {:>+7.4}",
                rms(&centres),
                mean(0),
                mean(1)
            )
        };
        let _ = writeln!(
            s,
            "{:<10} {:>5} {:>9} {centre} {:>8.1} % {:>9} {:>9} {:>6} {:>7.0} % {:>5}",
            name,
            rs.len(),
            ok.len(),
            100.0 * fm as f64 / fr.max(1) as f64,
            stats(&de)
                .map(|x| format!("{:.4}", x.0))
                .unwrap_or_else(|| "—".into()),
            stats(&de)
                .map(|x| format!("{:.4}", x.2))
                .unwrap_or_else(|| "—".into()),
            format!(
                "{}/{}",
                ok.iter().filter(|r| r.psi1.is_some()).count(),
                ok.len()
            ),
            100.0 * coverage(&z),
            z.iter().filter(|x| x.abs() > 5.0).count()
        );
    }
    s
}

/// Whether an experiment counts for the measurement issue's goals: analysed, and on the data
/// they are stated for (240×192 frames, noise σ = 2 grey levels).
fn on_goals_data(c: &Case, r: &CaseResult) -> bool {
    r.failed.is_none() && c.width == 240 && c.height == 192 && c.noise_sigma_grey == 2.0
}

/// ψ1, ψ2 and β against the measurement issue's goals, on its data (240×192, σ = 2): the
/// largest |Δψ1|, |Δψ2| and how many exceed 0.1, and |Δβ| only where the true ψ1 ≥ 0.2 (β =
/// −ψ2/ψ1 means nothing as ψ1 → 0), its largest and how many exceed 0.15.
pub(super) fn spin_goals_line(results: &[(Case, CaseResult)]) -> String {
    let on_goal: Vec<&CaseResult> = results
        .iter()
        .filter(|(c, r)| on_goals_data(c, r))
        .map(|(_, r)| r)
        .collect();
    let errs = |pick: &dyn Fn(&CaseResult) -> Option<(f64, f64)>,
                only: &dyn Fn(&CaseResult) -> bool| {
        on_goal
            .iter()
            .filter(|r| only(r))
            .filter_map(|r| pick(r).map(|(e, _)| e.abs()))
            .collect::<Vec<f64>>()
    };
    let every = |_: &CaseResult| true;
    let psi1 = errs(&|r| r.psi1, &every);
    let psi2 = errs(&|r| r.psi2, &every);
    let beta = errs(&|r| r.beta, &|r| r.true_psi1 >= 0.2);
    let max = |v: &[f64]| v.iter().copied().fold(0.0f64, f64::max);
    let above = |v: &[f64], k: f64| v.iter().filter(|x| **x > k).count();
    format!(
        "ψ, β on the goals' data ({} experiments with a spin): max |Δψ1| {:.4}, {} above 0.1; max |Δψ2| {:.4}, {} above 0.1; |Δβ| where the true ψ1 ≥ 0.2 ({}): max {:.4}, {} above 0.15",
        psi1.len(),
        max(&psi1),
        above(&psi1, 0.1),
        max(&psi2),
        above(&psi2, 0.1),
        beta.len(),
        max(&beta),
        above(&beta, 0.15)
    )
}

/// How many experiments measured a spin (ψ1 reported: all four phases), and the same among
/// those whose frames show dots at all. Why both: a backlit silhouette shows no dot, so no
/// spin can be measured from it however good the analysis; the count over the rest says how
/// often the analysis measures a spin it could, and a spin reported where no dot was drawn
/// would be invented (counted apart, which should be none).
pub(super) fn spin_count_line(ok: &[&CaseResult]) -> String {
    let measured =
        |rs: &mut dyn Iterator<Item = &&CaseResult>| rs.filter(|r| r.psi1.is_some()).count();
    let with_dots: Vec<&&CaseResult> = ok.iter().filter(|r| !r.no_dots_seen).collect();
    let without = ok.len() - with_dots.len();
    let mut line = format!(
        "spin measured in {} of {} experiments (ψ, β need all four phases)",
        measured(&mut ok.iter()),
        ok.len()
    );
    if without > 0 {
        line += &format!(
            "; in {} of the {} whose frames show dots ({without} show none: backlit silhouettes or no markers; a spin reported in {} of those)",
            measured(&mut with_dots.into_iter()),
            ok.len() - without,
            measured(&mut ok.iter().filter(|r| r.no_dots_seen)),
        );
    }
    line
}
