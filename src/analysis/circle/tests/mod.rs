//! The circle fits on hw-sim's renders and on synthetic discs: edge points, the grey-level model, dots
//! on the rim, the view's border; two discs in `pairs`, one disc under a lab's looks in `lone`.

use super::*;

#[test]
fn taubin_and_geometric_recover_a_partial_arc() {
    // 120° arc, centre (10.3, -4.7), R 7.5: Taubin is unbiased on arcs where Kåsa is not.
    let pts: Vec<[f64; 2]> = (0..40)
        .map(|k| {
            let a = (k as f64 / 39.0) * 2.0944;
            [10.3 + 7.5 * a.cos(), -4.7 + 7.5 * a.sin()]
        })
        .collect();
    let (c, r) = taubin(&pts).unwrap();
    assert!((c[0] - 10.3).abs() < 1e-6 && (c[1] + 4.7).abs() < 1e-6 && (r - 7.5).abs() < 1e-6);
    let f = robust_fit(&pts, 1.0).unwrap();
    assert!((f.centre[0] - 10.3).abs() < 1e-6 && (f.radius - 7.5).abs() < 1e-6);
}

#[test]
fn outliers_are_rejected() {
    let mut pts: Vec<[f64; 2]> = (0..60)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / 60.0;
            [5.0 + 6.0 * a.cos(), 5.0 + 6.0 * a.sin()]
        })
        .collect();
    for p in pts.iter_mut().take(6) {
        p[0] -= 2.0; // a marker at the limb pulls these edge points inward
    }
    let f = robust_fit(&pts, 1.0).unwrap();
    assert!((f.centre[0] - 5.0).abs() < 1e-6, "{:?}", f.centre);
    assert_eq!(f.points_used, 54);
}

use crate::analysis::geometry::{ViewKind, V3};
use crate::analysis::image::SATURATED_GREY;

const SPHERE_RADIUS_MM: f64 = 3.175;

/// One view filling a `width`×`height` frame, u along +x.
pub(super) fn test_view(
    kind: ViewKind,
    width: u32,
    height: u32,
    px_per_mm: f64,
    origin_px: [f64; 2],
    v_axis: &str,
) -> View {
    let g = crate::config::ViewGeometry::shorthand(
        [0, 0, width, height],
        px_per_mm,
        origin_px,
        "+x",
        v_axis,
    );
    View::from_config(kind, &g)
}

/// The lab's direct view (2.1576 px/mm) filling a `width`×`height` frame, the sphere's
/// radius in it, px, and the simulator's scene without dots (noise σ = 2).
pub(super) fn dotless_direct_view(
    width: u32,
    height: u32,
    origin_px: [f64; 2],
) -> (View, f64, hw_sim::LabConfig) {
    let view = test_view(ViewKind::Direct, width, height, 2.1576, origin_px, "-y");
    let r_px = SPHERE_RADIUS_MM * view.px_per_mm;
    let cfg = hw_sim::LabConfig {
        markers_per_sphere: 0,
        ..Default::default()
    };
    (view, r_px, cfg)
}

/// Two still spheres without dots, rendered by the simulator: the frame and their true
/// centres, px.
pub(super) fn render_pair(
    view: &View,
    width: u32,
    height: u32,
    centres: [V3; 2],
    cfg: &hw_sim::LabConfig,
    seed: u64,
) -> (GreyImage, [[f64; 2]; 2]) {
    render_with_dots(view, width, height, centres, [vec![], vec![]], cfg, seed)
}

/// As `render_pair`, with dots at the given world points (on each sphere's surface).
pub(super) fn render_with_dots(
    view: &View,
    width: u32,
    height: u32,
    centres: [V3; 2],
    dots: [Vec<V3>; 2],
    cfg: &hw_sim::LabConfig,
    seed: u64,
) -> (GreyImage, [[f64; 2]; 2]) {
    let body = |pos: V3| hw_sim::physics::Body {
        pos_mm: pos,
        vel_mm_s: V3::zeros(),
        spin_rad_s: V3::zeros(),
        orientation: nalgebra::UnitQuaternion::identity(),
        radius_mm: SPHERE_RADIUS_MM,
        mass_g: 1.0,
    };
    let state = move |_t: f64| ([body(centres[0]), body(centres[1])], dots.clone());
    let scene = crate::analysis::geometry::one_view_scene(view, width, height);
    let mut r = hw_sim::render::Renderer::new(scene, cfg.clone(), seed);
    let mut raw = Vec::new();
    r.render(0.0, &state, &mut raw);
    let mut img = GreyImage::new();
    img.load(&raw, width as usize, height as usize, 1);
    (img, centres.map(|c| view.project(&c)))
}

/// Renders of two spheres with noise σ = 2, alone (12 px apart at the edge) and touching
/// (0.5 px apart): the grey-level fit is unbiased on the whole ring and on the ring cut by
/// the neighbour, and scatters clearly less than the edge points do. The spread includes
/// the sub-pixel phase, which the renders vary.
#[test]
fn profile_fit_beats_edge_points_without_bias() {
    let (view, r_px, noisy) = dotless_direct_view(96, 64, [47.3, 31.6]);
    // Without noise the residuals are the model's own misfit: the fit must still settle.
    let clean = hw_sim::LabConfig {
        noise_sigma_grey: 0.0,
        ..noisy.clone()
    };
    for (gap_px, cfg) in [(12.0, &noisy), (0.5, &noisy), (12.0, &clean)] {
        let (mut edge, mut model) = (Vec::new(), Vec::new());
        for k in 0..30 {
            let sep = (2.0 * r_px + gap_px) / view.px_per_mm;
            let angle = 0.4 + 0.07 * k as f64;
            let shift = V3::new(
                (k as f64 * 0.37) % 1.0 / view.px_per_mm,
                (k as f64 * 0.61) % 1.0 / view.px_per_mm,
                0.0,
            );
            let half = V3::new(angle.cos(), angle.sin(), 0.0) * (sep / 2.0);
            let (img, truth) =
                render_pair(&view, 96, 64, [shift - half, shift + half], cfg, 11 + k);
            let other = Some((truth[1], r_px));
            let rough = [truth[0][0] + 0.3, truth[0][1] - 0.2];
            let e = fit_edges(&img, &view, rough, r_px - 0.15, cfg.background_grey, other)
                .expect("edge fit")
                .0;
            let m = profile_fit(&img, &view, &e, cfg.background_grey, other, &[])
                .expect("the profile fit settles (a ring the neighbour cuts by a third at most)");
            edge.push([e.centre[0] - truth[0][0], e.centre[1] - truth[0][1]]);
            model.push([m.centre[0] - truth[0][0], m.centre[1] - truth[0][1]]);
        }
        let stats = |v: &[[f64; 2]]| {
            let n = v.len() as f64;
            let mean = [0, 1].map(|i| v.iter().map(|p| p[i]).sum::<f64>() / n);
            let rms = (v
                .iter()
                .map(|p| (p[0] - mean[0]).powi(2) + (p[1] - mean[1]).powi(2))
                .sum::<f64>()
                / n)
                .sqrt();
            (mean, rms)
        };
        let ((me, se), (mm, sm)) = (stats(&edge), stats(&model));
        assert!(
            mm[0].abs() < 0.006 && mm[1].abs() < 0.006,
            "gap {gap_px} px: profile fit biased by {mm:?} px (edge points {me:?})"
        );
        assert!(
            sm < 0.8 * se,
            "gap {gap_px} px: profile fit scatters {sm:.4} px, edge points {se:.4} px"
        );
    }
}

/// `markers` directions spread over the whole sphere (Fibonacci points; some on the rim),
/// turned by the rotation vector `turn`, rad.
fn spread_dots(markers: usize, turn: V3) -> Vec<V3> {
    let turn = nalgebra::UnitQuaternion::from_scaled_axis(turn);
    (0..markers)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / markers as f64;
            let a = i as f64 * 2.399963;
            let r = (1.0 - z * z).sqrt();
            turn * V3::new(r * a.cos(), r * a.sin(), z)
        })
        .collect()
}

/// One of `lone_sphere_renders`: the frame, its view, the true centre, the edge-point fit a
/// grey-level fit starts from, and the true dots near the rim as masks.
pub(super) struct LoneRender {
    pub(super) img: GreyImage,
    pub(super) view: View,
    pub(super) truth: [f64; 2],
    pub(super) edge: CircleFit,
    pub(super) masks: Vec<DotMask>,
}

/// Renders of one sphere (as `cfg` draws it) at 40 sub-pixel phases, with `markers` dots
/// turned at random.
pub(super) fn lone_sphere_renders(cfg: &hw_sim::LabConfig, markers: usize) -> Vec<LoneRender> {
    let view = test_view(ViewKind::Direct, 64, 48, 2.1576, [31.3, 23.6], "-y");
    let r_px = SPHERE_RADIUS_MM * view.px_per_mm;
    let mut out = Vec::new();
    for k in 0..40 {
        let kf = k as f64;
        let shift = V3::new(
            (kf * 0.37) % 1.0 / view.px_per_mm,
            (kf * 0.618) % 1.0 / view.px_per_mm,
            0.0,
        );
        let dirs = spread_dots(markers, V3::new(0.3 * kf, 0.17 * kf, 0.05));
        let on_sphere: Vec<V3> = dirs.iter().map(|d| shift + d * SPHERE_RADIUS_MM).collect();
        let far = V3::new(40.0, 40.0, 0.0);
        let (img, _) = render_with_dots(
            &view,
            64,
            48,
            [shift, far],
            [on_sphere.clone(), Vec::new()],
            cfg,
            31 + k,
        );
        let t = view.project(&shift);
        let dot_r_mm = cfg.marker_diameter_mm / 2.0;
        // A dot is wholly behind the limb once its centre is its own angular radius past it.
        let behind_limb = -(dot_r_mm / SPHERE_RADIUS_MM).sin();
        let masks: Vec<DotMask> = dirs
            .iter()
            .zip(&on_sphere)
            .filter(|(d, _)| d.dot(&view.facing) > behind_limb)
            .map(|(_, p)| DotMask::around(view.project(p), dot_r_mm * view.px_per_mm))
            .collect();
        let rough = [t[0] + 0.3, t[1] - 0.2];
        let edge = fit_edges(&img, &view, rough, r_px - 0.15, cfg.background_grey, None)
            .expect("edge fit")
            .0;
        out.push(LoneRender {
            img,
            view: view.clone(),
            truth: [t[0], t[1]],
            edge,
            masks,
        });
    }
    out
}

/// The grey-level fit's centre error on each of `lone_sphere_renders` where it settles, px,
/// without and with the true dots near the rim masked.
pub(super) fn lone_sphere_errors(
    cfg: &hw_sim::LabConfig,
    markers: usize,
) -> Vec<([f64; 2], [f64; 2])> {
    let mut out = Vec::new();
    for r in lone_sphere_renders(cfg, markers) {
        let (Some(plain), Some(masked)) = (
            profile_fit(&r.img, &r.view, &r.edge, cfg.background_grey, None, &[]),
            profile_fit(
                &r.img,
                &r.view,
                &r.edge,
                cfg.background_grey,
                None,
                &r.masks,
            ),
        ) else {
            continue;
        };
        let t = r.truth;
        out.push((
            [plain.centre[0] - t[0], plain.centre[1] - t[1]],
            [masked.centre[0] - t[0], masked.centre[1] - t[1]],
        ));
    }
    out
}

fn rms(v: &[[f64; 2]]) -> f64 {
    (v.iter().map(|p| p[0] * p[0] + p[1] * p[1]).sum::<f64>() / (2 * v.len()) as f64).sqrt()
}

/// The simulator samples the pixels a limb crosses 16×16: on a regular 4×4 grid the limb was
/// a staircase of quarter pixels, and the grey-level fit's centre of a noise-free disc
/// scattered 0.0055 px per axis with the sub-pixel phase (0.0029 px at 16×16). That floor
/// was the simulator's, not the measurement's: a camera integrates over the whole pixel.
#[test]
fn the_simulated_limb_is_not_a_staircase() {
    let clean = hw_sim::LabConfig {
        markers_per_sphere: 0,
        noise_sigma_grey: 0.0,
        ..Default::default()
    };
    let coarse = hw_sim::LabConfig {
        edge_supersample: clean.supersample,
        ..clean.clone()
    };
    let fine: Vec<[f64; 2]> = lone_sphere_errors(&clean, 0).iter().map(|e| e.0).collect();
    let grid: Vec<[f64; 2]> = lone_sphere_errors(&coarse, 0).iter().map(|e| e.0).collect();
    assert!(fine.len() >= 38 && grid.len() >= 38);
    let (f, g) = (rms(&fine), rms(&grid));
    assert!(f < 0.0040, "16×16 limb: {f:.4} px per axis");
    assert!(
        g > 1.4 * f,
        "4×4 limb {g:.4} px vs 16×16 {f:.4} px: no staircase to remove?"
    );
}

/// Dots on the rim, masked where they are known to be (`DotMask`), no longer move the
/// grey-level centre: with 8 dots on a noise-free sphere (hw-sim's default look) the scatter is
/// under 0.0025 px. Masks take parts of the ring away at random, and a model of the pixel's
/// centre only (no area) left 0.0046 px: its misfit, which depends on the edge's direction
/// across the pixel grid, no longer cancelled round the ring. Unmasked, the fit finds the dots
/// itself: with plain least squares in its first round the dots steered that round and the
/// scatter was 0.0084 px; with Cauchy's loss there, 0.0031 px (bound 0.004).
#[test]
fn masked_rim_dots_do_not_move_the_centre() {
    let cfg = hw_sim::LabConfig {
        noise_sigma_grey: 0.0,
        ..Default::default()
    };
    let errs = lone_sphere_errors(&cfg, 8);
    assert!(errs.len() >= 30, "only {} of 40 fits settled", errs.len());
    let plain: Vec<[f64; 2]> = errs.iter().map(|e| e.0).collect();
    let masked: Vec<[f64; 2]> = errs.iter().map(|e| e.1).collect();
    let (p, m) = (rms(&plain), rms(&masked));
    assert!(m <= p, "masked {m:.4} px, unmasked {p:.4} px per axis");
    assert!(m < 0.0025, "masked {m:.4} px per axis");
    assert!(p < 0.004, "unmasked {p:.4} px per axis");
}

/// A sphere entering the view: its disc cut by the view's border 4 px from its centre (a
/// quarter of the ring beyond), noise σ = 2. These are the first and last frames of a
/// flight, where a trajectory's slope is decided; the edge points there scattered
/// 0.01–0.07 px in recordings. The grey levels inside the border fit it like a whole disc.
#[test]
fn a_disc_cut_by_the_view_border_is_fitted_on_its_grey_levels() {
    // The view is the frame's top 32 rows; the 16 below it are another view's.
    let (view, r_px, cfg) = dotless_direct_view(64, 32, [31.3, 12.0]);
    let (mut edge, mut model) = (Vec::new(), Vec::new());
    for k in 0..40 {
        let kf = k as f64;
        // Centre at v ≈ 27.5 ± 0.5: the border (v = 31.5) 3.5–4.5 px below it.
        let centre = V3::new(
            (kf * 0.37) % 1.0 / view.px_per_mm,
            -(15.0 + (kf * 0.618) % 1.0) / view.px_per_mm,
            0.0,
        );
        let far = V3::new(40.0, 40.0, 0.0);
        let (img, truth) = render_pair(&view, 64, 48, [centre, far], &cfg, 51 + k);
        let t = truth[0];
        let e = fit_edges(
            &img,
            &view,
            [t[0] + 0.3, t[1] - 0.2],
            r_px - 0.15,
            30.0,
            None,
        )
        .expect("edge fit on the visible arc")
        .0;
        edge.push([e.centre[0] - t[0], e.centre[1] - t[1]]);
        if let Some(m) = profile_fit(&img, &view, &e, 30.0, None, &[]) {
            model.push([m.centre[0] - t[0], m.centre[1] - t[1]]);
        }
    }
    assert!(
        model.len() >= 36,
        "the grey-level fit settled on {} of 40",
        model.len()
    );
    let n = model.len() as f64;
    let bias = [0, 1].map(|i| model.iter().map(|p| p[i]).sum::<f64>() / n);
    assert!(
        bias[0].abs() < 0.006 && bias[1].abs() < 0.006,
        "grey-level fit of the cut disc biased by {bias:?} px"
    );
    let (se, sm) = (rms(&edge), rms(&model));
    assert!(
        sm < 0.8 * se,
        "cut disc: grey levels {sm:.4} px, edge points {se:.4} px"
    );
}

/// The k-th of a set of sub-pixel phases spread over a pixel (golden-ratio steps on each axis),
/// as a world offset in `view`, mm: so that pixel locking averages out over a set of renders.
fn sub_pixel_phase(view: &View, k: u64) -> V3 {
    let kf = k as f64;
    V3::new(
        (kf * 0.618).fract() / view.px_per_mm,
        (kf * 0.382).fract() / view.px_per_mm,
        0.0,
    )
}

/// A lone sphere under `look` (its first view's), measured by `refine` at 48 sub-pixel phases
/// spread over a pixel (so that pixel locking averages out), noise σ = 2, the k-th rendered
/// with seed `seed + k`: each phase's centre error and the σ the fit claims, px.
fn lone_sphere_fits(look: hw_sim::Look, seed: u64) -> Vec<([f64; 2], [f64; 2])> {
    lone_sphere_fits_encoded(look, seed, 1.0, false)
}

/// As `lone_sphere_fits`, the camera encoding its levels with `gamma` (`hw_sim::LabConfig::
/// gamma`), each render decoded to linear light before it is measured where `decode`.
fn lone_sphere_fits_encoded(
    look: hw_sim::Look,
    seed: u64,
    gamma: f64,
    decode: bool,
) -> Vec<([f64; 2], [f64; 2])> {
    let (view, r_px, mut cfg) = dotless_direct_view(64, 64, [31.3, 31.6]);
    cfg.look = Some(look);
    cfg.gamma = gamma;
    let far = V3::new(100.0, 100.0, 0.0);
    (0..48u64)
        .map(|k| {
            let c = sub_pixel_phase(&view, k);
            let (mut img, truth) = render_pair(&view, 64, 64, [c, far], &cfg, seed + k);
            if decode {
                crate::analysis::linear::decode(&mut img, gamma);
            }
            // Pixels at the camera's ceiling marked as the normalisation marks them.
            img.unmeasured = img.data.iter().map(|&g| g >= SATURATED_GREY).collect();
            let rough = [truth[0][0] + 0.4, truth[0][1] - 0.3];
            let f = refine(&img, &view, rough, r_px, cfg.background_grey, None, &[])
                .expect("a lone sphere is measured");
            (
                [f.centre[0] - truth[0][0], f.centre[1] - truth[0][1]],
                f.centre_sigma,
            )
        })
        .collect()
}

/// hw-sim's lab defocused by 1.1 px, lit from 30° to one side (ambient 0.3), its dots painted
/// at a fifth of the shading (multiplicative) and blurred with it.
pub(super) fn defocused_with_dark_dots() -> hw_sim::LabConfig {
    hw_sim::LabConfig {
        look: Some(hw_sim::Look {
            defocus_sigma_px: 1.1,
            marker_paint: hw_sim::look::MarkerPaint::Multiplicative,
            marker_factor: 0.2,
            ..lit_from(30.0, 60.0, 0.3)
        }),
        ..Default::default()
    }
}

/// A look lit from `off_axis_deg` at `azimuth_deg` in the image, otherwise hw-sim's.
fn lit_from(off_axis_deg: f64, azimuth_deg: f64, ambient: f64) -> hw_sim::Look {
    hw_sim::Look {
        views: vec![hw_sim::ViewLook {
            light_off_axis_deg: off_axis_deg,
            light_azimuth_deg: azimuth_deg,
            ..Default::default()
        }],
        ambient,
        ..Default::default()
    }
}

/// `bench analysis` prints the grey-level model's evaluations per frame as the measure of the
/// fits' work that does not scatter with the machine's load: a fit counts every pass over its
/// ring (at least three rounds, each over at least half the ring's pixels), and the same fit
/// again counts exactly the same.
#[test]
fn the_fits_work_is_counted_and_the_same_each_time() {
    let (view, r_px, cfg) = dotless_direct_view(64, 64, [31.3, 31.6]);
    let far = V3::new(40.0, 40.0, 0.0);
    let (img, truth) = render_pair(&view, 64, 64, [V3::zeros(), far], &cfg, 7);
    let t = truth[0];
    let e = fit_edges(&img, &view, [t[0] + 0.3, t[1] - 0.2], r_px, 30.0, None)
        .expect("edge fit")
        .0;
    let ring_px = (2.0 * std::f64::consts::PI * r_px * 2.0 * PROFILE_BAND_PX) as u64;
    crate::analysis::stages::take_model_samples();
    let counts: Vec<u64> = (0..2)
        .map(|_| {
            profile_fit(&img, &view, &e, 30.0, None, &[]).expect("the disc is fitted");
            crate::analysis::stages::take_model_samples()
        })
        .collect();
    assert!(
        counts[0] >= 3 * ring_px / 2,
        "{} evaluations for a ring of about {ring_px} pixels",
        counts[0]
    );
    assert_eq!(counts[0], counts[1], "the same fit counted differently");
}

mod lone;
mod pairs;
