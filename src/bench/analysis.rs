//! `impactcam bench analysis`: the analysis's CPU time per frame on one thread, whole and stage
//! by stage (`analysis::stages`), as ratios against two baselines measured in the same run on
//! the same frames: reading and decoding them, and a plain threshold + moments centroid (the
//! cheapest thing that finds spheres at all, implemented here). Frames come from hw-sim
//! sessions drawn with varied looks and, when given, from an independent renderer's recordings.
//! With `--opencv PYTHON` (a Python with `cv2`), OpenCV's HoughCircles on the same frames is a
//! third baseline (`scripts/opencv-baseline.py`, embedded here).

use super::validation::config_from_calibration;
use crate::analysis::geometry::{self, View};
use crate::analysis::image::GreyImage;
use crate::analysis::source;
use crate::analysis::stages::{self, Stage, StageTimes, STAGES};
use crate::config::Config;
use std::fmt::Write;
use std::path::{Path, PathBuf};

/// CPU time this thread has used, s (the kernel's per-thread clock: a noisy neighbour on the
/// machine does not count, time waiting for the disk does not either).
fn thread_cpu_s() -> f64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes one timespec into the struct passed; the clock id is a
    // constant the kernel always has.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    if rc != 0 {
        return 0.0;
    }
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}

/// One input's figures (or a group's sums): frames, and seconds for decoding, the centroid
/// baseline, the whole analysis and its stages.
#[derive(Default)]
struct Timing {
    frames: usize,
    decode_s: f64,
    centroid_s: f64,
    analysis_s: f64,
    stages: StageTimes,
    /// Grey-level model evaluations of the circle fits (`stages::count_model_samples`).
    model_samples: u64,
    /// OpenCV's HoughCircles on the same frames, s (with `--opencv`).
    opencv_s: Option<f64>,
}

/// `scripts/opencv-baseline.py`, written next to the sessions when `--opencv` is given.
const OPENCV_SCRIPT: &str = include_str!("../../scripts/opencv-baseline.py");

/// OpenCV's HoughCircles CPU time on `path`'s frames, s, run by `python` on `script`.
fn opencv_time(python: &Path, script: &Path, path: &Path, cfg: &Config) -> Result<f64, String> {
    let radii: Vec<f64> = geometry::views(cfg)
        .iter()
        .flat_map(|v| [0, 1].map(|s| cfg.spheres.sphere(s).0 / 2.0 * v.px_per_mm))
        .collect();
    let r_min = radii.iter().copied().fold(f64::INFINITY, f64::min) * 0.8;
    let r_max = radii.iter().copied().fold(0.0, f64::max) * 1.25;
    let out = std::process::Command::new(python)
        .arg(script)
        .arg(path)
        .arg(format!("{r_min:.2}"))
        .arg(format!("{r_max:.2}"))
        .output()
        .map_err(|e| format!("--opencv {}: {e}", python.display()))?;
    if !out.status.success() {
        return Err(format!(
            "--opencv {}: {}",
            python.display(),
            String::from_utf8_lossy(&out.stderr).trim()
        ));
    }
    let v: serde_json::Value = serde_json::from_slice(&out.stdout)
        .map_err(|e| format!("--opencv: the script's output is not JSON: {e}"))?;
    v["cpu_s"]
        .as_f64()
        .ok_or_else(|| "--opencv: the script's output has no cpu_s".to_string())
}

/// The baseline: in each view, the grey level halfway between the view's darkest and brightest
/// pixel as threshold, the 4-connected regions above it, and the intensity-weighted centroid
/// (first moments) of the two largest. Returns the centroids so that the work is not optimised
/// away.
pub fn threshold_centroids(
    img: &GreyImage,
    views: &[View],
    labels: &mut Vec<u32>,
) -> Vec<[f64; 2]> {
    let mut out = Vec::new();
    let mut stack: Vec<(usize, usize)> = Vec::new();
    for view in views {
        let [x0, y0, w, h] = view.region.map(|x| x as usize);
        let (x1, y1) = ((x0 + w).min(img.width), (y0 + h).min(img.height));
        if x1 <= x0 || y1 <= y0 {
            continue;
        }
        let (mut lo, mut hi) = (f32::MAX, f32::MIN);
        for v in y0..y1 {
            for &g in &img.data[v * img.width + x0..v * img.width + x1] {
                lo = lo.min(g);
                hi = hi.max(g);
            }
        }
        let threshold = 0.5 * (lo + hi);
        labels.clear();
        labels.resize(img.width * img.height, 0);
        // (area, Σg, Σg·u, Σg·v) per region.
        let mut regions: Vec<(usize, f64, f64, f64)> = Vec::new();
        for v in y0..y1 {
            for u in x0..x1 {
                let k = v * img.width + u;
                if labels[k] != 0 || img.data[k] <= threshold {
                    continue;
                }
                regions.push((0, 0.0, 0.0, 0.0));
                let id = regions.len() as u32;
                labels[k] = id;
                stack.push((u, v));
                while let Some((pu, pv)) = stack.pop() {
                    let g = f64::from(img.data[pv * img.width + pu] - threshold);
                    let r = regions.last_mut().expect("pushed above");
                    r.0 += 1;
                    r.1 += g;
                    r.2 += g * pu as f64;
                    r.3 += g * pv as f64;
                    let mut visit = |qu: usize, qv: usize| {
                        let q = qv * img.width + qu;
                        if labels[q] == 0 && img.data[q] > threshold {
                            labels[q] = id;
                            stack.push((qu, qv));
                        }
                    };
                    if pu > x0 {
                        visit(pu - 1, pv);
                    }
                    if pu + 1 < x1 {
                        visit(pu + 1, pv);
                    }
                    if pv > y0 {
                        visit(pu, pv - 1);
                    }
                    if pv + 1 < y1 {
                        visit(pu, pv + 1);
                    }
                }
            }
        }
        regions.sort_by_key(|r| std::cmp::Reverse(r.0));
        out.extend(
            regions
                .iter()
                .take(2)
                .filter(|r| r.1 > 0.0)
                .map(|r| [r.2 / r.1, r.3 / r.1]),
        );
    }
    out
}

/// Times one input: decoding all frames, the centroid baseline on the decoded frames, and the
/// whole analysis with its stages. The baselines are the best of three runs (they are short
/// enough for a timer tick to matter); the analysis runs once.
fn time_input(path: &Path, cfg: &Config, opencv: Option<(&Path, &Path)>) -> Result<Timing, String> {
    let open = || {
        source::open(path, Some(cfg.camera.frame_rate_hz))
            .map_err(|e| format!("{}: {e}", path.display()))
    };
    let views = geometry::views(cfg);
    let n = open()?.len();
    let mut frames: Vec<GreyImage> = Vec::with_capacity(n);
    let mut decode_s = f64::INFINITY;
    for _ in 0..3 {
        frames.clear();
        // Opened afresh each time: a source may keep what it decoded.
        let t0 = thread_cpu_s();
        let mut src = open()?;
        for i in 0..n {
            let mut img = GreyImage::new();
            src.read(i, &mut img).map_err(|e| e.to_string())?;
            frames.push(img);
        }
        decode_s = decode_s.min(thread_cpu_s() - t0);
    }
    let mut centroid_s = f64::INFINITY;
    let mut labels = Vec::new();
    let mut found = 0usize;
    for _ in 0..3 {
        let t0 = thread_cpu_s();
        for img in &frames {
            found += threshold_centroids(img, &views, &mut labels).len();
        }
        centroid_s = centroid_s.min(thread_cpu_s() - t0);
    }
    std::hint::black_box(found);
    drop(frames);
    let mut src = open()?;
    stages::take();
    stages::take_model_samples();
    let t0 = thread_cpu_s();
    let result = crate::analysis::analyze(src.as_mut(), cfg, &mut |_, _| {});
    let analysis_s = thread_cpu_s() - t0;
    let stages = stages::take();
    let model_samples = stages::take_model_samples();
    result.map_err(|e| format!("{}: {e}", path.display()))?;
    let opencv_s = opencv
        .map(|(python, script)| opencv_time(python, script, path, cfg))
        .transpose()?;
    Ok(Timing {
        frames: n,
        decode_s,
        centroid_s,
        analysis_s,
        stages,
        model_samples,
        opencv_s,
    })
}

/// Records one hw-sim session with a look drawn from `seed`; returns its directory.
fn record(seed: u64, dir: &Path) -> Result<(PathBuf, Config), String> {
    let mut cfg = Config::default_config();
    cfg.recording.dir = dir.to_path_buf();
    cfg.sim.seed = seed;
    cfg.sim.look_family = Some("varied".into());
    Ok((super::record_sim(&cfg)?, cfg))
}

/// Sums of a group of inputs, printed as one block.
#[derive(Default)]
struct Group {
    sum: Timing,
    failed: Vec<String>,
    inputs: usize,
}

impl Group {
    fn add(&mut self, t: Result<Timing, String>) {
        match t {
            Ok(t) => {
                self.inputs += 1;
                let sum = &mut self.sum;
                sum.frames += t.frames;
                sum.decode_s += t.decode_s;
                sum.centroid_s += t.centroid_s;
                sum.analysis_s += t.analysis_s;
                sum.model_samples += t.model_samples;
                if let Some(o) = t.opencv_s {
                    *sum.opencv_s.get_or_insert(0.0) += o;
                }
                for p in 0..2 {
                    for s in 0..STAGES {
                        sum.stages[p][s] += t.stages[p][s];
                    }
                }
            }
            Err(e) => self.failed.push(e),
        }
    }

    fn print(&self, title: &str, out: &mut String) {
        if self.inputs == 0 && self.failed.is_empty() {
            return;
        }
        let sum = &self.sum;
        let _ = writeln!(
            out,
            "\n{title}: {} inputs, {} frames",
            self.inputs, sum.frames
        );
        for e in &self.failed {
            let _ = writeln!(out, "  not timed (no result): {e}");
        }
        if sum.frames == 0 {
            return;
        }
        let per = |s: f64| 1e3 * s / sum.frames as f64;
        let (dec, cen) = (per(sum.decode_s), per(sum.centroid_s));
        let _ = writeln!(
            out,
            "  {:<44} {:>12} {:>10} {:>11}",
            "CPU time per frame, one thread", "ms/frame", "× decode", "× centroid"
        );
        let mut row = |name: &str, ms: f64| {
            let _ = writeln!(
                out,
                "  {name:<44} {ms:>12.4} {:>10.2} {:>11.2}",
                ms / dec.max(1e-12),
                ms / cen.max(1e-12)
            );
        };
        row("read and decode the frames (baseline)", dec);
        row("threshold + moments centroid (baseline)", cen);
        if let Some(o) = sum.opencv_s {
            row("OpenCV HoughCircles (baseline, --opencv)", per(o));
        }
        row("whole analysis", per(sum.analysis_s));
        let st = |p: usize, s: Stage| sum.stages[p][s as usize];
        let inner = |p: usize| {
            st(p, Stage::Read)
                + st(p, Stage::Detect)
                + st(p, Stage::Circles)
                + st(p, Stage::Markers)
        };
        row("  backdrop estimate", per(st(0, Stage::Backdrop)));
        row(
            "  first pass: read, subtract backdrop",
            per(st(0, Stage::Read)),
        );
        row(
            "  first pass: detection (levels, blobs)",
            per(st(0, Stage::Detect)),
        );
        row("  first pass: circle fits", per(st(0, Stage::Circles)));
        row("  first pass: markers", per(st(0, Stage::Markers)));
        row(
            "  first pass: tracking (labels, memory)",
            per(st(0, Stage::Measure) - inner(0)),
        );
        row(
            "  first pass: fits, impact, spins, report",
            per(st(0, Stage::Fits)),
        );
        row(
            "  second pass (all of it)",
            per(st(1, Stage::Measure) + st(1, Stage::Fits)),
        );
        row("    of which circle fits", per(st(1, Stage::Circles)));
        let accounted = st(0, Stage::Backdrop)
            + st(0, Stage::Measure)
            + st(0, Stage::Fits)
            + st(1, Stage::Measure)
            + st(1, Stage::Fits);
        row(
            "  not in a stage (setup, dot masks)",
            per(sum.analysis_s - accounted),
        );
        let _ = writeln!(
            out,
            "  grey-level model evaluations per frame (a count, the same on any machine): {:.0}",
            sum.model_samples as f64 / sum.frames as f64
        );
        if let Some(o) = sum.opencv_s {
            let _ = writeln!(
                out,
                "  whole analysis / OpenCV HoughCircles: {:.1}× (the goal is about 2.5×)",
                sum.analysis_s / o.max(1e-12)
            );
        }
    }
}

/// Times the analysis on `experiments` hw-sim sessions with varied looks (recorded into `dir`
/// and removed afterwards) and, with `validation`, on each of that folder's recordings.
pub fn analysis(
    experiments: usize,
    validation: Option<&Path>,
    opencv: Option<&Path>,
    dir: &Path,
) -> Result<String, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let script = dir.join("opencv-baseline.py");
    if let Some(python) = opencv {
        let ok = std::process::Command::new(python)
            .args(["-c", "import cv2"])
            .output()
            .map_err(|e| format!("--opencv {}: {e}", python.display()))?;
        if !ok.status.success() {
            return Err(format!(
                "--opencv {}: expected a Python with cv2 (pip install opencv-python-headless): {}",
                python.display(),
                String::from_utf8_lossy(&ok.stderr)
                    .lines()
                    .last()
                    .unwrap_or("")
            ));
        }
        std::fs::write(&script, OPENCV_SCRIPT).map_err(|e| format!("{}: {e}", script.display()))?;
    }
    let opencv = opencv.map(|p| (p, script.as_path()));
    let mut out = String::from(
        "impactcam bench analysis — CPU time per frame on one thread; ratios against baselines on the same frames in this run\n",
    );
    // One thread: the figures are CPU time per frame of one core's work.
    crate::analysis::set_threads(1);
    let mut sim = Group::default();
    for i in 0..experiments as u64 {
        let (session, cfg) = record(2000 + i, dir)?;
        sim.add(time_input(&session, &cfg, opencv));
        let _ = std::fs::remove_dir_all(&session);
    }
    sim.print("hw-sim sessions, varied looks (240×192, 2 views)", &mut out);
    if let Some(vdir) = validation {
        let mut group = Group::default();
        let mut dirs: Vec<PathBuf> = std::fs::read_dir(vdir)
            .map_err(|e| format!("{}: {e}", vdir.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.join("frames.tif").is_file() && p.join("calibration.json").is_file())
            .collect();
        dirs.sort();
        for d in &dirs {
            let cfg = std::fs::read_to_string(d.join("calibration.json"))
                .map_err(|e| format!("{}: {e}", d.display()))
                .and_then(|t| serde_json::from_str(&t).map_err(|e| format!("{}: {e}", d.display())))
                .and_then(|v| config_from_calibration(&v));
            group.add(cfg.and_then(|c| time_input(&d.join("frames.tif"), &c, opencv)));
        }
        group.print(
            &format!("independent renderer ({})", vdir.display()),
            &mut out,
        );
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_centroid_baseline_finds_two_discs() {
        let cfg = Config::default_config();
        let views = geometry::views(&cfg);
        let mut img = GreyImage::new();
        img.width = 240;
        img.height = 192;
        img.data = vec![20.0; 240 * 192];
        for (cu, cv) in [(60.0, 40.0), (150.5, 50.0)] {
            for v in 0..96 {
                for u in 0..240 {
                    if (u as f64 - cu).hypot(v as f64 - cv) < 10.0 {
                        img.data[v * 240 + u] = 200.0;
                    }
                }
            }
        }
        let c = threshold_centroids(&img, &views[..1], &mut Vec::new());
        assert_eq!(c.len(), 2);
        for want in [[60.0, 40.0], [150.5, 50.0]] {
            assert!(
                c.iter()
                    .any(|g| (g[0] - want[0]).hypot(g[1] - want[1]) < 0.01),
                "{c:?}"
            );
        }
    }
}
