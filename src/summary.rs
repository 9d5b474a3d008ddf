//! Human-readable text for reports and progress: every number with its unit and, where it is an
//! estimate, its uncertainty.

use crate::analysis::report::{Estimate, Report};
use std::fmt::Write;

fn vec3(e: &Estimate<[f64; 3]>, digits: usize) -> String {
    let v = e.value;
    let u = e.uncertainty;
    format!(
        "({:>9.d$}, {:>9.d$}, {:>9.d$}) ± ({:.d$}, {:.d$}, {:.d$})",
        v[0],
        v[1],
        v[2],
        u[0],
        u[1],
        u[2],
        d = digits
    )
}

fn scalar(e: &Option<Estimate<f64>>, unit: &str) -> String {
    match e {
        Some(e) => format!("{:.4} ± {:.4}{unit}", e.value, e.uncertainty),
        None => "not measured".into(),
    }
}

pub fn report_text(r: &Report) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "source      {} {} ({} frames at {} Hz, {} dropped, {})",
        r.source.kind,
        r.source.name,
        r.source.frames,
        r.source.frame_rate_hz,
        r.quality.frames_dropped,
        r.dimensionality
    );
    let _ = writeln!(
        s,
        "impact      t = {:.6} s ± {:.6} s (frame {}; trajectory intersection {:.6} s)",
        r.impact.time_s.value,
        r.impact.time_s.uncertainty,
        r.impact.frame,
        r.impact.time_intersection_s
    );
    for (name, sp) in [("a", &r.spheres.a), ("b", &r.spheres.b)] {
        let _ = writeln!(
            s,
            "sphere {name}    v_pre  = {} mm/s",
            vec3(&sp.velocity_pre_mm_s, 1)
        );
        let _ = writeln!(
            s,
            "            v_post = {} mm/s",
            vec3(&sp.velocity_post_mm_s, 1)
        );
    }
    let _ = writeln!(
        s,
        "normal      n = {} (unit vector, a to b)",
        vec3(&r.normal, 3)
    );
    let _ = writeln!(s, "e           {}", scalar(&r.e, ""));
    let _ = writeln!(s, "beta        {}", scalar(&r.beta, ""));
    let _ = writeln!(
        s,
        "psi1, psi2  {}, {}",
        scalar(&r.psi1, ""),
        scalar(&r.psi2, "")
    );
    let _ = writeln!(
        s,
        "frames used a: {} before / {} after, b: {} before / {} after; {} frame/view pairs unmeasured",
        r.quality.frames_used_pre.a,
        r.quality.frames_used_post.a,
        r.quality.frames_used_pre.b,
        r.quality.frames_used_post.b,
        r.quality.unmeasured.len()
    );
    for w in &r.quality.warnings {
        let _ = writeln!(s, "warning: {w}");
    }
    s
}

/// A one-line live status on a terminal; plain milestone lines otherwise.
pub struct Status {
    tty: bool,
    json: bool,
    last_len: usize,
}

static JSON_PROGRESS: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// With `--log-format json`, progress lines go out as log events (one JSON object per line)
/// instead of text.
pub fn set_json_progress(on: bool) {
    JSON_PROGRESS.store(on, std::sync::atomic::Ordering::Relaxed);
}

impl Status {
    pub fn new() -> Status {
        use std::io::IsTerminal;
        let json = JSON_PROGRESS.load(std::sync::atomic::Ordering::Relaxed);
        Status {
            tty: std::io::stderr().is_terminal() && !json,
            json,
            last_len: 0,
        }
    }

    /// A transient line (replaced by the next one on a terminal, dropped otherwise).
    pub fn live(&mut self, text: &str) {
        if self.tty {
            let pad = self.last_len.saturating_sub(text.len());
            eprint!("\r{text}{}", " ".repeat(pad));
            self.last_len = text.len();
        }
    }

    /// A line that stays.
    pub fn line(&mut self, text: &str) {
        if self.json {
            tracing::info!(progress = true, "{text}");
            return;
        }
        if self.tty && self.last_len > 0 {
            eprint!("\r{}\r", " ".repeat(self.last_len));
            self.last_len = 0;
        }
        eprintln!("{text}");
    }
}

impl Default for Status {
    fn default() -> Self {
        Self::new()
    }
}

pub fn bar(done: usize, total: usize, width: usize) -> String {
    let filled = (done * width)
        .checked_div(total)
        .map_or(width, |f| f.min(width));
    format!(
        "[{}{}] {done}/{total}",
        "#".repeat(filled),
        "-".repeat(width - filled)
    )
}

/// Prints an experiment's progress: stage lines that stay, and a live bar while recording and
/// analysing.
pub fn progress_printer(status: &mut Status) -> impl FnMut(crate::experiment::Event) + '_ {
    move |ev| match ev {
        crate::experiment::Event::Recorder(crate::recorder::Progress::Armed { frames_seen }) => {
            status.line(&format!(
                "armed: camera delivering frames ({frames_seen} seen)"
            ))
        }
        crate::experiment::Event::Recorder(crate::recorder::Progress::Fired { session }) => status
            .line(&format!(
                "fired: relay closed; recording into {}",
                session.display()
            )),
        crate::experiment::Event::Recorder(crate::recorder::Progress::Frames {
            recorded,
            total,
        }) => status.live(&format!(
            "recording {}",
            bar(recorded as usize, total as usize, 30)
        )),
        crate::experiment::Event::Recorder(crate::recorder::Progress::Finished {
            recorded,
            dropped,
        }) => status.line(&format!("recorded {recorded} frames, {dropped} dropped")),
        crate::experiment::Event::Analysing {
            frames_done,
            frames_total,
        } => {
            if frames_done.is_multiple_of(10) || frames_done == frames_total {
                status.live(&format!("analysing {}", bar(frames_done, frames_total, 30)))
            }
        }
    }
}
