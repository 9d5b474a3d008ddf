//! Walking the frames: read a chunk at a time (memory stays bounded whatever the length), the
//! next chunk's work done ahead on the other threads while the tracker walks through this one
//! in order (`ahead`), one frame after another with one thread.

use super::ahead::{self, FitMemo};
use super::{FrameCtx, FrameObs, SecondPass, Tracker};
use crate::analysis::geometry::View;
use crate::analysis::image::GreyImage;
use crate::analysis::report::Unmeasured;
use crate::analysis::stages::{self, Stage};
use crate::analysis::{AnalysisError, FrameSource};
use crate::config::Config;
use crate::session::FrameMeta;

/// Every frame measured and labelled, with what `pass` gives the second pass (nothing on the
/// first); `memo` keeps the first pass's fits for the second to finish.
pub fn measure_all(
    source: &mut dyn FrameSource,
    views: &[View],
    cfg: &Config,
    pass: &SecondPass,
    memo: &FitMemo,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(Vec<FrameObs>, Vec<Unmeasured>), AnalysisError> {
    stages::timed(Stage::Measure, || {
        let mut out = Vec::with_capacity(source.len());
        let mut tracker = Tracker::new(views.len(), source.source().frame_rate_hz);
        let n = source.len();
        // One thread: frame by frame. More: frames are read a chunk at a time (memory stays
        // bounded whatever the length); while tracking walks through one chunk in order, the other
        // threads do the next chunk's detection and likely fits (`ahead`), and the tracking thread
        // joins them when it is done.
        let threads = crate::analysis::threads();
        let chunk = if threads > 1 { 8 * threads } else { 1 };
        if n == 0 {
            return Ok((out, tracker.finish(views).1));
        }
        let read = |source: &mut dyn FrameSource,
                    imgs: &mut Vec<GreyImage>,
                    metas: &mut Vec<FrameMeta>,
                    first: usize|
         -> Result<(), AnalysisError> {
            imgs.resize_with(chunk.min(n - first), GreyImage::new);
            metas.clear();
            for (k, img) in imgs.iter_mut().enumerate() {
                stages::timed(Stage::Read, || source.read(first + k, img))?;
                metas.push(source.meta(first + k));
            }
            Ok(())
        };
        let mut track =
            |imgs: &[GreyImage], metas: &[FrameMeta], ahead: &[ahead::Ahead], first: usize| {
                let none = ahead::Ahead::default();
                for (k, (img, meta)) in imgs.iter().zip(metas).enumerate() {
                    let i = first + k;
                    let cx = FrameCtx {
                        i,
                        t: meta.timestamp_ns as f64 * 1e-9,
                        img,
                        views,
                        cfg,
                        pass,
                        memo,
                        ahead: ahead.get(k).unwrap_or(&none),
                    };
                    let spheres = tracker.measure_frame(&cx);
                    out.push(FrameObs {
                        index: i as u64,
                        frame_id: meta.frame_id,
                        time_s: cx.t,
                        spheres,
                        position_mm: [None, None],
                    });
                    progress(i + 1, n);
                }
            };
        let (mut cur, mut cur_meta) = (Vec::new(), Vec::new());
        read(source, &mut cur, &mut cur_meta, 0)?;
        let mut first = 0;
        if threads <= 1 {
            loop {
                track(&cur, &cur_meta, &[], first);
                first += cur.len();
                if first >= n {
                    break;
                }
                read(source, &mut cur, &mut cur_meta, first)?;
            }
        } else {
            let mut cur_ahead = ahead::chunk_ahead(&cur, 0, views, cfg, pass, memo, threads, || {});
            let (mut next, mut next_meta) = (Vec::new(), Vec::new());
            loop {
                let next_first = first + cur.len();
                if next_first >= n {
                    track(&cur, &cur_meta, &cur_ahead, first);
                    break;
                }
                read(source, &mut next, &mut next_meta, next_first)?;
                let next_ahead =
                    ahead::chunk_ahead(&next, next_first, views, cfg, pass, memo, threads, || {
                        track(&cur, &cur_meta, &cur_ahead, first)
                    });
                std::mem::swap(&mut cur, &mut next);
                std::mem::swap(&mut cur_meta, &mut next_meta);
                cur_ahead = next_ahead;
                first = next_first;
            }
        }
        // Held runs named after their frames were put out (`held`).
        let (released, unmeasured) = tracker.finish(views);
        for (i, vi, [a, b]) in released {
            if let Some(f) = out.get_mut(i) {
                f.spheres[0][vi] = Some(a);
                f.spheres[1][vi] = Some(b);
            }
        }
        Ok((out, unmeasured))
    })
}
