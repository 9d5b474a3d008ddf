//! Where the frames come from: the `FrameSource` trait and its adapters for a recorded session
//! and a TIFF stack recorded elsewhere, and `open`, which picks one for a path; `Filtered`, a
//! source whose frames pass through a `FrameFilter` as they are read (decoded to linear light,
//! the backdrop subtracted).

use super::image::GreyImage;
use super::report::Source;
use super::AnalysisError;
use crate::config::Config;
use crate::footage::{FrameFile, Timing};
use crate::session::{FrameMeta, SessionReader};
use std::path::Path;

/// Frames to analyse, from a session or from footage recorded elsewhere.
pub trait FrameSource {
    fn source(&self) -> Source;
    fn len(&self) -> usize;
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    fn meta(&self, i: usize) -> FrameMeta;
    fn read(&mut self, i: usize, img: &mut GreyImage) -> Result<(), AnalysisError>;
    fn frames_dropped(&self) -> u64;
    fn dimensions(&self) -> (u32, u32);
    /// Things about the input a reader of the report must know.
    fn warnings(&self) -> Vec<String>;
    /// The config the footage was recorded with, where the source carries one (a session).
    fn recorded_config(&self) -> Option<&Config> {
        None
    }
}

/// What a source wrapping another does to each frame as it is read (`Filtered`).
pub trait FrameFilter {
    fn apply(&mut self, img: &mut GreyImage);
    /// What the filter has to say about the input, after the inner source's warnings.
    fn warnings(&self) -> Vec<String> {
        Vec::new()
    }
}

/// `inner`'s frames, each passed through `filter` as it is read; everything else about the
/// source is `inner`'s.
pub struct Filtered<'a, F> {
    pub inner: &'a mut dyn FrameSource,
    pub filter: F,
}

impl<F: FrameFilter> FrameSource for Filtered<'_, F> {
    fn source(&self) -> Source {
        self.inner.source()
    }
    fn len(&self) -> usize {
        self.inner.len()
    }
    fn meta(&self, i: usize) -> FrameMeta {
        self.inner.meta(i)
    }
    fn read(&mut self, i: usize, img: &mut GreyImage) -> Result<(), AnalysisError> {
        self.inner.read(i, img)?;
        self.filter.apply(img);
        Ok(())
    }
    fn frames_dropped(&self) -> u64 {
        self.inner.frames_dropped()
    }
    fn dimensions(&self) -> (u32, u32) {
        self.inner.dimensions()
    }
    fn warnings(&self) -> Vec<String> {
        let mut w = self.inner.warnings();
        w.extend(self.filter.warnings());
        w
    }
    fn recorded_config(&self) -> Option<&Config> {
        self.inner.recorded_config()
    }
}

pub struct SessionSource {
    pub reader: SessionReader,
    buf: Vec<u8>,
}

impl SessionSource {
    pub fn new(reader: SessionReader) -> Self {
        SessionSource {
            reader,
            buf: Vec::new(),
        }
    }
}

impl FrameSource for SessionSource {
    fn source(&self) -> Source {
        Source {
            kind: "session".into(),
            name: self.reader.manifest.id.clone(),
            frames: self.reader.frames.len() as u64,
            frame_rate_hz: self.reader.manifest.camera.frame_rate_hz,
            timestamps: "device".into(),
            trigger_frame: None,
            first_frame_number: None,
            exposure_s: None,
        }
    }
    fn len(&self) -> usize {
        self.reader.frames.len()
    }
    fn meta(&self, i: usize) -> FrameMeta {
        self.reader.frames[i]
    }
    fn read(&mut self, i: usize, img: &mut GreyImage) -> Result<(), AnalysisError> {
        self.reader.read_frame(i, &mut self.buf)?;
        img.load(
            &self.buf,
            self.reader.width as usize,
            self.reader.height as usize,
            self.reader.bytes_per_pixel,
        );
        Ok(())
    }
    fn frames_dropped(&self) -> u64 {
        crate::session::count_gaps(&self.reader.frames)
    }
    fn dimensions(&self) -> (u32, u32) {
        (self.reader.width, self.reader.height)
    }
    fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        if !self.reader.is_complete() {
            w.push(format!(
                "session status is {:?}{}: analysed the {} frames that were written",
                self.reader.manifest.status,
                self.reader
                    .manifest
                    .reason
                    .as_ref()
                    .map(|r| format!(" ({r})"))
                    .unwrap_or_default(),
                self.reader.frames.len()
            ));
        }
        if self.reader.frames_truncated > 0 {
            w.push(format!(
                "{} frame(s) listed in the index were cut short on disk and ignored",
                self.reader.frames_truncated
            ));
        }
        w
    }
    fn recorded_config(&self) -> Option<&Config> {
        Some(self.reader.config())
    }
}

/// Footage from another camera or program (`footage`): MRAW, CINE, FMF, image sequences, TIFF
/// stacks, read a frame at a time.
pub struct FileSource {
    file: Box<dyn FrameFile>,
    frame_rate_hz: f64,
    warnings: Vec<String>,
    buf: Vec<u8>,
}

impl FileSource {
    /// `frame_rate_hz`: the rate the analysis uses (the file's own where it has one, see
    /// `rate_for`); `warnings`: what the report must say about the file.
    pub fn new(file: Box<dyn FrameFile>, frame_rate_hz: f64, warnings: Vec<String>) -> Self {
        FileSource {
            file,
            frame_rate_hz,
            warnings,
            buf: Vec::new(),
        }
    }
}

impl FrameSource for FileSource {
    fn source(&self) -> Source {
        let i = self.file.info();
        Source {
            kind: i.kind.into(),
            name: i.name.clone(),
            frames: self.file.len() as u64,
            frame_rate_hz: self.frame_rate_hz,
            timestamps: match (i.timing, i.frame_rate_hz) {
                (Timing::File, _) => format!("the {} file's own frame times", i.kind),
                (Timing::Rate, Some(_)) => "frame number / the file's frame rate".into(),
                (Timing::Rate, None) => "frame number / camera.frame_rate_hz".into(),
            },
            trigger_frame: i.trigger_frame,
            first_frame_number: i.first_frame_number,
            exposure_s: i.exposure_s,
        }
    }
    fn len(&self) -> usize {
        self.file.len()
    }
    fn meta(&self, i: usize) -> FrameMeta {
        self.file.meta(i)
    }
    fn read(&mut self, i: usize, img: &mut GreyImage) -> Result<(), AnalysisError> {
        self.file
            .read(i, &mut self.buf)
            .map_err(|e| AnalysisError::Input {
                source_name: e.path.display().to_string(),
                message: e.message,
            })?;
        let info = self.file.info();
        img.load(
            &self.buf,
            info.width as usize,
            info.height as usize,
            info.bytes_per_pixel,
        );
        Ok(())
    }
    fn frames_dropped(&self) -> u64 {
        crate::session::count_gaps(self.file.frames())
    }
    fn dimensions(&self) -> (u32, u32) {
        let i = self.file.info();
        (i.width, i.height)
    }
    fn warnings(&self) -> Vec<String> {
        self.warnings.clone()
    }
}

/// The frame rate to analyse a file at: its own where it states one, else the config's; and a
/// warning when both are given and differ by more than 0.01 %.
pub fn rate_for(file: &dyn FrameFile, config_rate_hz: f64) -> (f64, Option<String>) {
    let i = file.info();
    match i.frame_rate_hz {
        Some(r) if (r - config_rate_hz).abs() > 1e-4 * r => (
            r,
            Some(format!(
                "the {} file says {r} frames/s; camera.frame_rate_hz ({config_rate_hz}) is not used",
                i.kind
            )),
        ),
        // They agree: the config's number, so that footage whose header rounds the rate (an
        // ImageJ interval) analyses exactly as footage that states none.
        Some(_) => (config_rate_hz, None),
        None => (config_rate_hz, None),
    }
}

/// The frame rate the median interval between a file's frame ids and times gives, Hz.
fn rate_from_times(file: &dyn FrameFile) -> Option<f64> {
    let mut per_frame: Vec<f64> = file
        .frames()
        .windows(2)
        .filter_map(|w| {
            let (a, b) = (w[0], w[1]);
            let frames = b.frame_id.checked_sub(a.frame_id).filter(|d| *d > 0)?;
            Some(b.timestamp_ns.saturating_sub(a.timestamp_ns) as f64 / frames as f64)
        })
        .collect();
    if per_frame.is_empty() {
        return None;
    }
    per_frame.sort_by(f64::total_cmp);
    let ns = per_frame[per_frame.len() / 2];
    (ns > 0.0).then(|| 1e9 / ns)
}

/// Opens `path` as frames: a session directory, or footage recorded elsewhere (`footage::open`,
/// by content), whose frame rate is its own where it states one, else `frame_rate_hz`.
pub fn open(
    path: &Path,
    frame_rate_hz: Option<f64>,
) -> Result<Box<dyn FrameSource>, AnalysisError> {
    if crate::batch::is_session(path) {
        return Ok(Box::new(SessionSource::new(SessionReader::open(path)?)));
    }
    let file = crate::footage::open(path, frame_rate_hz).map_err(|e| AnalysisError::Input {
        source_name: e.path.display().to_string(),
        message: e.message,
    })?;
    let (rate, warning) = match (frame_rate_hz, file.info().frame_rate_hz) {
        (Some(r), _) => rate_for(file.as_ref(), r),
        (None, Some(r)) => (r, None),
        // Only a file with its own frame times gets here without a rate (the others are refused
        // by `footage::open`): the median interval between them.
        (None, None) => match rate_from_times(file.as_ref()) {
            Some(r) => (
                r,
                Some(format!("frame rate {r:.6} frames/s, from the median interval of the file's frame times")),
            ),
            None => {
                return Err(AnalysisError::Input {
                    source_name: path.display().to_string(),
                    message: "the file states no frame rate: give a config with camera.frame_rate_hz".into(),
                })
            }
        },
    };
    let mut warnings: Vec<String> = file.info().notes.clone();
    warnings.extend(warning);
    Ok(Box::new(FileSource::new(file, rate, warnings)))
}

/// Frames held in memory, for tests: `frames[k]` is row-major grey levels, one frame a
/// millisecond.
#[cfg(test)]
pub(crate) struct MemoryFrames {
    pub w: usize,
    pub h: usize,
    pub frames: Vec<Vec<f32>>,
}

#[cfg(test)]
impl FrameSource for MemoryFrames {
    fn source(&self) -> Source {
        Source {
            kind: "test".into(),
            name: "frames".into(),
            frames: self.frames.len() as u64,
            frame_rate_hz: 1000.0,
            timestamps: "frame number".into(),
            trigger_frame: None,
            first_frame_number: None,
            exposure_s: None,
        }
    }
    fn len(&self) -> usize {
        self.frames.len()
    }
    fn meta(&self, i: usize) -> FrameMeta {
        FrameMeta {
            frame_id: i as u64,
            timestamp_ns: i as u64 * 1_000_000,
        }
    }
    fn read(&mut self, i: usize, img: &mut GreyImage) -> Result<(), AnalysisError> {
        img.width = self.w;
        img.height = self.h;
        img.unmeasured.clear();
        img.data.clone_from(&self.frames[i]);
        Ok(())
    }
    fn frames_dropped(&self) -> u64 {
        0
    }
    fn dimensions(&self) -> (u32, u32) {
        (self.w as u32, self.h as u32)
    }
    fn warnings(&self) -> Vec<String> {
        Vec::new()
    }
}
