//! The normalisation on small synthetic recordings: clutter, a backlit view, a flickering lamp.

use super::*;
use crate::analysis::geometry::ViewKind;
use crate::analysis::source::MemoryFrames as Frames;

fn view(w: u32, h: u32) -> View {
    let g = crate::config::ViewGeometry::shorthand([0, 0, w, h], 2.0, [0.0, 0.0], "+x", "-y");
    View::from_config(ViewKind::Direct, &g)
}

/// The light of frame k under a lamp flickering by `depth` at a tenth of the frame rate
/// (100 Hz at 1000 fps).
fn lamp(depth: f64, k: usize) -> f64 {
    1.0 + depth * (std::f64::consts::TAU * k as f64 / 10.0 + 0.7).sin()
}

/// A view with a bright static bar (a ruler), a smooth gradient and a disc crossing it,
/// `ground` and `disc` the levels, lit by a lamp flickering by `flicker`: frame k has the
/// disc at u = 8 + 3k.
fn recording(ground: f32, disc: f32, bar: f32, flicker: f64) -> Frames {
    let (w, h) = (96, 32);
    let frames = (0..30)
        .map(|k| {
            let cu = 8.0 + 3.0 * k as f32;
            (0..w * h)
                .map(|i| {
                    let (u, v) = ((i % w) as f32, (i / w) as f32);
                    let mut g = ground + 0.1 * u;
                    if (26.0..30.0).contains(&v) {
                        g = bar;
                    }
                    if (u - cu).hypot(v - 12.0) < 6.0 {
                        g = disc;
                    }
                    // Deterministic "noise", ±1.
                    g * lamp(flicker, k) as f32 + ((i * 7919 + k * 104_729) % 3) as f32 - 1.0
                })
                .collect()
        })
        .collect();
    Frames { w, h, frames }
}

#[test]
fn static_clutter_is_removed_and_the_moving_disc_stays() {
    let mut src = recording(20.0, 180.0, 160.0, 0.0);
    let views = [view(96, 32)];
    let b = Backdrop::estimate(&mut src, &views).expect("estimate");
    assert!(!b.views[0].dark_spheres);
    let mut img = GreyImage::new();
    src.read(10, &mut img).expect("read");
    b.apply(&mut img);
    // The ruler and the gradient are gone: within the noise of the ground's level.
    let level = b.views[0].level;
    for u in [5, 40, 90] {
        assert!(
            (img.at(u, 28) - level).abs() < 3.0,
            "ruler at u {u}: {}",
            img.at(u, 28)
        );
        assert!((img.at(u, 2) - level).abs() < 3.0, "gradient at u {u}");
    }
    // The disc (at u = 38 in frame 10) is still ~160 above its ground.
    assert!(img.at(38, 12) - level > 140.0);
    assert!(b.warnings().is_empty());
}

/// A shaded disc of radius 7 px crossing a bright bar (a ruler): frame k has it at u =
/// 10.3 + 2.5k, v = 20.4, over the bar's rows 18–29 for most of its lower half. Pixels
/// are averaged over 4 × 4 points. The lamp flickers by `flicker`. `frames`: 30, or more for
/// a recording in which the disc covers each pixel of the bar in fewer of the frames (it is
/// darker than the bar at its limb; over a fifth of them it would be the backdrop's quantile
/// there).
fn disc_over_a_bar(ground: f32, bar: f32, flicker: f64, frames: usize) -> Frames {
    let (w, h) = (120, 40);
    let frames = (0..frames)
        .map(|k| {
            let (cu, cv) = (10.3 + 2.5 * k as f64, 20.4);
            (0..w * h)
                .map(|i| {
                    let (u, v) = ((i % w) as f64, (i / w) as f64);
                    let mut sum = 0.0;
                    for a in 0..4 {
                        for b in 0..4 {
                            let (x, y) = (u - 0.375 + 0.25 * a as f64, v - 0.375 + 0.25 * b as f64);
                            let rho = (x - cu).hypot(y - cv) / 7.0;
                            sum += if rho < 1.0 {
                                // Lit from the left: brighter there, an ambient floor.
                                let nz = (1.0 - rho * rho).sqrt();
                                60.0 + 130.0 * (0.8 * nz - 0.6 * (x - cu) / 7.0).max(0.0)
                            } else if (18.0..30.0).contains(&y) {
                                bar as f64
                            } else {
                                ground as f64
                            };
                        }
                    }
                    // Deterministic "noise", ±1.
                    (lamp(flicker, k) * sum / 16.0) as f32 + ((i * 7919 + k * 104_729) % 3) as f32
                        - 1.0
                })
                .collect()
        })
        .collect();
    Frames { w, h, frames }
}

/// A disc in front of static clutter hides it: measured on the frame with the backdrop
/// subtracted, its centre comes out where it is only if the fit knows what the disc hides
/// (`GreyImage::ground`). Without it (edge points and the grey-level model both reading
/// the subtracted frame as the sphere) neither frame's disc was measured at all.
#[test]
fn a_disc_in_front_of_a_bright_bar_is_measured_where_it_is() {
    for bar in [150.0, 90.0] {
        let mut src = disc_over_a_bar(20.0, bar, 0.0, 30);
        let views = [view(120, 40)];
        let b = Backdrop::estimate(&mut src, &views).expect("estimate");
        for k in [8, 13, 17] {
            let mut img = GreyImage::new();
            src.read(k, &mut img).expect("read");
            b.apply(&mut img);
            let truth = [10.3 + 2.5 * k as f64, 20.4];
            let level = b.views[0].level as f64;
            let fit = crate::analysis::circle::refine(
                &img,
                &views[0],
                [truth[0] + 0.8, truth[1] - 0.6],
                7.0,
                level,
                None,
                &[],
            )
            .expect("the disc is measured");
            let err = (fit.centre[0] - truth[0]).hypot(fit.centre[1] - truth[1]);
            assert!(
                fit.grey_levels && err < 0.03,
                "bar {bar}, frame {k}: centre {:?} is {err:.3} px from {truth:?}",
                fit.centre
            );
        }
    }
}

#[test]
fn a_backlit_view_is_inverted_and_said_so() {
    let mut src = recording(200.0, 25.0, 60.0, 0.0);
    let views = [view(96, 32)];
    let b = Backdrop::estimate(&mut src, &views).expect("estimate");
    assert!(b.views[0].dark_spheres);
    let mut img = GreyImage::new();
    src.read(10, &mut img).expect("read");
    b.apply(&mut img);
    let level = b.views[0].level;
    assert!(
        img.at(38, 12) - level > 150.0,
        "the dark disc comes out bright"
    );
    assert!((img.at(70, 28) - level).abs() < 3.0, "the dark bar is gone");
    assert!(b.warnings()[0].contains("backlit"));
    // Markers are looked for in the sphere's own grey, the right way up: the raw frame's
    // level inside the disc, whatever was subtracted and inverted.
    let mut raw = GreyImage::new();
    src.read(10, &mut raw).expect("read");
    for (u, v) in [(38, 12), (70, 28), (5, 5)] {
        assert!(
            (img.lit_at(u, v) - raw.at(u, v)).abs() < 1e-3,
            "({u}, {v}): lit_at {} against the raw {}",
            img.lit_at(u, v),
            raw.at(u, v)
        );
    }
}

/// A grey ground (100) vignetted by 30 % at the corners, a disc lit from one side crossing it
/// in the last two thirds of the frames (its lit side 200, its shaded side 30: more of it
/// brighter than the ground than darker): not a backlit view. In each frame without the disc
/// the darkest 0.3 % is the vignetted corners, 25 levels below the median where the brightest
/// 0.3 % is within 4 of it, and voted on the frames as they are the view was turned over.
#[test]
fn a_vignetted_grey_ground_is_not_taken_for_a_backlit_view() {
    let (w, h) = (96usize, 32usize);
    let frames = (0..30)
        .map(|k| {
            let cu = 3.0 * k as f32 - 40.0;
            (0..w * h)
                .map(|i| {
                    let (u, v) = ((i % w) as f32, (i / w) as f32);
                    let (du, dv) = ((u - 47.5) / 47.5, (v - 15.5) / 15.5);
                    let q = (du * du + dv * dv) / 2.0;
                    let mut g = 100.0 * (1.0 - 0.3 * q * q);
                    let (x, y) = (u - cu, v - 16.0);
                    if x.hypot(y) < 9.0 {
                        // Lit from the left: bright on that side, below the ground on the other.
                        g = if x < 4.0 { 200.0 + 4.0 * x } else { 30.0 };
                    }
                    g + ((i * 7919 + k * 104_729) % 3) as f32 - 1.0
                })
                .collect()
        })
        .collect();
    let mut src = Frames { w, h, frames };
    let b = Backdrop::estimate(&mut src, &[view(96, 32)]).expect("estimate");
    assert!(!b.views[0].dark_spheres, "a grey ground turned over");
}

/// Under a lamp flickering by ±30 % the bar is subtracted at each frame's light: the ground
/// comes out flat (the bar's rows level with the ground's, where the still subtracted as it
/// is left 0.3 of the bar's 130 grey levels in them), the disc in front of it is measured
/// where it is, and the sphere's own levels (`sphere_at`) are the frame's. Under a steady
/// lamp nothing is matched (`ground_light` empty).
#[test]
fn a_flickering_lamp_is_matched_frame_by_frame() {
    let views = [view(120, 40)];
    let mut steady = disc_over_a_bar(20.0, 150.0, 0.0, 60);
    let b = Backdrop::estimate(&mut steady, &views).expect("estimate");
    for k in 0..60 {
        let mut img = GreyImage::new();
        steady.read(k, &mut img).expect("read");
        b.apply(&mut img);
        assert!(img.ground_light.is_empty(), "steady frame {k} was matched");
    }
    let mut src = disc_over_a_bar(20.0, 150.0, 0.3, 60);
    let b = Backdrop::estimate(&mut src, &views).expect("estimate");
    let mut matched = 0;
    for k in [1, 3, 6, 8, 13, 16, 17, 19] {
        let mut img = GreyImage::new();
        src.read(k, &mut img).expect("read");
        let mut raw = GreyImage::new();
        src.read(k, &mut raw).expect("read");
        b.apply(&mut img);
        matched += usize::from(!img.ground_light.is_empty());
        // Far from the disc (at u = 10.3 + 2.5k), the bar's rows against the ground's.
        let u = if 10.3 + 2.5 * k as f64 > 60.0 {
            15
        } else {
            105
        };
        let (bar, ground) = (
            img.at(u, 25) + img.at(u + 3, 27),
            img.at(u, 5) + img.at(u + 3, 8),
        );
        assert!(
            (bar - ground).abs() / 2.0 < 2.0,
            "frame {k} (light {:.2}): the bar stands {:.1} above the ground",
            lamp(0.3, k),
            (bar - ground) / 2.0
        );
        for (u, v) in [(u, 25), (u, 5), (10 + (5 * k) / 2, 20)] {
            assert!(
                (img.sphere_at(u, v) - raw.at(u, v)).abs() < 1e-2,
                "frame {k} ({u}, {v}): sphere_at {} against the raw {}",
                img.sphere_at(u, v),
                raw.at(u, v)
            );
        }
        if !(8..=17).contains(&k) {
            continue;
        }
        let truth = [10.3 + 2.5 * k as f64, 20.4];
        let fit = crate::analysis::circle::refine(
            &img,
            &views[0],
            [truth[0] + 0.8, truth[1] - 0.6],
            7.0,
            b.views[0].level as f64,
            None,
            &[],
        )
        .expect("the disc is measured");
        let err = (fit.centre[0] - truth[0]).hypot(fit.centre[1] - truth[1]);
        assert!(
            fit.grey_levels && err < 0.03,
            "frame {k} (light {:.2}): centre {:?} is {err:.3} px from {truth:?}",
            lamp(0.3, k),
            fit.centre
        );
    }
    assert!(matched >= 6, "{matched} of 8 frames matched");
}

/// A backlit view under a flickering lamp: the dark bar subtracted at each frame's light (the
/// bar's rows level with the ground's), and the sphere's levels the right way up (`lit_at`)
/// still the frame's own.
#[test]
fn a_backlit_view_under_a_flickering_lamp_is_matched_the_right_way_up() {
    let mut src = recording(200.0, 25.0, 60.0, 0.3);
    let views = [view(96, 32)];
    let b = Backdrop::estimate(&mut src, &views).expect("estimate");
    assert!(b.views[0].dark_spheres);
    let mut matched = 0;
    for k in [2, 5, 10, 14] {
        let mut img = GreyImage::new();
        src.read(k, &mut img).expect("read");
        let mut raw = GreyImage::new();
        src.read(k, &mut raw).expect("read");
        b.apply(&mut img);
        matched += usize::from(!img.ground_light.is_empty());
        let (bar, ground) = (img.at(70, 28), img.at(70, 20));
        assert!(
            (bar - ground).abs() < 3.0,
            "frame {k}: the dark bar at {bar} against the ground's {ground}"
        );
        for (u, v) in [(8 + 3 * k, 12), (70, 28), (5, 5)] {
            assert!(
                (img.lit_at(u, v) - raw.at(u, v)).abs() < 1e-2,
                "frame {k} ({u}, {v}): lit_at {} against the raw {}",
                img.lit_at(u, v),
                raw.at(u, v)
            );
        }
    }
    // (A frame whose light happens to be the still's is left as it is.)
    assert!(matched >= 3, "{matched} of 4 frames matched");
}

/// Pixels stuck at one level (hot, or dead) where the disc passes are marked unmeasured in
/// every frame, and said; none of the pixels that see the disc pass is, nor the still ground,
/// whose noise here (±1) ranges too little to tell a stuck pixel there from a quiet one.
#[test]
fn a_stuck_pixel_on_the_spheres_path_is_left_out_and_said() {
    let mut src = recording(20.0, 180.0, 160.0, 0.0);
    let (hot, dead) = (12 * 96 + 40, 12 * 96 + 61);
    for f in src.frames.iter_mut() {
        f[hot] = 255.0;
        f[dead] = 0.0;
    }
    let b = Backdrop::estimate(&mut src, &[view(96, 32)]).expect("estimate");
    assert_eq!(b.views[0].stuck, vec![hot, dead]);
    let mut img = GreyImage::new();
    src.read(10, &mut img).expect("read");
    b.apply(&mut img);
    assert!(img.unmeasured_at(40, 12) && img.unmeasured_at(61, 12));
    assert_eq!(img.unmeasured.iter().filter(|&&m| m).count(), 2);
    // Nor do they stand for the backdrop behind them: the ground there is their neighbours'
    // (a hot pixel's own level, 235 above the ground, read as a tube end's edge by every ray
    // of a disc that crossed it: sphere b unmeasured in 4 frames of tests/looks.rs's stuck
    // pixels, in one run of four).
    for (u, v) in [(40, 12), (61, 12)] {
        let (here, beside) = (img.ground_at(u, v), img.ground_at(u + 1, v));
        assert!(
            (here - beside).abs() < 3.0,
            "({u}, {v}): ground {here}, beside it {beside}"
        );
    }
    assert!(
        b.warnings().iter().any(|w| w.contains("2 stuck pixel(s)")),
        "{:?}",
        b.warnings()
    );
    // The same recording without them: nothing stuck, nothing said.
    let mut clean = recording(20.0, 180.0, 160.0, 0.0);
    let b = Backdrop::estimate(&mut clean, &[view(96, 32)]).expect("estimate");
    assert!(b.views[0].stuck.is_empty());
    assert!(b.warnings().is_empty(), "{:?}", b.warnings());
}

/// The noise the still keeps (`GreyImage::ground_noise`, which the edge points' test for a
/// backdrop's edge must clear): on a flat ground with noise σ = 3 over 30 frames, the still's
/// pixels scatter as it says, within a fifth. (Measured on the still's own pixel-to-pixel
/// differences instead, whole grey levels, a median of them said twice as much at σ = 2.)
#[test]
fn the_stills_noise_is_the_quantiles() {
    let (w, h) = (96usize, 32usize);
    let mut rng = hw_sim::Rng::new(5);
    let frames = (0..30)
        .map(|k| {
            let cu = 3.0 * k as f32;
            (0..w * h)
                .map(|i| {
                    let (u, v) = ((i % w) as f32, (i / w) as f32);
                    let g = if (u - cu).hypot(v - 8.0) < 6.0 {
                        190.0
                    } else {
                        40.0
                    };
                    g + 3.0 * rng.gaussian() as f32
                })
                .collect()
        })
        .collect();
    let mut src = Frames { w, h, frames };
    let b = Backdrop::estimate(&mut src, &[view(96, 32)]).expect("estimate");
    let mut img = GreyImage::new();
    src.read(3, &mut img).expect("read");
    b.apply(&mut img);
    let ground = img.ground.clone().expect("a still was subtracted");
    // Rows 16 on: never crossed by the disc.
    let flat: Vec<f64> = ground[16 * w..].iter().map(|&g| g as f64).collect();
    let mean = flat.iter().sum::<f64>() / flat.len() as f64;
    let sd = (flat.iter().map(|g| (g - mean).powi(2)).sum::<f64>() / flat.len() as f64).sqrt();
    let said = img.ground_noise as f64;
    assert!(
        (sd - said).abs() < 0.2 * sd,
        "the still scatters by {sd:.3} grey levels; ground_noise says {said:.3}"
    );
}

/// `order_stats` gives the elements a full sort puts at the ranks, whether the values are
/// whole grey levels (counted) or not (selected), repeated ranks and ties included.
#[test]
fn order_statistics_counted_or_selected_are_the_sorted_ones() {
    // A small generator of its own (no dependency): whole levels with many ties; the same less
    // 200 (whole and signed, as frames less a still: counted); less a fraction (not whole, so
    // selected); and spread beyond −256–255 (selected), the range's two ends among them.
    let mut state = 12345u64;
    let mut next = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 33) as u32
    };
    let whole: Vec<f32> = (0..5000).map(|_| (next() % 256) as f32).collect();
    let fractional: Vec<f32> = whole.iter().map(|&x| x - 0.37).collect();
    let signed: Vec<f32> = whole.iter().map(|&x| x - 200.0).collect();
    let mut wide: Vec<f32> = whole.iter().map(|&x| 4.0 * x - 300.0).collect();
    wide[..3].copy_from_slice(&[-256.0, 255.0, -257.0]);
    let mut ends = signed.clone();
    ends[..2].copy_from_slice(&[-256.0, 255.0]);
    for vals in [whole, signed, fractional, wide, ends] {
        let mut sorted = vals.clone();
        sorted.sort_by(f32::total_cmp);
        let n = vals.len();
        for ranks in [[0, n / 2, n - 1], [15, 2500, 4985], [2500; 3], [7, 7, 4999]] {
            let mut v = vals.clone();
            let got = order_stats(&mut v, ranks);
            assert_eq!(got, ranks.map(|r| sorted[r]), "ranks {ranks:?}");
        }
    }
}

/// A sphere lit from the side over a grey ground, bright on its lit side and far below the
/// ground over most of the rest, crossing slowly enough that its dark part covers a pixel of
/// its path in a quarter of the samples (and the whole disc in less than half): the view is
/// two-sided, its still the median, and the path comes out as the ground once the sphere has
/// passed. The 20th percentile took the dark part in as the ground, and its subtraction left a
/// bright trail 70 levels high along the path, which detection found as spheres beside the
/// spheres (an independent render drawn at random: names swapped, centres 18–30 px off).
#[test]
fn a_sphere_both_brighter_and_darker_than_a_grey_ground_leaves_no_trail() {
    let (w, h) = (96usize, 32usize);
    let centre_u = |k: usize| 10.0 + 1.5 * k as f32;
    let frames = (0..30)
        .map(|k| {
            let cu = centre_u(k);
            (0..w * h)
                .map(|i| {
                    let (u, v) = ((i % w) as f32, (i / w) as f32);
                    let mut g = 100.0;
                    let (x, y) = (u - cu, v - 16.0);
                    if x.hypot(y) < 9.0 {
                        // Lit from the left: bright on that side, below the ground on the other.
                        g = if x < -4.0 { 200.0 } else { 30.0 };
                    }
                    g + ((i * 7919 + k * 104_729) % 3) as f32 - 1.0
                })
                .collect()
        })
        .collect();
    let mut src = Frames { w, h, frames };
    let b = Backdrop::estimate(&mut src, &[view(96, 32)]).expect("estimate");
    assert!(!b.views[0].dark_spheres, "turned over");
    // Frame 29 has the sphere at u = 53.5; its path behind it, u 20–40, is the ground again.
    let mut img = GreyImage::new();
    src.read(29, &mut img).expect("read");
    b.apply(&mut img);
    let level = b.views[0].level;
    for u in [20, 25, 30, 35, 40] {
        assert!(
            (img.at(u, 16) - level).abs() < 3.0,
            "the path at u {u} reads {} against the ground's {level}",
            img.at(u, 16)
        );
    }
}
