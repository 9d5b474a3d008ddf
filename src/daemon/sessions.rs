//! The session viewer's routes: every session under the sessions directory (recorded by this
//! daemon or not), its manifest and report, and any of its frames as a PNG, with the
//! measurement drawn on it on request (`?overlay=1`). A session name from a request must be one
//! plain directory name directly under the sessions directory, checked before anything is
//! opened: nothing outside it can be named.

use super::{error, Shared};
use crate::analysis::report::Report;
use crate::figures::canvas::{Canvas, Raster};
use axum::extract::{Path, State};
use axum::http::StatusCode;
use axum::http::Uri;
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde_json::{json, Value};
use std::path::PathBuf;

/// The most sessions `/api/sessions` lists (newest first).
const MAX_SESSIONS_LISTED: usize = 10_000;

/// The session directory `name` names, or the response saying why there is none: a name is 1
/// to 128 of `A-Za-z0-9._-`, not starting with a dot, and a session (it holds `session.json`).
fn session_dir(state: &Shared, name: &str) -> Result<PathBuf, (StatusCode, String)> {
    let plain = !name.is_empty()
        && name.len() <= 128
        && !name.starts_with('.')
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'.' | b'_' | b'-'));
    if !plain {
        return Err((
            StatusCode::BAD_REQUEST,
            format!("{name:?} is not a session name: expected 1 to 128 of A-Za-z0-9._- not starting with a dot"),
        ));
    }
    let dir = state.cfg.recording.dir.join(name);
    if !crate::batch::is_session(&dir) {
        return Err((
            StatusCode::NOT_FOUND,
            format!("no session {name} in the sessions directory"),
        ));
    }
    Ok(dir)
}

fn read_json(path: &std::path::Path) -> Option<Value> {
    serde_json::from_str(&std::fs::read_to_string(path).ok()?).ok()
}

/// `GET /api/sessions`: name, status, frames and e (when analysed) of each session, newest
/// first.
pub(super) async fn list(State(state): State<Shared>) -> Response {
    let dir = state.cfg.recording.dir.clone();
    let listed = tokio::task::spawn_blocking(move || {
        let mut names: Vec<String> = std::fs::read_dir(&dir)
            .map(|entries| {
                entries
                    .filter_map(|e| e.ok())
                    .filter(|e| crate::batch::is_session(&e.path()))
                    .filter_map(|e| e.file_name().into_string().ok())
                    .collect()
            })
            .unwrap_or_default();
        names.sort_unstable_by(|a, b| b.cmp(a));
        names.truncate(MAX_SESSIONS_LISTED);
        names
            .into_iter()
            .map(|name| {
                let manifest = read_json(&dir.join(&name).join("session.json"));
                let report = read_json(&dir.join(&name).join("report.json"));
                json!({
                    "name": name,
                    "status": manifest.as_ref().map(|m| m["status"].clone()),
                    "frames_recorded": manifest.as_ref().map(|m| m["frames_recorded"].clone()),
                    "analysed": report.is_some(),
                    "e": report.as_ref().map(|r| r["e"].clone()),
                })
            })
            .collect::<Vec<Value>>()
    })
    .await
    .unwrap_or_default();
    Json(json!({ "sessions": listed })).into_response()
}

/// `GET /api/sessions/{name}`: the manifest and the report (null before analysis).
pub(super) async fn one(State(state): State<Shared>, Path(name): Path<String>) -> Response {
    let dir = match session_dir(&state, &name) {
        Ok(d) => d,
        Err((status, message)) => return error(status, message),
    };
    Json(json!({
        "name": name,
        "manifest": read_json(&dir.join("session.json")),
        "report": read_json(&dir.join("report.json")),
    }))
    .into_response()
}

/// `GET /api/sessions/{name}/report.json`: the report as recorded, for download.
pub(super) async fn report(State(state): State<Shared>, Path(name): Path<String>) -> Response {
    let dir = match session_dir(&state, &name) {
        Ok(d) => d,
        Err((status, message)) => return error(status, message),
    };
    match std::fs::read(dir.join("report.json")) {
        Ok(bytes) => (
            [
                ("content-type", "application/json"),
                (
                    "content-disposition",
                    "attachment; filename=\"report.json\"",
                ),
            ],
            bytes,
        )
            .into_response(),
        Err(_) => error(
            StatusCode::NOT_FOUND,
            format!("session {name} has no report.json (not analysed)"),
        ),
    }
}

/// `GET /api/sessions/{name}/trajectory.svg` and `…/residuals.svg`: the fitted trajectories
/// with the measured centres, and each centre's residual from its fit, per axis and phase.
pub(super) async fn figure(
    State(state): State<Shared>,
    Path((name, file)): Path<(String, String)>,
) -> Response {
    let dir = match session_dir(&state, &name) {
        Ok(d) => d,
        Err((status, message)) => return error(status, message),
    };
    let Some(report) =
        read_json(&dir.join("report.json")).and_then(|v| serde_json::from_value::<Report>(v).ok())
    else {
        return error(
            StatusCode::NOT_FOUND,
            format!("session {name} has no report.json (not analysed)"),
        );
    };
    // The session's own g, as its analysis used.
    let g = read_json(&dir.join("session.json"))
        .and_then(|m| m["config"]["analysis"]["gravity_mm_s2"].as_f64())
        .unwrap_or(state.cfg.analysis.gravity_mm_s2);
    let (svg, _) = match file.as_str() {
        "trajectory.svg" => crate::figures::trajectory::trajectory_plot(&report, g),
        "residuals.svg" => crate::figures::trajectory::residual_plot(&report, g),
        other => {
            return error(
                StatusCode::NOT_FOUND,
                format!(
                    "{other:?}: expected trajectory.svg, residuals.svg, report.json or frames.tif"
                ),
            )
        }
    };
    ([("content-type", "image/svg+xml")], svg).into_response()
}

/// `GET /api/sessions/{name}/frames.tif`: every frame as a multi-page TIFF with ImageJ's frame
/// interval, for download. Written to a temporary file (unlinked once open) and streamed from
/// it, so a long recording is never held in memory.
pub(super) async fn tiff(State(state): State<Shared>, Path(name): Path<String>) -> Response {
    let dir = match session_dir(&state, &name) {
        Ok(d) => d,
        Err((status, message)) => return error(status, message),
    };
    let exported = tokio::task::spawn_blocking(move || -> Result<std::fs::File, String> {
        let tmp = std::env::temp_dir().join(format!(
            "impactcam-export-{}-{}.tif",
            std::process::id(),
            EXPORTS.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
        ));
        let mut reader = crate::session::SessionReader::open(&dir).map_err(|e| e.to_string())?;
        let written = crate::session::tiff::export_session(&mut reader, &tmp)
            .map_err(|e| e.to_string())
            .and_then(|_| std::fs::File::open(&tmp).map_err(|e| e.to_string()));
        let _ = std::fs::remove_file(&tmp);
        written
    })
    .await;
    let mut file = match exported {
        Ok(Ok(f)) => f,
        Ok(Err(e)) => {
            return error(
                StatusCode::INTERNAL_SERVER_ERROR,
                format!("TIFF export: {e}"),
            )
        }
        Err(e) => return error(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()),
    };
    // Its length is known: sent whole, not chunked, so a download shows its progress.
    let length = file.metadata().map(|m| m.len()).unwrap_or(0);
    let (tx, rx) = tokio::sync::mpsc::channel::<Result<Vec<u8>, std::io::Error>>(4);
    tokio::task::spawn_blocking(move || {
        use std::io::Read;
        loop {
            let mut chunk = vec![0u8; 1 << 20];
            match file.read(&mut chunk) {
                Ok(0) => break,
                Ok(n) => {
                    chunk.truncate(n);
                    if tx.blocking_send(Ok(chunk)).is_err() {
                        break;
                    }
                }
                Err(e) => {
                    let _ = tx.blocking_send(Err(e));
                    break;
                }
            }
        }
    });
    (
        [
            ("content-type", "image/tiff".to_string()),
            ("content-length", length.to_string()),
            (
                "content-disposition",
                format!("attachment; filename=\"{name}.tif\""),
            ),
        ],
        axum::body::Body::from_stream(tokio_stream::wrappers::ReceiverStream::new(rx)),
    )
        .into_response()
}

/// Temporary TIFF exports made so far: part of each one's unique name.
static EXPORTS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// `GET /api/sessions/{name}/frames/{k}.png[?overlay=1]`: frame k (0-based, in recording order)
/// as a PNG; with the overlay, the views' regions (yellow; magenta where the frame has a view
/// not measured, with the reasons in the report's `quality.unmeasured`), the fitted
/// trajectories (light blue and light red), the measured circles and centres (a blue, b red),
/// the markers found (green) and those of the nearest other frame carried here by the fitted
/// spins (orange), and a red border on the impact frame.
pub(super) async fn frame(
    State(state): State<Shared>,
    Path((name, file)): Path<(String, String)>,
    uri: Uri,
) -> Response {
    let dir = match session_dir(&state, &name) {
        Ok(d) => d,
        Err((status, message)) => return error(status, message),
    };
    let Some(k) = file
        .strip_suffix(".png")
        .and_then(|n| n.parse::<usize>().ok())
    else {
        return error(
            StatusCode::BAD_REQUEST,
            format!("{file:?}: expected FRAME.png with FRAME a frame number from 0"),
        );
    };
    // The one query key, read by hand (no query-string parser in the tree for one flag).
    let overlay = uri.query().is_some_and(|q| {
        q.split('&')
            .any(|kv| kv == "overlay=1" || kv == "overlay=true")
    });
    let png = tokio::task::spawn_blocking(move || draw_frame(&dir, k, overlay)).await;
    match png {
        Ok(Ok(bytes)) => ([("content-type", "image/png")], bytes).into_response(),
        Ok(Err((status, e))) => error(status, e),
        Err(e) => error(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()),
    }
}

fn draw_frame(
    dir: &std::path::Path,
    k: usize,
    overlay: bool,
) -> Result<Vec<u8>, (StatusCode, String)> {
    let (mut r, cfg) = frame_raster(dir, k)?;
    if overlay {
        let report: Option<Report> = std::fs::read_to_string(dir.join("report.json"))
            .ok()
            .and_then(|t| serde_json::from_str(&t).ok());
        draw_overlay(&mut r, &cfg, report.as_ref(), k);
    }
    r.png()
        .map_err(|e| (StatusCode::INTERNAL_SERVER_ERROR, e.to_string()))
}

/// Frame `k` of the session in `dir` as a raster to draw on, and the session's config; 404
/// for a frame it does not have.
pub(super) fn frame_raster(
    dir: &std::path::Path,
    k: usize,
) -> Result<(Raster, crate::config::Config), (StatusCode, String)> {
    let internal = |e: String| (StatusCode::INTERNAL_SERVER_ERROR, e);
    let mut reader =
        crate::session::SessionReader::open(dir).map_err(|e| internal(e.to_string()))?;
    if k >= reader.frames.len() {
        return Err((
            StatusCode::NOT_FOUND,
            format!(
                "frame {k}: the session has {} frames (0 to {})",
                reader.frames.len(),
                reader.frames.len().saturating_sub(1)
            ),
        ));
    }
    let mut raw = Vec::new();
    reader
        .read_frame(k, &mut raw)
        .map_err(|e| internal(e.to_string()))?;
    let mut img = crate::analysis::image::GreyImage::new();
    img.load(
        &raw,
        reader.width as usize,
        reader.height as usize,
        reader.bytes_per_pixel,
    );
    Ok((
        Raster::from_grey(img.width, img.height, &img.data),
        reader.config().clone(),
    ))
}

fn draw_overlay(r: &mut Raster, cfg: &crate::config::Config, report: Option<&Report>, k: usize) {
    const YELLOW: [u8; 3] = [230, 200, 40];
    const MAGENTA: [u8; 3] = [220, 40, 220];
    let views = crate::analysis::geometry::views(cfg);
    for v in &views {
        let not_measured = report.is_some_and(|rep| {
            rep.quality
                .unmeasured
                .iter()
                .any(|u| u.frame as usize == k && u.view == v.kind.name())
        });
        let [x, y, w, h] = v.region.map(f64::from);
        let c = if not_measured { MAGENTA } else { YELLOW };
        r.rect((x + 0.5, y + 0.5), (x + w - 0.5, y + h - 0.5), c, 0.5);
    }
    let Some(rep) = report else { return };
    // The fitted trajectories, through the pre-impact fit's centre at the impact, over the
    // frames where the sphere was tracked: before the impact with the velocity before, after it
    // with the velocity after.
    let g = cfg.analysis.gravity_mm_s2;
    let t_c = rep.impact.time_s.value;
    for (s, colour) in [
        (&rep.spheres.a, [120u8, 170, 230]),
        (&rep.spheres.b, [240, 130, 130]),
    ] {
        let Some(p_c) = s.position_impact_mm.as_ref() else {
            continue;
        };
        let at = |t: f64| {
            let v = if t < t_c {
                s.velocity_pre_mm_s.value
            } else {
                s.velocity_post_mm_s.value
            };
            let dt = t - t_c;
            nalgebra::Vector3::new(
                p_c.value[0] + v[0] * dt,
                p_c.value[1] + v[1] * dt - 0.5 * g * dt * dt,
                p_c.value[2] + v[2] * dt,
            )
        };
        let sphere_is = |t: &crate::analysis::report::TrackFrame| {
            if std::ptr::eq(s, &rep.spheres.a) {
                t.a.is_some()
            } else {
                t.b.is_some()
            }
        };
        let times: Vec<f64> = rep
            .tracks
            .iter()
            .filter(|t| sphere_is(t))
            .map(|t| t.time_s)
            .collect();
        for v in &views {
            let pts: Vec<[f64; 2]> = times.iter().map(|&t| v.project(&at(t))).collect();
            for w in pts
                .windows(2)
                .filter(|w| w.iter().all(|p| v.contains(p[0], p[1])))
            {
                r.line(
                    (w[0][0] + 0.5, w[0][1] + 0.5),
                    (w[1][0] + 0.5, w[1][1] + 0.5),
                    colour,
                    0.3,
                );
            }
        }
    }
    for t in rep.tracks.iter().filter(|t| t.frame as usize == k) {
        for (track, colour) in [(&t.a, [31u8, 119, 180]), (&t.b, [214, 39, 40])] {
            for v in track.iter().flat_map(|s| [&s.direct, &s.mirror]).flatten() {
                let c = (v.centre_px[0] + 0.5, v.centre_px[1] + 0.5);
                if v.diameter_px.is_finite() {
                    r.circle(c, v.diameter_px / 2.0, colour, false);
                }
                r.line((c.0 - 1.5, c.1), (c.0 + 1.5, c.1), colour, 0.5);
                r.line((c.0, c.1 - 1.5), (c.0, c.1 + 1.5), colour, 0.5);
                for m in &v.markers_px {
                    r.circle((m[0] + 0.5, m[1] + 0.5), 1.0, [44, 160, 44], false);
                }
            }
        }
    }
    // The markers of the nearest other frame, carried here by the fitted spins (orange): on
    // the markers found when the spin fits them.
    let radii = [0, 1].map(|i| cfg.spheres.sphere(i).0 / 2.0);
    for m in crate::figures::carried::carried(rep, &views, radii, k)
        .iter()
        .flatten()
    {
        r.circle((m[0] + 0.5, m[1] + 0.5), 1.6, [255, 140, 0], false);
    }
    if rep.impact.frame as usize == k {
        let (w, h) = (r.width() as f64, r.height() as f64);
        let red = [214, 39, 40];
        r.rect((0.5, 0.5), (w - 0.5, h - 0.5), red, 1.0);
    }
}
