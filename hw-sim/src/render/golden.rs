//! The renderer checked against what it drew before (a frame's hash, bit for bit: old seeds must
//! replay the same frames) and against its own lens model.

use super::*;
use crate::config::{LabConfig, Scene, SphereSpec, ViewSpec};
use crate::physics::Body;

/// FNV-1a of a frame's bytes.
fn fnv(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
        (h ^ b as u64).wrapping_mul(0x0100_0000_01b3)
    })
}

fn default_frame_hash() -> u64 {
    frame_hash_with(None)
}

fn frame_hash_with(look: Option<crate::look::Look>) -> u64 {
    let view = ViewSpec {
        name: "direct".into(),
        region: [0, 0, 96, 64],
        px_per_mm: 2.1576,
        origin_px: [47.3, 31.6],
        u_axis: [1.0, 0.0, 0.0],
        v_axis: [0.0, -1.0, 0.0],
        facing: [0.0, 0.0, 1.0],
        distance_mm: None,
        lens: None,
    };
    let scene = Scene {
        width: 96,
        height: 64,
        frame_rate_hz: 1000.0,
        bit_depth: 8,
        views: vec![view],
        spheres: [
            SphereSpec {
                diameter_mm: 6.35,
                mass_g: 0.3,
            },
            SphereSpec {
                diameter_mm: 6.35,
                mass_g: 0.3,
            },
        ],
    };
    let body = |x: f64, vx: f64| Body {
        pos_mm: V3::new(x, 0.3, 0.0),
        vel_mm_s: V3::new(vx, -200.0, 0.0),
        spin_rad_s: V3::zeros(),
        orientation: nalgebra::UnitQuaternion::identity(),
        radius_mm: 3.175,
        mass_g: 0.3,
    };
    let state = |t: f64| {
        let (a, b) = (body(-6.0 + 900.0 * t, 900.0), body(7.0 - 800.0 * t, -800.0));
        let dots = |c: V3| vec![c + V3::new(0.0, 0.0, 3.175), c + V3::new(2.245, 0.0, 2.245)];
        let (da, db) = (dots(a.pos_mm), dots(b.pos_mm));
        ([a, b], [da, db])
    };
    let cfg = LabConfig {
        look,
        ..LabConfig::default()
    };
    let mut r = Renderer::new(scene, cfg, 42);
    let mut out = Vec::new();
    r.render(0.001, &state, &mut out);
    fnv(&out)
}

/// Without a look the render is the one sessions were recorded with before looks existed
/// (the hash was taken from a frame rendered by that code, commit 17ddbb4): replaying an
/// old seed must give the same frames, bit for bit.
#[test]
fn without_a_look_the_frames_are_those_rendered_before_looks_existed() {
    assert_eq!(default_frame_hash(), 0xa816_a695_48c2_f482);
}

/// A lens's radial distortion moves a sphere's image where `Lens::distort` says: a still
/// sphere near a corner, rendered without noise through an ideal lens and through a
/// barrel one, its image's centroid against the distortion of its centre's projection.
#[test]
fn a_distorting_lens_moves_the_sphere_as_its_model_says() {
    let centroid = |k1: f64| -> ((f64, f64), (f64, f64)) {
        let (w, h) = (240u32, 192u32);
        let lens = (k1 != 0.0).then_some(crate::config::Lens {
            k1,
            centre_px: [119.5, 95.5],
            radius_px: 0.5 * 240f64.hypot(192.0),
        });
        let view = ViewSpec {
            name: "direct".into(),
            region: [0, 0, w, h],
            px_per_mm: 2.1576,
            origin_px: [119.5, 95.5],
            u_axis: [1.0, 0.0, 0.0],
            v_axis: [0.0, -1.0, 0.0],
            facing: [0.0, 0.0, 1.0],
            distance_mm: None,
            lens,
        };
        let sphere = SphereSpec {
            diameter_mm: 6.35,
            mass_g: 0.3,
        };
        let scene = Scene {
            width: w,
            height: h,
            frame_rate_hz: 1000.0,
            bit_depth: 8,
            views: vec![view.clone()],
            spheres: [sphere.clone(), sphere],
        };
        let body = |p: V3| Body {
            pos_mm: p,
            vel_mm_s: V3::zeros(),
            spin_rad_s: V3::zeros(),
            orientation: nalgebra::UnitQuaternion::identity(),
            radius_mm: 3.175,
            mass_g: 0.3,
        };
        // Sphere a 40 mm left of and 30 mm above the centre (about 108 px out, 0.70 of
        // the half-diagonal); b far out of the frame.
        let a = V3::new(-40.0, 30.0, 0.0);
        let state = move |_t: f64| ([body(a), body(V3::new(500.0, 0.0, 0.0))], [vec![], vec![]]);
        let cfg = LabConfig {
            noise_sigma_grey: 0.0,
            shot_noise_e_per_grey: 0.0,
            ..LabConfig::default()
        };
        let bg = cfg.background_grey;
        let mut r = Renderer::new(scene, cfg, 7);
        let mut out = Vec::new();
        r.render(0.001, &state, &mut out);
        let (mut sw, mut su, mut sv) = (0.0, 0.0, 0.0);
        for (i, &g) in out.iter().enumerate() {
            let d = (g as f64 - bg).max(0.0);
            sw += d;
            su += d * (i % w as usize) as f64;
            sv += d * (i / w as usize) as f64;
        }
        ((su / sw, sv / sw), project(&view, &a))
    };
    let (ideal, at_ideal) = centroid(0.0);
    let (barrel, at_barrel) = centroid(-0.05);
    // Without a lens the centroid is the projected centre.
    assert!(
        (ideal.0 - at_ideal.0).hypot(ideal.1 - at_ideal.1) < 0.02,
        "{ideal:?} {at_ideal:?}"
    );
    // The barrel lens pulls the sphere 0.05·0.70²·108 ≈ 2.6 px towards the centre, and
    // its image is where the lens model puts its centre's projection.
    let moved = (barrel.0 - ideal.0).hypot(barrel.1 - ideal.1);
    assert!(moved > 2.0, "moved {moved} px");
    assert!(
        barrel.0 > ideal.0 && barrel.1 > ideal.1,
        "towards the centre: {barrel:?} {ideal:?}"
    );
    assert!(
        (barrel.0 - at_barrel.0).hypot(barrel.1 - at_barrel.1) < 0.05,
        "{barrel:?} against {at_barrel:?}"
    );
}

/// A drawn look changes the frame (so the hash above would notice a look leaking into
/// the default path).
#[test]
fn a_look_changes_the_frame() {
    let base = default_frame_hash();
    let (look, _) = crate::look::Look::draw("side_lit", 3).expect("family");
    assert_ne!(frame_hash_with(Some(look)), base);
    assert_eq!(frame_hash_with(None), base);
}
