//! The frames before any geometry is trusted, for `calibrate`: every frame measured without the
//! fits that follow, and the whole blobs each view shows (their positions and sizes).

use super::geometry::{self, View};
use super::tracking::{self, FrameObs, SecondPass};
use super::{backdrop, detect, image, AnalysisError, FrameSource};
use crate::config::Config;

/// Every frame measured (backdrop removed, circles fitted, spheres labelled) without the fits
/// that follow: what `calibrate` needs from a recording whose geometry is only roughly known,
/// where the impact's contact distance cannot be relied on yet.
pub fn measure(
    src: &mut dyn FrameSource,
    cfg: &Config,
) -> Result<(Vec<View>, Vec<FrameObs>), AnalysisError> {
    let views = geometry::views(cfg);
    let src = &mut super::linear::Linear::new(src, cfg);
    let backdrop = backdrop::Backdrop::estimate(src, &views)?;
    let src = &mut super::source::Filtered {
        inner: src,
        filter: backdrop,
    };
    // One pass, so its fits are final ones (not the first pass's, stopped after their box
    // rounds for a second to finish).
    let memo = tracking::FitMemo::default();
    memo.start_second_pass();
    let (obs, _) = tracking::measure_all(
        src,
        &views,
        cfg,
        &SecondPass::default(),
        &memo,
        &mut |_, _| {},
    )?;
    Ok((views, obs))
}

/// Per frame, per view, each whole blob's (centroid px, equivalent diameter px).
pub type BlobSurvey = Vec<Vec<Vec<([f64; 2], f64)>>>;

/// The whole (unclipped) blobs of every view in up to `frames` frames spread across the
/// recording, backdrop removed, as [frame][view] → (centroid px, equivalent diameter px): what
/// `calibrate` reads the views' rough scales and the mirror's offset from, before any geometry
/// is trusted.
pub fn blob_survey(
    src: &mut dyn FrameSource,
    cfg: &Config,
    frames: usize,
) -> Result<BlobSurvey, AnalysisError> {
    Ok(blobs(src, cfg, frames)?
        .into_iter()
        .map(|f| {
            f.into_iter()
                .map(|v| v.iter().map(|b| (b.centroid, b.diameter_px())).collect())
                .collect()
        })
        .collect())
}

/// As `blob_survey`, each view's whole blobs as found (with their pixel extents).
pub fn blobs(
    src: &mut dyn FrameSource,
    cfg: &Config,
    frames: usize,
) -> Result<Vec<Vec<Vec<detect::Blob>>>, AnalysisError> {
    let views = geometry::views(cfg);
    let src = &mut super::linear::Linear::new(src, cfg);
    let backdrop = backdrop::Backdrop::estimate(src, &views)?;
    let n = src.len();
    let src = &mut super::source::Filtered {
        inner: src,
        filter: backdrop,
    };
    let mut img = image::GreyImage::new();
    let take = n.min(frames.max(1));
    let mut out = Vec::with_capacity(take);
    for k in 0..take {
        src.read(k * n / take, &mut img)?;
        out.push(
            views
                .iter()
                .map(|view| {
                    let lv = detect::levels(&img, view);
                    // Any blob of a few pixels or more: the size is what is sought.
                    detect::find_blobs(&img, view, &lv, 2.0, cfg.analysis.threshold_fraction)
                        .into_iter()
                        .filter(|b| !b.clipped)
                        .collect()
                })
                .collect(),
        );
    }
    Ok(out)
}
