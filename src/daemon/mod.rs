//! The lab daemon (`impactcam serve`): an HTTP API and a web page to run and watch experiments.
//! It owns request handling, the one-experiment-at-a-time rule (a second request gets 409, never
//! a queue that fires later), progress events (server-sent events), the bearer token off
//! loopback, and shutdown on SIGTERM / Ctrl-C (the running experiment is aborted through the
//! same flag as Ctrl-C on the command line, so the relay is released and the session kept).
//! The rig (camera and relay) is opened once at start and kept from one experiment to the next;
//! after an error that may have left a device in a bad state (a disconnect, a relay that stopped
//! answering) it is closed, and opened again before the next experiment. Experiments run on
//! blocking threads through `experiment::run_on`; the daemon itself never drives a device.

mod campaigns;
pub mod guard;
mod listen;
mod live;
mod sessions;
mod views;

use crate::config::Config;
use crate::experiment::{self, Event as ExpEvent, ExperimentError, Rig};
use crate::recorder::Progress;
use axum::body::Bytes;
use axum::extract::{DefaultBodyLimit, Request, State};
use axum::http::{Method, StatusCode};
use axum::middleware::Next;
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

const PAGE: &str = include_str!("page.html");
/// Shown at `/` to a browser without the token: a form that posts it to `/api/login`.
const LOGIN_PAGE: &str = include_str!("login.html");
/// Connections served at once; more are closed as they arrive.
const MAX_CONNECTIONS: usize = 64;
/// A client that has not sent a whole request head within this is disconnected.
const HEADER_READ_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(5);
/// After SIGTERM / Ctrl-C, how long open connections (event streams) may take to end.
const SHUTDOWN_GRACE: std::time::Duration = std::time::Duration::from_millis(300);
const MAX_BODY_BYTES: usize = 16 * 1024;
const MAX_EXPERIMENTS_LISTED: usize = 10_000;

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
    /// The campaign the experiment belongs to (`experiment.campaign`).
    pub campaign: Option<String>,
}

struct Record {
    status: &'static str,
    error: Option<String>,
    /// The report stays on disk (report.json in the session) and is read when asked for: a
    /// daemon that runs for months must not hold every report in memory.
    session: Option<String>,
    notes: Option<String>,
    /// (stage, event as JSON text): one per stage, the latest; kept as text because a daemon
    /// that runs for months keeps one of these per experiment.
    events: Vec<(String, String)>,
}

/// What `/api/status` says of the devices.
#[derive(Default)]
struct RigHealth {
    open: bool,
    opened_times: u64,
    /// Why the rig is closed, when it is.
    error: Option<String>,
}

struct AppState {
    cfg: Config,
    /// The open devices; held by the running experiment for its whole length.
    rig: Mutex<Option<Rig>>,
    rig_health: Mutex<RigHealth>,
    guard: guard::RequestGuard,
    experiments: Mutex<BTreeMap<IdKey, Record>>,
    running: Mutex<Option<(String, tokio::task::JoinHandle<()>)>>,
    abort: Arc<AtomicBool>,
    /// (experiment id, event as JSON text)
    events: broadcast::Sender<(Arc<str>, Arc<str>)>,
    last_error: Mutex<Option<String>>,
    next_id: Mutex<u64>,
    /// The latest live-view frame.
    live: live::Live,
}

type Shared = Arc<AppState>;

/// Ids are zero-padded counters ("0001", …, "10000"): ordered by length, then text, they are in
/// the order they were given.
type IdKey = (usize, String);

fn key(id: &str) -> IdKey {
    (id.len(), id.to_string())
}

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
    let token = match std::env::var("IMPACTCAM_TOKEN") {
        Ok(t) if !t.is_empty() => {
            crate::config::check_token(&t).map_err(|e| DaemonError::Listen {
                addr: listen.into(),
                message: format!("IMPACTCAM_TOKEN: {e}"),
            })?;
            Some(t)
        }
        _ => cfg.daemon.token.clone(),
    };
    if !addr.ip().is_loopback() && token.is_none() {
        return Err(DaemonError::Listen {
            addr: listen.into(),
            message: "not a loopback address, and no token: set daemon.token or IMPACTCAM_TOKEN (anyone who can reach it could fire the relay)".into(),
        });
    }
    limit_malloc_arenas();
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
            cfg: cfg.clone(),
            rig: Mutex::new(None),
            rig_health: Mutex::new(RigHealth::default()),
            guard: guard::RequestGuard::new(bound, &cfg.daemon.allowed_hosts, token),
            experiments: Mutex::new(BTreeMap::new()),
            running: Mutex::new(None),
            abort: Arc::new(AtomicBool::new(false)),
            events,
            last_error: Mutex::new(None),
            next_id: Mutex::new(1),
            live: live::Live::default(),
        });
        // A panic on any thread aborts the running experiment at once: its relay pulse watches
        // this flag every millisecond (`trigger::raise_on_panic`). The next experiment lowers it.
        crate::trigger::raise_on_panic(state.abort.clone());
        let app = Router::new()
            .route("/", get(|| async { Html(PAGE) }))
            .route("/api/status", get(views::status))
            .route("/api/experiments", post(start).get(views::list))
            .route("/api/experiments/{id}", get(views::one))
            .route("/api/experiments/{id}/events", get(views::events_sse))
            .route("/api/experiments/{id}/trajectory.svg", get(views::trajectory))
            .route("/api/experiments/{id}/impact.png", get(views::impact_frame))
            .route("/api/camera/frame.png", get(live::frame_png))
            .route("/api/camera/overlay.json", get(live::overlay_json))
            .route("/api/camera/live", get(live::live_stream))
            .route("/api/config", get(views::config))
            .route("/api/devices", get(views::devices))
            .route("/api/sessions", get(sessions::list))
            .route("/api/sessions/{name}", get(sessions::one))
            .route("/api/sessions/{name}/report.json", get(sessions::report))
            .route("/api/sessions/{name}/frames/{file}", get(sessions::frame))
            .route("/api/sessions/{name}/frames.tif", get(sessions::tiff))
            .route("/api/sessions/{name}/{figure}", get(sessions::figure))
            .route("/api/campaigns", get(campaigns::list))
            .route("/api/campaigns/{name}", get(campaigns::one))
            .route("/api/campaigns/{name}/psi.svg", get(campaigns::psi_svg))
            .route("/api/campaigns/{name}/collisions.csv", get(campaigns::csv))
            .route("/api/login", post(login))
            .layer(DefaultBodyLimit::max(MAX_BODY_BYTES))
            .layer(axum::middleware::from_fn_with_state(state.clone(), refuse_forged))
            .with_state(state.clone());
        {
            let st = state.clone();
            // A rig that cannot be opened now is retried when an experiment is asked for; the
            // daemon still starts, so the page can say what is wrong.
            let _ = tokio::task::spawn_blocking(move || {
                let mut slot = lock(&st.rig);
                if let Err(e) = ensure_rig(&st, &mut slot) {
                    tracing::warn!(error = %e, "cannot open the rig; will retry on the next experiment");
                }
            })
            .await;
        }
        tracing::info!(%bound, "listening");
        ready(bound);
        let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
        let server = tokio::spawn(listen::accept_loop(listener, app, stop_rx, listen::Limits {
            max_connections: MAX_CONNECTIONS,
            header_read_timeout: HEADER_READ_TIMEOUT,
            shutdown_grace: SHUTDOWN_GRACE,
        }));
        shutdown_signal().await;
        tracing::info!("shutting down: aborting any running experiment");
        // Stop accepting and end open connections (event streams included) first: they must
        // not hold the exit up.
        let _ = stop_tx.send(true);
        state.abort.store(true, Ordering::SeqCst);
        let running = lock(&state.running).take();
        if let Some((_, handle)) = running {
            let _ = handle.await;
        }
        // Close the devices now rather than whenever the last reference goes.
        drop(lock(&state.rig).take());
        tracing::info!("rig closed");
        let _ = tokio::time::timeout(SHUTDOWN_GRACE * 2, server).await;
        Ok(())
    })
}

/// Refuses what a browser could forge (see `guard`), and anything without the token when one
/// is set; a browser without it gets the login page at `/`.
async fn refuse_forged(State(state): State<Shared>, req: Request, next: Next) -> Response {
    if let Err(guard::Refusal(code, message)) = state.guard.check(req.method(), req.headers()) {
        return error(
            StatusCode::from_u16(code).unwrap_or(StatusCode::BAD_REQUEST),
            message,
        );
    }
    if !state.guard.authorised(req.headers()) {
        let path = req.uri().path();
        if path == "/api/login" {
            return next.run(req).await;
        }
        if req.method() == Method::GET && path == "/" {
            return Html(LOGIN_PAGE).into_response();
        }
        return error(
            StatusCode::UNAUTHORIZED,
            "this daemon needs its token: send Authorization: Bearer <token>, or log in on the page",
        );
    }
    next.run(req).await
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Login {
    token: String,
}

/// `POST /api/login {"token"}`: sets the token as an HttpOnly, same-site cookie, so the page
/// never holds it in its URL or its script.
async fn login(State(state): State<Shared>, body: Bytes) -> Response {
    let Ok(login) = serde_json::from_slice::<Login>(&body) else {
        return error(
            StatusCode::BAD_REQUEST,
            "request body: expected {\"token\": \"...\"}",
        );
    };
    if !state.guard.token_required() {
        return StatusCode::NO_CONTENT.into_response();
    }
    if !state.guard.token_matches(&login.token) {
        // Slows guessing; the token's length already makes it hopeless.
        tokio::time::sleep(std::time::Duration::from_millis(250)).await;
        return error(StatusCode::UNAUTHORIZED, "wrong token");
    }
    (
        StatusCode::NO_CONTENT,
        [(
            axum::http::header::SET_COOKIE,
            format!(
                "{}={}; HttpOnly; SameSite=Strict; Path=/",
                guard::TOKEN_COOKIE,
                login.token
            ),
        )],
    )
        .into_response()
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

/// glibc gives threads their own malloc arenas, and each experiment's acquisition and analysis
/// threads leave freed memory scattered over them: `bench soak` measured the daemon's RSS
/// growing about 25 KiB per experiment with the default arenas and 2 KiB with two.
fn limit_malloc_arenas() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets an allocator parameter; called before the runtime's threads.
    unsafe {
        libc::mallopt(libc::M_ARENA_MAX, 2);
    }
}

/// The open rig, opened (again) first when there is none or it lost its camera.
fn ensure_rig<'a>(
    st: &AppState,
    slot: &'a mut Option<Rig>,
) -> Result<&'a mut Rig, ExperimentError> {
    if let Some(rig) = slot.take().filter(|r| r.camera.is_some()) {
        return Ok(slot.insert(rig));
    }
    // The old devices are dropped (closed) before opening: a serial port or a camera cannot be
    // opened twice.
    match Rig::open(&st.cfg) {
        Ok(rig) => {
            let mut h = lock(&st.rig_health);
            h.open = true;
            h.opened_times += 1;
            h.error = None;
            tracing::info!(opened_times = h.opened_times, camera = ?st.cfg.camera.backend, trigger = ?st.cfg.trigger.backend, "rig opened");
            Ok(slot.insert(rig))
        }
        Err(e) => {
            let mut h = lock(&st.rig_health);
            h.open = false;
            h.error = Some(e.to_string());
            Err(e)
        }
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

async fn start(State(state): State<Shared>, body: Bytes) -> Response {
    let (cfg, overrides) = match experiment_config(&body, &state.cfg) {
        Ok(x) => x,
        Err(e) => return error(StatusCode::BAD_REQUEST, format!("request body: {e}")),
    };
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
    let mut experiments = lock(&state.experiments);
    // The sessions stay on disk; the daemon's own list keeps the most recent ones, so months of
    // running do not grow its memory without bound.
    while experiments.len() >= MAX_EXPERIMENTS_LISTED {
        experiments.pop_first();
    }
    experiments.insert(
        key(&id),
        Record {
            status: "running",
            error: None,
            session: None,
            notes: overrides.notes.clone(),
            events: Vec::new(),
        },
    );
    drop(experiments);
    state.abort.store(false, Ordering::SeqCst);
    let notes_for_log = overrides.notes.clone();
    let st = state.clone();
    let run_id = id.clone();
    let handle = tokio::task::spawn_blocking(move || {
        let mut on_event = |ev: ExpEvent| {
            if let ExpEvent::Analysing {
                frames_done,
                frames_total,
            } = ev
            {
                // Every tenth frame is progress enough for a page, as for recording.
                if !frames_done.is_multiple_of(10) && frames_done != frames_total {
                    return;
                }
            }
            let v = progress_json(&ev);
            if let Some(r) = lock(&st.experiments).get_mut(&key(&run_id)) {
                if let ExpEvent::Recorder(Progress::Fired { session }) = &ev {
                    r.session = session
                        .file_name()
                        .map(|s| s.to_string_lossy().into_owned());
                }
                // The history replayed to late subscribers keeps one event per stage (the
                // latest progress), so a long-running daemon does not keep every frame's.
                let stage = v["stage"].as_str().unwrap_or_default();
                match r.events.last_mut() {
                    Some(last) if last.0 == stage => last.1 = v.to_string(),
                    _ => r.events.push((stage.to_string(), v.to_string())),
                }
            }
            let _ = st
                .events
                .send((Arc::from(run_id.as_str()), Arc::from(v.to_string())));
        };
        tracing::info!(id = %run_id, notes = notes_for_log.as_deref().unwrap_or(""), frames = cfg.recording.frames, "experiment started");
        let result = {
            let mut slot = lock(&st.rig);
            let result = ensure_rig(&st, &mut slot)
                .and_then(|rig| experiment::run_on(rig, &cfg, st.abort.clone(), &mut on_event));
            if let Err(e) = &result {
                if e.rig_suspect() && slot.take().is_some() {
                    let mut h = lock(&st.rig_health);
                    h.open = false;
                    h.error = Some(e.to_string());
                    tracing::warn!(error = %e, "rig closed after this error; it is reopened before the next experiment");
                }
            }
            result
        };
        let (status, err) = match result {
            Ok((rec, report)) => {
                tracing::info!(
                    id = %run_id,
                    session = %rec.session_dir.display(),
                    frames_recorded = rec.frames_recorded,
                    frames_dropped = rec.frames_dropped,
                    e = report.e.as_ref().map(|e| e.value),
                    e_uncertainty = report.e.as_ref().map(|e| e.uncertainty),
                    "experiment done"
                );
                ("done", None)
            }
            Err(e) => {
                tracing::error!(id = %run_id, error = %e, "experiment failed");
                ("failed", Some(e.to_string()))
            }
        };
        if let Some(e) = &err {
            *lock(&st.last_error) = Some(e.clone());
        }
        let final_event = json!({"stage": status, "error": err});
        if let Some(r) = lock(&st.experiments).get_mut(&key(&run_id)) {
            r.status = status;
            r.error = err;
            r.events.push((status.to_string(), final_event.to_string()));
        }
        let _ = st.events.send((
            Arc::from(run_id.as_str()),
            Arc::from(final_event.to_string()),
        ));
    });
    *running = Some((id.clone(), handle));
    (StatusCode::ACCEPTED, Json(json!({ "id": id }))).into_response()
}

/// The config of one experiment: `base` with the request body's overrides (JSON, or empty for
/// none), validated like any config — so every size a request can set is bounded before it
/// reaches the recorder.
pub fn experiment_config(body: &[u8], base: &Config) -> Result<(Config, Overrides), String> {
    let overrides: Overrides = if body.iter().all(|b| b.is_ascii_whitespace()) {
        Overrides::default()
    } else {
        serde_json::from_slice(body).map_err(|e| e.to_string())?
    };
    let mut cfg = base.clone();
    if let Some(f) = overrides.frames {
        cfg.recording.frames = f;
    }
    if let Some(a) = overrides.tube_angle_deg {
        cfg.sim.tube_angle_deg = a;
        cfg.experiment.tube_angle_deg = Some(a);
    }
    // The label goes into the session's manifest with the config; empty fields are no label.
    let nonblank = |s: &Option<String>| s.as_ref().filter(|s| !s.trim().is_empty()).cloned();
    if let Some(n) = nonblank(&overrides.notes) {
        cfg.experiment.notes = Some(n);
    }
    if let Some(c) = nonblank(&overrides.campaign) {
        cfg.experiment.campaign = Some(c.trim().to_string());
    }
    cfg.validate()?;
    Ok((cfg, overrides))
}
