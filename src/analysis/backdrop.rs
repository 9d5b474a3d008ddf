//! What stands still in each view, and which way the spheres differ from it.
//!
//! A rig shows more than two spheres: tube ends, a ruler, the mirror's edge, dust, a background
//! lit unevenly; and it may be backlit, the spheres dark on a bright ground. Everything after
//! this module expects bright spheres on a flat dark ground, so each frame is normalised here
//! before it is measured: per view, the static backdrop (a low quantile over frames sampled
//! across the recording, taken per pixel) is subtracted and the view's backdrop level added
//! back, and a view whose moving things are darker than their ground is inverted. The backdrop
//! is what is there when no sphere is: a sphere covers a pixel for a short part of a flight, so
//! a quantile on the ground's side of the spheres (the 20th percentile for bright spheres, the
//! 80th for dark ones) leaves them out as long as no pixel is covered in more than 80 % of the
//! sampled frames. With fewer than `MIN_FRAMES` frames there is no backdrop, only the polarity.

use super::geometry::View;
use super::image::{GreyImage, SATURATED_GREY};
use super::report::Source;
use super::source::FrameSource;
use super::AnalysisError;
use crate::config::Config;
use crate::session::FrameMeta;
use std::sync::Arc;

/// Frames sampled for the backdrop, at most.
const SAMPLES: usize = 31;
/// Fewer frames than this give no backdrop (a quantile of so few says little).
pub const MIN_FRAMES: usize = 9;
/// Memory the sampled frames may take, bytes.
const MAX_SAMPLE_BYTES: usize = 256 << 20;
/// The backdrop's quantile on the ground's side of the spheres.
const GROUND_QUANTILE: f64 = 0.2;

/// One view's normalisation.
#[derive(Clone, Debug)]
struct ViewBackdrop {
    name: &'static str,
    /// x0, y0, x1, y1 in the frame (exclusive ends).
    rect: [usize; 4],
    /// The spheres are darker than the ground here: the view is inverted.
    dark_spheres: bool,
    /// The static image of the view (row-major over `rect`), when there are enough frames.
    still: Option<Vec<f32>>,
    /// The level the ground is given after normalisation.
    level: f32,
}

/// The per-view normalisation of a recording's frames.
#[derive(Clone, Debug, Default)]
pub struct Backdrop {
    views: Vec<ViewBackdrop>,
    /// The frame's `GreyImage::ground`: per pixel, the subtracted backdrop above its view's
    /// level (bright side up); None without a backdrop.
    ground: Option<Arc<[f32]>>,
    /// The rectangles of the inverted views (`GreyImage::inverted`).
    inverted: Arc<[[usize; 4]]>,
}

impl Backdrop {
    /// Samples the recording and estimates each view's polarity and static backdrop.
    pub fn estimate(src: &mut dyn FrameSource, views: &[View]) -> Result<Backdrop, AnalysisError> {
        let n = src.len();
        // The samples are held at once as f32: at most `MAX_SAMPLE_BYTES` of them (for large
        // frames, fewer samples; below `MIN_FRAMES`, the polarity only).
        let (w, h) = src.dimensions();
        let frame_bytes = (w as usize)
            .saturating_mul(h as usize)
            .saturating_mul(4)
            .max(1);
        let k = n.min(SAMPLES).min((MAX_SAMPLE_BYTES / frame_bytes).max(1));
        let mut frames: Vec<GreyImage> = Vec::with_capacity(k);
        for j in 0..k {
            // Evenly spread, first and last included.
            let i = if k > 1 { j * (n - 1) / (k - 1) } else { 0 };
            let mut img = GreyImage::new();
            src.read(i, &mut img)?;
            frames.push(img);
        }
        let Some(first) = frames.first() else {
            return Ok(Backdrop::default());
        };
        let (w, h) = (first.width, first.height);
        let mut out = Vec::with_capacity(views.len());
        for view in views {
            let [x, y, vw, vh] = view.region.map(|v| v as usize);
            let rect = [x.min(w), y.min(h), (x + vw).min(w), (y + vh).min(h)];
            let dark_spheres = dark_spheres(&frames, rect);
            let still = (k >= MIN_FRAMES).then(|| {
                let q = if dark_spheres {
                    1.0 - GROUND_QUANTILE
                } else {
                    GROUND_QUANTILE
                };
                let idx = ((k - 1) as f64 * q).round() as usize;
                let mut column = vec![0f32; k];
                let mut still = Vec::with_capacity((rect[2] - rect[0]) * (rect[3] - rect[1]));
                for v in rect[1]..rect[3] {
                    for u in rect[0]..rect[2] {
                        for (c, f) in column.iter_mut().zip(&frames) {
                            *c = f.at(u, v);
                        }
                        column.select_nth_unstable_by(idx, f32::total_cmp);
                        still.push(column[idx]);
                    }
                }
                still
            });
            let mut ground: Vec<f32> = match &still {
                Some(s) => s.clone(),
                None => (rect[1]..rect[3])
                    .flat_map(|v| (rect[0]..rect[2]).map(move |u| (u, v)))
                    .map(|(u, v)| first.at(u, v))
                    .collect(),
            };
            let level = if ground.is_empty() {
                0.0
            } else {
                let mid = ground.len() / 2;
                *ground.select_nth_unstable_by(mid, f32::total_cmp).1
            };
            let level = if dark_spheres { 255.0 - level } else { level };
            out.push(ViewBackdrop {
                name: view.kind.name(),
                rect,
                dark_spheres,
                still,
                level,
            });
        }
        // What a sphere in front of the backdrop hides: the subtracted still, bright side up,
        // above the level put in its place.
        let ground = out.iter().any(|vb| vb.still.is_some()).then(|| {
            let mut g = vec![0f32; w * h];
            for vb in &out {
                let Some(still) = &vb.still else { continue };
                let [x0, y0, x1, _] = vb.rect;
                let rw = x1 - x0;
                for (k, &b) in still.iter().enumerate() {
                    let bright = if vb.dark_spheres { 255.0 - b } else { b };
                    g[(y0 + k / rw) * w + x0 + k % rw] = bright - vb.level;
                }
            }
            Arc::from(g)
        });
        let inverted = out
            .iter()
            .filter(|vb| vb.dark_spheres)
            .map(|vb| vb.rect)
            .collect();
        Ok(Backdrop {
            views: out,
            ground,
            inverted,
        })
    }

    /// Normalises one frame in place (see the module's doc).
    pub fn apply(&self, img: &mut GreyImage) {
        let w = img.width;
        img.ground = self
            .ground
            .clone()
            .filter(|g| g.len() == img.width * img.height);
        img.inverted = self.inverted.clone();
        img.saturated.clear();
        for vb in &self.views {
            let [x0, y0, x1, y1] = vb.rect;
            if x1 > img.width || y1 > img.height {
                continue;
            }
            let rw = x1 - x0;
            for v in y0..y1 {
                for u in x0..x1 {
                    // Overexposed: marked before the level is moved (bright spheres only; in a
                    // backlit view what saturates is the ground).
                    if !vb.dark_spheres && img.data[v * w + u] >= SATURATED_GREY {
                        if img.saturated.is_empty() {
                            img.saturated.resize(img.width * img.height, false);
                        }
                        img.saturated[v * w + u] = true;
                    }
                    let p = &mut img.data[v * w + u];
                    let ground = vb
                        .still
                        .as_ref()
                        .map(|s| s[(v - y0) * rw + (u - x0)])
                        .unwrap_or(if vb.dark_spheres {
                            255.0 - vb.level
                        } else {
                            vb.level
                        });
                    *p = if vb.dark_spheres {
                        vb.level + (ground - *p)
                    } else {
                        vb.level + (*p - ground)
                    };
                }
            }
        }
    }

    /// What a reader of the report must know: views measured inverted.
    pub fn warnings(&self) -> Vec<String> {
        self.views
            .iter()
            .filter(|v| v.dark_spheres)
            .map(|v| {
                format!(
                    "{} view: the spheres are darker than their ground (backlit); measured inverted, its markers looked for as dots darker still (seen only where a light in front shows them)",
                    v.name
                )
            })
            .collect()
    }
}

/// Whether what differs from a view's ground is darker than it: in each sampled frame, the
/// view's darkest 0.3 % against its brightest 0.3 %, each measured from the median; a frame
/// votes only where one side stands out clearly (8× the noise) and is at least twice the other.
/// The noise is measured between neighbouring pixels, which an uneven ground does not inflate.
fn dark_spheres(frames: &[GreyImage], rect: [usize; 4]) -> bool {
    let mut votes = 0i32;
    let mut vals: Vec<f32> = Vec::new();
    let mut steps: Vec<f32> = Vec::new();
    for f in frames {
        vals.clear();
        steps.clear();
        for v in rect[1]..rect[3] {
            for u in rect[0]..rect[2] {
                vals.push(f.at(u, v));
                if u + 1 < rect[2] {
                    steps.push((f.at(u + 1, v) - f.at(u, v)).abs());
                }
            }
        }
        if vals.len() < 16 || steps.is_empty() {
            continue;
        }
        // Three order statistics, each selected rather than the whole view sorted (the sort
        // was 1.5 % of the analysis of a 40-frame recording): the same elements.
        let at = |p: f64| ((vals.len() - 1) as f64 * p).round() as usize;
        let (lo, mid, hi) = (at(0.003), at(0.5), at(0.997));
        let (below, med, above) = vals.select_nth_unstable_by(mid, f32::total_cmp);
        let med = *med as f64;
        let q_lo = if lo < mid {
            *below.select_nth_unstable_by(lo, f32::total_cmp).1 as f64
        } else {
            med
        };
        let q_hi = if hi > mid {
            *above.select_nth_unstable_by(hi - mid - 1, f32::total_cmp).1 as f64
        } else {
            med
        };
        let step_mid = steps.len() / 2;
        let step_median = *steps.select_nth_unstable_by(step_mid, f32::total_cmp).1 as f64;
        // |difference of two pixels| has median 0.954·σ·√2.
        let noise = (step_median / (0.954 * std::f64::consts::SQRT_2)).max(0.5);
        let (dark, bright) = (med - q_lo, q_hi - med);
        if dark > 8.0 * noise && dark > 2.0 * bright {
            votes -= 1;
        } else if bright > 8.0 * noise && bright > 2.0 * dark {
            votes += 1;
        }
    }
    votes < 0
}

/// A frame source whose frames come out normalised by a backdrop.
pub struct Normalised<'a> {
    pub inner: &'a mut dyn FrameSource,
    pub backdrop: Backdrop,
}

impl FrameSource for Normalised<'_> {
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
        self.backdrop.apply(img);
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
        w.extend(self.backdrop.warnings());
        w
    }
    fn recorded_config(&self) -> Option<&Config> {
        self.inner.recorded_config()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::geometry::ViewKind;
    use crate::analysis::source::MemoryFrames as Frames;

    fn view(w: u32, h: u32) -> View {
        let g = crate::config::ViewGeometry::shorthand([0, 0, w, h], 2.0, [0.0, 0.0], "+x", "-y");
        View::from_config(ViewKind::Direct, &g)
    }

    /// A view with a bright static bar (a ruler), a smooth gradient and a disc crossing it,
    /// `ground` and `disc` the levels: frame k has the disc at u = 8 + 3k.
    fn recording(ground: f32, disc: f32, bar: f32) -> Frames {
        let (w, h) = (96, 32);
        let frames = (0..30)
            .map(|k| {
                let cu = 8.0 + 3.0 * k as f32;
                (0..w * h)
                    .map(|i| {
                        let (u, v) = ((i % w) as f32, (i / w) as f32);
                        let mut g = ground + 0.1 * u;
                        if (26.0..30.0).contains(&v) {
                            g = bar;
                        }
                        if (u - cu).hypot(v - 12.0) < 6.0 {
                            g = disc;
                        }
                        // Deterministic "noise", ±1.
                        g + ((i * 7919 + k * 104_729) % 3) as f32 - 1.0
                    })
                    .collect()
            })
            .collect();
        Frames { w, h, frames }
    }

    #[test]
    fn static_clutter_is_removed_and_the_moving_disc_stays() {
        let mut src = recording(20.0, 180.0, 160.0);
        let views = [view(96, 32)];
        let b = Backdrop::estimate(&mut src, &views).expect("estimate");
        assert!(!b.views[0].dark_spheres);
        let mut img = GreyImage::new();
        src.read(10, &mut img).expect("read");
        b.apply(&mut img);
        // The ruler and the gradient are gone: within the noise of the ground's level.
        let level = b.views[0].level;
        for u in [5, 40, 90] {
            assert!(
                (img.at(u, 28) - level).abs() < 3.0,
                "ruler at u {u}: {}",
                img.at(u, 28)
            );
            assert!((img.at(u, 2) - level).abs() < 3.0, "gradient at u {u}");
        }
        // The disc (at u = 38 in frame 10) is still ~160 above its ground.
        assert!(img.at(38, 12) - level > 140.0);
        assert!(b.warnings().is_empty());
    }

    /// A shaded disc of radius 7 px crossing a bright bar (a ruler): frame k has it at u =
    /// 10.3 + 2.5k, v = 20.4, over the bar's rows 18–29 for most of its lower half. Pixels
    /// are averaged over 4 × 4 points.
    fn disc_over_a_bar(ground: f32, bar: f32) -> Frames {
        let (w, h) = (120, 40);
        let frames = (0..30)
            .map(|k| {
                let (cu, cv) = (10.3 + 2.5 * k as f64, 20.4);
                (0..w * h)
                    .map(|i| {
                        let (u, v) = ((i % w) as f64, (i / w) as f64);
                        let mut sum = 0.0;
                        for a in 0..4 {
                            for b in 0..4 {
                                let (x, y) =
                                    (u - 0.375 + 0.25 * a as f64, v - 0.375 + 0.25 * b as f64);
                                let rho = (x - cu).hypot(y - cv) / 7.0;
                                sum += if rho < 1.0 {
                                    // Lit from the left: brighter there, an ambient floor.
                                    let nz = (1.0 - rho * rho).sqrt();
                                    60.0 + 130.0 * (0.8 * nz - 0.6 * (x - cu) / 7.0).max(0.0)
                                } else if (18.0..30.0).contains(&y) {
                                    bar as f64
                                } else {
                                    ground as f64
                                };
                            }
                        }
                        // Deterministic "noise", ±1.
                        (sum / 16.0) as f32 + ((i * 7919 + k * 104_729) % 3) as f32 - 1.0
                    })
                    .collect()
            })
            .collect();
        Frames { w, h, frames }
    }

    /// A disc in front of static clutter hides it: measured on the frame with the backdrop
    /// subtracted, its centre comes out where it is only if the fit knows what the disc hides
    /// (`GreyImage::ground`). Without it (edge points and the grey-level model both reading
    /// the subtracted frame as the sphere) neither frame's disc was measured at all.
    #[test]
    fn a_disc_in_front_of_a_bright_bar_is_measured_where_it_is() {
        for bar in [150.0, 90.0] {
            let mut src = disc_over_a_bar(20.0, bar);
            let views = [view(120, 40)];
            let b = Backdrop::estimate(&mut src, &views).expect("estimate");
            for k in [8, 13, 17] {
                let mut img = GreyImage::new();
                src.read(k, &mut img).expect("read");
                b.apply(&mut img);
                let truth = [10.3 + 2.5 * k as f64, 20.4];
                let level = b.views[0].level as f64;
                let fit = crate::analysis::circle::refine(
                    &img,
                    &views[0],
                    [truth[0] + 0.8, truth[1] - 0.6],
                    7.0,
                    level,
                    None,
                    &[],
                )
                .expect("the disc is measured");
                let err = (fit.centre[0] - truth[0]).hypot(fit.centre[1] - truth[1]);
                assert!(
                    fit.grey_levels && err < 0.03,
                    "bar {bar}, frame {k}: centre {:?} is {err:.3} px from {truth:?}",
                    fit.centre
                );
            }
        }
    }

    #[test]
    fn a_backlit_view_is_inverted_and_said_so() {
        let mut src = recording(200.0, 25.0, 60.0);
        let views = [view(96, 32)];
        let b = Backdrop::estimate(&mut src, &views).expect("estimate");
        assert!(b.views[0].dark_spheres);
        let mut img = GreyImage::new();
        src.read(10, &mut img).expect("read");
        b.apply(&mut img);
        let level = b.views[0].level;
        assert!(
            img.at(38, 12) - level > 150.0,
            "the dark disc comes out bright"
        );
        assert!((img.at(70, 28) - level).abs() < 3.0, "the dark bar is gone");
        assert!(b.warnings()[0].contains("backlit"));
        // Markers are looked for in the sphere's own grey, the right way up: the raw frame's
        // level inside the disc, whatever was subtracted and inverted.
        let mut raw = GreyImage::new();
        src.read(10, &mut raw).expect("read");
        for (u, v) in [(38, 12), (70, 28), (5, 5)] {
            assert!(
                (img.lit_at(u, v) - raw.at(u, v)).abs() < 1e-3,
                "({u}, {v}): lit_at {} against the raw {}",
                img.lit_at(u, v),
                raw.at(u, v)
            );
        }
    }
}
