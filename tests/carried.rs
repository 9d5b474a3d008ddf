//! The session viewer's carried markers: the fitted spins carry each frame's nearest other
//! frame's markers onto the markers found in it (and a spin of the wrong sign would not).

mod common;

use impactcam::analysis::report::Report;
use impactcam::config::Config;

/// For every frame and view with markers found, the distance from each found marker to the
/// nearest carried one, px.
fn distances(report: &Report, cfg: &Config) -> Vec<f64> {
    let views = impactcam::analysis::geometry::views(cfg);
    let radii = [0, 1].map(|i| cfg.spheres.sphere(i).0 / 2.0);
    let mut out = Vec::new();
    for t in &report.tracks {
        let carried = impactcam::figures::carried::carried(report, &views, radii, t.frame as usize);
        for (s, track) in [&t.a, &t.b].into_iter().enumerate() {
            let Some(track) = track else { continue };
            for vt in [&track.direct, &track.mirror].into_iter().flatten() {
                for m in &vt.markers_px {
                    let nearest = carried[s]
                        .iter()
                        .map(|c| (c[0] - m[0]).hypot(c[1] - m[1]))
                        .fold(f64::INFINITY, f64::min);
                    if nearest.is_finite() {
                        out.push(nearest);
                    }
                }
            }
        }
    }
    out
}

fn median(mut x: Vec<f64>) -> f64 {
    x.sort_by(f64::total_cmp);
    x[x.len() / 2]
}

#[test]
fn the_fitted_spins_carry_markers_onto_the_markers_found() {
    let tmp = tempfile::tempdir().unwrap();
    let out = common::impactcam(tmp.path(), &["run"]);
    assert!(out.status.success(), "{}", common::stderr(&out));
    let session = common::first_session(tmp.path());
    let report: Report =
        serde_json::from_value(common::read_json(&session.join("report.json"))).unwrap();
    assert!(
        report.spheres.a.spin_pre_rad_s.is_some(),
        "the default run measures spin"
    );
    let cfg = Config::load(&session.join("config.toml")).unwrap();
    let d = distances(&report, &cfg);
    assert!(d.len() > 50, "{} markers compared", d.len());
    let m = median(d);
    assert!(
        m < 0.5,
        "median distance from a found marker to a carried one: {m:.3} px"
    );
    // The spins turned the other way carry the markers elsewhere: the check can fail.
    let mut wrong = report.clone();
    for s in [&mut wrong.spheres.a, &mut wrong.spheres.b] {
        for spin in [&mut s.spin_pre_rad_s, &mut s.spin_post_rad_s]
            .into_iter()
            .flatten()
        {
            spin.value = spin.value.map(|w| -w);
        }
    }
    let m_wrong = median(distances(&wrong, &cfg));
    eprintln!("median {m:.3} px; reversed spins {m_wrong:.3} px");
    assert!(
        m_wrong > 3.0 * m && m_wrong > 0.5,
        "reversed spins: {m_wrong:.3} px against {m:.3} px"
    );
}
