//! The lab daemon over real HTTP on loopback: the API contract, one experiment at a time,
//! progress events, validation, the token, and shutdown on SIGTERM.

mod common;

use std::io::{Read, Write};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

struct Daemon {
    child: Child,
    addr: String,
    _dir: tempfile::TempDir,
}

impl Daemon {
    fn start(env_token: Option<&str>, config: &str) -> Daemon {
        Daemon::start_with(env_token, config, &[])
    }

    /// The daemon's log (stderr) goes to `daemon.log` in its directory.
    fn start_with(env_token: Option<&str>, config: &str, args: &[&str]) -> Daemon {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("c.toml"), config).unwrap();
        let log = std::fs::File::create(dir.path().join("daemon.log")).unwrap();
        let mut all = vec!["--config", "c.toml"];
        all.extend_from_slice(args);
        let (child, addr) = common::spawn_daemon(dir.path(), &all, env_token, Stdio::from(log));
        Daemon {
            child,
            addr,
            _dir: dir,
        }
    }

    fn dir(&self) -> &std::path::Path {
        self._dir.path()
    }

    /// (status, body)
    fn request(&self, method: &str, path: &str, body: &str, auth: Option<&str>) -> (u16, String) {
        let auth = auth
            .map(|t| format!("Authorization: Bearer {t}\r\n"))
            .unwrap_or_default();
        let host = format!("Host: {}\r\n", self.addr);
        let headers = format!("{host}{auth}Content-Type: application/json\r\n");
        self.raw(method, path, &headers, body)
    }

    /// (status, body) of a request with exactly these header lines (each ending in CRLF).
    fn raw(&self, method: &str, path: &str, headers: &str, body: &str) -> (u16, String) {
        let (status, bytes) = self.raw_bytes(method, path, headers, body);
        (status, String::from_utf8_lossy(&bytes).into_owned())
    }

    /// (status, body bytes) of a request with exactly these header lines.
    fn raw_bytes(&self, method: &str, path: &str, headers: &str, body: &str) -> (u16, Vec<u8>) {
        let mut s = TcpStream::connect(&self.addr).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
        write!(s, "{method} {path} HTTP/1.1\r\nConnection: close\r\n{headers}Content-Length: {}\r\n\r\n{body}", body.len()).unwrap();
        let mut out = Vec::new();
        s.read_to_end(&mut out).unwrap();
        let head_end = out
            .windows(4)
            .position(|w| w == b"\r\n\r\n")
            .unwrap_or(out.len());
        let head = String::from_utf8_lossy(&out[..head_end]).into_owned();
        let status = head
            .split_whitespace()
            .nth(1)
            .and_then(|c| c.parse().ok())
            .unwrap_or(0);
        (status, out[(head_end + 4).min(out.len())..].to_vec())
    }

    /// (status, body bytes) of a GET.
    fn get_bytes(&self, path: &str) -> (u16, Vec<u8>) {
        self.raw_bytes("GET", path, &format!("Host: {}\r\n", self.addr), "")
    }

    fn start_experiment(&self, body: &str) -> String {
        let (code, body) = self.request("POST", "/api/experiments", body, None);
        assert_eq!(code, 202, "{body}");
        serde_json::from_str::<serde_json::Value>(&body).unwrap()["id"]
            .as_str()
            .unwrap()
            .to_string()
    }

    fn json(&self, path: &str) -> serde_json::Value {
        let (code, body) = self.request("GET", path, "", None);
        assert_eq!(code, 200, "{path}: {body}");
        serde_json::from_str(&body).unwrap()
    }

    fn wait_done(&self, id: &str) -> serde_json::Value {
        let t0 = Instant::now();
        loop {
            let v = self.json(&format!("/api/experiments/{id}"));
            if v["status"] != "running" {
                return v;
            }
            assert!(
                t0.elapsed() < Duration::from_secs(60),
                "experiment {id} did not finish"
            );
            std::thread::sleep(Duration::from_millis(100));
        }
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[test]
fn the_api_runs_one_experiment_at_a_time_and_reports_it() {
    let d = Daemon::start(None, "");
    let (code, page) = d.request("GET", "/", "", None);
    assert_eq!(code, 200);
    assert!(page.contains("id=\"run\"") && page.contains("EventSource"));
    let (code, body) = d.request("POST", "/api/experiments", r#"{"notes": "first"}"#, None);
    assert_eq!(code, 202, "{body}");
    let id = serde_json::from_str::<serde_json::Value>(&body).unwrap()["id"]
        .as_str()
        .unwrap()
        .to_string();
    let (code, body) = d.request("POST", "/api/experiments", "", None);
    assert_eq!(
        code, 409,
        "a second experiment must be refused, not queued: {body}"
    );
    assert_eq!(d.json("/api/status")["running"], id.as_str());
    let done = d.wait_done(&id);
    assert_eq!(done["status"], "done", "{done}");
    let e = done["report"]["e"]["value"].as_f64().unwrap();
    assert!((e - 0.9).abs() < 0.02, "e {e}");
    assert_eq!(
        d.json("/api/experiments")["experiments"][0]["notes"],
        "first"
    );
    let (code, svg) = d.request(
        "GET",
        &format!("/api/experiments/{id}/trajectory.svg"),
        "",
        None,
    );
    assert!(code == 200 && svg.contains("<svg"));
    // The progress stream replays what happened, through to the end.
    let mut s = TcpStream::connect(&d.addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    write!(
        s,
        "GET /api/experiments/{id}/events HTTP/1.1\r\nHost: {}\r\n\r\n",
        d.addr
    )
    .unwrap();
    let mut seen = String::new();
    let mut buf = [0u8; 4096];
    while !seen.contains("\"stage\":\"done\"") {
        let n = s.read(&mut buf).unwrap();
        assert!(n > 0, "stream ended early: {seen}");
        seen.push_str(&String::from_utf8_lossy(&buf[..n]));
    }
    // Each stage once: the history a daemon keeps is the latest progress of each stage, not
    // every frame's (that was most of its memory growth per experiment).
    for stage in ["armed", "fired", "recording", "analysing", "done"] {
        assert_eq!(
            seen.matches(&format!("\"stage\":\"{stage}\"")).count(),
            1,
            "{stage} once in {seen}"
        );
    }
    // A session was written where the config says, and the status says how much room is left
    // for the next ones.
    assert!(d.dir().join("sessions").read_dir().unwrap().count() == 1);
    let status = d.json("/api/status");
    let free = status["disk"]["free_bytes"].as_u64().expect("free_bytes");
    let total = status["disk"]["total_bytes"].as_u64().expect("total_bytes");
    assert!(free > 0 && free <= total, "{status}");
}

#[test]
fn the_rig_is_opened_once_and_kept_between_experiments() {
    let d = Daemon::start(None, "");
    let first = d.start_experiment("");
    assert_eq!(d.wait_done(&first)["status"], "done");
    let second = d.start_experiment(r#"{"tube_angle_deg": 40}"#);
    assert_eq!(d.wait_done(&second)["status"], "done");
    let status = d.json("/api/status");
    assert_eq!(status["camera"]["state"], "open", "{status}");
    assert_eq!(status["camera"]["opened_times"], 1, "{status}");
    // The kept simulated lab was loaded again for the second firing, with its tube angle.
    let mut truths: Vec<serde_json::Value> = std::fs::read_dir(d.dir().join("sessions"))
        .unwrap()
        .map(|e| common::read_json(&e.unwrap().path().join("truth.json")))
        .collect();
    truths.sort_by(|a, b| {
        a["release_time_s"]
            .as_f64()
            .partial_cmp(&b["release_time_s"].as_f64())
            .unwrap()
    });
    assert_eq!(truths.len(), 2);
    for t in &truths {
        let closings = t["relay_events"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|e| e["closed"] == true)
            .count();
        assert_eq!(
            closings, 1,
            "each session's truth has its own firing: {}",
            t["relay_events"]
        );
    }
    let speed = |t: &serde_json::Value| {
        let v = &t["spheres"]["a"]["pre"]["velocity_mm_s"];
        (0..3)
            .map(|i| v[i].as_f64().unwrap().powi(2))
            .sum::<f64>()
            .sqrt()
    };
    assert!(
        (speed(&truths[0]) - speed(&truths[1])).abs() > 1.0,
        "a steeper tube gives a faster sphere: {} vs {} mm/s",
        speed(&truths[0]),
        speed(&truths[1])
    );
}

#[test]
fn a_disconnected_camera_is_reopened_for_the_next_experiment() {
    // The simulated camera drops off the bus after 800 frames: the first experiment (1000
    // frames) loses it; a camera kept open would fail every later one. The count includes the
    // frames streamed while arming and during the preflight, so the second experiment (280
    // frames) leaves half a second for those (a slow preflight on a busy machine once took a
    // 280-frame experiment past a limit of 320).
    let d = Daemon::start(None, "[sim]\ndisconnect_after_frames = 800\n");
    let first = d.start_experiment(r#"{"frames": 1000}"#);
    let failed = d.wait_done(&first);
    assert_eq!(failed["status"], "failed", "{failed}");
    let status = d.json("/api/status");
    assert_eq!(status["camera"]["state"], "closed", "{status}");
    assert!(
        status["camera"]["error"]
            .as_str()
            .unwrap()
            .contains("disconnected"),
        "{status}"
    );
    let second = d.start_experiment("");
    let done = d.wait_done(&second);
    assert_eq!(done["status"], "done", "{done}");
    let status = d.json("/api/status");
    assert_eq!(status["camera"]["state"], "open", "{status}");
    assert_eq!(status["camera"]["opened_times"], 2, "{status}");
}

#[test]
fn logs_can_be_json_lines_with_the_experiment_in_them() {
    let mut d = Daemon::start_with(None, "", &["--log-format", "json"]);
    let id = d.start_experiment(r#"{"notes": "log me"}"#);
    assert_eq!(d.wait_done(&id)["status"], "done");
    let _ = Command::new("kill")
        .args(["-TERM", &d.child.id().to_string()])
        .status();
    let _ = d.child.wait();
    let log = std::fs::read_to_string(d.dir().join("daemon.log")).unwrap();
    let lines: Vec<serde_json::Value> = log
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("not JSON ({e}): {l}")))
        .collect();
    let done = lines
        .iter()
        .find(|l| l["message"] == "experiment done")
        .unwrap_or_else(|| panic!("no 'experiment done' in {log}"));
    assert_eq!(done["id"], id.as_str());
    assert_eq!(done["level"], "INFO");
    assert!((done["e"].as_f64().unwrap() - 0.9).abs() < 0.02, "{done}");
    assert!(done["session"].as_str().unwrap().contains("sessions"));
    assert!(lines.iter().any(|l| l["message"] == "rig closed"), "{log}");
}

#[test]
fn bad_requests_get_a_400_that_names_the_problem() {
    let d = Daemon::start(None, "");
    let (code, body) = d.request("POST", "/api/experiments", r#"{"nots": "x"}"#, None);
    assert_eq!(code, 400);
    assert!(body.contains("nots"), "{body}");
    let (code, body) = d.request("POST", "/api/experiments", r#"{"frames": 1}"#, None);
    assert_eq!(code, 400);
    assert!(body.contains("recording.frames"), "{body}");
    let big = format!("{{\"notes\": \"{}\"}}", "x".repeat(64 * 1024));
    let (code, _) = d.request("POST", "/api/experiments", &big, None);
    assert_eq!(code, 413);
    let (code, _) = d.request("GET", "/api/experiments/9999", "", None);
    assert_eq!(code, 404);
}

#[test]
fn a_token_guards_firing_and_is_required_off_loopback() {
    let d = Daemon::start(Some("0123456789abcdef-token"), "");
    let (code, _) = d.request("POST", "/api/experiments", "", None);
    assert_eq!(code, 401);
    let (code, _) = d.request(
        "POST",
        "/api/experiments",
        "",
        Some("wrong-token-wrong-token"),
    );
    assert_eq!(code, 401);
    let (code, body) = d.request(
        "POST",
        "/api/experiments",
        "",
        Some("0123456789abcdef-token"),
    );
    assert_eq!(code, 202, "{body}");
    // Every route needs it, the scheme in any case; the page gets a login form instead.
    let token = "0123456789abcdef-token";
    let host = format!("Host: {}\r\n", d.addr);
    assert_eq!(d.request("GET", "/api/status", "", None).0, 401);
    assert_eq!(d.request("GET", "/api/experiments/0001", "", None).0, 401);
    let bearer = format!("{host}Authorization: bEaReR {token}\r\n");
    assert_eq!(d.raw("GET", "/api/status", &bearer, "").0, 200);
    let (code, page) = d.raw("GET", "/", &host, "");
    assert_eq!(code, 200);
    assert!(
        page.contains("/api/login") && !page.contains("api/experiments"),
        "{page}"
    );
    // Logging in sets an HttpOnly cookie that then opens every route.
    let (code, _) = d.request(
        "POST",
        "/api/login",
        r#"{"token": "wrong-token-wrong-token"}"#,
        None,
    );
    assert_eq!(code, 401);
    let mut s = TcpStream::connect(&d.addr).unwrap();
    let body = format!("{{\"token\": \"{token}\"}}");
    write!(s, "POST /api/login HTTP/1.1\r\n{host}Connection: close\r\nContent-Type: application/json\r\nContent-Length: {}\r\n\r\n{body}", body.len()).unwrap();
    let mut answer = String::new();
    s.read_to_string(&mut answer).unwrap();
    assert!(answer.starts_with("HTTP/1.1 204"), "{answer}");
    let cookie_line = answer
        .lines()
        .find(|l| l.to_ascii_lowercase().starts_with("set-cookie:"))
        .unwrap_or_default()
        .to_string();
    assert!(
        cookie_line.contains("HttpOnly") && cookie_line.contains("SameSite=Strict"),
        "{cookie_line}"
    );
    let cookie = cookie_line
        .split_once(':')
        .unwrap()
        .1
        .split(';')
        .next()
        .unwrap()
        .trim()
        .to_string();
    let with_cookie = format!("{host}Cookie: {cookie}\r\n");
    assert_eq!(d.raw("GET", "/api/status", &with_cookie, "").0, 200);
    let (code, page) = d.raw("GET", "/", &with_cookie, "");
    assert!(code == 200 && page.contains("api/experiments"));
    // A short token from the environment is refused like one in the config.
    let out = Command::new(env!("CARGO_BIN_EXE_impactcam"))
        .args(["serve", "--listen", "127.0.0.1:0"])
        .env("IMPACTCAM_TOKEN", "short")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("IMPACTCAM_TOKEN"));
    // Refused before binding anything.
    let out = Command::new(env!("CARGO_BIN_EXE_impactcam"))
        .args(["serve", "--listen", "0.0.0.0:0"])
        .env_remove("IMPACTCAM_TOKEN")
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("token"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn sigterm_aborts_the_running_experiment_safely_and_exits_0() {
    let mut d = Daemon::start(None, "[recording]\nframes = 5000\n");
    let (code, body) = d.request("POST", "/api/experiments", "", None);
    assert_eq!(code, 202, "{body}");
    // Let it fire and record a while.
    let t0 = Instant::now();
    while d.json("/api/experiments/0001")["session"].is_null() {
        assert!(t0.elapsed() < Duration::from_secs(10));
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_millis(300));
    assert!(Command::new("kill")
        .args(["-TERM", &d.child.id().to_string()])
        .status()
        .unwrap()
        .success());
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = d.child.try_wait().unwrap() {
            break s;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(15),
            "daemon did not exit after SIGTERM"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    assert_eq!(status.code(), Some(0));
    let session = common::first_session(d.dir());
    let m = common::read_json(&session.join("session.json"));
    assert_eq!(m["status"], "incomplete", "{m}");
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(session.join("truth.json")).unwrap())
            .unwrap();
    assert_eq!(
        truth["relay_events"].as_array().unwrap().last().unwrap()["closed"],
        false
    );
}

/// What a web page open on the lab PC could send: none of it may start an experiment (the
/// relay would fire) or read a report.
#[test]
fn requests_a_browser_could_forge_are_refused_and_nothing_fires() {
    let d = Daemon::start(None, "");
    let host = format!("Host: {}\r\n", d.addr);
    let cases: [(&str, String, &str, u16); 6] = [
        (
            "text/plain {} (no preflight)",
            format!("{host}Content-Type: text/plain\r\n"),
            "{}",
            415,
        ),
        (
            "empty form",
            format!("{host}Content-Type: application/x-www-form-urlencoded\r\n"),
            "",
            415,
        ),
        ("no content type", host.clone(), "{}", 415),
        (
            "foreign origin",
            format!("{host}Content-Type: application/json\r\nOrigin: http://evil.example\r\n"),
            "{}",
            403,
        ),
        (
            "null origin",
            format!("{host}Content-Type: application/json\r\nOrigin: null\r\n"),
            "{}",
            403,
        ),
        (
            "rebound host",
            "Host: evil.example:80\r\nContent-Type: application/json\r\n".into(),
            "{}",
            421,
        ),
    ];
    for (what, headers, body, want) in cases {
        let (code, answer) = d.raw("POST", "/api/experiments", &headers, body);
        assert_eq!(code, want, "{what}: {answer}");
        assert!(!answer.contains("\"id\""), "{what}: {answer}");
    }
    let port = d.addr.rsplit_once(':').unwrap().1;
    let (code, _) = d.raw(
        "GET",
        "/api/experiments",
        &format!("Host: evil.example:{port}\r\n"),
        "",
    );
    assert_eq!(code, 421, "DNS rebinding must not read reports");
    // Nothing started, nothing recorded.
    assert_eq!(
        d.json("/api/experiments")["experiments"],
        serde_json::json!([])
    );
    assert!(!d.dir().join("sessions").exists());
    // The page's own request (same origin, JSON) still works.
    let own = format!(
        "{host}Content-Type: application/json\r\nOrigin: http://{}\r\n",
        d.addr
    );
    let (code, answer) = d.raw("POST", "/api/experiments", &own, "{}");
    assert_eq!(code, 202, "{answer}");
    // No CORS: a preflight gets no Access-Control-Allow-Origin.
    let mut s = TcpStream::connect(&d.addr).unwrap();
    write!(s, "OPTIONS /api/experiments HTTP/1.1\r\n{host}Origin: http://evil.example\r\nAccess-Control-Request-Method: POST\r\nConnection: close\r\n\r\n").unwrap();
    let mut answer = String::new();
    s.read_to_string(&mut answer).unwrap();
    assert!(
        !answer.to_ascii_lowercase().contains("access-control-allow"),
        "{answer}"
    );
    d.wait_done("0001");
}

/// Idle sockets are closed after the header-read timeout, and connections past the limit are
/// closed at once; the daemon still answers afterwards.
#[test]
fn idle_connections_time_out_and_are_limited() {
    let d = Daemon::start(None, "");
    let idle: Vec<TcpStream> = (0..80)
        .map(|_| TcpStream::connect(&d.addr).unwrap())
        .collect();
    let t0 = Instant::now();
    let mut closed = 0;
    for mut s in idle {
        s.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
        let mut buf = [0u8; 64];
        // 0 bytes (or a reset) means the daemon closed it; a read timeout means it did not.
        match s.read(&mut buf) {
            Ok(0) => closed += 1,
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => closed += 1,
            _ => {}
        }
    }
    assert_eq!(closed, 80, "every idle socket must be closed");
    assert!(
        t0.elapsed() < Duration::from_secs(15),
        "closed after {:?}",
        t0.elapsed()
    );
    assert_eq!(d.json("/api/status")["running"], serde_json::Value::Null);
}

/// An open event stream (the page keeps one) must not hold up shutdown.
#[test]
fn sigterm_exits_within_a_second_with_an_event_stream_open() {
    let mut d = Daemon::start(None, "[recording]\nframes = 40\n");
    let id = d.start_experiment("{}");
    d.wait_done(&id);
    let mut s = TcpStream::connect(&d.addr).unwrap();
    write!(
        s,
        "GET /api/experiments/{id}/events HTTP/1.1\r\nHost: {}\r\n\r\n",
        d.addr
    )
    .unwrap();
    let mut buf = [0u8; 4096];
    assert!(s.read(&mut buf).unwrap() > 0);
    let t0 = Instant::now();
    assert!(Command::new("kill")
        .args(["-TERM", &d.child.id().to_string()])
        .status()
        .unwrap()
        .success());
    let status = loop {
        if let Some(st) = d.child.try_wait().unwrap() {
            break st;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(5),
            "daemon did not exit after SIGTERM"
        );
        std::thread::sleep(Duration::from_millis(10));
    };
    let took = t0.elapsed();
    assert_eq!(status.code(), Some(0));
    assert!(took < Duration::from_secs(1), "exit took {took:?}");
}

/// The session viewer's routes: every session listed, its report, and any frame as a PNG, the
/// overlay drawing the measurement on it; names that would leave the sessions directory, and
/// frames that do not exist, are refused with a message.
#[test]
fn sessions_are_listed_and_their_frames_drawn_with_the_measurement() {
    let d = Daemon::start(None, "");
    let id = d.start_experiment("{}");
    let done = d.wait_done(&id);
    assert_eq!(done["status"], "done", "{done}");
    let session = done["session"].as_str().unwrap().to_string();

    let list = d.json("/api/sessions");
    let listed = list["sessions"].as_array().unwrap();
    assert!(
        listed.iter().any(|s| s["name"] == session.as_str()
            && s["analysed"] == true
            && s["e"]["value"].is_f64()),
        "{list}"
    );
    let one = d.json(&format!("/api/sessions/{session}"));
    assert_eq!(one["manifest"]["status"], "complete");
    let k = one["report"]["impact"]["frame"].as_u64().unwrap();

    let (code, raw) = d.get_bytes(&format!("/api/sessions/{session}/frames/{k}.png"));
    assert_eq!(code, 200);
    assert!(raw.starts_with(b"\x89PNG"), "a PNG");
    let (code, drawn) = d.get_bytes(&format!("/api/sessions/{session}/frames/{k}.png?overlay=1"));
    assert_eq!(code, 200);
    assert!(drawn.starts_with(b"\x89PNG"));
    assert_ne!(raw, drawn, "the overlay draws on the impact frame");

    for figure in ["trajectory.svg", "residuals.svg"] {
        let (code, svg) = d.get_bytes(&format!("/api/sessions/{session}/{figure}"));
        assert_eq!(code, 200, "{figure}");
        assert!(String::from_utf8_lossy(&svg).contains("<svg"), "{figure}");
    }
    // The TIFF download: every frame, with ImageJ's frame interval.
    let (code, tif) = d.get_bytes(&format!("/api/sessions/{session}/frames.tif"));
    assert_eq!(code, 200);
    let path = d.dir().join("download.tif");
    std::fs::write(&path, &tif).unwrap();
    let stack = impactcam::footage::open(&path, None).unwrap();
    assert_eq!(
        stack.len() as u64,
        one["manifest"]["frames_recorded"].as_u64().unwrap()
    );
    assert_eq!(stack.info().frame_rate_hz, Some(1000.0));
    let (code, report) = d.get_bytes(&format!("/api/sessions/{session}/report.json"));
    assert_eq!(code, 200);
    let on_disk =
        std::fs::read(d.dir().join("sessions").join(&session).join("report.json")).unwrap();
    assert_eq!(report, on_disk);

    for (path, want, says) in [
        (
            "/api/sessions/..%2F..%2Fetc/frames/0.png",
            400,
            "not a session name",
        ),
        ("/api/sessions/.hidden", 400, "not a session name"),
        ("/api/sessions/a%2Fb/report.json", 400, "not a session name"),
        ("/api/sessions/nosuch", 404, "no session nosuch"),
    ] {
        let (code, body) = d.request("GET", path, "", None);
        assert_eq!(code, want, "{path}: {body}");
        assert!(body.contains(says), "{path}: {body}");
    }
    let (code, body) = d.request(
        "GET",
        &format!("/api/sessions/{session}/frames/99999.png"),
        "",
        None,
    );
    assert_eq!(code, 404, "{body}");
    assert!(body.contains("frames (0 to"), "{body}");
    let (code, body) = d.request(
        "GET",
        &format!("/api/sessions/{session}/frames/x.png"),
        "",
        None,
    );
    assert_eq!(code, 400, "{body}");
}

/// The rig on the page: the config in use, read-only and without the token, and the devices.
#[test]
fn the_config_in_use_and_the_devices_are_shown_without_the_token() {
    let token = "tok-0123456789abcdef";
    let d = Daemon::start(None, &format!("[daemon]\ntoken = \"{token}\"\n"));
    let (code, body) = d.request("GET", "/api/config", "", Some(token));
    assert_eq!(code, 200, "{body}");
    assert!(!body.contains(token), "the token is not shown: {body}");
    let cfg: serde_json::Value = serde_json::from_str(&body).unwrap();
    assert_eq!(cfg["camera"]["width"], 240);
    assert_eq!(cfg["daemon"]["token"], "(set, not shown)");
    // Without the token, nothing.
    let (code, _) = d.request("GET", "/api/config", "", None);
    assert_eq!(code, 401);
    let (code, body) = d.request("GET", "/api/devices", "", Some(token));
    assert_eq!(code, 200, "{body}");
    let dev: serde_json::Value = serde_json::from_str(&body).unwrap();
    assert!(dev["camera_backends"]
        .as_array()
        .unwrap()
        .iter()
        .any(|b| b == "sim"));
    assert_eq!(dev["in_use"]["camera"], "sim");
    assert!(
        dev["serial_ports"].is_array() || dev["serial_ports"]["error"].is_string(),
        "{dev}"
    );
}

/// Live view: the current frame as a PNG (two grabs differ, the sensor's noise), what the
/// analysis sees in it with the exposure, a multipart stream at about 10 frames a second, and
/// a pause (409) while an experiment records.
#[test]
fn live_view_shows_the_camera_while_idle_and_pauses_while_recording() {
    let d = Daemon::start(None, "");
    let (code, a) = d.get_bytes("/api/camera/frame.png");
    assert_eq!(code, 200);
    assert!(a.starts_with(b"\x89PNG"));
    std::thread::sleep(Duration::from_millis(150));
    let (_, b) = d.get_bytes("/api/camera/frame.png?overlay=1");
    assert!(b.starts_with(b"\x89PNG"));
    assert_ne!(a, b, "a later frame, drawn on");
    // Without the drawing too: the camera is grabbed again, not a cached frame served.
    std::thread::sleep(Duration::from_millis(150));
    let (_, c) = d.get_bytes("/api/camera/frame.png");
    assert!(c.starts_with(b"\x89PNG"));
    assert_ne!(a, c, "a later raw frame differs (the sensor's noise)");
    let overlay = d.json("/api/camera/overlay.json");
    let views = overlay["measured"].as_array().unwrap();
    assert_eq!(views.len(), 2, "{overlay}");
    for v in views {
        let e = &v["exposure"];
        assert!(e["saturated_percent"].as_f64().unwrap() >= 0.0, "{v}");
        let pixels: u64 = e["histogram_16_bins"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_u64().unwrap())
            .sum();
        assert_eq!(pixels, 240 * 96, "{v}");
        // The simulator's preview holds both spheres in view: two circles, each with its edge
        // width (the focus figure).
        let circles = v["circles"].as_array().unwrap();
        assert_eq!(circles.len(), 2, "{v}");
        assert!(
            circles.iter().all(|c| c["edge_width_px"]
                .as_f64()
                .is_some_and(|w| w > 0.0 && w < 6.0)),
            "{v}"
        );
    }
    // Both views see x: the default rig's mirror agrees with the direct view well inside a pixel.
    let pairs = overlay["mirror_x_agreement"]["pairs"].as_array().unwrap();
    assert_eq!(pairs.len(), 2, "{overlay}");
    for p in pairs {
        assert!(p["difference_px"].as_f64().unwrap().abs() < 0.3, "{p}");
    }

    // The stream: parts arrive about every 100 ms.
    let mut s = TcpStream::connect(&d.addr).unwrap();
    s.set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    write!(
        s,
        "GET /api/camera/live HTTP/1.1\r\nHost: {}\r\n\r\n",
        d.addr
    )
    .unwrap();
    let t0 = Instant::now();
    let mut got = Vec::new();
    let mut buf = [0u8; 65536];
    while t0.elapsed() < Duration::from_millis(1200) {
        if let Ok(n) = s.read(&mut buf) {
            got.extend_from_slice(&buf[..n]);
        }
    }
    drop(s);
    let parts = got.windows(7).filter(|w| w == b"--frame").count();
    assert!(parts >= 5, "{parts} frames in 1.2 s");
    assert!(
        String::from_utf8_lossy(&got[..200.min(got.len())]).contains("multipart/x-mixed-replace")
    );

    // While an experiment records, live view pauses rather than take the camera.
    std::thread::sleep(Duration::from_millis(150));
    let id = d.start_experiment("{}");
    let (code, body) = d.request("GET", "/api/camera/frame.png", "", None);
    assert_eq!(code, 409, "{body}");
    assert!(body.contains("pauses"), "{body}");
    let done = d.wait_done(&id);
    assert_eq!(done["status"], "done", "{done}");
    let m = d.json(&format!(
        "/api/sessions/{}",
        done["session"].as_str().unwrap()
    ));
    assert_eq!(
        m["manifest"]["frames_dropped"], 0,
        "live view cost no recorded frame"
    );
    let (code, _) = d.get_bytes("/api/camera/frame.png");
    assert_eq!(code, 200, "live again once it is done");
}

/// Campaigns: experiments labelled with a campaign (and their tube angle and notes, kept in the
/// manifest) are grouped, fitted as `impactcam fit` fits them, plotted and tabled.
#[test]
fn experiments_grouped_by_campaign_are_fitted_plotted_and_tabled() {
    let d = Daemon::start(None, "");
    assert_eq!(d.json("/api/campaigns")["campaigns"], serde_json::json!([]));
    let mut sessions = Vec::new();
    for (angle, notes) in [(30.0, "first"), (40.0, "second")] {
        let id = d.start_experiment(&format!(
            r#"{{"campaign": "glass beads", "tube_angle_deg": {angle}, "notes": "{notes}"}}"#
        ));
        let done = d.wait_done(&id);
        assert_eq!(done["status"], "done", "{done}");
        sessions.push(done["session"].as_str().unwrap().to_string());
    }
    // One more outside the campaign: not in its fit.
    let id = d.start_experiment("{}");
    assert_eq!(d.wait_done(&id)["status"], "done");

    let manifest = d.json(&format!("/api/sessions/{}", sessions[1]))["manifest"].clone();
    assert_eq!(
        manifest["config"]["experiment"],
        serde_json::json!({"campaign": "glass beads", "tube_angle_deg": 40.0, "notes": "second"}),
        "the label is stored in the manifest"
    );
    assert_eq!(
        d.json("/api/campaigns")["campaigns"],
        serde_json::json!([{"name": "glass beads", "sessions": 2}])
    );
    let c = d.json("/api/campaigns/glass%20beads");
    let rows = c["fit"]["collisions"].as_array().unwrap();
    let sources: Vec<&str> = rows.iter().map(|r| r["source"].as_str().unwrap()).collect();
    assert_eq!(sources, [sessions[0].as_str(), sessions[1].as_str()]);
    let angles: Vec<f64> = rows
        .iter()
        .map(|r| r["tube_angle_deg"].as_f64().unwrap())
        .collect();
    assert_eq!(angles, [30.0, 40.0]);
    assert_eq!(c["notes"][&sessions[0]], "first");
    // The same computation as `impactcam fit` over the same two sessions.
    let paths: Vec<String> = sessions.iter().map(|s| format!("sessions/{s}")).collect();
    let mut args = vec!["fit", "--json"];
    args.extend(paths.iter().map(String::as_str));
    let cli = common::run_json(d.dir(), &args);
    assert_eq!(c["fit"]["e"], cli["e"], "page and `fit` agree on e");
    assert!(c["fit"]["e"]["value"].as_f64().is_some(), "{c}");

    let (code, svg) = d.get_bytes("/api/campaigns/glass%20beads/psi.svg");
    assert_eq!(code, 200);
    let svg = String::from_utf8_lossy(&svg);
    assert!(
        svg.starts_with("<svg") || svg.starts_with("<?xml"),
        "{svg:.80}"
    );
    let (code, csv) = d.get_bytes("/api/campaigns/glass%20beads/collisions.csv");
    assert_eq!(code, 200);
    let csv = String::from_utf8_lossy(&csv);
    assert_eq!(csv.lines().count(), 3, "header and two rows: {csv}");
    assert!(
        csv.lines()
            .nth(2)
            .unwrap()
            .starts_with(&format!("{},40,", sessions[1])),
        "{csv}"
    );

    for (path, want, says) in [
        ("/api/campaigns/..%2Fx", 400, "not a campaign name"),
        ("/api/campaigns/%20lead", 400, "not a campaign name"),
        ("/api/campaigns/nosuch/psi.svg", 404, "no session"),
    ] {
        let (code, body) = d.request("GET", path, "", None);
        assert_eq!(code, want, "{path}: {body}");
        assert!(body.contains(says), "{path}: {body}");
    }
    let (code, body) = d.request("POST", "/api/experiments", r#"{"campaign": "a/b"}"#, None);
    assert_eq!(code, 400, "{body}");
    assert!(body.contains("experiment.campaign"), "{body}");
}
