//! `impactcam bench soak`: N experiments back to back through the daemon's HTTP API on the
//! simulated lab, with the daemon a separate process whose memory (VmRSS) and open file
//! descriptors are read from /proc after the first experiment and after the last. Every session
//! must be complete with a report; the growth is printed as a ratio to the first reading.

use std::fmt::Write as _;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn request(addr: &str, method: &str, path: &str) -> Result<(u16, String), String> {
    let mut s = TcpStream::connect(addr).map_err(|e| e.to_string())?;
    s.set_read_timeout(Some(Duration::from_secs(30)))
        .map_err(|e| e.to_string())?;
    write!(
        s,
        "{method} {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\nContent-Type: application/json\r\nContent-Length: 0\r\n\r\n"
    )
    .map_err(|e| e.to_string())?;
    let mut out = String::new();
    s.read_to_string(&mut out).map_err(|e| e.to_string())?;
    let code = out
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    Ok((
        code,
        out.split_once("\r\n\r\n")
            .map(|(_, b)| b.to_string())
            .unwrap_or_default(),
    ))
}

fn proc_figures(pid: u32) -> (u64, usize) {
    let rss_kib = std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmRSS:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|v| v.parse().ok())
        })
        .unwrap_or(0);
    let fds = std::fs::read_dir(format!("/proc/{pid}/fd"))
        .map(|d| d.count())
        .unwrap_or(0);
    (rss_kib, fds)
}

pub fn soak(experiments: usize, dir: &std::path::Path) -> Result<String, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let exe = std::env::current_exe().map_err(|e| e.to_string())?;
    let mut child = Command::new(exe)
        .args(["serve", "--listen", "127.0.0.1:0"])
        .current_dir(dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .map_err(|e| e.to_string())?;
    let mut line = String::new();
    let stdout = child.stdout.take().ok_or("no stdout")?;
    BufReader::new(stdout)
        .read_line(&mut line)
        .map_err(|e| e.to_string())?;
    let addr = line
        .trim()
        .strip_prefix("listening on http://")
        .ok_or("daemon did not start")?
        .to_string();
    let run = || -> Result<String, String> {
        let mut first = None;
        let mut samples: Vec<(u64, usize)> = Vec::with_capacity(experiments);
        let t0 = Instant::now();
        for k in 0..experiments {
            let (code, body) = request(&addr, "POST", "/api/experiments")?;
            if code != 202 {
                return Err(format!("experiment {}: POST gave {code}: {body}", k + 1));
            }
            let id = serde_json::from_str::<serde_json::Value>(&body).map_err(|e| e.to_string())?
                ["id"]
                .as_str()
                .unwrap_or("")
                .to_string();
            loop {
                let (_, b) = request(&addr, "GET", &format!("/api/experiments/{id}"))?;
                let v: serde_json::Value = serde_json::from_str(&b).map_err(|e| e.to_string())?;
                match v["status"].as_str() {
                    Some("running") => std::thread::sleep(Duration::from_millis(50)),
                    Some("done") if v["report"]["e"]["value"].is_number() => break,
                    _ => return Err(format!("experiment {id} ended without a report: {v}")),
                }
            }
            if k == 0 || k + 1 == experiments {
                // Let the daemon close the connection that just answered, so it is not
                // counted as a descriptor held.
                std::thread::sleep(Duration::from_millis(200));
            }
            let fig = proc_figures(child.id());
            if k == 0 {
                first = Some(fig);
            }
            samples.push(fig);
        }
        let elapsed = t0.elapsed();
        let last = proc_figures(child.id());
        let first = first.unwrap_or(last);
        let sessions = std::fs::read_dir(dir.join("sessions"))
            .map(|d| d.count())
            .unwrap_or(0);
        let complete = std::fs::read_dir(dir.join("sessions"))
            .map(|d| {
                d.filter_map(|e| e.ok())
                    .filter(|e| {
                        std::fs::read_to_string(e.path().join("session.json"))
                            .is_ok_and(|t| t.contains("\"status\": \"complete\""))
                            && e.path().join("report.json").exists()
                    })
                    .count()
            })
            .unwrap_or(0);
        let mut s = String::new();
        let _ = writeln!(s, "impactcam bench soak — {experiments} experiments through the daemon in {:.1} s ({:.2} s each)", elapsed.as_secs_f64(), elapsed.as_secs_f64() / experiments.max(1) as f64);
        let _ = writeln!(
            s,
            "sessions written: {sessions}, complete with a report: {complete}"
        );
        let _ = writeln!(
            s,
            "daemon memory (VmRSS): {} KiB after the first, {} KiB after the last ({:.2}×)",
            first.0,
            last.0,
            last.0 as f64 / first.0.max(1) as f64
        );
        let _ = writeln!(
            s,
            "daemon open file descriptors: {} after the first, {} after the last",
            first.1, last.1
        );
        // Growth that stops (allocator arenas, caches filling once) and growth that goes on
        // (a leak) look alike over the whole run; the second half tells them apart.
        let checkpoints: Vec<String> = [
            1,
            experiments / 4,
            experiments / 2,
            3 * experiments / 4,
            experiments,
        ]
        .iter()
        .filter(|&&k| k >= 1 && k <= samples.len())
        .map(|&k| format!("{k}: {} KiB", samples[k - 1].0))
        .collect();
        let _ = writeln!(s, "VmRSS after experiment {}", checkpoints.join(", "));
        if samples.len() >= 4 {
            let half = samples.len() / 2;
            let per = (samples[samples.len() - 1].0 as f64 - samples[half - 1].0 as f64)
                / (samples.len() - half) as f64;
            let _ = writeln!(
                s,
                "growth over the second half: {per:.1} KiB per experiment"
            );
        }
        if complete != experiments {
            return Err(format!(
                "{s}only {complete} of {experiments} sessions are complete with a report"
            ));
        }
        Ok(s)
    };
    let result = run();
    let _ = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status();
    let _ = child.wait();
    result
}
