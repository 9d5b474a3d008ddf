//! Live view while idle, to set the rig up: the camera's current frame, what the analysis sees
//! in it (each view's region, the circles found), the exposure (histogram, saturated and black
//! pixels) and a focus figure (the spheres' edge width). A frame is grabbed on request, at most
//! every `MIN_GRAB_INTERVAL`, from the rig the daemon holds open: start, one frame, stop. While
//! an experiment runs it holds the rig, so live view pauses (409) and never takes a frame from a
//! recording. Nothing here can fire the relay: it touches the camera only.

use super::{error, lock, AppState, Shared};
use crate::analysis::circle::refine;
use crate::analysis::detect::{find_blobs, levels};
use crate::analysis::geometry::{self, View, ViewKind};
use crate::analysis::image::GreyImage;
use crate::figures::canvas::{Canvas, Raster};
use axum::body::Body;
use axum::extract::State;
use axum::http::{StatusCode, Uri};
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde_json::{json, Value};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Grabs no more often than this: ≥ 10 frames per second, whatever the camera's rate.
const MIN_GRAB_INTERVAL: Duration = Duration::from_millis(80);
/// The live stream's frame interval.
const STREAM_INTERVAL: Duration = Duration::from_millis(100);

/// One grabbed frame: its PNG, with and without the measurement drawn, and what was measured.
pub(super) struct LiveFrame {
    raw_png: Vec<u8>,
    drawn_png: Vec<u8>,
    overlay: Value,
}

/// The latest grab, shared by every live request.
#[derive(Default)]
pub(super) struct Live {
    last: Mutex<Option<(Instant, Arc<LiveFrame>)>>,
}

/// The latest frame, grabbed now unless one was grabbed within `MIN_GRAB_INTERVAL`.
fn current(state: &AppState) -> Result<Arc<LiveFrame>, (StatusCode, String)> {
    if let Some((at, f)) = lock(&state.live.last).as_ref() {
        if at.elapsed() < MIN_GRAB_INTERVAL {
            return Ok(f.clone());
        }
    }
    let busy = || {
        (
            StatusCode::CONFLICT,
            "an experiment is running: live view pauses while it records".to_string(),
        )
    };
    if lock(&state.running)
        .as_ref()
        .is_some_and(|(_, h)| !h.is_finished())
    {
        return Err(busy());
    }
    // The running experiment holds the rig for its whole length: never wait for it.
    let Ok(mut slot) = state.rig.try_lock() else {
        return Err(busy());
    };
    let Some(camera) = slot.as_mut().and_then(|r| r.camera.as_mut()) else {
        let why = lock(&state.rig_health).error.clone().unwrap_or_default();
        return Err((
            StatusCode::SERVICE_UNAVAILABLE,
            format!("the camera is not open ({why}); it is opened again for the next experiment"),
        ));
    };
    let info = camera.info();
    // Preview only for this grab: an experiment on this camera records the experiment.
    camera.set_preview(true);
    let grabbed = camera.start().and_then(|_| camera.next_frame(Vec::new()));
    let stopped = camera.stop();
    camera.set_preview(false);
    drop(slot);
    let frame = grabbed
        .and_then(|f| stopped.map(|_| f))
        .map_err(|e| (StatusCode::SERVICE_UNAVAILABLE, format!("camera: {e}")))?;
    let mut img = GreyImage::new();
    img.load(
        &frame.data,
        info.width as usize,
        info.height as usize,
        info.pixel_format.bytes_per_pixel(),
    );
    let views = geometry::views(&state.cfg);
    let (overlay, drawn) = measure(&img, &views, &state.cfg);
    let mut r = Raster::from_grey(img.width, img.height, &img.data);
    let raw_png = r.png().map_err(|e| internal(e.to_string()))?;
    for v in &views {
        let [x, y, w, h] = v.region.map(f64::from);
        r.rect(
            (x + 0.5, y + 0.5),
            (x + w - 0.5, y + h - 0.5),
            [230, 200, 40],
            0.5,
        );
    }
    for (c, radius) in drawn.circles {
        r.circle((c[0] + 0.5, c[1] + 0.5), radius, [44, 160, 44], false);
    }
    for m in drawn.markers {
        r.circle((m[0] + 0.5, m[1] + 0.5), 1.5, [230, 60, 200], false);
    }
    let drawn_png = r.png().map_err(|e| internal(e.to_string()))?;
    let f = Arc::new(LiveFrame {
        raw_png,
        drawn_png,
        overlay: json!({"frame_id": frame.frame_id, "timestamp_ns": frame.timestamp_ns, "width": info.width, "height": info.height, "measured": overlay["views"], "mirror_x_agreement": overlay["mirror_x_agreement"]}),
    });
    *lock(&state.live.last) = Some((Instant::now(), f.clone()));
    Ok(f)
}

fn internal(e: String) -> (StatusCode, String) {
    (StatusCode::INTERNAL_SERVER_ERROR, e)
}

/// What the live overlay draws: the circles (centre, radius, px) and the markers found.
struct Drawn {
    circles: Vec<([f64; 2], f64)>,
    markers: Vec<[f64; 2]>,
}

/// Per view: its region, the circles found (centre, radius, edge width) and the exposure of its
/// pixels. Returns the JSON and the circles to draw.
fn measure(img: &GreyImage, views: &[View], cfg: &crate::config::Config) -> (Value, Drawn) {
    let mut out = Vec::new();
    let mut drawn = Vec::new();
    let mut drawn_markers = Vec::new();
    // World x of each circle, per view: what the mirror's agreement compares.
    let mut world_x: [Vec<f64>; 2] = [Vec::new(), Vec::new()];
    for v in views {
        let lv = levels(img, v);
        let radius = [0, 1].map(|s| cfg.spheres.sphere(s).0 / 2.0 * v.px_per_mm);
        let r_mean = 0.5 * (radius[0] + radius[1]);
        let blobs = find_blobs(img, v, &lv, r_mean, cfg.analysis.threshold_fraction);
        let mut circles = Vec::new();
        for b in blobs.iter().take(4) {
            let Some(f) = refine(img, v, b.centroid, r_mean, lv.background, None, &[]) else {
                continue;
            };
            let width = edge_width_px(img, f.centre, f.radius);
            // The sphere's markers, found as the analysis finds them (against the disc's own
            // shading): what a user checks for paint contrast and focus.
            let radius_mm = 0.5 * (cfg.spheres.sphere(0).0 + cfg.spheres.sphere(1).0) / 2.0;
            let markers: Vec<[f64; 2]> = crate::analysis::markers::find(
                img,
                v,
                &f,
                radius_mm,
                cfg.analysis.marker_diameter_mm,
                lv.noise_sigma,
            )
            .iter()
            .map(|m| m.centre_px)
            .collect();
            circles.push(json!({"centre_px": f.centre, "radius_px": f.radius, "edge_width_px": width, "markers_px": markers}));
            drawn.push((f.centre, f.radius));
            drawn_markers.extend(markers);
            let slot = usize::from(v.kind == ViewKind::Mirror);
            world_x[slot].push(v.solve(f.centre, None).x);
        }
        let [x0, y0, w, h] = v.region.map(|x| x as usize);
        let mut hist = [0u64; 16];
        let (mut saturated, mut black, mut n) = (0u64, 0u64, 0u64);
        for y in y0..(y0 + h).min(img.height) {
            for x in x0..(x0 + w).min(img.width) {
                let g = img.at(x, y);
                hist[((g / 16.0) as usize).min(15)] += 1;
                saturated += u64::from(g >= 254.5);
                black += u64::from(g <= 0.5);
                n += 1;
            }
        }
        let pct = |k: u64| 100.0 * k as f64 / n.max(1) as f64;
        out.push(json!({
            "view": v.kind.name(),
            "region": v.region,
            "circles": circles,
            "exposure": {"histogram_16_bins": hist, "saturated_percent": pct(saturated), "black_percent": pct(black), "background_grey": lv.background, "peak_grey": lv.peak},
        }));
    }
    let direct_px_per_mm = views
        .iter()
        .find(|v| v.kind == ViewKind::Direct)
        .map(|v| v.px_per_mm);
    let agreement = mirror_x_agreement(&world_x[0], &world_x[1], direct_px_per_mm);
    (
        json!({"views": out, "mirror_x_agreement": agreement}),
        Drawn {
            circles: drawn,
            markers: drawn_markers,
        },
    )
}

/// The mirror's x agreement (the thesis's Table 4 check): both views see world x, so the same
/// sphere must have the same x in each. With as many circles in the mirror as in the direct
/// view (one or two), each pair in x order: both x, the mirror's minus the direct one in mm and
/// in direct-view px. A rig set up well agrees within a fraction of a pixel; a mirror off its
/// 45° or a wrong `[geometry]` shows here. Otherwise a reason why there is nothing to compare.
fn mirror_x_agreement(direct: &[f64], mirror: &[f64], direct_px_per_mm: Option<f64>) -> Value {
    if direct.is_empty() || direct.len() != mirror.len() || direct.len() > 2 {
        return json!({
            "pairs": [],
            "why_none": format!(
                "needs the same one or two spheres in both views; the direct view shows {}, the mirror {}",
                direct.len(),
                mirror.len()
            ),
        });
    }
    let sorted = |x: &[f64]| {
        let mut x = x.to_vec();
        x.sort_by(f64::total_cmp);
        x
    };
    let pairs: Vec<Value> = sorted(direct)
        .into_iter()
        .zip(sorted(mirror))
        .map(|(d, m)| {
            json!({
                "x_direct_mm": d,
                "x_mirror_mm": m,
                "difference_mm": m - d,
                "difference_px": direct_px_per_mm.map(|s| (m - d) * s),
            })
        })
        .collect();
    json!({ "pairs": pairs, "why_none": null })
}

/// A sphere's edge width, px: how far apart the radial profile crosses 10 % and 90 % of the way
/// from the background outside to the level inside (averaged over 36 directions). Smaller is
/// sharper; a user watches it while turning the focus ring. None where the profile has no
/// contrast.
fn edge_width_px(img: &GreyImage, c: [f64; 2], r: f64) -> Option<f64> {
    const STEP: f64 = 0.25;
    let offsets: Vec<f64> = (0..=32).map(|i| -4.0 + STEP * f64::from(i)).collect();
    let mut profile = vec![0.0; offsets.len()];
    for k in 0..36 {
        let (s, co) = (f64::from(k) * 10f64.to_radians()).sin_cos();
        for (p, d) in profile.iter_mut().zip(&offsets) {
            *p += img.sample(c[0] + (r + d) * co, c[1] + (r + d) * s)? / 36.0;
        }
    }
    let (inside, outside) = (profile[0], profile[profile.len() - 1]);
    let contrast = inside - outside;
    if contrast.abs() < 5.0 {
        return None;
    }
    let crossing = |level: f64| {
        let target = outside + level * contrast;
        (1..profile.len()).find_map(|i| {
            let (a, b) = (profile[i - 1], profile[i]);
            ((a - target) * (b - target) <= 0.0 && a != b)
                .then(|| offsets[i - 1] + STEP * (a - target) / (a - b))
        })
    };
    Some((crossing(0.1)? - crossing(0.9)?).abs())
}

/// `GET /api/camera/frame.png[?overlay=1]`: the latest frame, the measurement drawn on request.
pub(super) async fn frame_png(State(state): State<Shared>, uri: Uri) -> Response {
    let drawn = uri
        .query()
        .is_some_and(|q| q.split('&').any(|kv| kv == "overlay=1"));
    match tokio::task::spawn_blocking(move || current(&state)).await {
        Ok(Ok(f)) => (
            [("content-type", "image/png"), ("cache-control", "no-store")],
            if drawn {
                f.drawn_png.clone()
            } else {
                f.raw_png.clone()
            },
        )
            .into_response(),
        Ok(Err((status, e))) => error(status, e),
        Err(e) => error(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()),
    }
}

/// `GET /api/camera/overlay.json`: what the latest frame shows: per view the circles (with
/// their edge width) and the exposure.
pub(super) async fn overlay_json(State(state): State<Shared>) -> Response {
    match tokio::task::spawn_blocking(move || current(&state)).await {
        Ok(Ok(f)) => Json(f.overlay.clone()).into_response(),
        Ok(Err((status, e))) => error(status, e),
        Err(e) => error(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()),
    }
}

/// `GET /api/camera/live`: `multipart/x-mixed-replace` PNG frames with the measurement drawn,
/// one every `STREAM_INTERVAL`, until the client goes away or the daemon stops; while an
/// experiment runs the stream waits.
pub(super) async fn live_stream(State(state): State<Shared>) -> Response {
    let (tx, rx) = tokio::sync::mpsc::channel::<Result<Vec<u8>, std::io::Error>>(2);
    tokio::spawn(async move {
        loop {
            if tx.is_closed() {
                break;
            }
            let st = state.clone();
            let next = tokio::time::Instant::now() + STREAM_INTERVAL;
            if let Ok(Ok(f)) = tokio::task::spawn_blocking(move || current(&st)).await {
                let mut part = format!(
                    "--frame\r\nContent-Type: image/png\r\nContent-Length: {}\r\n\r\n",
                    f.drawn_png.len()
                )
                .into_bytes();
                part.extend_from_slice(&f.drawn_png);
                part.extend_from_slice(b"\r\n");
                if tx.send(Ok(part)).await.is_err() {
                    break;
                }
            }
            tokio::time::sleep_until(next).await;
        }
    });
    let body = Body::from_stream(tokio_stream::wrappers::ReceiverStream::new(rx));
    (
        [
            ("content-type", "multipart/x-mixed-replace; boundary=frame"),
            ("cache-control", "no-store"),
        ],
        body,
    )
        .into_response()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A disc whose edge ramps linearly over `ramp_px` from 200 inside to 20 outside.
    fn disc(ramp_px: f64) -> GreyImage {
        let mut img = GreyImage::new();
        img.width = 64;
        img.height = 64;
        img.data = (0..64 * 64)
            .map(|k| {
                let d = ((k % 64) as f64 - 31.3).hypot((k / 64) as f64 - 32.6) - 12.0;
                let t = (0.5 - d / ramp_px).clamp(0.0, 1.0);
                (20.0 + 180.0 * t) as f32
            })
            .collect();
        img
    }

    /// A frame with a bright disc of radius `r_px` at each image point.
    fn discs(width: usize, height: usize, at: &[[f64; 2]], r_px: f64) -> GreyImage {
        let mut img = GreyImage::new();
        img.width = width;
        img.height = height;
        img.data = (0..width * height)
            .map(|k| {
                let (x, y) = ((k % width) as f64, (k / width) as f64);
                let inside = at.iter().any(|c| (x - c[0]).hypot(y - c[1]) < r_px);
                if inside {
                    190.0
                } else {
                    25.0
                }
            })
            .collect();
        img
    }

    #[test]
    fn the_mirror_x_agreement_shows_a_mirror_view_shifted_along_x() {
        let cfg = crate::config::Config::default_config();
        let views = geometry::views(&cfg);
        let (direct, mirror) = (&views[0], &views[1]);
        assert_eq!(
            (direct.kind, mirror.kind),
            (ViewKind::Direct, ViewKind::Mirror)
        );
        // Two spheres in both views; the mirror's images drawn 0.8 mm further along x, as a
        // mirror view shifted by a misplaced mirror would show them.
        let spheres = [
            nalgebra::Vector3::new(-6.0, 0.0, 0.0),
            nalgebra::Vector3::new(7.0, 2.0, 0.0),
        ];
        let shift = nalgebra::Vector3::new(0.8, 0.0, 0.0);
        let mut at: Vec<[f64; 2]> = spheres.iter().map(|p| direct.project(p)).collect();
        at.extend(spheres.iter().map(|p| mirror.project(&(p + shift))));
        let r_px = cfg.spheres.sphere(0).0 / 2.0 * direct.px_per_mm;
        let mut img = discs(
            cfg.camera.width as usize,
            cfg.camera.height as usize,
            &at,
            r_px,
        );
        // A painted dot on the first sphere in the direct view, off its centre.
        let dot = [at[0][0] + 2.2, at[0][1] - 1.6];
        let dot_r = cfg.analysis.marker_diameter_mm / 2.0 * direct.px_per_mm;
        for y in 0..img.height {
            for x in 0..img.width {
                if (x as f64 - dot[0]).hypot(y as f64 - dot[1]) < dot_r {
                    img.data[y * img.width + x] = 60.0;
                }
            }
        }
        let (overlay, drawn) = measure(&img, &views, &cfg);
        let near = |m: &[f64; 2]| (m[0] - dot[0]).hypot(m[1] - dot[1]) < 0.7;
        assert!(
            drawn.markers.iter().any(near),
            "the dot at {dot:?} is found: {:?}",
            drawn.markers
        );
        assert!(overlay["views"][0]["circles"]
            .as_array()
            .unwrap()
            .iter()
            .any(|c| c["markers_px"].as_array().is_some_and(|m| !m.is_empty())));
        assert_eq!(drawn.circles.len(), 4, "{overlay}");
        let pairs = overlay["mirror_x_agreement"]["pairs"].as_array().unwrap();
        assert_eq!(pairs.len(), 2, "{overlay}");
        for (pair, p) in pairs.iter().zip(&spheres) {
            let d = pair["difference_mm"].as_f64().unwrap();
            assert!((d - 0.8).abs() < 0.05, "{pair}");
            let x = pair["x_direct_mm"].as_f64().unwrap();
            assert!((x - p.x).abs() < 0.05, "{pair}");
            let px = pair["difference_px"].as_f64().unwrap();
            assert!((px - 0.8 * direct.px_per_mm).abs() < 0.1, "{pair}");
        }
        // One sphere in the direct view only: nothing to compare, and why.
        let img = discs(
            cfg.camera.width as usize,
            cfg.camera.height as usize,
            &at[..1],
            r_px,
        );
        let (overlay, _) = measure(&img, &views, &cfg);
        let a = &overlay["mirror_x_agreement"];
        assert_eq!(a["pairs"], json!([]));
        assert!(
            a["why_none"]
                .as_str()
                .unwrap()
                .contains("direct view shows 1, the mirror 0"),
            "{a}"
        );
    }

    #[test]
    fn the_edge_width_is_the_ramp_and_smaller_when_sharper() {
        // 10 % to 90 % of a linear ramp is 0.8 of its length.
        let wide = edge_width_px(&disc(3.0), [31.3, 32.6], 12.0).unwrap();
        assert!((wide - 2.4).abs() < 0.25, "3 px ramp: {wide:.2} px");
        let sharp = edge_width_px(&disc(1.0), [31.3, 32.6], 12.0).unwrap();
        assert!(
            sharp < 0.6 * wide,
            "1 px ramp {sharp:.2} px vs 3 px ramp {wide:.2} px"
        );
        let mut flat = disc(1.0);
        flat.data.iter_mut().for_each(|g| *g = 20.0);
        assert_eq!(edge_width_px(&flat, [31.3, 32.6], 12.0), None);
    }
}
