use super::*;
use crate::calibrate::MirrorFit;
use crate::config::Config;

fn fitted(value: f64, sigma: f64) -> Fitted {
    Fitted { value, sigma }
}

/// Scales that agree are weighed by their σ, the result knowing more than either where
/// they lie within 1σ of each other, and its σ widened by their distance in σ beyond; a
/// diameter's scale beyond 3σ of the flights' is left out, the distance said and taken
/// into the σ.
#[test]
fn the_flights_and_the_diameters_scales_are_weighed_where_they_agree() {
    let (wf, wd) = (0.0178f64.powi(-2), 0.0095f64.powi(-2));
    let weighed = (wf + wd).recip().sqrt();
    let (both, note) = combine_scales(fitted(2.3275, 0.0178), fitted(2.3146, 0.0095));
    assert_eq!(note, None);
    assert!((both.value - (wf * 2.3275 + wd * 2.3146) / (wf + wd)).abs() < 1e-12);
    assert!(both.value > 2.3146 && both.value < 2.3275);
    assert_eq!(both.sigma, weighed, "within 1σ of each other");
    // 2.0σ apart: the same weighing, its σ twice as wide.
    let apart = 2.0 * 0.0178f64.hypot(0.0095);
    let (wide, note) = combine_scales(fitted(2.3146 + apart, 0.0178), fitted(2.3146, 0.0095));
    assert_eq!(note, None);
    assert!((wide.sigma - 2.0 * weighed).abs() < 1e-12, "{}", wide.sigma);
    let (alone, note) = combine_scales(fitted(2.1576, 0.002), fitted(2.10, 0.005));
    assert_eq!(alone.value, 2.1576);
    assert!((alone.sigma - 0.002f64.hypot(2.1576 - 2.10)).abs() < 1e-12);
    let z = note.unwrap();
    assert!(
        (z - (2.10 - 2.1576) / 0.002f64.hypot(0.005)).abs() < 1e-9,
        "{z}"
    );
    // Nothing to weigh: the flights' as they are.
    let (kept, note) = combine_scales(fitted(2.0, 0.01), fitted(f64::NAN, f64::NAN));
    assert_eq!((kept.value, note), (2.0, None));
}

/// A lens left out widens each map parameter's σ by how far a lens fitted moves it (here
/// the mirror's roll, 7° against 0.6°), and leaves the values and the 1/distance alone.
#[test]
fn a_lens_left_out_widens_the_maps_by_what_it_would_move() {
    let bundle = |roll_deg: f64, scale: f64| bundle::Bundle {
        direct_scale: fitted(scale, 0.01),
        direct_roll: fitted(0.3, 0.2),
        kappa: [fitted(0.0, 1e-4), fitted(0.001, 2e-4)],
        lens_k1: fitted(0.0, 0.0),
        mirror: Some(MirrorFit {
            scale: fitted(2.1, 0.02),
            scale_from_diameter: fitted(f64::NAN, f64::NAN),
            roll_deg: fitted(roll_deg, 1.0),
            tilt_deg: fitted(-5.0, 0.4),
            yaw_deg: fitted(0.5, 0.3),
            origin_x_px: fitted(120.0, 0.01),
            x_along_v: false,
            x_reversed: false,
            residual_rms_px: 0.04,
            points: 100,
            camera_distance_mm: None,
        }),
        residual_rms_px: [0.04, 0.04],
        mean_depth_mm: [0.0, 0.0],
    };
    let without = bundle(7.0, 2.16);
    let with_lens = bundle(0.6, 2.14);
    let w = widened_by(without, &with_lens);
    let m = w.mirror.as_ref().unwrap();
    assert_eq!(m.roll_deg.value, 7.0);
    assert!(
        (m.roll_deg.sigma - 1.0f64.hypot(6.4)).abs() < 1e-9,
        "{}",
        m.roll_deg.sigma
    );
    assert!((w.direct_scale.sigma - 0.01f64.hypot(0.02)).abs() < 1e-9);
    assert_eq!(
        (m.tilt_deg.sigma, m.yaw_deg.sigma),
        (0.4, 0.3),
        "unmoved: as they were"
    );
    assert_eq!((w.kappa[1].value, w.kappa[1].sigma), (0.001, 2e-4));
}

/// The flights' accelerations scattered twice as widely as their σ say widen every scale
/// from them twice; scattered within their σ, not at all (the ratio is never below 1).
#[test]
fn flights_that_scatter_beyond_their_sigma_widen_it() {
    let mean = [0.0, 21_000.0];
    let at = |du: f64, dv: f64| ([mean[0] + du, mean[1] + dv], 100.0);
    // Each flight 2σ off in u and in v: χ² = 4·(2² + 2²) = 32 over 2·(4 − 1) = 6 dof.
    let wide = [
        at(200.0, 200.0),
        at(-200.0, -200.0),
        at(200.0, -200.0),
        at(-200.0, 200.0),
    ];
    let r = scatter_ratio(&wide, mean);
    assert!((r - (32.0f64 / 6.0).sqrt()).abs() < 1e-12, "{r}");
    let tight = [
        at(10.0, -20.0),
        at(-10.0, 20.0),
        at(5.0, 0.0),
        at(-5.0, 0.0),
    ];
    assert_eq!(scatter_ratio(&tight, mean), 1.0);
    assert_eq!(scatter_ratio(&wide[..1], mean), 1.0);
}

/// What calibrate writes for how well it knows a map is always a value the config accepts:
/// the analysis must not refuse the config calibrate printed.
#[test]
fn how_well_a_map_is_known_is_written_within_the_configs_bounds() {
    let toml = |p: f64, d: f64| {
        format!(
                "[geometry.direct]\nregion = [0, 0, 240, 96]\npx_per_mm = 2.0\norigin_px = [120.0, 48.0]\nu_axis = \"+x\"\nv_axis = \"-y\"\npx_per_mm_uncertainty_percent = {}\nturn_uncertainty_deg = [0.0, 0.0, {}]\n",
                percent_known(p),
                degrees_known(d)
            )
    };
    for (p, d) in [
        (0.21, 0.088),
        (35.0, 12.0),
        (f64::NAN, f64::INFINITY),
        (-0.3, -0.1),
    ] {
        let t = toml(p, d);
        assert!(Config::from_toml_str(&t, "cal.toml").is_ok(), "{t}");
    }
    assert_eq!(percent_known(0.21), 0.21);
    assert_eq!(degrees_known(f64::NAN), 10.0);
}
