//! Tracking over synthetic recordings whose truth is known exactly.

use crate::analysis::geometry::{self, View};
use crate::analysis::source::MemoryFrames;
use crate::analysis::tracking::HiddenInPart;
use crate::config::Config;
use nalgebra::Vector3;

/// World position (mm) of sphere `s` in frame `k`.
type Path = fn(usize, usize) -> Vector3<f64>;

/// a moves +x through the mirror view's tube end, b moves −x well clear of it.
fn past_the_tube_end(s: usize, k: usize) -> Vector3<f64> {
    let k = k as f64;
    match s {
        0 => Vector3::new(-32.0 + 0.3 * k, 10.0, 0.0),
        _ => Vector3::new(30.0 - 0.3 * k, 0.0, 5.0),
    }
}

/// One above the other, 1 mm apart in x and both drifting +x: a falls out of the direct
/// view's region at its bottom (wholly beyond it from frame 31 on) while b stays at one
/// height; the mirror view sees both throughout, 10 mm apart in z.
fn one_leaves_below(s: usize, k: usize) -> Vector3<f64> {
    let k = k as f64;
    match s {
        0 => Vector3::new(-8.0 + 0.3 * k, -15.0 - 0.4 * k, 0.0),
        _ => Vector3::new(-7.0 + 0.3 * k, 10.0, 10.0),
    }
}

/// The mirror view's static tube end, [u0, u1) × [v0, v1) px, grey `TUBE`: its grey lies
/// between the spheres' shading at the dark limb (60) and inside (up to 200).
const TUBE_PX: [f64; 4] = [70.0, 110.0, 134.0, 156.0];
const TUBE: f64 = 110.0;

/// Two spheres lit from 30° off each view's axis (Lambertian, an ambient floor) on a dark
/// ground, 4 × 4 samples a pixel, deterministic noise of ±1 grey level.
/// Through a pinhole view each disc is drawn with the radius its limb images at (the image of a
/// point one radius from its centre along the view's u axis; the ellipse a pinhole makes of a
/// sphere is round to well under a hundredth of a pixel at these distances).
fn recording(cfg: &Config, views: &[View], path: Path, tube: bool, frames: usize) -> MemoryFrames {
    let (w, h) = (240, 192);
    let r_mm = cfg.spheres.sphere(0).0 / 2.0;
    let radius = |vi: usize, at: &Vector3<f64>| match views[vi].map {
        geometry::Map::Pinhole { .. } => {
            let (c, rim) = (
                views[vi].project(at),
                views[vi].project(&(at + views[vi].u_axis * r_mm)),
            );
            (rim[0] - c[0]).hypot(rim[1] - c[1])
        }
        _ => views[vi].px_per_mm * r_mm,
    };
    let frames = (0..frames)
        .map(|k| {
            let discs: Vec<(usize, [f64; 2], f64)> = (0..2)
                .flat_map(|s| (0..views.len()).map(move |vi| (vi, s)))
                .map(|(vi, s)| (vi, views[vi].project(&path(s, k)), radius(vi, &path(s, k))))
                .collect();
            (0..w * h)
                .map(|i| {
                    let (u, v) = ((i % w) as f64, (i / w) as f64);
                    let vi = usize::from(v >= 96.0);
                    let mut sum = 0.0;
                    for a in 0..4 {
                        for b in 0..4 {
                            let (x, y) = (u - 0.375 + 0.25 * a as f64, v - 0.375 + 0.25 * b as f64);
                            let ground = if tube
                                && vi == 1
                                && (TUBE_PX[0]..TUBE_PX[1]).contains(&x)
                                && (TUBE_PX[2]..TUBE_PX[3]).contains(&y)
                            {
                                TUBE
                            } else {
                                20.0
                            };
                            let shade =
                                discs.iter().filter(|d| d.0 == vi).find_map(|&(_, c, r)| {
                                    let (dx, dy) = ((x - c[0]) / r, (y - c[1]) / r);
                                    let rho2 = dx * dx + dy * dy;
                                    (rho2 < 1.0).then(|| {
                                        let nz = (1.0 - rho2).sqrt();
                                        60.0 + 140.0 * (0.5 * dx + 0.866 * nz).max(0.0)
                                    })
                                });
                            sum += shade.unwrap_or(ground);
                        }
                    }
                    (sum / 16.0) as f32 + ((i * 7919 + k * 104_729) % 3) as f32 - 1.0
                })
                .collect()
        })
        .collect();
    MemoryFrames { w, h, frames }
}

/// A sphere passing wholly in front of a tube end in the mirror view: the backdrop's
/// subtraction leaves a blob that is only part of its disc (darker than the tube at the limb,
/// brighter inside), with no edge to fit, and whose centroid lies pixels off. It is measured
/// in every such frame, from where its own track puts it, and where it is. Before, it went
/// unmeasured there ("too few edge points for a circle fit").
#[test]
fn a_sphere_in_front_of_a_tube_end_is_measured_where_it_is() {
    let cfg = Config::default_config();
    let views = geometry::views(&cfg);
    let n = 90;
    let mut src = recording(&cfg, &views, past_the_tube_end, true, n);
    let (_, obs) = crate::analysis::measure(&mut src, &cfg).expect("measured");
    let r = views[1].px_per_mm * cfg.spheres.sphere(0).0 / 2.0;
    let (mut over, mut measured, mut worst) = (0, 0, 0.0f64);
    for (k, f) in obs.iter().enumerate() {
        let c = views[1].project(&past_the_tube_end(0, k));
        let wholly_over = c[0] - r > TUBE_PX[0] + 1.0
            && c[0] + r < TUBE_PX[1] - 1.0
            && c[1] - r > TUBE_PX[2] + 1.0
            && c[1] + r < TUBE_PX[3] - 1.0;
        if !wholly_over {
            continue;
        }
        over += 1;
        if let Some(m) = &f.spheres[0][1] {
            measured += 1;
            worst = worst.max((m.centre_px[0] - c[0]).hypot(m.centre_px[1] - c[1]));
        }
    }
    assert!(
        over >= 30,
        "{over} frames with a wholly in front of the tube end"
    );
    assert!(
        measured == over && worst < 0.05,
        "a measured in {measured} of {over} frames in front of the tube end; worst centre {worst:.3} px off"
    );
}

/// A lone circle in the primary view where the mirror view sees both spheres closer in x than
/// they are wide may hold both, and is dropped; but not where the other sphere's own track has
/// taken it wholly beyond the view's border (for as long as that track is extrapolated, 20
/// frames). Before, b went unmeasured in the direct view from the frame a left it.
#[test]
fn a_lone_circle_is_kept_where_the_other_sphere_has_left_the_view() {
    let cfg = Config::default_config();
    let views = geometry::views(&cfg);
    let n = 50;
    let mut src = recording(&cfg, &views, one_leaves_below, false, n);
    let (_, obs) = crate::analysis::measure(&mut src, &cfg).expect("measured");
    let r = views[0].px_per_mm * cfg.spheres.sphere(0).0 / 2.0;
    let bottom = (views[0].region[1] + views[0].region[3]) as f64 - 0.5;
    let (mut gone, mut kept, mut worst) = (0, 0, 0.0f64);
    for (k, f) in obs.iter().enumerate() {
        let a = views[0].project(&one_leaves_below(0, k));
        // Wholly beyond the border, for 10 frames: the track is extrapolated for 20 from
        // where a was last measured (frame 22, before its disc reached the border).
        if a[1] - r <= bottom || gone >= 10 {
            continue;
        }
        gone += 1;
        let b = views[0].project(&one_leaves_below(1, k));
        if let Some(m) = &f.spheres[1][0] {
            kept += 1;
            worst = worst.max((m.centre_px[0] - b[0]).hypot(m.centre_px[1] - b[1]));
        }
    }
    assert_eq!(gone, 10, "a leaves the direct view early enough");
    assert!(
        kept == gone && worst < 0.05,
        "b measured in {kept} of {gone} frames after a left the direct view; worst {worst:.3} px"
    );
}

/// One behind the other in the direct view for the whole recording — a 4 mm nearer its camera
/// than b, 3.2 mm apart in x (half a diameter), so one silhouette there — while the mirror
/// view sees them 8 mm apart or more in z: an impact whose normal leans towards the direct
/// camera, after it. Only the direct view measures y.
fn one_behind_the_other(s: usize, k: usize) -> Vector3<f64> {
    let k = k as f64;
    match s {
        0 => Vector3::new(-1.6 + 0.25 * k, -0.2 * k, 4.0 + 0.1 * k),
        _ => Vector3::new(1.6 + 0.25 * k, 0.3 - 0.25 * k, -4.0 - 0.1 * k),
    }
}

/// Over `one_behind_the_other`'s frames measured in the direct view `direct`: how many have both
/// spheres, how many both as crescents (`HiddenInPart::Crescent`), and those crescents' worst
/// centre errors (a, b), px.
fn crescents(
    obs: &[crate::analysis::tracking::FrameObs],
    direct: &View,
) -> (usize, usize, [f64; 2]) {
    let (mut both, mut refitted, mut worst) = (0, 0, [0.0f64; 2]);
    for (k, f) in obs.iter().enumerate() {
        let (Some(a), Some(b)) = (&f.spheres[0][0], &f.spheres[1][0]) else {
            continue;
        };
        both += 1;
        if [a, b]
            .iter()
            .all(|m| m.hidden_in_part == Some(HiddenInPart::Crescent))
        {
            refitted += 1;
            for (s, m) in [a, b].into_iter().enumerate() {
                let c = direct.project(&one_behind_the_other(s, k));
                worst[s] = worst[s].max((m.centre_px[0] - c[0]).hypot(m.centre_px[1] - c[1]));
            }
        }
    }
    (both, refitted, worst)
}

/// Both spheres are measured in the direct view's one silhouette of both, split by the
/// mirror's x, and nearly everywhere refitted on the grey levels with a's disc hiding b's: a
/// (whole) where it is, b (a crescent a radius wide, its lit side) within a tenth of a pixel
/// (0.036 px at worst, a 0.027). Before, a circle fitted to the silhouette was dropped (it
/// holds both) and neither sphere had a y; with the refit started from the outline split
/// alone, which the lamp 30° off axis puts 1.3 px towards itself, the refit was refused in
/// every frame; and with b's shading held symmetric round it (a lamp of its own traded off
/// with its centre) b came out up to 0.79 px off, 1.09 px had the fit been let settle
/// (session 41).
#[test]
fn one_silhouette_of_both_in_the_direct_view_is_split_by_the_mirrors_x() {
    let cfg = Config::default_config();
    let views = geometry::views(&cfg);
    let n = 40;
    let mut src = recording(&cfg, &views, one_behind_the_other, false, n);
    let (_, obs) = crate::analysis::measure(&mut src, &cfg).expect("measured");
    let (both, refitted, worst) = crescents(&obs, &views[0]);
    assert!(
        both >= n * 9 / 10 && refitted >= n * 9 / 10 && worst[0] < 0.06 && worst[1] < 0.1,
        "both measured in the direct view in {both} of {n} frames, refitted in {refitted}; worst refitted centres (a, b) {worst:.3?} px off"
    );
}

/// The same, the direct view seen through a pinhole 150 mm from the world origin (its scale
/// there the default's): a, nearer the camera, images 5–10 % larger than b behind it, and the
/// crescent's fit holds the radii at the ratio the mirror's depths give (`split`). Held at the
/// spheres' ratio of sizes, b came out up to 0.60 px off and 11 of the 40 frames were not
/// refitted as a crescent; now all 40 are, a within 0.027 px and b 0.037.
#[test]
fn a_crescent_behind_under_a_pinhole_is_fitted_at_its_own_radius() {
    use crate::config::ViewGeometry;
    let mut cfg = Config::default_config();
    let direct = cfg
        .geometry
        .direct
        .clone()
        .expect("the default has a direct view");
    let (m, o) = direct
        .local_affine()
        .expect("the default's maps are complete");
    // u = o + m·X/w, w = 1 − z/D: the camera on +z, D away, its scale at z = 0 the default's.
    let d_mm = 150.0;
    let row = |i: usize| [m[i][0], m[i][1], m[i][2] - o[i] / d_mm, o[i]];
    cfg.geometry.direct = Some(ViewGeometry {
        region: direct.region,
        projection: Some([row(0), row(1), [0.0, 0.0, -1.0 / d_mm, 1.0]]),
        ..Default::default()
    });
    cfg.validate().expect("the pinhole config is valid");
    let views = geometry::views(&cfg);
    let n = 40;
    let mut src = recording(&cfg, &views, one_behind_the_other, false, n);
    let (_, obs) = crate::analysis::measure(&mut src, &cfg).expect("measured");
    let (_, refitted, worst) = crescents(&obs, &views[0]);
    assert!(
        refitted >= n * 9 / 10 && worst[0] < 0.06 && worst[1] < 0.1,
        "refitted as a crescent in {refitted} of {n} frames; worst centres (a, b) {worst:.3?} px off"
    );
}

/// `recording`'s frames and `upright`'s config from a camera mounted on its side: every frame
/// turned by 90° (pixel (u, v) to (v, w − 1 − u): the views side by side, world x down the
/// image's rows), each view's map turned to match.
fn turned_on_its_side(upright: &Config, src: &MemoryFrames) -> (Config, MemoryFrames) {
    use crate::config::ViewGeometry;
    let (w, h) = (src.w, src.h);
    let frames = src
        .frames
        .iter()
        .map(|f| {
            (0..w * h)
                .map(|i| {
                    let (u2, v2) = (i % h, i / h);
                    f[u2 * w + (w - 1 - v2)]
                })
                .collect()
        })
        .collect();
    let mut cfg = upright.clone();
    cfg.camera.width = h as u32;
    cfg.camera.height = w as u32;
    let turn = |g: &ViewGeometry| -> ViewGeometry {
        let (m, o) = g.local_affine().expect("the default's maps are complete");
        let [x0, y0, _, rows] = g.region;
        assert_eq!(x0, 0, "the default's views span the frame's width");
        ViewGeometry::affine(
            [y0, 0, rows, w as u32],
            [m[1], m[0].map(|x| -x)],
            [o[1], (w - 1) as f64 - o[0]],
        )
    };
    cfg.geometry.direct = upright.geometry.direct.as_ref().map(turn);
    cfg.geometry.mirror = upright.geometry.mirror.as_ref().map(turn);
    cfg.validate().expect("the turned config is valid");
    (cfg, MemoryFrames { w: h, h: w, frames })
}

/// Where the other view's x puts the two discs of one silhouette (`split::starts_from_x`, the
/// starts the direct view's crescents are refitted from where the outline split gives none),
/// read across whichever image axis x images nearer: upright across rows, on a camera turned
/// on its side across columns. Read down the columns whatever the view, the turned view gave
/// none (its discs are apart along v, not u), and an independent render so turned lost the
/// direct view's y for the whole phase after its impact (docs/accuracy.md, session 47). Both
/// within the pixel the refit may move a start.
#[test]
fn the_other_views_x_starts_a_split_whichever_way_the_camera_is_turned() {
    use crate::analysis::{detect, image::GreyImage};
    let upright = Config::default_config();
    let upright_views = geometry::views(&upright);
    let k = 5;
    let src = recording(&upright, &upright_views, one_behind_the_other, false, k + 1);
    let (turned, turned_src) = turned_on_its_side(&upright, &src);
    for (name, cfg, frames) in [
        ("upright", &upright, &src),
        ("turned", &turned, &turned_src),
    ] {
        let views = geometry::views(cfg);
        let mut img = GreyImage::new();
        (img.width, img.height, img.data) = (frames.w, frames.h, frames.frames[k].clone());
        let lv = detect::levels(&img, &views[0]);
        let r = views[0].px_per_mm * cfg.spheres.sphere(0).0 / 2.0;
        let blobs = detect::find_blobs(&img, &views[0], &lv, r, cfg.analysis.threshold_fraction);
        let [blob] = &blobs[..] else {
            panic!(
                "{name}: {} blobs in the direct view, expected one of both",
                blobs.len()
            );
        };
        let x = [0, 1].map(|s| one_behind_the_other(s, k).x);
        let starts = super::split::starts_from_x(&img, &views[0], blob, &lv, x, [r; 2]);
        let Some(starts) = starts else {
            panic!("{name}: no starts from the other view's x");
        };
        for (s, start) in starts.iter().enumerate() {
            let c = views[0].project(&one_behind_the_other(s, k));
            let off = (start.centre[0] - c[0]).hypot(start.centre[1] - c[1]);
            assert!(off < 1.0, "{name}: sphere {s}'s start {off:.2} px off");
        }
    }
}

/// A lone circle larger than its sphere by more than `MAY_HOLD_BOTH_PX` where the other sphere
/// has no blob of its own and its track puts it over this disc, or cannot say where it is, may
/// hold both and is not taken (seed 105's varied-look recording: one circle 0.55 px too large
/// fitted to two discs nearly one behind the other, its centre 3.9 px off, 8σ). A circle of its
/// own size is taken (the other wholly behind it), as is a larger one where the other's track
/// is far off or the other has its own blob (the size gate of `measure_blob` is then the
/// only one).
#[test]
fn a_lone_circle_too_large_over_the_other_spheres_track_may_hold_both() {
    use super::measure::may_hold_both;
    use crate::analysis::circle::CircleFit;
    let r = 6.85;
    let at = |radius: f64| CircleFit::start_at([120.0, 48.0], radius);
    let near = Some(Some([120.0, 53.9]));
    let unseen = Some(None);
    let far = Some(Some([140.0, 48.0]));
    assert!(may_hold_both(1, &at(r + 0.55), [r; 2], near, Some(r)).is_some());
    assert!(may_hold_both(1, &at(r + 0.55), [r; 2], unseen, None).is_some());
    // Its remembered size, where it is within a tenth of the config's, is what it is held to.
    assert!(may_hold_both(1, &at(r + 0.55), [r; 2], near, Some(r + 0.4)).is_none());
    assert!(may_hold_both(1, &at(r + 0.55), [r; 2], near, Some(r + 0.9)).is_some());
    assert!(may_hold_both(1, &at(r + 0.05), [r; 2], near, Some(r)).is_none());
    assert!(may_hold_both(1, &at(r + 0.55), [r; 2], far, Some(r)).is_none());
    assert!(may_hold_both(1, &at(r + 0.55), [r; 2], None, Some(r)).is_none());
    let reason = may_hold_both(0, &at(r + 0.55), [r; 2], near, Some(r)).unwrap_or_default();
    assert!(
        reason.starts_with("a: one silhouette, b's track 5.9 px away")
            && reason.contains("0.55 px larger"),
        "{reason}"
    );
}

/// A side-lit sphere over a grey ground under a noise of 4 levels, as detection finds it.
struct SideLit {
    img: crate::analysis::image::GreyImage,
    view: crate::analysis::geometry::View,
    lv: crate::analysis::detect::ViewLevels,
    blob: crate::analysis::detect::Blob,
    r: f64,
}

impl SideLit {
    /// Radius `r` at `centre`: the frame, its view and levels, and its one blob.
    fn new(r: f64, centre: [f64; 2]) -> SideLit {
        use crate::analysis::detect::{self, tests as synthetic};
        let img = synthetic::frame(104.0, r, &[centre], &synthetic::side_lit(r));
        let view = synthetic::view();
        let lv = detect::levels(&img, &view);
        let blobs = detect::find_blobs(&img, &view, &lv, r, 0.5);
        let [blob] = &blobs[..] else {
            panic!("blobs {blobs:?}, expected the sphere's");
        };
        let blob = blob.clone();
        SideLit {
            img,
            view,
            lv,
            blob,
            r,
        }
    }

    /// Sphere a's refit of `blob` (its own, or one made of it), alone in the view, its track
    /// at `track`.
    fn refit<'a>(
        &'a self,
        blob: &'a crate::analysis::detect::Blob,
        track: Option<[f64; 2]>,
    ) -> super::measure::Refit<'a> {
        super::measure::Refit {
            img: &self.img,
            view: &self.view,
            s: 0,
            blob,
            other_blob: None,
            predicted: [track, None],
            radius: [self.r; 2],
            lv: &self.lv,
            dots: &[],
        }
    }
}

/// A side-lit sphere over a grey ground under a noise of 4 levels, its first frame in a view
/// (no track yet): the grey-level fit from the blob's centroid measures it within a tenth of a
/// pixel. Without a track there was no fit where the edge points were too few, and such a
/// view's spheres, never measured, never had a track (an independent render drawn at random:
/// no result on three recordings of eight).
#[test]
fn a_sphere_without_a_track_is_fitted_from_its_blob() {
    let r = 6.25;
    let centre = [100.3, 40.7];
    let scene = SideLit::new(r, centre);
    let fit = scene
        .refit(&scene.blob, None)
        .grey_level_fit()
        .expect("a fit from the blob's centroid");
    let off = (fit.centre[0] - centre[0]).hypot(fit.centre[1] - centre[1]);
    assert!(
        off < 0.1,
        "fitted {:?}, {off:.3} px from the centre {centre:?}",
        fit.centre
    );
}

/// The same, where the blob holds the lit side alone (its shaded limb not joined to it, as on a
/// sphere 34 px across entering hw-sim's grey-ground view): its centroid lies a third of a
/// radius towards the light, and a grey-level fit from there alone settled on a disc 0.7 px too
/// small, 5–6 px towards the light (centre σ 0.3 px). Started also round the centroid, the fit
/// whose radius is the sphere's is the sphere.
#[test]
fn a_sphere_without_a_track_whose_blob_is_its_lit_side_is_fitted_where_it_is() {
    let r = 17.1;
    let centre = [100.3, 44.7];
    let scene = SideLit::new(r, centre);
    let towards_light = std::f64::consts::FRAC_1_SQRT_2 * r / 3.0;
    let lit_side = crate::analysis::detect::Blob {
        centroid: [centre[0] - towards_light, centre[1] - towards_light],
        ..scene.blob.clone()
    };
    let fit = scene
        .refit(&lit_side, None)
        .grey_level_fit()
        .expect("a fit from round the blob's centroid");
    let off = (fit.centre[0] - centre[0]).hypot(fit.centre[1] - centre[1]);
    assert!(
        off < 0.1,
        "fitted {:?} radius {:.2}, {off:.3} px from the centre {centre:?}",
        fit.centre,
        fit.radius
    );
}

/// A side-lit sphere whose edge-point fit came out too large and 1.5 px off its track (a shaded
/// limb's inner and outer edges both taken, hw-sim's grey-ground look): the fit from the track
/// has the sphere's radius and is kept. A fit on the track is kept as it is, and so is one off
/// a track that is itself off (near the impact) where the track's disc is no nearer the
/// sphere's size.
#[test]
fn an_edge_fit_off_its_track_gives_way_to_the_disc_of_the_spheres_size() {
    use super::measure::BlobFit;
    use crate::analysis::circle::CircleFit;
    let r = 6.85;
    let centre = [100.3, 40.7];
    let scene = SideLit::new(r, centre);
    let again = |first: CircleFit, track: [f64; 2]| {
        let fit = BlobFit::Fitted(first, false);
        match scene.refit(&scene.blob, Some(track)).again(fit, Some(r)) {
            BlobFit::Fitted(f, _) => f,
            other => panic!("{other:?}"),
        }
    };
    let wrong = CircleFit::start_at([centre[0] + 1.2, centre[1] - 0.9], r + 0.23);
    let kept = again(wrong, centre);
    let off = (kept.centre[0] - centre[0]).hypot(kept.centre[1] - centre[1]);
    assert!(
        off < 0.1,
        "kept {:?} r {:.2}, {off:.3} px off",
        kept.centre,
        kept.radius
    );
    let right = CircleFit::start_at(centre, r);
    assert_eq!(again(right, [centre[0] + 0.5, centre[1]]).centre, centre);
    assert_eq!(
        again(right, [centre[0] + 3.0, centre[1] + 2.0]).centre,
        centre
    );
    // A fit whose edge a backdrop hid in part, with no track: kept, not refitted from the blob.
    let hidden = BlobFit::Fitted(right, true);
    let kept = scene.refit(&scene.blob, None).again(hidden, None);
    assert!(
        matches!(kept, BlobFit::Fitted(f, true) if f.centre == centre),
        "{kept:?}"
    );
}
