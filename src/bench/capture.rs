//! `impactcam bench capture`: recorder throughput. For 240×192 @ 1000 fps and 640×480 @ 2000 fps, frames/s of
//! - the simulated camera alone (rendering) — the baseline for RAM,
//! - the recorder's acquisition path into RAM (thread + bounded queue + RAM store),
//! - a raw sequential write of the same frames to disk — the baseline for disk,
//! - the recorder writing a session to disk (pixels, index, manifest),
//!
//! and a real-time run at the nominal rate into RAM that must drop nothing.

use crate::camera::{self, Camera};
use crate::config::Config;
use crate::experiment::Rig;
use crate::recorder::{stream_to_ram, Progress};
use std::fmt::Write as _;
use std::io::Write;
use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::{Duration, Instant};

#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    #[error("bench: {0}")]
    Failed(String),
}

fn fail(e: impl std::fmt::Display) -> BenchError {
    BenchError::Failed(e.to_string())
}

fn bench_config(width: u32, height: u32, fps: f64, pace: hw_sim::Pace, dir: &Path) -> Config {
    let mut cfg = Config::default_config();
    cfg.camera.width = width;
    cfg.camera.height = height;
    cfg.camera.frame_rate_hz = fps;
    cfg.sim.pace = pace;
    cfg.recording.dir = dir.to_path_buf();
    cfg
}

fn sim_camera(cfg: &Config) -> Result<(Arc<hw_sim::SimLab>, Box<dyn Camera>), BenchError> {
    let lab = hw_sim::SimLab::new(cfg.sim.clone(), crate::analysis::geometry::sim_scene(cfg))
        .map_err(fail)?;
    let cam = camera::open(cfg, Some(&lab)).map_err(fail)?;
    Ok((lab, cam))
}

/// A camera that hands out frames drawn beforehand, in a loop, as fast as they are asked for.
struct MemoryCamera {
    info: camera::CameraInfo,
    frames: Vec<Vec<u8>>,
    next: u64,
}

impl Camera for MemoryCamera {
    fn info(&self) -> camera::CameraInfo {
        self.info.clone()
    }
    fn start(&mut self) -> Result<(), camera::CameraError> {
        Ok(())
    }
    fn next_frame(&mut self, mut buf: Vec<u8>) -> Result<camera::Frame, camera::CameraError> {
        let k = self.next;
        self.next += 1;
        let src = &self.frames[k as usize % self.frames.len().max(1)];
        buf.clear();
        buf.extend_from_slice(src);
        Ok(camera::Frame {
            frame_id: k,
            timestamp_ns: (k as f64 * 1e9 / self.info.frame_rate_hz) as u64,
            host_time: Instant::now(),
            data: buf,
        })
    }
    fn stop(&mut self) -> Result<(), camera::CameraError> {
        Ok(())
    }
}

fn rate(frames: u64, d: Duration) -> f64 {
    frames as f64 / d.as_secs_f64().max(1e-9)
}

pub fn capture(frames: usize, dir: &Path) -> Result<String, BenchError> {
    let tmp = dir.join(format!(".impactcam-bench-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).map_err(|e| fail(format!("{}: {e}", tmp.display())))?;
    let result = capture_in(frames, &tmp);
    let _ = std::fs::remove_dir_all(&tmp);
    result
}

fn capture_in(frames: usize, tmp: &Path) -> Result<String, BenchError> {
    let mut out = String::new();
    let _ = writeln!(out, "impactcam bench capture — {frames} frames per measurement; ratios are against baselines from this run");
    for (w, h, fps) in [(240u32, 192u32, 1000.0f64), (640, 480, 2000.0)] {
        let free = bench_config(w, h, fps, hw_sim::Pace::FreeRun, tmp);
        let frame_bytes = (w * h) as usize;
        let _ = writeln!(
            out,
            "\n{w}×{h} Mono8 ({:.1} KiB/frame), nominal {fps} fps",
            frame_bytes as f64 / 1024.0
        );

        // Camera alone, rendering into one reused buffer.
        let (_lab, mut cam) = sim_camera(&free)?;
        cam.start().map_err(fail)?;
        let t0 = Instant::now();
        let mut buf = Vec::new();
        for _ in 0..frames {
            buf = cam.next_frame(buf).map_err(fail)?.data;
        }
        let cam_fps = rate(frames as u64, t0.elapsed());

        // Acquisition path into RAM.
        let (_lab, cam) = sim_camera(&free)?;
        let ram = stream_to_ram(cam, frames, 1 << 16).map_err(fail)?;
        let ram_fps = rate(ram.frames_received, ram.elapsed);

        // The disk's pace drifts as the kernel writes back what earlier measurements left
        // dirty: the raw write and the recorder take turns, three rounds, and the best round
        // of each counts.
        let (_lab, mut sim) = sim_camera(&free)?;
        sim.start().map_err(fail)?;
        let mut drawn = Vec::new();
        for _ in 0..32 {
            drawn.push(sim.next_frame(Vec::new()).map_err(fail)?.data);
        }
        let mut raw_fps: f64 = 0.0;
        let mut disk_fps: f64 = 0.0;
        let mut dropped = 0;
        for _round in 0..3 {
            // Raw sequential write baseline.
            let raw_path = tmp.join("raw.bin");
            let data = vec![7u8; frame_bytes];
            let t0 = Instant::now();
            {
                let mut f = std::fs::File::create(&raw_path).map_err(fail)?;
                for _ in 0..frames {
                    f.write_all(&data).map_err(fail)?;
                }
                f.sync_data().map_err(fail)?;
            }
            raw_fps = raw_fps.max(rate(frames as u64, t0.elapsed()));
            let _ = std::fs::remove_file(&raw_path);

            // The recorder writing a session, from a camera that hands out frames the simulator
            // drew beforehand (its rendering of flying spheres, not the recorder, would otherwise
            // set the pace), with the simulated lab's relay.
            let mut cfg = free.clone();
            cfg.recording.frames = frames as u32;
            cfg.recording.pre_trigger_frames = 1;
            let rig = Rig::open(&cfg).map_err(fail)?;
            let mut camera = Some(Box::new(MemoryCamera {
                info: sim.info(),
                frames: drawn.clone(),
                next: 0,
            }) as Box<dyn Camera>);
            let mut fired_at = None;
            let mut finished_at = None;
            let rec = crate::recorder::record(
                &mut camera,
                &rig.trigger,
                &cfg,
                Arc::new(AtomicBool::new(false)),
                &mut |ev| match ev {
                    Progress::Fired { .. } => fired_at = Some(Instant::now()),
                    Progress::Finished { .. } => finished_at = Some(Instant::now()),
                    _ => {}
                },
            )
            .map_err(fail)?;
            let disk_time = match (fired_at, finished_at) {
                (Some(a), Some(b)) => b - a,
                _ => return Err(fail("recorder did not report firing and finishing")),
            };
            disk_fps = disk_fps.max(rate(rec.frames_recorded, disk_time));
            dropped += rec.frames_dropped;
            let _ = std::fs::remove_dir_all(&rec.session_dir);
        }

        // Real time, nominal rate, into RAM: nothing may be lost.
        let rt = bench_config(w, h, fps, hw_sim::Pace::RealTime, tmp);
        let (_lab, cam) = sim_camera(&rt)?;
        let rt_frames = (fps as usize).min(frames.max(500));
        let queue = (rt.recording.ram_buffer_mb as usize * 1024 * 1024 / frame_bytes).max(8);
        let live = stream_to_ram(cam, rt_frames, queue).map_err(fail)?;
        let live_fps = rate(live.frames_received, live.elapsed);

        let _ = writeln!(
            out,
            "  simulated camera alone         {cam_fps:>10.0} frames/s   (baseline for RAM)"
        );
        let _ = writeln!(
            out,
            "  recorder into RAM              {ram_fps:>10.0} frames/s   ratio {:.2} of camera alone; {} lost",
            ram_fps / cam_fps,
            ram.frames_lost_queue + ram.frames_missing_ids
        );
        let _ = writeln!(out, "  raw sequential write           {raw_fps:>10.0} frames/s   (baseline for disk, {:.0} MiB/s)", raw_fps * frame_bytes as f64 / 1048576.0);
        let _ = writeln!(
            out,
            "  recorder into a session        {disk_fps:>10.0} frames/s   ratio {:.2} of raw write; {} dropped",
            disk_fps / raw_fps,
            dropped
        );
        let _ = writeln!(
            out,
            "  real time at {fps} fps into RAM: {} frames in {:.3} s ({:.3} of nominal rate), {} lost to the queue, {} missing ids",
            live.frames_received,
            live.elapsed.as_secs_f64(),
            live_fps / fps,
            live.frames_lost_queue,
            live.frames_missing_ids
        );
    }
    Ok(out)
}
