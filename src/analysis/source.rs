//! Where the frames come from: the `FrameSource` trait and its adapters for a recorded session
//! and a TIFF stack recorded elsewhere, and `open`, which picks one for a path.

use super::image::GreyImage;
use super::report::Source;
use super::AnalysisError;
use crate::config::Config;
use crate::session::tiff::TiffStack;
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

pub struct TiffSource {
    stack: TiffStack,
    meta: Vec<FrameMeta>,
    frame_rate_hz: f64,
}

impl TiffSource {
    pub fn new(stack: TiffStack, frame_rate_hz: f64) -> Self {
        let meta = stack.meta(frame_rate_hz);
        TiffSource {
            stack,
            meta,
            frame_rate_hz,
        }
    }
}

impl FrameSource for TiffSource {
    fn source(&self) -> Source {
        Source {
            kind: "tiff".into(),
            name: self
                .stack
                .path
                .file_name()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default(),
            frames: self.stack.frames.len() as u64,
            frame_rate_hz: self.frame_rate_hz,
            timestamps: "frame number / camera.frame_rate_hz".into(),
        }
    }
    fn len(&self) -> usize {
        self.stack.frames.len()
    }
    fn meta(&self, i: usize) -> FrameMeta {
        self.meta[i]
    }
    fn read(&mut self, i: usize, img: &mut GreyImage) -> Result<(), AnalysisError> {
        img.load(
            &self.stack.frames[i],
            self.stack.width as usize,
            self.stack.height as usize,
            self.stack.bytes_per_pixel,
        );
        Ok(())
    }
    fn frames_dropped(&self) -> u64 {
        0
    }
    fn dimensions(&self) -> (u32, u32) {
        (self.stack.width, self.stack.height)
    }
    fn warnings(&self) -> Vec<String> {
        Vec::new()
    }
}

/// Opens `path` as frames: a session directory, or a multi-page TIFF stack whose frame k is at
/// k / `frame_rate_hz` (which a stack needs: it carries no times).
pub fn open(
    path: &Path,
    frame_rate_hz: Option<f64>,
) -> Result<Box<dyn FrameSource>, AnalysisError> {
    if path.is_dir() {
        return Ok(Box::new(SessionSource::new(SessionReader::open(path)?)));
    }
    let rate = frame_rate_hz.ok_or_else(|| AnalysisError::Input {
        source_name: path.display().to_string(),
        message: "a TIFF stack carries no frame times: give a config (camera.frame_rate_hz)".into(),
    })?;
    Ok(Box::new(TiffSource::new(TiffStack::open(path)?, rate)))
}
