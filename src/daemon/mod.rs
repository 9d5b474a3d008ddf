//! The lab daemon (`impactcam serve`): an HTTP API and a web page to run and watch experiments.
//! It owns request handling, the one-experiment-at-a-time rule (a second request gets 409, never
//! a queue that fires later), progress events (server-sent events), the bearer token off
//! loopback, and shutdown on SIGTERM / Ctrl-C (the running experiment is aborted through the
//! same flag as Ctrl-C on the command line, so the relay is released and the session kept).
//! Experiments run on blocking threads through `experiment::run`; the daemon touches no device.

use crate::config::Config;
use crate::experiment::{self, Event as ExpEvent};
use crate::recorder::Progress;
use axum::body::Bytes;
use axum::extract::{DefaultBodyLimit, Path, State};
use axum::http::{HeaderMap, StatusCode};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use serde::Deserialize;
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use tokio::sync::broadcast;
use tokio_stream::wrappers::BroadcastStream;
use tokio_stream::StreamExt;

const PAGE: &str = include_str!("page.html");
const MAX_BODY_BYTES: usize = 16 * 1024;

#[derive(Debug, thiserror::Error)]
pub enum DaemonError {
    #[error("--listen {addr}: {message}")]
    Listen { addr: String, message: String },
}

/// Overrides a request may give for one experiment.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Overrides {
    /// Free text kept with the experiment.
    pub notes: Option<String>,
    /// Recorded as a label (the tube angle is set by hand on a real rig; in the simulator it is
    /// the simulated angle).
    pub tube_angle_deg: Option<f64>,
    /// recording.frames for this experiment.
    pub frames: Option<u32>,
}

struct Record {
    status: &'static str,
    error: Option<String>,
    /// The report stays on disk (report.json in the session) and is read when asked for: a
    /// daemon that runs for months must not hold every report in memory.
    session: Option<String>,
    notes: Option<String>,
    events: Vec<Value>,
}

struct AppState {
    cfg: Config,
    token: Option<String>,
    experiments: Mutex<BTreeMap<String, Record>>,
    running: Mutex<Option<(String, tokio::task::JoinHandle<()>)>>,
    abort: Arc<AtomicBool>,
    events: broadcast::Sender<(String, Value)>,
    last_error: Mutex<Option<String>>,
    next_id: Mutex<u64>,
}

type Shared = Arc<AppState>;

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

fn error(status: StatusCode, message: impl Into<String>) -> Response {
    (status, Json(json!({ "error": message.into() }))).into_response()
}

/// Runs the daemon until SIGTERM or Ctrl-C. `ready` is told the bound address.
pub fn serve(
    cfg: Config,
    listen: &str,
    ready: &mut dyn FnMut(SocketAddr),
) -> Result<(), DaemonError> {
    let addr: SocketAddr = listen.parse().map_err(|e| DaemonError::Listen {
        addr: listen.into(),
        message: format!("not an address: {e}"),
    })?;
    let token = std::env::var("IMPACTCAM_TOKEN")
        .ok()
        .filter(|t| !t.is_empty())
        .or_else(|| cfg.daemon.token.clone());
    if !addr.ip().is_loopback() && token.is_none() {
        return Err(DaemonError::Listen {
            addr: listen.into(),
            message: "not a loopback address, and no token: set daemon.token or IMPACTCAM_TOKEN (anyone who can reach it could fire the relay)".into(),
        });
    }
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| DaemonError::Listen {
            addr: listen.into(),
            message: e.to_string(),
        })?;
    rt.block_on(async move {
        let listener =
            tokio::net::TcpListener::bind(addr)
                .await
                .map_err(|e| DaemonError::Listen {
                    addr: listen.into(),
                    message: e.to_string(),
                })?;
        let bound = listener.local_addr().map_err(|e| DaemonError::Listen {
            addr: listen.into(),
            message: e.to_string(),
        })?;
        let (events, _) = broadcast::channel(1024);
        let state = Arc::new(AppState {
            cfg,
            token,
            experiments: Mutex::new(BTreeMap::new()),
            running: Mutex::new(None),
            abort: Arc::new(AtomicBool::new(false)),
            events,
            last_error: Mutex::new(None),
            next_id: Mutex::new(1),
        });
        let app = Router::new()
            .route("/", get(|| async { Html(PAGE) }))
            .route("/api/status", get(status))
            .route("/api/experiments", post(start).get(list))
            .route("/api/experiments/{id}", get(one))
            .route("/api/experiments/{id}/events", get(events_sse))
            .route("/api/experiments/{id}/trajectory.svg", get(trajectory))
            .route("/api/experiments/{id}/impact.png", get(impact_frame))
            .layer(DefaultBodyLimit::max(MAX_BODY_BYTES))
            .with_state(state.clone());
        tracing::info!(%bound, "listening");
        ready(bound);
        let shutdown_state = state.clone();
        axum::serve(listener, app)
            .with_graceful_shutdown(async move {
                shutdown_signal().await;
                tracing::info!("shutting down: aborting any running experiment");
                shutdown_state.abort.store(true, Ordering::SeqCst);
                let running = lock(&shutdown_state.running).take();
                if let Some((_, handle)) = running {
                    let _ = handle.await;
                }
            })
            .await
            .map_err(|e| DaemonError::Listen {
                addr: listen.into(),
                message: e.to_string(),
            })
    })
}

async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    tokio::select! {
        _ = ctrl_c => {},
        _ = term => {},
    }
}

fn authorised(state: &AppState, headers: &HeaderMap) -> bool {
    match &state.token {
        None => true,
        Some(t) => headers
            .get("authorization")
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.strip_prefix("Bearer "))
            .is_some_and(|given| given == t),
    }
}

fn progress_json(ev: &ExpEvent) -> Value {
    match ev {
        ExpEvent::Recorder(Progress::Armed { frames_seen }) => {
            json!({"stage": "armed", "frames_seen": frames_seen})
        }
        ExpEvent::Recorder(Progress::Fired { session }) => {
            json!({"stage": "fired", "session": session.file_name().map(|s| s.to_string_lossy().into_owned())})
        }
        ExpEvent::Recorder(Progress::Frames { recorded, total }) => {
            json!({"stage": "recording", "frames_recorded": recorded, "frames_total": total})
        }
        ExpEvent::Recorder(Progress::Finished { recorded, dropped }) => {
            json!({"stage": "recorded", "frames_recorded": recorded, "frames_dropped": dropped})
        }
        ExpEvent::Analysing {
            frames_done,
            frames_total,
        } => {
            json!({"stage": "analysing", "frames_done": frames_done, "frames_total": frames_total})
        }
    }
}

async fn start(State(state): State<Shared>, headers: HeaderMap, body: Bytes) -> Response {
    if !authorised(&state, &headers) {
        return error(
            StatusCode::UNAUTHORIZED,
            "this request fires the relay: send Authorization: Bearer <token>",
        );
    }
    let overrides: Overrides = if body.iter().all(|b| b.is_ascii_whitespace()) {
        Overrides::default()
    } else {
        match serde_json::from_slice(&body) {
            Ok(o) => o,
            Err(e) => return error(StatusCode::BAD_REQUEST, format!("request body: {e}")),
        }
    };
    let mut cfg = state.cfg.clone();
    if let Some(f) = overrides.frames {
        cfg.recording.frames = f;
    }
    if let Some(a) = overrides.tube_angle_deg {
        cfg.sim.tube_angle_deg = a;
    }
    if let Err(e) = cfg.validate() {
        return error(StatusCode::BAD_REQUEST, format!("request body: {e}"));
    }
    let mut running = lock(&state.running);
    if let Some((id, handle)) = running.as_ref() {
        if !handle.is_finished() {
            return error(
                StatusCode::CONFLICT,
                format!("experiment {id} is running; one at a time"),
            );
        }
    }
    let id = {
        let mut n = lock(&state.next_id);
        let id = format!("{:04}", *n);
        *n += 1;
        id
    };
    lock(&state.experiments).insert(
        id.clone(),
        Record {
            status: "running",
            error: None,
            session: None,
            notes: overrides.notes,
            events: Vec::new(),
        },
    );
    state.abort.store(false, Ordering::SeqCst);
    let st = state.clone();
    let run_id = id.clone();
    let handle = tokio::task::spawn_blocking(move || {
        let mut on_event = |ev: ExpEvent| {
            let v = progress_json(&ev);
            if let Some(r) = lock(&st.experiments).get_mut(&run_id) {
                if let ExpEvent::Recorder(Progress::Fired { session }) = &ev {
                    r.session = session
                        .file_name()
                        .map(|s| s.to_string_lossy().into_owned());
                }
                r.events.push(v.clone());
            }
            let _ = st.events.send((run_id.clone(), v));
        };
        let result = experiment::run(&cfg, st.abort.clone(), &mut on_event);
        let (status, err) = match result {
            Ok(_) => ("done", None),
            Err(e) => ("failed", Some(e.to_string())),
        };
        if let Some(e) = &err {
            *lock(&st.last_error) = Some(e.clone());
        }
        let final_event = json!({"stage": status, "error": err});
        if let Some(r) = lock(&st.experiments).get_mut(&run_id) {
            r.status = status;
            r.error = err;
            r.events.push(final_event.clone());
        }
        let _ = st.events.send((run_id, final_event));
    });
    *running = Some((id.clone(), handle));
    (StatusCode::ACCEPTED, Json(json!({ "id": id }))).into_response()
}

fn record_json(id: &str, r: &Record) -> Value {
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

async fn one(State(state): State<Shared>, Path(id): Path<String>) -> Response {
    let found = lock(&state.experiments)
        .get(&id)
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

async fn list(State(state): State<Shared>) -> Response {
    let all: Vec<Value> = lock(&state.experiments)
        .iter()
        .map(|(id, r)| record_json(id, r))
        .collect();
    Json(json!({ "experiments": all })).into_response()
}

async fn status(State(state): State<Shared>) -> Response {
    let running = lock(&state.running)
        .as_ref()
        .filter(|(_, h)| !h.is_finished())
        .map(|(id, _)| id.clone());
    let c = &state.cfg;
    Json(json!({
        "camera": {"backend": c.camera.backend, "device": c.camera.device, "width": c.camera.width, "height": c.camera.height, "frame_rate_hz": c.camera.frame_rate_hz},
        "trigger": {"backend": c.trigger.backend, "port": c.trigger.port},
        "sessions_dir": c.recording.dir,
        "running": running,
        "last_error": *lock(&state.last_error),
    }))
    .into_response()
}

async fn events_sse(State(state): State<Shared>, Path(id): Path<String>) -> Response {
    // Subscribe before copying the history, so nothing falls between the two.
    let live = BroadcastStream::new(state.events.subscribe());
    let past: Vec<Value> = match lock(&state.experiments).get(&id) {
        Some(r) => r.events.clone(),
        None => return error(StatusCode::NOT_FOUND, format!("no experiment {id}")),
    };
    let want = id.clone();
    let history = tokio_stream::iter(
        past.into_iter()
            .map(|v| Ok::<_, std::convert::Infallible>(Event::default().data(v.to_string()))),
    );
    let updates = live.filter_map(move |m| match m {
        Ok((eid, v)) if eid == want => Some(Ok(Event::default().data(v.to_string()))),
        _ => None,
    });
    Sse::new(history.chain(updates))
        .keep_alive(KeepAlive::default())
        .into_response()
}

async fn trajectory(State(state): State<Shared>, Path(id): Path<String>) -> Response {
    let report = lock(&state.experiments)
        .get(&id)
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
        crate::campaign::plot::trajectory_plot(&report, state.cfg.analysis.gravity_mm_s2);
    ([("content-type", "image/svg+xml")], svg).into_response()
}

/// The recorded frame nearest the impact, with the detected circles drawn (a blue, b red).
async fn impact_frame(State(state): State<Shared>, Path(id): Path<String>) -> Response {
    let found = lock(&state.experiments)
        .get(&id)
        .and_then(|r| Some((report_of(&state, r)?, r.session.clone()?)));
    let Some((report, session)) = found else {
        return error(
            StatusCode::NOT_FOUND,
            format!("experiment {id} has no report"),
        );
    };
    let dir = state.cfg.recording.dir.join(session);
    let png = tokio::task::spawn_blocking(move || -> Result<Vec<u8>, String> {
        use crate::campaign::canvas::{Canvas, Raster};
        let report: crate::analysis::report::Report =
            serde_json::from_value(report).map_err(|e| e.to_string())?;
        let mut reader = crate::session::SessionReader::open(&dir).map_err(|e| e.to_string())?;
        let k = report.impact.frame as usize;
        let mut raw = Vec::new();
        reader.read_frame(k, &mut raw).map_err(|e| e.to_string())?;
        let mut img = crate::analysis::image::GreyImage::new();
        img.load(
            &raw,
            reader.width as usize,
            reader.height as usize,
            reader.bytes_per_pixel,
        );
        let mut r = Raster::from_grey(img.width, img.height, &img.data);
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
