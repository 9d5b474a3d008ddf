//! The read-only routes: experiments and their reports (read from the sessions on disk, not
//! held in memory), the status of the rig and the disk, progress as server-sent events, and the
//! figures of an experiment (trajectory plot, the frame at impact with the circles drawn).

use super::{error, key, lock, AppState, Record, Shared};
use axum::extract::{Path, State};
use axum::http::StatusCode;
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde_json::{json, Value};
use tokio_stream::wrappers::BroadcastStream;
use tokio_stream::StreamExt;

pub(super) fn record_json(id: &str, r: &Record) -> Value {
    let mut v = json!({"id": id, "status": r.status, "session": r.session, "notes": r.notes});
    if let Some(e) = &r.error {
        v["error"] = json!(e);
    }
    v
}

/// The report of a finished experiment, from its session on disk.
fn report_of(state: &AppState, r: &Record) -> Option<Value> {
    if r.status != "done" {
        return None;
    }
    let path = state
        .cfg
        .recording
        .dir
        .join(r.session.as_ref()?)
        .join("report.json");
    serde_json::from_str(&std::fs::read_to_string(path).ok()?).ok()
}

pub(super) async fn one(State(state): State<Shared>, Path(id): Path<String>) -> Response {
    let found = lock(&state.experiments)
        .get(&key(&id))
        .map(|r| (record_json(&id, r), report_of(&state, r)));
    match found {
        Some((mut v, report)) => {
            if let Some(rep) = report {
                v["report"] = rep;
            }
            Json(v).into_response()
        }
        None => error(StatusCode::NOT_FOUND, format!("no experiment {id}")),
    }
}

pub(super) async fn list(State(state): State<Shared>) -> Response {
    let all: Vec<Value> = lock(&state.experiments)
        .iter()
        .map(|((_, id), r)| record_json(id, r))
        .collect();
    Json(json!({ "experiments": all })).into_response()
}

pub(super) async fn status(State(state): State<Shared>) -> Response {
    let running = lock(&state.running)
        .as_ref()
        .filter(|(_, h)| !h.is_finished())
        .map(|(id, _)| id.clone());
    let c = &state.cfg;
    let (rig_state, opened_times, rig_error) = {
        let h = lock(&state.rig_health);
        (
            if h.open { "open" } else { "closed" },
            h.opened_times,
            h.error.clone(),
        )
    };
    let disk = match crate::session::disk::disk_space(&c.recording.dir) {
        Ok((free, total)) => json!({"free_bytes": free, "total_bytes": total}),
        Err(e) => json!({"error": e}),
    };
    Json(json!({
        "camera": {"backend": c.camera.backend, "device": c.camera.device, "width": c.camera.width, "height": c.camera.height, "frame_rate_hz": c.camera.frame_rate_hz, "state": rig_state, "opened_times": opened_times, "error": rig_error},
        "trigger": {"backend": c.trigger.backend, "port": c.trigger.port, "state": rig_state, "error": rig_error},
        "sessions_dir": c.recording.dir,
        "disk": disk,
        "running": running,
        "last_error": *lock(&state.last_error),
    }))
    .into_response()
}

pub(super) async fn events_sse(State(state): State<Shared>, Path(id): Path<String>) -> Response {
    // Subscribe before copying the history, so nothing falls between the two.
    let live = BroadcastStream::new(state.events.subscribe());
    let past: Vec<String> = match lock(&state.experiments).get(&key(&id)) {
        Some(r) => r.events.iter().map(|(_, text)| text.clone()).collect(),
        None => return error(StatusCode::NOT_FOUND, format!("no experiment {id}")),
    };
    let want = id.clone();
    let history = tokio_stream::iter(
        past.into_iter()
            .map(|text| Ok::<_, std::convert::Infallible>(Event::default().data(text))),
    );
    let updates = live.filter_map(move |m| match m {
        Ok((eid, text)) if *eid == *want => Some(Ok(Event::default().data(&*text))),
        _ => None,
    });
    Sse::new(history.chain(updates))
        .keep_alive(KeepAlive::default())
        .into_response()
}

pub(super) async fn trajectory(State(state): State<Shared>, Path(id): Path<String>) -> Response {
    let report = lock(&state.experiments)
        .get(&key(&id))
        .and_then(|r| report_of(&state, r));
    let Some(report) =
        report.and_then(|v| serde_json::from_value::<crate::analysis::report::Report>(v).ok())
    else {
        return error(
            StatusCode::NOT_FOUND,
            format!("experiment {id} has no report"),
        );
    };
    let (svg, _) =
        crate::figures::trajectory::trajectory_plot(&report, state.cfg.analysis.gravity_mm_s2);
    ([("content-type", "image/svg+xml")], svg).into_response()
}

/// The recorded frame nearest the impact, with the detected circles drawn (a blue, b red).
pub(super) async fn impact_frame(State(state): State<Shared>, Path(id): Path<String>) -> Response {
    let found = lock(&state.experiments)
        .get(&key(&id))
        .and_then(|r| Some((report_of(&state, r)?, r.session.clone()?)));
    let Some((report, session)) = found else {
        return error(
            StatusCode::NOT_FOUND,
            format!("experiment {id} has no report"),
        );
    };
    let dir = state.cfg.recording.dir.join(session);
    let png = tokio::task::spawn_blocking(move || -> Result<Vec<u8>, String> {
        use crate::figures::canvas::Canvas;
        let report: crate::analysis::report::Report =
            serde_json::from_value(report).map_err(|e| e.to_string())?;
        let k = report.impact.frame as usize;
        let (mut r, _) = super::sessions::frame_raster(&dir, k).map_err(|(_, e)| e)?;
        // Circles from the frames around the impact, so both spheres show even when merged.
        for t in report
            .tracks
            .iter()
            .filter(|t| (t.frame as i64 - k as i64).abs() <= 3)
        {
            for (track, colour) in [(&t.a, [31u8, 119, 180]), (&t.b, [214, 39, 40])] {
                for v in track.iter().flat_map(|s| [&s.direct, &s.mirror]).flatten() {
                    if t.frame as usize == k || v.diameter_px.is_finite() {
                        r.circle(
                            (v.centre_px[0] + 0.5, v.centre_px[1] + 0.5),
                            v.diameter_px / 2.0,
                            colour,
                            false,
                        );
                    }
                }
            }
        }
        r.png().map_err(|e| e.to_string())
    })
    .await;
    match png {
        Ok(Ok(bytes)) => ([("content-type", "image/png")], bytes).into_response(),
        Ok(Err(e)) => error(StatusCode::INTERNAL_SERVER_ERROR, e),
        Err(e) => error(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()),
    }
}

/// `GET /api/config`: the config in use, read-only, without the token.
pub(super) async fn config(State(state): State<Shared>) -> Response {
    let mut cfg = state.cfg.clone();
    let had_token = cfg.daemon.token.take().is_some();
    let mut v = serde_json::to_value(&cfg).unwrap_or(Value::Null);
    if had_token {
        v["daemon"]["token"] = json!("(set, not shown)");
    }
    Json(v).into_response()
}

/// `GET /api/devices`: the camera backends built in and the serial ports (relay modules). No
/// network discovery here: it broadcasts, and would disturb a GigE camera the rig holds open
/// (`impactcam devices` does it).
pub(super) async fn devices(State(state): State<Shared>) -> Response {
    let ports = tokio::task::spawn_blocking(|| match serialport::available_ports() {
        Ok(ports) => json!(ports
            .iter()
            .map(|p| json!({"port": p.port_name, "type": format!("{:?}", p.port_type)}))
            .collect::<Vec<_>>()),
        Err(e) => json!({"error": e.to_string()}),
    })
    .await
    .unwrap_or(Value::Null);
    let mut backends = vec!["sim"];
    if cfg!(feature = "aravis") {
        backends.push("aravis");
    }
    if cfg!(feature = "v4l") {
        backends.push("v4l");
    }
    Json(json!({
        "camera_backends": backends,
        "gpio": cfg!(feature = "gpio"),
        "serial_ports": ports,
        "in_use": {"camera": state.cfg.camera.backend, "trigger": state.cfg.trigger.backend, "port": state.cfg.trigger.port},
    }))
    .into_response()
}
