//! The recorder: arms the camera, fires the trigger once frames flow, and streams the window
//! around the firing into a session.
//!
//! Acquisition runs on its own thread and hands frames over a bounded queue (the RAM ring: its
//! capacity is `recording.ram_buffer_mb`), so the disk never paces the camera; a frame that
//! finds the queue full is lost, counted, and shows as a gap in the saved frame ids. Before the
//! firing only the last `pre_trigger_frames` frames are kept; after it every frame is appended
//! to the session as it arrives, so a crash keeps everything written so far.

use crate::camera::{Camera, CameraError, Frame};
use crate::config::Config;
use crate::session::{count_gaps, FrameMeta, ManifestTrigger, SessionError, SessionWriter, Status};
use crate::trigger::{CameraLive, Trigger, TriggerError};
use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, RecvTimeoutError, TrySendError};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("camera delivered {frames} frame(s) within recording.arm_timeout_ms = {timeout_ms} ms; relay not fired: {detail}")]
    NotArmed {
        frames: u64,
        timeout_ms: u32,
        detail: String,
    },
    #[error(transparent)]
    Camera(#[from] CameraError),
    #[error(transparent)]
    Trigger(#[from] TriggerError),
    #[error(transparent)]
    Session(#[from] SessionError),
    #[error("{0}; relay not fired")]
    Preflight(String),
    #[error("interrupted; the session in {0} is marked incomplete, its frames are kept")]
    Interrupted(PathBuf),
}

/// What the recorder tells whoever watches (progress bar, daemon events).
#[derive(Clone, Debug, PartialEq)]
pub enum Progress {
    Armed { frames_seen: u64 },
    Fired { session: PathBuf },
    Frames { recorded: u64, total: u64 },
    Finished { recorded: u64, dropped: u64 },
}

pub struct Recording {
    pub session_dir: PathBuf,
    pub status: Status,
    pub reason: Option<String>,
    pub frames_recorded: u64,
    pub frames_dropped: u64,
}

struct Acquisition {
    rx: Receiver<Result<Frame, CameraError>>,
    recycle: std::sync::mpsc::Sender<Vec<u8>>,
    stop: Arc<AtomicBool>,
    queue_full_losses: Arc<AtomicU64>,
    thread: Option<JoinHandle<Box<dyn Camera>>>,
}

impl Acquisition {
    /// Takes the camera out of `slot` for the acquisition thread; `finish` puts it back.
    fn start(
        slot: &mut Option<Box<dyn Camera>>,
        queue_frames: usize,
    ) -> Result<Acquisition, CameraError> {
        let mut camera = slot.take().ok_or_else(|| {
            CameraError::Failed("the camera was lost by an earlier failure; reopen it".into())
        })?;
        if let Err(e) = camera.start() {
            *slot = Some(camera);
            return Err(e);
        }
        let (tx, rx) = sync_channel::<Result<Frame, CameraError>>(queue_frames);
        let (recycle, recycled) = std::sync::mpsc::channel::<Vec<u8>>();
        let stop = Arc::new(AtomicBool::new(false));
        let losses = Arc::new(AtomicU64::new(0));
        let (stop2, losses2) = (stop.clone(), losses.clone());
        let thread = std::thread::Builder::new()
            .name("acquisition".into())
            .spawn(move || {
                while !stop2.load(Ordering::Relaxed) {
                    let buf = recycled.try_recv().unwrap_or_default();
                    match camera.next_frame(buf) {
                        Ok(f) => match tx.try_send(Ok(f)) {
                            Ok(()) => {}
                            Err(TrySendError::Full(_)) => {
                                losses2.fetch_add(1, Ordering::Relaxed);
                            }
                            Err(TrySendError::Disconnected(_)) => break,
                        },
                        Err(e) => {
                            let _ = tx.send(Err(e));
                            break;
                        }
                    }
                }
                let _ = camera.stop();
                camera
            })
            .map_err(|e| CameraError::Failed(format!("cannot start acquisition thread: {e}")))?;
        // (A failed spawn drops the camera with the closure; the rig is then reopened.)
        Ok(Acquisition {
            rx,
            recycle,
            stop,
            queue_full_losses: losses,
            thread: Some(thread),
        })
    }

    /// Stops streaming and puts the camera back in `slot` (it stays out only if the
    /// acquisition thread panicked, and then the rig must be reopened).
    fn finish(mut self, slot: &mut Option<Box<dyn Camera>>) {
        self.stop.store(true, Ordering::Relaxed);
        // Unblock a sender waiting on a full queue.
        while self.rx.try_recv().is_ok() {}
        *slot = self.thread.take().and_then(|t| t.join().ok());
    }
}

impl Drop for Acquisition {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// Arms, fires, records. On success the session is complete; on a camera failure after firing
/// it is finalised as incomplete (frames kept) and returned with that status. The camera is
/// borrowed from `camera` for the recording and put back after it, so a daemon keeps it open
/// from one experiment to the next.
pub fn record(
    camera: &mut Option<Box<dyn Camera>>,
    trigger: &Trigger,
    cfg: &Config,
    abort: Arc<AtomicBool>,
    progress: &mut dyn FnMut(Progress),
) -> Result<Recording, RecordError> {
    let info = camera
        .as_ref()
        .ok_or_else(|| {
            CameraError::Failed("the camera was lost by an earlier failure; reopen it".into())
        })?
        .info();
    let rec = &cfg.recording;
    let frame_bytes = info.frame_bytes().max(1);
    let queue_frames = ((rec.ram_buffer_mb as usize * 1024 * 1024) / frame_bytes).clamp(8, 1 << 20);
    let acq = Acquisition::start(camera, queue_frames)?;
    let period = Duration::from_secs_f64(1.0 / info.frame_rate_hz);
    let stall_timeout = (period * 50).max(Duration::from_secs(1));

    // Arm: frames must flow before anything is fired.
    let arm_deadline = std::time::Instant::now() + Duration::from_millis(rec.arm_timeout_ms as u64);
    let mut ring: VecDeque<Frame> = VecDeque::new();
    let keep = (rec.pre_trigger_frames as usize).max(1);
    let mut seen = 0u64;
    while seen < 2 || ring.len() < keep {
        if abort.load(Ordering::Relaxed) {
            acq.finish(camera);
            return Err(RecordError::NotArmed {
                frames: seen,
                timeout_ms: rec.arm_timeout_ms,
                detail: "interrupted".into(),
            });
        }
        let left = arm_deadline.saturating_duration_since(std::time::Instant::now());
        match acq.rx.recv_timeout(left.min(Duration::from_millis(100))) {
            Ok(Ok(f)) => {
                seen += 1;
                keep_latest(&mut ring, f, keep, &acq.recycle);
            }
            Ok(Err(e)) => {
                acq.finish(camera);
                return Err(RecordError::NotArmed {
                    frames: seen,
                    timeout_ms: rec.arm_timeout_ms,
                    detail: e.to_string(),
                });
            }
            Err(RecvTimeoutError::Timeout) if std::time::Instant::now() < arm_deadline => {}
            Err(_) => {
                acq.finish(camera);
                return Err(RecordError::NotArmed {
                    frames: seen,
                    timeout_ms: rec.arm_timeout_ms,
                    detail: "no frames arrived".into(),
                });
            }
        }
    }
    progress(Progress::Armed { frames_seen: seen });

    // Preflight: everything the recording needs is checked, created and allocated before the
    // relay is touched. A failure here fires nothing and leaves no session.
    let total = rec.frames as u64;
    let mut session = match preflight(&info, trigger, cfg) {
        Ok(s) => s,
        Err(e) => {
            acq.finish(camera);
            return Err(e);
        }
    };
    let mut saved: Vec<FrameMeta> = Vec::new();
    if let Err(e) = saved.try_reserve_exact(rec.frames as usize) {
        session.abandon();
        acq.finish(camera);
        return Err(RecordError::Preflight(format!(
            "recording.frames: cannot allocate the index of {} frames: {e}",
            rec.frames
        )));
    }
    // Frames that arrived during the preflight are still before the firing: the ring keeps
    // the latest of them.
    // A camera that failed meanwhile fires nothing.
    let camera_failed = loop {
        match acq.rx.try_recv() {
            Ok(Ok(f)) => keep_latest(&mut ring, f, keep, &acq.recycle),
            Ok(Err(e)) => break Some(e.to_string()),
            Err(std::sync::mpsc::TryRecvError::Empty) => break None,
            Err(std::sync::mpsc::TryRecvError::Disconnected) => {
                break Some("acquisition stopped before firing".into())
            }
        }
    };
    if let Some(detail) = camera_failed {
        session.abandon();
        acq.finish(camera);
        return Err(RecordError::NotArmed {
            frames: seen,
            timeout_ms: rec.arm_timeout_ms,
            detail,
        });
    }
    if rec.pre_trigger_frames == 0 {
        ring.clear();
    }

    let pulse = match trigger.fire(&CameraLive::confirmed(seen), abort.clone()) {
        Ok(p) => p,
        Err(e) => {
            // The relay may have been touched: the session says so rather than vanish.
            let _ = session.finish(Status::Failed, Some(format!("firing failed: {e}")));
            acq.finish(camera);
            return Err(e.into());
        }
    };
    if let Some(last) = ring.back() {
        let dt = pulse.closed_at().saturating_duration_since(last.host_time);
        session.manifest_mut().trigger.fired_at_ns =
            Some(last.timestamp_ns.saturating_add(dt.as_nanos() as u64));
    }
    progress(Progress::Fired {
        session: session.dir().to_path_buf(),
    });
    // A fail point for the fault matrix (tests/faults.rs): a panic with the relay closed.
    // Debug builds only; a release binary has no such switch.
    #[cfg(debug_assertions)]
    if std::env::var_os("IMPACTCAM_TEST_PANIC_AFTER_FIRING").is_some() {
        std::thread::sleep(Duration::from_millis(200));
        panic!("IMPACTCAM_TEST_PANIC_AFTER_FIRING: a panic while the relay is closed");
    }

    let mut failure: Option<String> = None;
    let mut pulse = Some(pulse);
    // Frames that wait in the queue are written together (`append_batch`): when the disk
    // falls behind, the index costs one write per burst rather than one per frame.
    let append = |session: &mut SessionWriter,
                  batch: &mut Vec<Frame>,
                  saved: &mut Vec<FrameMeta>|
     -> Result<(), SessionError> {
        let metas: Vec<FrameMeta> = batch
            .iter()
            .map(|f| FrameMeta {
                frame_id: f.frame_id,
                timestamp_ns: f.timestamp_ns,
            })
            .collect();
        let parts: Vec<(FrameMeta, &[u8])> = metas
            .iter()
            .zip(batch.iter())
            .map(|(m, f)| (*m, f.data.as_slice()))
            .collect();
        let before = session.manifest().frames_recorded;
        let result = session.append_batch(&parts);
        let written = (session.manifest().frames_recorded - before) as usize;
        saved.extend_from_slice(&metas[..written.min(metas.len())]);
        for f in batch.drain(..) {
            let _ = acq.recycle.send(f.data);
        }
        result
    };
    let mut write_error = None;
    let mut last_frame_at = std::time::Instant::now();
    let mut batch: Vec<Frame> = ring.drain(..).collect();
    if let Err(e) = append(&mut session, &mut batch, &mut saved) {
        write_error = Some(e);
    }
    while write_error.is_none() && (saved.len() as u64) < total {
        if abort.load(Ordering::Relaxed) {
            failure = Some("interrupted by the user".into());
            break;
        }
        // The pulse ends on its own timer; collect it as soon as it has, so errors surface.
        if pulse.as_ref().is_some_and(|p| {
            p.closed_at().elapsed() > Duration::from_millis(trigger.pulse_ms() as u64 + 5)
        }) {
            if let Some(p) = pulse.take() {
                if let Err(e) = p.finish() {
                    failure = Some(format!("relay did not confirm opening: {e}"));
                    break;
                }
            }
        }
        match acq.rx.recv_timeout(Duration::from_millis(100)) {
            Ok(Ok(f)) => {
                last_frame_at = std::time::Instant::now();
                let before = saved.len() as u64;
                batch.push(f);
                // Whatever else is already waiting, up to the frames still wanted.
                let mut camera_error = None;
                while (before + batch.len() as u64) < total && batch.len() < MAX_BATCH_FRAMES {
                    match acq.rx.try_recv() {
                        Ok(Ok(f)) => batch.push(f),
                        Ok(Err(e)) => {
                            camera_error = Some(e.to_string());
                            break;
                        }
                        Err(_) => break,
                    }
                }
                if let Err(e) = append(&mut session, &mut batch, &mut saved) {
                    write_error = Some(e);
                    break;
                }
                let n = saved.len() as u64;
                if n / 10 > before / 10 || n == total {
                    progress(Progress::Frames { recorded: n, total });
                }
                if let Some(e) = camera_error {
                    failure = Some(e);
                    break;
                }
            }
            Ok(Err(e)) => {
                failure = Some(e.to_string());
                break;
            }
            Err(RecvTimeoutError::Timeout) => {
                if last_frame_at.elapsed() > stall_timeout {
                    failure = Some(format!(
                        "camera stopped delivering frames for {} ms",
                        stall_timeout.as_millis()
                    ));
                    break;
                }
            }
            Err(RecvTimeoutError::Disconnected) => {
                failure = Some("acquisition stopped unexpectedly".into());
                break;
            }
        }
    }
    let pulse_result = pulse.take().map(|p| p.cancel());
    let losses = acq.queue_full_losses.load(Ordering::Relaxed);
    acq.finish(camera);

    let dropped = count_gaps(&saved);
    {
        let m = session.manifest_mut();
        m.frames_dropped = dropped;
        if let Some(fired) = m.trigger.fired_at_ns {
            m.trigger.fired_in_frame = saved
                .iter()
                .position(|f| f.timestamp_ns + period.as_nanos() as u64 / 2 >= fired)
                .map(|i| i as u64);
        }
    }
    if let Some(Err(e)) = pulse_result {
        failure.get_or_insert(format!("relay did not confirm opening: {e}"));
    }
    if let Some(e) = write_error {
        // The frames' own error is the reason; nothing else is written to a failing disk.
        let _ = session.finish(Status::Failed, Some(e.to_string()));
        return Err(e.into());
    }
    let interrupted = abort.load(Ordering::Relaxed);
    let (status, reason) = match failure {
        None => (Status::Complete, None),
        Some(r) => (Status::Incomplete, Some(r)),
    };
    if losses > 0 {
        tracing::warn!(losses, "frames lost because the RAM buffer was full");
    }
    let recorded = saved.len() as u64;
    let dir = session.finish(status, reason.clone())?;
    progress(Progress::Finished { recorded, dropped });
    if interrupted {
        return Err(RecordError::Interrupted(dir));
    }
    Ok(Recording {
        session_dir: dir,
        status,
        reason,
        frames_recorded: recorded,
        frames_dropped: dropped,
    })
}

/// Appends `f` to the pre-trigger ring and hands the frames beyond the last `keep` back to
/// the acquisition thread for reuse.
fn keep_latest(
    ring: &mut VecDeque<Frame>,
    f: Frame,
    keep: usize,
    recycle: &std::sync::mpsc::Sender<Vec<u8>>,
) {
    ring.push_back(f);
    while ring.len() > keep {
        if let Some(old) = ring.pop_front() {
            let _ = recycle.send(old.data);
        }
    }
}

/// Free space asked for beyond the frames themselves: index lines, manifest, report, plots.
const DISK_MARGIN_BYTES: u64 = 64 << 20;

/// Creates the session and checks that the recording fits: free disk space for every frame and
/// index line plus a margin (then reserved), and memory for the RAM ring. Returns the session,
/// or an error naming the key to change; on error no session is left behind.
fn preflight(
    info: &crate::camera::CameraInfo,
    trigger: &Trigger,
    cfg: &Config,
) -> Result<SessionWriter, RecordError> {
    let rec = &cfg.recording;
    let trig = ManifestTrigger::new(&trigger.info(), trigger.pulse_ms());
    let mut session = SessionWriter::create(&rec.dir, info, trig, cfg).map_err(|e| {
        RecordError::Preflight(format!("recording.dir: cannot create a session: {e}"))
    })?;
    // Index lines are at most 42 bytes ("id,timestamp\n" of two u64).
    let need = (info.frame_bytes() as u64 + 42)
        .saturating_mul(rec.frames as u64)
        .saturating_add(DISK_MARGIN_BYTES);
    let checked = match crate::session::disk::disk_space(session.dir()) {
        Ok((free, _)) if free < need => Err(format!(
            "recording.dir: {}: {} MiB free, the recording needs {} MiB ({} frames of {} bytes, plus {} MiB margin)",
            rec.dir.display(),
            free >> 20,
            need.div_ceil(1 << 20),
            rec.frames,
            info.frame_bytes(),
            DISK_MARGIN_BYTES >> 20
        )),
        Ok(_) => Ok(()),
        Err(e) => Err(format!("recording.dir: cannot tell the free space: {e}")),
    }
    .and_then(|()| {
        session
            .reserve(rec.frames as u64)
            .map_err(|e| format!("recording.dir: {e}"))
    })
    .and_then(|()| match mem_available_bytes() {
        Some(avail) if (rec.ram_buffer_mb as u64) << 20 > avail => Err(format!(
            "recording.ram_buffer_mb: {} MiB, but only {} MiB of memory is available",
            rec.ram_buffer_mb,
            avail >> 20
        )),
        _ => Ok(()),
    });
    match checked {
        Ok(()) => Ok(session),
        Err(message) => {
            session.abandon();
            Err(RecordError::Preflight(message))
        }
    }
}

/// MemAvailable from /proc/meminfo, in bytes (None where there is no such file).
fn mem_available_bytes() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// What `stream_to_ram` measured.
/// The most frames written in one go (`SessionWriter::append_batch`).
const MAX_BATCH_FRAMES: usize = 64;

pub struct RamStats {
    pub frames_received: u64,
    /// Frames lost because the queue was full (the consumer fell behind).
    pub frames_lost_queue: u64,
    /// Gaps in the device frame ids among the frames received.
    pub frames_missing_ids: u64,
    pub elapsed: Duration,
}

/// Streams `frames` frames from a camera into a RAM ring through the same acquisition thread
/// and bounded queue the recorder uses, without touching the disk (benchmarks, drop tests). The
/// ring is allocated and touched before streaming starts, as a recorder arming for a RAM
/// recording would, so page faults do not pace the camera.
pub fn stream_to_ram(
    camera: Box<dyn Camera>,
    frames: usize,
    queue_frames: usize,
) -> Result<RamStats, RecordError> {
    let bytes = camera.info().frame_bytes();
    let mut ring = vec![0u8; frames * bytes];
    for page in ring.chunks_mut(4096) {
        page[0] = 1;
    }
    let mut camera = Some(camera);
    let camera = &mut camera;
    let acq = Acquisition::start(camera, queue_frames.max(1))?;
    let mut metas: Vec<FrameMeta> = Vec::with_capacity(frames);
    let start = std::time::Instant::now();
    while metas.len() < frames {
        match acq.rx.recv_timeout(Duration::from_secs(5)) {
            Ok(Ok(f)) => {
                let k = metas.len();
                let n = f.data.len().min(bytes);
                ring[k * bytes..k * bytes + n].copy_from_slice(&f.data[..n]);
                metas.push(FrameMeta {
                    frame_id: f.frame_id,
                    timestamp_ns: f.timestamp_ns,
                });
                let _ = acq.recycle.send(f.data);
            }
            Ok(Err(e)) => {
                acq.finish(camera);
                return Err(e.into());
            }
            Err(_) => break,
        }
    }
    let elapsed = start.elapsed();
    let lost = acq.queue_full_losses.load(Ordering::Relaxed);
    acq.finish(camera);
    Ok(RamStats {
        frames_received: metas.len() as u64,
        frames_lost_queue: lost,
        frames_missing_ids: count_gaps(&metas),
        elapsed,
    })
}
