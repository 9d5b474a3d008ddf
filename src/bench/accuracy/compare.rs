//! One case's report against the simulator's truth: each estimate's error and its error in σ,
//! the centres where both spheres are apart, the spins as rotations, and the thesis's methods
//! on the same frames (`analyse_case`, for `run_case` and `--sessions`).

use super::*;
use crate::analysis::geometry::ViewKind;

fn v3(v: &Value) -> V3 {
    V3::new(
        v[0].as_f64().unwrap_or(f64::NAN),
        v[1].as_f64().unwrap_or(f64::NAN),
        v[2].as_f64().unwrap_or(f64::NAN),
    )
}

/// The angle of the rotation between an estimated and a true rotation vector, degrees.
fn angle_err(rotvec: V3, truth: V3) -> f64 {
    (Rotation3::from_scaled_axis(rotvec) * Rotation3::from_scaled_axis(truth).inverse())
        .angle()
        .to_degrees()
}

const PHASES: [(&str, &str); 4] = [("a", "pre"), ("b", "pre"), ("a", "post"), ("b", "post")];

/// Analyses `session` with `cfg` and puts each estimate's error against its `truth.json` into
/// `out`, with the thesis's methods' on the same frames.
pub(super) fn analyse_case(
    cfg: &Config,
    session: &Path,
    out: &mut CaseResult,
) -> Result<(), String> {
    let truth: Value = std::fs::read_to_string(session.join("truth.json"))
        .map_err(|e| e.to_string())
        .and_then(|t| serde_json::from_str(&t).map_err(|e| e.to_string()))?;
    out.true_psi1 = truth["psi1"].as_f64().unwrap_or(f64::NAN);
    out.true_branch = truth["branch"].as_str().unwrap_or("").into();
    if let Some(f) = truth["look"]["family"].as_str() {
        out.look_family = f.into();
    }
    // A silhouette (lit from behind only) shows no dot, and a rig without markers has none.
    let silhouette = truth["look"]["backlit"].as_bool() == Some(true)
        && truth["look"]["backlit_front_light"].as_bool() != Some(true);
    out.no_dots_seen = silhouette || cfg.sim.markers_per_sphere == 0;
    // Baseline for the analysis time: reading the same frames from disk.
    let mut reader = SessionReader::open(session).map_err(|e| e.to_string())?;
    let t0 = Instant::now();
    let mut buf = Vec::new();
    for i in 0..reader.frames.len() {
        reader.read_frame(i, &mut buf).map_err(|e| e.to_string())?;
    }
    out.read_time = t0.elapsed();
    out.frames_analysed = reader.frames.len();
    let mut src = SessionSource::new(reader);
    let t0 = Instant::now();
    let result = analysis::analyze_detailed(&mut src, cfg, &mut |_, _| {});
    out.analysis_time = t0.elapsed();
    let (report, details) = result.map_err(|e| e.to_string())?;

    let scalar = |est: &Option<Scalar>, key: &str| {
        est.as_ref()
            .zip(truth[key].as_f64())
            .map(|(e, t)| (e.value - t, e.uncertainty))
    };
    out.e = scalar(&report.e, "e");
    out.psi1 = scalar(&report.psi1, "psi1");
    out.psi2 = scalar(&report.psi2, "psi2");
    out.beta = scalar(&report.beta, "beta");
    for (name, est) in [
        ("e", out.e),
        ("ψ1", out.psi1),
        ("ψ2", out.psi2),
        ("β", out.beta),
    ] {
        if let Some((err, sigma)) = est {
            out.z.push(err / sigma);
            if (err / sigma).abs() > 5.0 {
                out.beyond_5_sigma.push(format!(
                    "{name}: error {err:+.4} ± {sigma:.4} ({:+.1}σ)",
                    err / sigma
                ));
            }
        }
    }
    let mut true_spins = [V3::zeros(); 4];
    for (k, (s, ph)) in PHASES.iter().enumerate() {
        let sp = if *s == "a" {
            &report.spheres.a
        } else {
            &report.spheres.b
        };
        let (vel, spin) = if *ph == "pre" {
            (&sp.velocity_pre_mm_s, &sp.spin_pre_rad_s)
        } else {
            (&sp.velocity_post_mm_s, &sp.spin_post_rad_s)
        };
        let tv = v3(&truth["spheres"][s][ph]["velocity_mm_s"]);
        let tw = v3(&truth["spheres"][s][ph]["spin_rad_s"]);
        true_spins[k] = tw;
        // Axes the analysis did not measure (a 2-D result) are not errors of the measurement.
        let measured = V3::from(vel.uncertainty.map(|u| if u > 0.0 { 1.0 } else { 0.0 }));
        let ev = V3::from(vel.value);
        out.vel_rel
            .push((ev - tv).component_mul(&measured).norm() / tv.component_mul(&measured).norm());
        let mut note = |what: &str, i: usize, err: f64, sigma: f64, unit: &str| {
            if (err / sigma).abs() > 5.0 {
                out.beyond_5_sigma.push(format!(
                    "{s} {ph} {what} {}: error {err:+.3} ± {sigma:.3} {unit} ({:+.1}σ)",
                    ["x", "y", "z"][i],
                    err / sigma
                ));
            }
        };
        let mut z_velocity = Vec::new();
        for i in (0..3).filter(|&i| vel.uncertainty[i] > 0.0) {
            note("velocity", i, ev[i] - tv[i], vel.uncertainty[i], "mm/s");
            z_velocity.push((ev[i] - tv[i]) / vel.uncertainty[i]);
        }
        let mut z_spin = Vec::new();
        if let Some(w) = spin {
            for i in 0..3 {
                note("spin", i, w.value[i] - tw[i], w.uncertainty[i], "rad/s");
                z_spin.push((w.value[i] - tw[i]) / w.uncertainty[i]);
            }
            out.spin_err.push((V3::from(w.value) - tw).norm());
        }
        out.z.extend(z_velocity.iter().chain(&z_spin));
        out.z_velocity.extend(z_velocity);
        out.z_spin.extend(z_spin);
    }
    // Whether, by the truth, both spheres are out of their tubes and their discs lie wholly
    // inside view `view`'s region with a gap of at least a pixel between them: where the goals ask for both spheres measured, and for
    // the centres' accuracy.
    // Before the spheres leave their tubes they are not in free flight (and a rig's tubes
    // hide them): those frames do not count.
    let exit_s = truth["tube_exit_time_s"]
        .as_f64()
        .unwrap_or(f64::NEG_INFINITY);
    let clear = |tf: &Value, view: &analysis::geometry::View| -> bool {
        if tf["time_s"].as_f64().is_none_or(|t| t < exit_s) {
            return false;
        }
        let disc = |name: &str| {
            let t = &tf["spheres"][name]["views"][view.kind.name()];
            Some((
                t["centre_px"][0].as_f64()?,
                t["centre_px"][1].as_f64()?,
                t["diameter_px"].as_f64()? / 2.0,
            ))
        };
        let (Some(a), Some(b)) = (disc("a"), disc("b")) else {
            return false;
        };
        let [rx, ry, rw, rh] = view.region.map(|x| x as f64);
        let inside = |d: (f64, f64, f64)| {
            d.0 - d.2 > rx + 1.0
                && d.0 + d.2 < rx + rw - 2.0
                && d.1 - d.2 > ry + 1.0
                && d.1 + d.2 < ry + rh - 2.0
        };
        inside(a) && inside(b) && (a.0 - b.0).hypot(a.1 - b.1) > a.2 + b.2 + 1.0
    };
    // Centres against the truth, per frame and view.
    let frames: HashMap<u64, &Value> = truth["frames"]
        .as_array()
        .map(|a| {
            a.iter()
                .map(|f| (f["frame_id"].as_u64().unwrap_or(u64::MAX), f))
                .collect()
        })
        .unwrap_or_default();
    // Each centre's σ as the report gives it (`flight_misfit`: the observations' own, checked
    // against the flights), by frame, sphere and view.
    let reported_sigma = |frame_id: u64, s: usize, kind: ViewKind| -> Option<[f64; 2]> {
        let t = report.tracks.iter().find(|t| t.frame_id == frame_id)?;
        let sphere = if s == 0 { t.a.as_ref() } else { t.b.as_ref() }?;
        let view = match kind {
            ViewKind::Direct => sphere.direct.as_ref(),
            ViewKind::Mirror => sphere.mirror.as_ref(),
        }?;
        Some(view.uncertainty_px)
    };
    for f in &details.obs {
        let Some(tf) = frames.get(&f.frame_id) else {
            continue;
        };
        for (s, name) in [(0, "a"), (1, "b")] {
            for (vi, view) in details.views.iter().enumerate() {
                let Some(m) = &f.spheres[s][vi] else { continue };
                let tc = &tf["spheres"][name]["views"][view.kind.name()]["centre_px"];
                let (Some(tu), Some(tv)) = (tc[0].as_f64(), tc[1].as_f64()) else {
                    continue;
                };
                out.centre_err_px
                    .push((m.centre_px[0] - tu).hypot(m.centre_px[1] - tv));
                let sigma_px = reported_sigma(f.frame_id, s, view.kind).unwrap_or(m.sigma_px);
                for (err, sigma) in [m.centre_px[0] - tu, m.centre_px[1] - tv]
                    .into_iter()
                    .zip(sigma_px)
                {
                    if sigma > 0.0 && sigma.is_finite() {
                        out.centre_z.push(err / sigma);
                    }
                }
                if clear(tf, view) {
                    out.centre_err_uv
                        .push([m.centre_px[0] - tu, m.centre_px[1] - tv]);
                }
                let sphere = &tf["spheres"][name];
                let c = v3(&sphere["centre_mm"]);
                let r_px = m.diameter_px / 2.0;
                let truths: Vec<[f64; 2]> = sphere["markers_mm"]
                    .as_array()
                    .map(|a| a.iter().map(v3).collect::<Vec<V3>>())
                    .unwrap_or_default()
                    .iter()
                    .map(|mk| mk - c)
                    .filter(|d| d.dot(&view.facing) > 0.0)
                    .map(|d| {
                        [
                            view.px_per_mm * view.u_axis.dot(&d),
                            view.px_per_mm * view.v_axis.dot(&d),
                        ]
                    })
                    .collect();
                for mk in &m.markers {
                    let rel = [
                        mk.centre_px[0] - m.centre_px[0],
                        mk.centre_px[1] - m.centre_px[1],
                    ];
                    let nearest = truths.iter().min_by(|a, b| {
                        let da = (a[0] - rel[0]).hypot(a[1] - rel[1]);
                        let db = (b[0] - rel[0]).hypot(b[1] - rel[1]);
                        da.total_cmp(&db)
                    });
                    let Some(t) = nearest else { continue };
                    let err = [rel[0] - t[0], rel[1] - t[1]];
                    let rho = t[0].hypot(t[1]);
                    if err[0].hypot(err[1]) > 1.0 || rho <= 0.0 {
                        continue; // not this marker: a neighbour was nearer
                    }
                    let radial = (err[0] * t[0] + err[1] * t[1]) / rho;
                    out.marker_err_px
                        .push((rho / r_px, err[0].hypot(err[1]), radial));
                }
                let r = m.blob_centroid_px.map(f64::round);
                out.thesis_centre_err_px.push((r[0] - tu).hypot(r[1] - tv));
            }
        }
    }
    // Detection rate where both are wholly in a view and apart.
    let measured: HashMap<u64, &analysis::tracking::FrameObs> =
        details.obs.iter().map(|f| (f.frame_id, f)).collect();
    for (id, tf) in &frames {
        for (vi, view) in details.views.iter().enumerate() {
            if !clear(tf, view) {
                continue;
            }
            out.apart_frames += 1;
            if measured
                .get(id)
                .is_some_and(|f| f.spheres[0][vi].is_some() && f.spheres[1][vi].is_some())
            {
                out.apart_measured += 1;
            }
        }
    }
    // Rotation per frame pair (≥ 4 markers) against the true constant spin of the phase.
    let rounded = thesis::rounded(&details.obs, &details.views, cfg);
    for (k, true_spin) in true_spins.iter().enumerate() {
        for p in details.spins[k].pairs.iter().filter(|p| p.markers >= 4) {
            out.rot_err_deg
                .push(angle_err(p.rotvec, true_spin * p.dt_s));
        }
        let (pairs, _) = spin::pairs(
            &rounded,
            &details.phases[k],
            k % 2,
            RotationMethod::Thesis,
            V3::zeros(),
            1.3,
        );
        for p in pairs.iter().filter(|p| p.markers >= 4) {
            out.thesis_rot_err_deg
                .push(angle_err(p.rotvec, true_spin * p.dt_s));
        }
    }
    let th = thesis::estimate(&details.obs, &details.views, cfg, details.impact_time_s);
    if let Some(c) = th.collision {
        let diff = |est: Option<f64>, key: &str| est.zip(truth[key].as_f64()).map(|(a, b)| a - b);
        out.thesis_e = diff(Some(c.e), "e");
        out.thesis_psi1 = diff(c.psi1, "psi1");
        out.thesis_psi2 = diff(c.psi2, "psi2");
        out.thesis_beta = diff(c.beta, "beta");
    }
    for (k, (s, ph)) in PHASES.iter().enumerate() {
        if let Some(v) = th.velocities {
            let tv = v3(&truth["spheres"][s][ph]["velocity_mm_s"]);
            out.thesis_vel_rel.push((v[k] - tv).norm() / tv.norm());
        }
        if let Some(w) = th.spins {
            out.thesis_spin_err.push((w[k] - true_spins[k]).norm());
        }
    }
    Ok(())
}
