//! The daemon's page in a real headless browser (Debian's chromium, driven over the Chrome
//! DevTools protocol): load the page, click "Run", wait for the result, check what it shows.
//! Ignored by a plain `cargo test` (it needs a browser); `scripts/test` installs Debian's chromium
//! and runs it. Asked to run without a browser, it fails and says how to get one.

mod common;

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};
use tungstenite::Message;

fn browser() -> String {
    let path = std::env::var("IMPACTCAM_CHROMIUM").unwrap_or_else(|_| "/usr/bin/chromium".into());
    assert!(std::path::Path::new(&path).exists(), "no headless browser at {path}: run scripts/test (it installs Debian's chromium) or set IMPACTCAM_CHROMIUM");
    path
}

/// GET with a body read by Content-Length (the DevTools server keeps connections open).
fn http_get(addr: &str, path: &str) -> String {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut r = BufReader::new(s);
    let mut len = 0usize;
    loop {
        let mut h = String::new();
        if r.read_line(&mut h).unwrap_or(0) == 0 || h == "\r\n" {
            break;
        }
        if let Some(v) = h.to_ascii_lowercase().strip_prefix("content-length:") {
            len = v.trim().parse().unwrap_or(0);
        }
    }
    let mut body = vec![0u8; len];
    let _ = r.read_exact(&mut body);
    String::from_utf8_lossy(&body).into_owned()
}

/// A page driven over the DevTools protocol.
struct Cdp {
    ws: tungstenite::WebSocket<tungstenite::stream::MaybeTlsStream<TcpStream>>,
    next_id: u64,
}

impl Cdp {
    /// One DevTools call: its result.
    fn call(&mut self, method: &str, params: serde_json::Value) -> serde_json::Value {
        self.next_id += 1;
        let msg = serde_json::json!({"id": self.next_id, "method": method, "params": params});
        self.ws.send(Message::Text(msg.to_string().into())).unwrap();
        loop {
            if let Message::Text(t) = self.ws.read().unwrap() {
                let v: serde_json::Value = serde_json::from_str(t.as_str()).unwrap();
                if v["id"] == self.next_id {
                    return v["result"].clone();
                }
            }
        }
    }

    /// A JavaScript expression's value.
    fn eval(&mut self, expr: &str) -> serde_json::Value {
        self.call(
            "Runtime.evaluate",
            serde_json::json!({"expression": expr, "returnByValue": true}),
        )["result"]["value"]
            .clone()
    }

    /// The page as a PNG, saved under the test's target directory for review.
    fn screenshot(&mut self, name: &str) -> std::path::PathBuf {
        let shot = self.call(
            "Page.captureScreenshot",
            serde_json::json!({"format": "png"}),
        );
        let bytes = base64_decode(shot["data"].as_str().unwrap_or(""));
        assert!(bytes.starts_with(b"\x89PNG"), "a screenshot");
        let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("browser");
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join(name);
        std::fs::write(&path, bytes).unwrap();
        path
    }
}

/// Standard base64 (the screenshot's encoding), without a crate for one use.
fn base64_decode(text: &str) -> Vec<u8> {
    let value = |c: u8| match c {
        b'A'..=b'Z' => Some(c - b'A'),
        b'a'..=b'z' => Some(c - b'a' + 26),
        b'0'..=b'9' => Some(c - b'0' + 52),
        b'+' => Some(62),
        b'/' => Some(63),
        _ => None,
    };
    let mut out = Vec::with_capacity(text.len() * 3 / 4);
    let (mut acc, mut bits) = (0u32, 0u32);
    for v in text.bytes().filter_map(value) {
        acc = (acc << 6) | u32::from(v);
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
        }
    }
    out
}

struct Kill(std::process::Child);
impl Drop for Kill {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
#[ignore = "needs Debian's chromium: scripts/test installs it and runs this test"]
fn clicking_run_in_a_browser_shows_the_result() {
    let chromium = browser();
    let dir = tempfile::tempdir().unwrap();
    let (daemon, addr) = common::spawn_daemon(dir.path(), &[], None, Stdio::null());
    let _daemon = Kill(daemon);
    let url = format!("http://{addr}");

    let profile = tempfile::tempdir().unwrap();
    let mut chrome = Command::new(chromium)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--remote-debugging-port=0",
            &format!("--user-data-dir={}", profile.path().display()),
            &format!("{url}/"),
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stderr = BufReader::new(chrome.stderr.take().unwrap());
    let _chrome = Kill(chrome);
    // "DevTools listening on ws://127.0.0.1:PORT/devtools/browser/…"; the rest of stderr keeps
    // being drained, or chromium would block on a full pipe.
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for l in stderr.lines().map_while(Result::ok) {
            if let Some(rest) = l.split("ws://").nth(1) {
                let _ = tx.send(rest.split('/').next().unwrap_or("").to_string());
            }
        }
    });
    let devtools = rx
        .recv_timeout(Duration::from_secs(30))
        .expect("chromium printed its DevTools address");
    let t0 = Instant::now();
    let page_ws = loop {
        let list: serde_json::Value =
            serde_json::from_str(&http_get(&devtools, "/json/list")).unwrap_or_default();
        let found = list.as_array().into_iter().flatten().find(|t| {
            t["type"] == "page" && t["url"].as_str().is_some_and(|u| u.starts_with(&url))
        });
        if let Some(t) = found {
            break t["webSocketDebuggerUrl"].as_str().unwrap().to_string();
        }
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "page never opened: {list}"
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    let (ws, _) = tungstenite::connect(page_ws.as_str()).unwrap();
    let mut cdp = Cdp { ws, next_id: 0 };
    let mut eval = |expr: &str| cdp.eval(expr);
    let wait_for = |eval: &mut dyn FnMut(&str) -> serde_json::Value,
                    expr: &str,
                    secs: u64|
     -> serde_json::Value {
        let t0 = Instant::now();
        loop {
            let v = eval(expr);
            if v.as_bool() == Some(true) || (v.is_string() && !v.as_str().unwrap_or("").is_empty())
            {
                return v;
            }
            assert!(
                t0.elapsed() < Duration::from_secs(secs),
                "timed out waiting for {expr}"
            );
            std::thread::sleep(Duration::from_millis(200));
        }
    };
    wait_for(&mut eval, "document.readyState === 'complete' && !!document.getElementById('run') && document.getElementById('rig').textContent.includes('camera sim')", 20);
    let rig = eval("document.getElementById('rig').textContent");
    let rig = rig.as_str().unwrap();
    assert!(
        rig.contains(", open;") && rig.contains("GB free for sessions"),
        "the page shows the rig's state and the free disk space: {rig}"
    );
    // Live view: the image is there and changes over time (the sensor's noise, frame to frame).
    let live_hash = "(() => { const i = document.getElementById('live'); if (!i.complete || !i.naturalWidth) return ''; const c = document.createElement('canvas'); c.width = i.naturalWidth; c.height = i.naturalHeight; const g = c.getContext('2d'); g.drawImage(i, 0, 0); const d = g.getImageData(0, 0, c.width, c.height).data; let h = 0; for (let k = 0; k < d.length; k += 4) h = (h * 31 + d[k]) >>> 0; return String(h); })()";
    let first = wait_for(&mut eval, live_hash, 10);
    std::thread::sleep(Duration::from_millis(400));
    let second = wait_for(&mut eval, live_hash, 10);
    assert_ne!(first, second, "the live image changes over time");
    assert!(eval("document.getElementById('live-info').textContent")
        .as_str()
        .unwrap_or("")
        .contains("% saturated"));
    // The mirror's x agreement is read out too, in mm and px for each sphere (the simulator's
    // preview holds both spheres in view).
    let info = eval("document.getElementById('live-info').textContent");
    let info = info.as_str().unwrap_or("");
    assert!(
        info.contains("mirror x agreement: ")
            && info.contains(" mm (")
            && info.contains("2 circle(s)"),
        "{info}"
    );

    eval("document.getElementById('notes').value = 'from the browser'; document.getElementById('campaign').value = 'glass beads'; document.getElementById('tube').value = '30'; document.getElementById('run').click(); true");
    let e_text = wait_for(
        &mut eval,
        "document.getElementById('result').hidden ? '' : document.getElementById('e').textContent",
        60,
    );
    let e_text = e_text.as_str().unwrap().to_string();
    let e: f64 = e_text.split(" ± ").next().unwrap().parse().unwrap();
    assert!((e - 0.9).abs() < 0.02, "the page shows e = {e_text}");
    assert_eq!(
        eval("document.getElementById('status').textContent"),
        "done"
    );
    // The table is refreshed when the run starts and again when it ends: wait for the latter.
    let past = wait_for(&mut eval, "(t => t.includes('from the browser') && t.includes('done') ? t : '')(document.getElementById('past').textContent)", 10);
    assert!(past.as_str().unwrap().contains("0001done"), "{past}");
    wait_for(&mut eval, "document.getElementById('traj').complete && document.getElementById('traj').naturalWidth > 0", 10);
    // The frame at impact loads too (its element's id was once the impact time's, twice).
    wait_for(&mut eval, "document.getElementById('impact-frame').complete && document.getElementById('impact-frame').naturalWidth > 0", 10);

    // The rig: the devices and the config in use.
    wait_for(&mut eval, "document.getElementById('config').textContent.includes('\"frame_rate_hz\"') && document.getElementById('devices').textContent.includes('in use: camera sim')", 10);

    // The session viewer: the session is listed, opens at the impact frame with the
    // measurement drawn, and the drawn frame differs from the raw one.
    wait_for(
        &mut eval,
        "!!document.querySelector('#sessions button')",
        10,
    );
    eval("document.querySelector('#sessions button').click(); true");
    wait_for(&mut eval, "!document.getElementById('viewer').hidden && document.getElementById('v-impact-mark').textContent === 'impact' && document.getElementById('v-frame').src.includes('overlay=1') && document.getElementById('v-frame').complete && document.getElementById('v-frame').naturalWidth > 0", 10);
    // The session's trajectory and residual plots load, and the TIFF download is offered.
    wait_for(&mut eval, "['v-traj', 'v-resid'].every(id => document.getElementById(id).complete && document.getElementById(id).naturalWidth > 0) && document.getElementById('v-tiff').href.endsWith('/frames.tif')", 10);
    let e_viewer = eval("document.getElementById('v-e').textContent");
    assert_eq!(
        e_viewer.as_str(),
        Some(e_text.as_str()),
        "the viewer shows the same e"
    );
    eval("window.__differs = undefined; (async () => { const src = document.getElementById('v-frame').src; const [a, b] = await Promise.all([fetch(src), fetch(src.replace('?overlay=1', ''))].map(p => p.then(r => r.arrayBuffer()))); const x = new Uint8Array(a), y = new Uint8Array(b); window.__differs = x.length !== y.length || x.some((v, i) => v !== y[i]); })(); true");
    let differs = wait_for(
        &mut eval,
        "window.__differs === undefined ? '' : String(window.__differs)",
        10,
    );
    assert_eq!(
        differs.as_str(),
        Some("true"),
        "the overlay draws on the impact frame"
    );
    // Keyboard: → steps one frame on.
    let k0 = eval("Number(document.getElementById('v-k').textContent)")
        .as_f64()
        .unwrap();
    eval("document.dispatchEvent(new KeyboardEvent('keydown', {key: 'ArrowRight'})); true");
    let k1 = eval("Number(document.getElementById('v-k').textContent)")
        .as_f64()
        .unwrap();
    assert_eq!(k1, k0 + 1.0, "→ steps a frame");
    eval("document.dispatchEvent(new KeyboardEvent('keydown', {key: 'ArrowLeft'})); true");
    wait_for(&mut eval, "document.getElementById('v-frame').complete && document.getElementById('v-frame').naturalWidth > 0", 10);
    eval("document.getElementById('viewer').scrollIntoView(); true");
    let shot = cdp.screenshot("session-viewer.png");
    eprintln!("screenshot: {}", shot.display());

    // Campaigns: after one experiment the campaign is listed with its one row; a second one at
    // another tube angle joins it, and the table, the fit and the ψ plot follow.
    let mut eval = |expr: &str| cdp.eval(expr);
    wait_for(&mut eval, "document.getElementById('c-select').value === 'glass beads' && document.querySelectorAll('#c-table tr.row').length === 1", 10);
    eval("document.getElementById('notes').value = 'second'; document.getElementById('tube').value = '40'; document.getElementById('run').click(); true");
    wait_for(&mut eval, "document.querySelectorAll('#c-table tr.row').length === 2 && document.getElementById('c-plot').complete && document.getElementById('c-plot').naturalWidth > 0 && document.getElementById('c-plot').src.includes('n=2')", 60);
    let table = eval("document.getElementById('c-table').textContent");
    let table = table.as_str().unwrap_or("");
    assert!(
        table.contains("from the browser") && table.contains("second") && table.contains("40"),
        "the campaign table has both experiments, their notes and tube angles: {table}"
    );
    let fit_e = eval("document.getElementById('c-e').textContent");
    assert!(
        fit_e.as_str().unwrap_or("").contains(" ± "),
        "the campaign's e is fitted with its uncertainty: {fit_e}"
    );
    assert_eq!(
        eval("document.getElementById('c-csv').hidden"),
        serde_json::Value::Bool(false)
    );
    eval("document.getElementById('c-panel').scrollIntoView(); true");
    let shot = cdp.screenshot("campaign.png");
    eprintln!("screenshot: {}", shot.display());
}
