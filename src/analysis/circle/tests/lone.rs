//! One disc under the looks a lab shows: lit from the side, gamma-encoded, darker than its ground
//! at the limb, overexposed, defocused, smeared over the exposure.

use super::*;

/// The mean of the errors `lone_sphere_fits` gives, px.
fn mean_error(fits: &[([f64; 2], [f64; 2])]) -> [f64; 2] {
    let n = fits.len() as f64;
    [0, 1].map(|i| fits.iter().map(|(e, _)| e[i]).sum::<f64>() / n)
}

/// A lone sphere lit from 30° to one side (Lambertian, ambient floor 0.4), noise σ = 2: the
/// centre from `refine` is unbiased to 0.01 px along the light and across it. A shading model
/// symmetric round the disc put such centres 0.1–0.4 px towards the lit side.
#[test]
fn a_lone_sphere_lit_from_the_side_is_not_biased() {
    for azimuth_deg in [0.0, 120.0, 250.0] {
        let bias = mean_error(&lone_sphere_fits(lit_from(30.0, azimuth_deg, 0.4), 700));
        assert!(
            bias[0].abs() < 0.01 && bias[1].abs() < 0.01,
            "lit from azimuth {azimuth_deg}°: mean error ({:+.4}, {:+.4}) px",
            bias[0],
            bias[1]
        );
    }
}

/// A camera that encodes its levels with gamma 2.2 (an sRGB-like curve): a lone sphere lit from
/// 30° to one side, measured in the levels as recorded, comes out biased (the curve bends the
/// shading and the edge the model fits: 0.025 px towards the lamp at each of three azimuths);
/// decoded to linear light first (`linear::decode`, which the config's `camera.gamma` has the
/// analysis do) it is unbiased to 0.01 px (at most 0.005 px).
#[test]
fn a_gamma_encoded_sphere_is_measured_in_linear_light() {
    let mut worst_encoded: f64 = 0.0;
    for azimuth_deg in [0.0, 120.0, 250.0] {
        let look = || lit_from(30.0, azimuth_deg, 0.4);
        let encoded = mean_error(&lone_sphere_fits_encoded(look(), 2700, 2.2, false));
        let decoded = mean_error(&lone_sphere_fits_encoded(look(), 2700, 2.2, true));
        worst_encoded = worst_encoded.max(encoded[0].abs()).max(encoded[1].abs());
        assert!(
            decoded[0].abs() < 0.01 && decoded[1].abs() < 0.01,
            "lit from azimuth {azimuth_deg}°, decoded: mean error ({:+.4}, {:+.4}) px (as recorded: ({:+.4}, {:+.4}))",
            decoded[0],
            decoded[1],
            encoded[0],
            encoded[1]
        );
    }
    assert!(
        worst_encoded > 0.02,
        "as recorded the centres were within {worst_encoded:.4} px: the test shows nothing"
    );
}

/// A sphere lit from 35° to one side over a grey ground (ground 90, the sphere 200 with an
/// ambient floor of 0.3: its shaded limb about 60, below the ground, its lit side above), noise
/// σ = 2, at 24 sub-pixel phases: the edge points find its limb all round, the radius within
/// 0.3 px (read as the fall through half the shading's height alone, the crossing lay inside
/// the disc where its shading sinks through the ground's level, the radius a pixel short, and
/// whole recordings lost a third of their frames as "not one circle"), and the centre is
/// unbiased to 0.01 px.
#[test]
fn a_sphere_darker_than_a_grey_ground_at_its_limb_is_measured() {
    let ground = 90.0;
    for azimuth_deg in [0.0, 120.0, 250.0] {
        let (view, r_px, mut cfg) = dotless_direct_view(64, 64, [31.3, 31.6]);
        cfg.look = Some(lit_from(35.0, azimuth_deg, 0.3));
        cfg.background_grey = ground;
        let far = V3::new(100.0, 100.0, 0.0);
        let mut errors = Vec::new();
        let mut worst_radius: f64 = 0.0;
        for k in 0..24u64 {
            let c = sub_pixel_phase(&view, k);
            let (img, truth) = render_pair(&view, 64, 64, [c, far], &cfg, 4500 + k);
            let t = truth[0];
            // The premise: the limb away from the lamp (its azimuth is in image axes, u and v)
            // is darker than the ground.
            let away = (azimuth_deg + 180.0_f64).to_radians();
            let limb = img
                .sample(
                    t[0] + (r_px - 0.7) * away.cos(),
                    t[1] + (r_px - 0.7) * away.sin(),
                )
                .expect("inside the frame");
            assert!(
                limb < ground - 15.0,
                "the shaded limb is at {limb:.0}, not below the ground"
            );
            let rough = [t[0] + 0.4, t[1] - 0.3];
            let (edge, _) =
                fit_edges(&img, &view, rough, r_px, ground, None).expect("edge points all round");
            worst_radius = worst_radius.max((edge.radius - r_px).abs());
            let f = refine(&img, &view, rough, r_px, ground, None, &[])
                .expect("a lone sphere is measured");
            errors.push(([f.centre[0] - t[0], f.centre[1] - t[1]], f.centre_sigma));
        }
        let bias = mean_error(&errors);
        assert!(
            worst_radius < 0.3 && bias[0].abs() < 0.01 && bias[1].abs() < 0.01,
            "lit from azimuth {azimuth_deg}°: edge radius up to {worst_radius:.3} px off, mean centre error ({:+.4}, {:+.4}) px",
            bias[0],
            bias[1]
        );
    }
}

/// A sphere lit from 30° to one side over a grey ground whose level its shaded limb nearly
/// matches (ground 80, the sphere 200 with an ambient floor of 0.4: a contrast of a few grey
/// levels there), noise σ = 4 (a grey ground's shot noise), and the subtracted backdrop as noisy
/// as a quantile of 31 frames keeps it (σ = 1.04, `GreyImage::ground` and `ground_noise`), at
/// 24 sub-pixel phases: no edge-point fit is taken as crossing a static backdrop. A tenth of a
/// few levels of contrast is below the backdrop's own noise, and without the floor of
/// `Ground::still_noise` such rays were "hidden" on 16 of the 24 phases — the disc then taken
/// as partly hidden, and left unmeasured wherever its grey-level fit did not settle (an
/// independent render over a ground of 80: one sphere in 8 of a view's first 10 frames). The
/// centres are unbiased to 0.02 px.
#[test]
fn a_noisy_backdrop_is_not_taken_for_a_tube_end() {
    let ground = 80.0;
    let (view, r_px, mut cfg) = dotless_direct_view(64, 64, [31.3, 31.6]);
    cfg.look = Some(lit_from(30.0, 200.0, 0.4));
    cfg.background_grey = ground;
    cfg.noise_sigma_grey = 4.0;
    let far = V3::new(100.0, 100.0, 0.0);
    let mut rng = hw_sim::Rng::new(77);
    let mut hidden = 0;
    let mut errors = Vec::new();
    for k in 0..24u64 {
        let c = sub_pixel_phase(&view, k);
        let (mut img, truth) = render_pair(&view, 64, 64, [c, far], &cfg, 8100 + k);
        let still: Vec<f32> = (0..img.width * img.height)
            .map(|_| 1.04 * rng.gaussian() as f32)
            .collect();
        img.ground = Some(still.into());
        img.ground_noise = 1.04;
        let t = truth[0];
        let rough = [t[0] + 0.4, t[1] - 0.3];
        let (_, was_hidden) =
            fit_edges(&img, &view, rough, r_px, ground, None).expect("edge points");
        hidden += usize::from(was_hidden);
        let f = refine(&img, &view, rough, r_px, ground, None, &[]).expect("measured");
        errors.push(([f.centre[0] - t[0], f.centre[1] - t[1]], f.centre_sigma));
    }
    let bias = mean_error(&errors);
    assert!(
        hidden == 0 && bias[0].abs() < 0.02 && bias[1].abs() < 0.02,
        "{hidden} of 24 taken as crossing a backdrop; mean centre error ({:+.4}, {:+.4}) px",
        bias[0],
        bias[1]
    );
}

/// A lone sphere whose disc the view's border cuts near its middle (its centre half a pixel
/// inside the border, less than 200° of its edge in view; a noise-free render: no backdrop
/// noise to leave rays out by chance) has its edge points fitted at the known radius, as an
/// arc a backdrop hid is, and says so: the rays beyond the border are left out. (With a free radius such arcs put centres 1–2 px off on hw-sim's defocused looks,
/// with a claimed σ of 0.25 px.)
#[test]
fn a_disc_the_border_cuts_is_fitted_at_its_radius() {
    let (view, r_px, mut cfg) = dotless_direct_view(64, 64, [31.3, 31.6]);
    cfg.noise_sigma_grey = 0.0;
    cfg.look = Some(lit_from(20.0, 60.0, 0.4));
    let far = V3::new(100.0, 100.0, 0.0);
    // 32.2 px right of the origin: u ≈ 63.5 of a 64 px view, the disc's right half beyond it.
    let c = V3::new(32.2 / view.px_per_mm, 0.2 / view.px_per_mm, 0.0);
    let (img, truth) = render_pair(&view, 64, 64, [c, far], &cfg, 31);
    let t = truth[0];
    assert!(
        t[0] + r_px > 64.0,
        "the disc is not cut: centre u {:.1}",
        t[0]
    );
    let (edge, cut) = fit_edges(
        &img,
        &view,
        [t[0] - 0.5, t[1]],
        r_px,
        cfg.background_grey,
        None,
    )
    .expect("the arc in view gives edge points");
    assert!(
        cut && (edge.radius - r_px).abs() < 1e-9,
        "cut: {cut}; radius {:.3} px where the sphere's is {r_px:.3}",
        edge.radius
    );
}

/// An overexposed sphere lit from 30° to one side (gain 1.45: its lit side at the camera's
/// ceiling, 255) is measured unbiased to 0.01 px with its saturated pixels marked, as the
/// normalisation marks them, and so left out of the fit. (A guard, not a demonstration: on
/// a lone dotless sphere the robust fit is hardly biased by the ceiling even unmarked,
/// 0.003 px here; what marking does on whole recordings is in docs/accuracy.md, session 35.)
#[test]
fn an_overexposed_sphere_is_not_biased_by_its_ceiling() {
    for azimuth_deg in [0.0, 120.0, 250.0] {
        let mut look = lit_from(30.0, azimuth_deg, 0.4);
        look.views[0].gain = 1.45;
        let bias = mean_error(&lone_sphere_fits(look, 1700));
        assert!(
            bias[0].abs() < 0.01 && bias[1].abs() < 0.01,
            "lit from azimuth {azimuth_deg}°: mean error ({:+.4}, {:+.4}) px",
            bias[0],
            bias[1]
        );
    }
}

/// A lone sphere blurred by 1.1 px (defocus), 48 sub-pixel phases under read noise σ = 2:
/// lit on the view's axis, its centres scatter no more than 1.6 times the σ the fit claims
/// (with a ring 2.5 px deep they scattered 0.20 px against a claimed 0.11: the blur, the
/// shading and the centre traded off); lit from 10° and from 30° off the axis at three
/// azimuths each, the mean centre is within 0.035 px of the truth (measured: 0.015–0.02 at
/// 10°, 0.021–0.031 at 30°, each away from the lamp). The ring reaches further
/// inside where the edge is blurred (`INNER_BAND_PER_EDGE_WIDTH`), and there the shading's rise
/// under the limb is blurred with the edge (`model::blurred_rise`): with the step times the
/// shading at the blurred depth instead, a lamp 10° off put the centre 0.09–0.12 px away from
/// it (30° off: 0.05–0.06 px towards it before the ring reached further in, within 0.02 after).
/// What is left at 30° is open (docs/accuracy.md, session 36).
#[test]
fn a_defocused_sphere_is_measured_as_well_as_its_fit_claims() {
    let lone = |off_axis_deg: f64, azimuth_deg: f64| {
        let look = hw_sim::Look {
            defocus_sigma_px: 1.1,
            ..lit_from(off_axis_deg, azimuth_deg, 0.3)
        };
        let fits = lone_sphere_fits(look, 900);
        let n = fits.len() as f64;
        let square = |v: [f64; 2]| v[0] * v[0] + v[1] * v[1];
        let scatter = (fits.iter().map(|f| square(f.0)).sum::<f64>() / n).sqrt();
        let claimed = (fits.iter().map(|f| square(f.1)).sum::<f64>() / n).sqrt();
        (mean_error(&fits), scatter, claimed)
    };
    let (_, rms, claimed) = lone(0.0, 0.0);
    assert!(
        rms <= 1.6 * claimed && rms < 0.16,
        "lit on axis: centres scatter {rms:.4} px RMS, the fit claims {claimed:.4} px"
    );
    for off_axis_deg in [10.0, 30.0] {
        for azimuth_deg in [30.0, 150.0, 270.0] {
            let (bias, _, _) = lone(off_axis_deg, azimuth_deg);
            assert!(
                bias[0].hypot(bias[1]) < 0.035,
                "lit from {off_axis_deg}° at azimuth {azimuth_deg}°: mean error ({:+.4}, {:+.4}) px",
                bias[0],
                bias[1]
            );
        }
    }
}

/// A grey-level fit started 1.1–2 px from a blurred, side-lit disc (where the edge-point fit
/// puts such a disc: the threshold crosses the dark limb's blur well inside it) settles on the
/// disc, not on "no fit": it is tried again from where it went and kept when that agrees
/// (`profile::fit_one`). Before, any fit that moved more than a pixel was refused and the
/// edge-point fit, a pixel off with a claimed 0.02 px, stood in for it.
#[test]
fn a_fit_started_far_from_a_blurred_disc_is_tried_again_from_where_it_went() {
    let (view, r_px, mut cfg) = dotless_direct_view(64, 64, [31.3, 31.6]);
    cfg.look = Some(hw_sim::Look {
        defocus_sigma_px: 1.2,
        ..lit_from(40.0, 330.0, 0.3)
    });
    let far = V3::new(100.0, 100.0, 0.0);
    let mut worst: f64 = 0.0;
    for k in 0..12u64 {
        let kf = k as f64;
        let c = sub_pixel_phase(&view, k);
        let (img, truth) = render_pair(&view, 64, 64, [c, far], &cfg, 1300 + k);
        let t = truth[0];
        let angle = kf * 0.9;
        let off = 1.1 + 0.08 * kf;
        let start = [t[0] + off * angle.cos(), t[1] + off * angle.sin()];
        let f = profile_fit_at(&img, &view, start, r_px, cfg.background_grey, None, &[])
            .unwrap_or_else(|| panic!("phase {k}: started {off:.2} px off, no fit"));
        worst = worst.max((f.centre[0] - t[0]).hypot(f.centre[1] - t[1]));
    }
    assert!(worst < 0.2, "worst centre {worst:.3} px from the truth");
}

/// Blurred dots no marker search finds: a sphere defocused by 1.1 px and lit from 30° to one
/// side, eight dots painted at a fifth of the shading (multiplicative) and blurred with it,
/// noise σ = 2, no masks, 40 phases. Each dot is 5–15σ darker over a dozen pixels, hardly a
/// pixel of it 4σ off a model that bends to meet it, so the rejection of single pixels leaves
/// it in; Cauchy's loss in every round weighs it down, and on a blurred disc the patches darker
/// than the model are left out too (`profile::dark_patches`). Measured: without dots 0.028 px
/// per axis; with them 0.077 px before the patches were looked for, 0.059 px since (0.087 px
/// with least squares after the first round, as before session 29). What is left, 0.05 px in
/// quadrature, is open (docs/accuracy.md).
#[test]
fn blurred_dots_left_in_the_ring_do_not_pull_the_centre() {
    let cfg = defocused_with_dark_dots();
    let errs = lone_sphere_errors(&cfg, 8);
    assert!(errs.len() >= 30, "only {} of 40 fits settled", errs.len());
    let plain: Vec<[f64; 2]> = errs.iter().map(|e| e.0).collect();
    let p = rms(&plain);
    assert!(p < 0.066, "blurred dots left in: {p:.4} px per axis");
}

/// A defocused sphere with blurred dots on its face, its radius held at the median of the free
/// fits' over the renders (`FirstPassDisc`, as the second pass holds it at the first pass's over
/// the frames round each): the centres scatter less than the free fits', and each held fit's σ
/// carries its free radius's stray from that median. Measured: 0.0569 px per axis free, 0.0401
/// held (the median radius 6.760 px, 0.09 below the sphere's: the blurred model's own bias,
/// which the median carries and the known size would not).
#[test]
fn a_blurred_disc_held_at_its_neighbours_radius_scatters_less() {
    let cfg = defocused_with_dark_dots();
    let bg = cfg.background_grey;
    let renders = lone_sphere_renders(&cfg, 8);
    let free: Vec<(usize, CircleFit)> = renders
        .iter()
        .enumerate()
        .filter_map(|(k, r)| Some((k, profile_fit(&r.img, &r.view, &r.edge, bg, None, &[])?)))
        .collect();
    assert!(free.len() >= 30, "only {} of 40 fits settled", free.len());
    let mut radii: Vec<f64> = free.iter().map(|(_, f)| f.radius).collect();
    radii.sort_by(f64::total_cmp);
    let median = radii[radii.len() / 2];
    let (mut free_err, mut held_err) = (Vec::new(), Vec::new());
    let mut widened = 0;
    for (k, f) in &free {
        let r = &renders[*k];
        let h = FirstPassDisc {
            centre_px: f.centre,
            radius_px: median,
            stray_px: f.radius - median,
            smear_px: [0.0; 2],
        };
        let (_, plan) = profile_plan(&r.img, &r.view, &r.edge, bg, None, &[], None, Some(h))
            .expect("planned with the radius held");
        let Some(held) = profile_finish(&r.img, &r.view, &plan, &[], Some(h)) else {
            continue;
        };
        // (Held by a stiff penalty, not exactly.)
        assert!(
            (held.radius - median).abs() < 1e-3,
            "render {k}: the radius was not held: {} against {median}",
            held.radius
        );
        widened += usize::from(held.centre_sigma[0] > f.centre_sigma[0]);
        let t = r.truth;
        free_err.push([f.centre[0] - t[0], f.centre[1] - t[1]]);
        held_err.push([held.centre[0] - t[0], held.centre[1] - t[1]]);
    }
    assert!(
        held_err.len() >= 30,
        "only {} held fits settled",
        held_err.len()
    );
    let (f, h) = (rms(&free_err), rms(&held_err));
    assert!(
        h < 0.85 * f,
        "held {h:.4} px per axis against free {f:.4}: holding the radius did not help"
    );
    assert!(
        widened * 2 > held_err.len(),
        "only {widened} of {} held fits carry their stray in σ",
        held_err.len()
    );
}

/// A lone sphere lit from 30° to one side, moving 3 px while the shutter is open (1 ms at
/// 3 px/ms), noise σ = 2, 16 sub-pixel phases: fitted with its smear (`FirstPassDisc::smear_px`)
/// its centre is unbiased to 0.02 px and scatters less than 0.04 px per axis; fitted as round,
/// the same renders come out 0.06–0.19 px off on average (checked here, so that the test
/// cannot pass on renders the smear does not disturb).
#[test]
fn a_disc_smeared_over_the_exposure_is_fitted_as_smeared() {
    let view = test_view(ViewKind::Direct, 64, 48, 2.1576, [31.3, 23.6], "-y");
    let r_px = SPHERE_RADIUS_MM * view.px_per_mm;
    // 3 px a millisecond in the image, along (0.8, −0.6) (v runs down, y up).
    let (speed_px_ms, exposure_ms) = (3.0, 1.0);
    let vel_mm_s = V3::new(0.8, 0.6, 0.0) * (speed_px_ms * 1000.0 / view.px_per_mm);
    let smear_px = [
        0.8 * speed_px_ms * exposure_ms,
        -0.6 * speed_px_ms * exposure_ms,
    ];
    for azimuth_deg in [0.0, 90.0] {
        let cfg = hw_sim::LabConfig {
            markers_per_sphere: 0,
            exposure_ms,
            look: Some(lit_from(30.0, azimuth_deg, 0.3)),
            ..Default::default()
        };
        let (mut round, mut smeared) = (Vec::new(), Vec::new());
        for k in 0..16u64 {
            let kf = k as f64;
            let at = V3::new(
                (kf * 0.37) % 1.0 / view.px_per_mm,
                (kf * 0.618) % 1.0 / view.px_per_mm,
                0.0,
            );
            let body = move |pos: V3, vel: V3| hw_sim::physics::Body {
                pos_mm: pos,
                vel_mm_s: vel,
                spin_rad_s: V3::zeros(),
                orientation: nalgebra::UnitQuaternion::identity(),
                radius_mm: SPHERE_RADIUS_MM,
                mass_g: 1.0,
            };
            let far = V3::new(40.0, 40.0, 0.0);
            let state = move |t: f64| {
                let moving = body(at + vel_mm_s * t, vel_mm_s);
                ([moving, body(far, V3::zeros())], [vec![], vec![]])
            };
            let scene = crate::analysis::geometry::one_view_scene(&view, 64, 48);
            let mut r = hw_sim::render::Renderer::new(scene, cfg.clone(), 91 + k);
            let mut raw = Vec::new();
            r.render(0.0, &state, &mut raw);
            let mut img = GreyImage::new();
            img.load(&raw, 64, 48, 1);
            let t = view.project(&at);
            let edge = fit_edges(
                &img,
                &view,
                [t[0] + 0.3, t[1] - 0.2],
                r_px - 0.15,
                30.0,
                None,
            )
            .expect("edge fit")
            .0;
            let disc = FirstPassDisc {
                centre_px: edge.centre,
                radius_px: r_px,
                stray_px: 0.0,
                smear_px,
            };
            let fit = |held: Option<FirstPassDisc>| {
                let (_, plan) = profile_plan(&img, &view, &edge, 30.0, None, &[], None, held)
                    .expect("box rounds");
                profile_finish(&img, &view, &plan, &[], held).expect("final round")
            };
            let error = |f: CircleFit| [f.centre[0] - t[0], f.centre[1] - t[1]];
            let unsmeared = FirstPassDisc {
                smear_px: [0.0; 2],
                ..disc
            };
            round.push(error(fit(Some(unsmeared))));
            smeared.push(error(fit(Some(disc))));
        }
        let (bias_round, bias) = (mean_of(&round), mean_of(&smeared));
        assert!(
            bias[0].abs() < 0.02 && bias[1].abs() < 0.02 && rms(&smeared) < 0.04,
            "lit from azimuth {azimuth_deg}°, smeared: mean error ({:+.4}, {:+.4}) px, RMS {:.4}",
            bias[0],
            bias[1],
            rms(&smeared)
        );
        assert!(
            bias_round[0].hypot(bias_round[1]) > 0.05,
            "lit from azimuth {azimuth_deg}°, fitted as round: mean error ({:+.4}, {:+.4}) px",
            bias_round[0],
            bias_round[1]
        );
    }
}

fn mean_of(errors: &[[f64; 2]]) -> [f64; 2] {
    let n = errors.len() as f64;
    [0, 1].map(|i| errors.iter().map(|e| e[i]).sum::<f64>() / n)
}

/// A sphere lit from 30° to one side (ambient 0.4, over a ground of 80) with its shadow against
/// its limb on a backdrop close behind: half as dark as the ground, a disc of the sphere's
/// size 0.6 radii away on the side away from the lamp (drawn by rendering the frame again over
/// a ground of 40, the same noise, and taking those pixels inside the shadow). The rays and the
/// sectors the shadow lies against are left out, and the centres come out as without it: the
/// median error within 0.02 px, each centre whose radius came out right (within 0.2 px) within
/// 5σ of the truth. (With the shadow read as the limb, as before session 52: every phase
/// 1.4 px towards the shadow, mean (+1.30, +0.54) px. One phase of the 24 still slides 0.6 px
/// with its radius 0.6 px too large; the analysis widens such a centre's σ by its radius's
/// stray from its neighbours', `radius_misfit`.)
#[test]
fn a_shadow_against_the_limb_is_left_out() {
    let (view, r_px, mut cfg) = dotless_direct_view(64, 64, [31.3, 31.6]);
    cfg.look = Some(lit_from(30.0, 200.0, 0.4));
    cfg.background_grey = 80.0;
    let mut dark = cfg.clone();
    dark.background_grey = 40.0;
    let far = V3::new(100.0, 100.0, 0.0);
    let away = 20f64.to_radians();
    let mut errors = Vec::new();
    for k in 0..24u64 {
        let c = sub_pixel_phase(&view, k);
        let (mut img, truth) = render_pair(&view, 64, 64, [c, far], &cfg, 5200 + k);
        let (shaded, _) = render_pair(&view, 64, 64, [c, far], &dark, 5200 + k);
        let t = truth[0];
        let s = [
            t[0] + 0.6 * r_px * away.cos(),
            t[1] + 0.6 * r_px * away.sin(),
        ];
        for v in 0..64 {
            for u in 0..64 {
                if (u as f64 - s[0]).hypot(v as f64 - s[1]) < r_px {
                    img.data[v * 64 + u] = shaded.data[v * 64 + u];
                }
            }
        }
        let rough = [t[0] + 0.4, t[1] - 0.3];
        let f = refine(&img, &view, rough, r_px, cfg.background_grey, None, &[]).expect("measured");
        errors.push((
            [f.centre[0] - t[0], f.centre[1] - t[1]],
            f.centre_sigma,
            f.radius,
        ));
    }
    let median = |i: usize| {
        let mut e: Vec<f64> = errors.iter().map(|(e, _, _)| e[i]).collect();
        e.sort_by(f64::total_cmp);
        0.5 * (e[11] + e[12])
    };
    let worst_z = errors
        .iter()
        .filter(|(_, _, r)| (r - r_px).abs() < 0.2)
        .map(|(e, s, _)| (e[0] / s[0]).abs().max((e[1] / s[1]).abs()))
        .fold(0.0, f64::max);
    assert!(
        median(0).hypot(median(1)) < 0.02 && worst_z < 5.0,
        "median centre error ({:+.4}, {:+.4}) px; largest error {worst_z:.1}σ",
        median(0),
        median(1)
    );
}
