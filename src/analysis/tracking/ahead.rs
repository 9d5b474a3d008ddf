//! Work done ahead, on other threads: each frame's detection and the circle fits that tracking
//! will most likely ask for, computed for a chunk of frames in parallel before tracking walks
//! through them in order. Tracking stays sequential (labels and memory pass from frame to
//! frame); it takes a fit from here only when it asks for one with exactly the arguments it was
//! computed with, and computes any other itself. The fits are pure functions of those
//! arguments, so the report is the same bits whatever the number of threads.
//!
//! The guess: in every view, each blob of at most two, with the other blob (if any) as the
//! other sphere. Spheres of two sizes give no guess (which radius goes with which blob is a
//! label), so there only detection is done ahead.
//!
//! `FitMemo` keeps the first pass's fits for the second: the first pass's stop after their box
//! rounds, and the second finishes each with its dots masked rather than fitting it again.

use super::measure::{finish_blob, fit_blob, plan_blob, BlobFit, BlobPlan};
use super::SecondPass;
use crate::analysis::circle::{DotMask, FirstPassDisc};
use crate::analysis::detect::{find_blobs, levels, Blob, ViewLevels};
use crate::analysis::geometry::View;
use crate::analysis::image::GreyImage;
use crate::config::Config;
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Mutex;

/// The exact arguments of one `fit_blob` call besides the frame and the view's dots.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(super) struct FitKey {
    view: usize,
    centroid: [u64; 2],
    clipped: bool,
    radius: u64,
    other: Option<([u64; 2], u64)>,
}

impl FitKey {
    pub(super) fn new(
        view: usize,
        b: &Blob,
        radius_px: f64,
        other: Option<([f64; 2], f64)>,
    ) -> FitKey {
        FitKey {
            view,
            centroid: b.centroid.map(f64::to_bits),
            clipped: b.clipped,
            radius: radius_px.to_bits(),
            other: other.map(|(c, r)| (c.map(f64::to_bits), r.to_bits())),
        }
    }
}

/// One frame's work done ahead: each view's levels and blobs, and the guessed fits.
#[derive(Default)]
pub(super) struct Ahead {
    detected: Vec<Option<(ViewLevels, Vec<Blob>)>>,
    fits: Vec<(FitKey, BlobFit)>,
}

impl Ahead {
    /// A view's levels and blobs, if detected ahead.
    pub(super) fn detected(&self, view: usize) -> Option<&(ViewLevels, Vec<Blob>)> {
        self.detected.get(view).and_then(Option::as_ref)
    }

    /// The fit computed ahead with exactly these arguments, if any.
    pub(super) fn fit(
        &self,
        view: usize,
        b: &Blob,
        radius_px: f64,
        other: Option<([f64; 2], f64)>,
    ) -> Option<BlobFit> {
        let key = FitKey::new(view, b, radius_px, other);
        self.fits.iter().find(|(k, _)| *k == key).map(|(_, f)| *f)
    }
}

/// The first pass's fits of lone blobs, by frame and arguments, as far as their box rounds went
/// and with what their final rounds need: the second pass finishes each with its own dots
/// masked rather than fitting it again. And each frame's detection by view, which the second
/// pass would otherwise repeat on the same frames (a few hundred bytes per frame and view).
#[derive(Default)]
pub struct FitMemo {
    fits: Mutex<HashMap<(usize, FitKey), Planned>>,
    detected: Mutex<HashMap<(usize, usize), Detection>>,
    /// Set once the first pass is over (`start_second_pass`): fits asked for from then on are
    /// final.
    second: AtomicBool,
}

/// A blob's fit as the first pass left it, and its plan if a final round is still to do.
type Planned = (BlobFit, Option<BlobPlan>);

/// One view's detection in one frame: its levels and its blobs.
type Detection = (ViewLevels, Vec<Blob>);

impl FitMemo {
    /// Frame `i`'s view `vi`: its levels and blobs, from the memo where detected before, else
    /// from `detect` (and kept). Detection is a pure function of the frame and the view.
    pub(super) fn detection(
        &self,
        i: usize,
        vi: usize,
        detect: impl FnOnce() -> Detection,
    ) -> Detection {
        if let Some(d) = self
            .detected
            .lock()
            .ok()
            .and_then(|m| m.get(&(i, vi)).cloned())
        {
            return d;
        }
        let d = detect();
        if let Ok(mut m) = self.detected.lock() {
            m.insert((i, vi), d.clone());
        }
        d
    }

    /// Whether the fits asked for now are final (`start_second_pass` has been called).
    pub(super) fn is_final(&self) -> bool {
        self.second.load(Ordering::SeqCst)
    }

    /// From now on the fits asked for are final (the second pass's, or a lone pass's:
    /// `survey::measure`).
    pub fn start_second_pass(&self) {
        self.second.store(true, Ordering::SeqCst);
    }

    /// A blob's fit for frame `i`: in the first pass as far as its box rounds go (`plan_blob`,
    /// kept with its plan); in the second, the first pass's finished with `dots` masked
    /// (`finish_blob`), or where the first pass did not ask for this one, `fit_blob` now.
    /// Each is a pure function of its arguments, so it does not matter which thread asks first.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn fit_blob(
        &self,
        i: usize,
        vi: usize,
        img: &GreyImage,
        view: &View,
        b: &Blob,
        radius_px: f64,
        other: Option<([f64; 2], f64)>,
        background: f64,
        dots: &[DotMask],
        held: &[FirstPassDisc],
    ) -> BlobFit {
        let key = FitKey::new(vi, b, radius_px, other);
        let kept = self
            .fits
            .lock()
            .ok()
            .and_then(|m| m.get(&(i, key)).cloned());
        if !self.second.load(Ordering::SeqCst) {
            if let Some((f, _)) = kept {
                return f;
            }
            let (f, plan) = plan_blob(img, view, b, radius_px, other, background, dots, held);
            if let Ok(mut m) = self.fits.lock() {
                m.insert((i, key), (f, plan));
            }
            return f;
        }
        match kept {
            Some((_, Some(plan))) => finish_blob(img, view, &plan, dots, held),
            // No grey-level fit was left to finish: without dots a fit now would fail as it
            // did; with them masked it may not. (A held radius changes only a grey-level fit's
            // blurred refit, which there was none of.)
            Some((f, None)) if dots.is_empty() => f,
            _ => fit_blob(img, view, b, radius_px, other, background, dots, held),
        }
    }
}

/// Detection, and the guessed fits, for one frame.
fn frame_ahead(
    img: &GreyImage,
    i: usize,
    views: &[View],
    cfg: &Config,
    pass: &SecondPass,
    memo: &FitMemo,
) -> Ahead {
    let mut out = Ahead::default();
    for (vi, view) in views.iter().enumerate() {
        let radius = [0, 1].map(|s| cfg.spheres.sphere(s).0 / 2.0 * view.px_per_mm);
        let r_mean = 0.5 * (radius[0] + radius[1]);
        let (lv, blobs) = memo.detection(i, vi, || {
            let lv = levels(img, view);
            let blobs = find_blobs(img, view, &lv, r_mean, cfg.analysis.threshold_fraction);
            (lv, blobs)
        });
        if radius[0] == radius[1] && blobs.len() <= 2 {
            let view_dots = pass.dots(i, vi);
            for (j, b) in blobs.iter().enumerate().filter(|(_, b)| !b.merged) {
                let other = (blobs.len() == 2).then(|| (blobs[1 - j].centroid, radius[0]));
                let fit = memo.fit_blob(
                    i,
                    vi,
                    img,
                    view,
                    b,
                    radius[0],
                    other,
                    lv.background,
                    view_dots,
                    pass.radii(i, vi),
                );
                out.fits.push((FitKey::new(vi, b, radius[0], other), fit));
            }
        }
        out.detected.push(Some((lv, blobs)));
    }
    out
}

/// The work ahead for frames `first..first + imgs.len()`, on `threads` threads, the calling
/// thread among them once it has run `meanwhile` (tracking the previous chunk: so the other
/// threads are not idle while it does).
#[allow(clippy::too_many_arguments)]
pub(super) fn chunk_ahead(
    imgs: &[GreyImage],
    first: usize,
    views: &[View],
    cfg: &Config,
    pass: &SecondPass,
    memo: &FitMemo,
    threads: usize,
    meanwhile: impl FnOnce(),
) -> Vec<Ahead> {
    let next = AtomicUsize::new(0);
    let done: Mutex<Vec<Option<Ahead>>> = Mutex::new((0..imgs.len()).map(|_| None).collect());
    let work = || loop {
        let k = next.fetch_add(1, Ordering::Relaxed);
        let Some(img) = imgs.get(k) else { break };
        let a = frame_ahead(img, first + k, views, cfg, pass, memo);
        if let Ok(mut d) = done.lock() {
            d[k] = Some(a);
        }
    };
    std::thread::scope(|scope| {
        for _ in 1..threads.max(1) {
            scope.spawn(work);
        }
        meanwhile();
        work();
    });
    done.into_inner()
        .unwrap_or_default()
        .into_iter()
        .map(Option::unwrap_or_default)
        .collect()
}
