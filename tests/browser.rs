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
    let (mut ws, _) = tungstenite::connect(page_ws.as_str()).unwrap();
    let mut next_id = 0;
    let mut eval = |expr: &str| -> serde_json::Value {
        next_id += 1;
        let msg = serde_json::json!({"id": next_id, "method": "Runtime.evaluate", "params": {"expression": expr, "returnByValue": true}});
        ws.send(Message::Text(msg.to_string().into())).unwrap();
        loop {
            if let Message::Text(t) = ws.read().unwrap() {
                let v: serde_json::Value = serde_json::from_str(t.as_str()).unwrap();
                if v["id"] == next_id {
                    return v["result"]["result"]["value"].clone();
                }
            }
        }
    };
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
    eval("document.getElementById('notes').value = 'from the browser'; document.getElementById('run').click(); true");
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
}
