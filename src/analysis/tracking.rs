//! Per-frame measurement: every view of every frame is segmented, each candidate sphere gets a
//! sub-pixel circle fit, and the measurements are labelled a or b (a has the smaller world x, as
//! the report contract says). What cannot be measured is listed with the reason.

use super::circle::refine;
use super::detect::{find_blobs, levels, Blob};
use super::geometry::View;
use super::image::GreyImage;
use super::markers::{self, MarkerObs};
use super::report::Unmeasured;
use super::{AnalysisError, FrameSource};
use crate::config::Config;

#[derive(Clone, Debug)]
pub struct Measurement {
    pub centre_px: [f64; 2],
    pub sigma_px: [f64; 2],
    pub diameter_px: f64,
    pub markers: Vec<MarkerObs>,
}

#[derive(Clone, Debug)]
pub struct FrameObs {
    pub index: u64,
    pub frame_id: u64,
    pub time_s: f64,
    /// [sphere a, sphere b][view index] (views in the order of `geometry::views`).
    pub spheres: [Vec<Option<Measurement>>; 2],
}

/// World x of an image point in a view (both views see x).
fn world_x(view: &View, px: [f64; 2]) -> f64 {
    view.unproject(px)
        .iter()
        .find(|(axis, _)| *axis == 0)
        .map(|(_, x)| *x)
        .unwrap_or(px[0])
}

pub fn measure_all(
    source: &mut dyn FrameSource,
    views: &[View],
    cfg: &Config,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(Vec<FrameObs>, Vec<Unmeasured>), AnalysisError> {
    let mut img = GreyImage::new();
    let mut out = Vec::with_capacity(source.len());
    let mut unmeasured = Vec::new();
    let mut last: Vec<[Option<[f64; 2]>; 2]> = vec![[None, None]; views.len()];
    let n = source.len();
    for i in 0..n {
        let meta = source.meta(i);
        source.read(i, &mut img)?;
        let mut spheres: [Vec<Option<Measurement>>; 2] =
            [vec![None; views.len()], vec![None; views.len()]];
        for (vi, view) in views.iter().enumerate() {
            let radius = [0, 1].map(|s| cfg.spheres.sphere(s).0 / 2.0 * view.px_per_mm);
            let r_mean = 0.5 * (radius[0] + radius[1]);
            let lv = levels(&img, view);
            let blobs = find_blobs(&img, view, &lv, r_mean, cfg.analysis.threshold_fraction);
            let assigned = assign(&blobs, view, &last[vi]);
            if let [only] = blobs.as_slice() {
                let reason = if only.merged {
                    Some("a, b: silhouettes merged")
                } else if assigned.iter().all(|a| a.is_none()) {
                    Some("one sphere seen and no earlier frame to tell whether it is a or b")
                } else {
                    None
                };
                if let Some(reason) = reason {
                    unmeasured.push(Unmeasured {
                        frame: i as u64,
                        view: view.kind.name().into(),
                        reason: reason.into(),
                    });
                }
            }
            for (s, blob) in assigned.iter().enumerate() {
                let Some(b) = blob else { continue };
                let why = if b.merged {
                    Some("silhouettes of a and b merged")
                } else if b.clipped {
                    Some("sphere clipped by the view border")
                } else {
                    None
                };
                if let Some(reason) = why {
                    unmeasured.push(Unmeasured {
                        frame: i as u64,
                        view: view.kind.name().into(),
                        reason: format!("{}: {reason}", ["a", "b"][s]),
                    });
                    continue;
                }
                match refine(&img, view, b.centroid, radius[s], lv.background) {
                    Some(f) => {
                        let radius_mm = cfg.spheres.sphere(s).0 / 2.0;
                        spheres[s][vi] = Some(Measurement {
                            centre_px: f.centre,
                            sigma_px: f.centre_sigma,
                            diameter_px: 2.0 * f.radius,
                            markers: markers::find(
                                &img,
                                view,
                                &f,
                                radius_mm,
                                cfg.analysis.marker_diameter_mm,
                                lv.noise_sigma,
                            ),
                        });
                        last[vi][s] = Some(f.centre);
                    }
                    None => unmeasured.push(Unmeasured {
                        frame: i as u64,
                        view: view.kind.name().into(),
                        reason: format!("{}: too few edge points for a circle fit", ["a", "b"][s]),
                    }),
                }
            }
            if blobs.len() > 2 {
                unmeasured.push(Unmeasured {
                    frame: i as u64,
                    view: view.kind.name().into(),
                    reason: format!(
                        "{} bright blobs, expected at most 2; the two largest were used",
                        blobs.len()
                    ),
                });
            }
        }
        out.push(FrameObs {
            index: i as u64,
            frame_id: meta.frame_id,
            time_s: meta.timestamp_ns as f64 * 1e-9,
            spheres,
        });
        progress(i + 1, n);
    }
    Ok((out, unmeasured))
}

/// Labels up to two blobs a/b: with two, by world x; with one, by nearness to where each sphere
/// was last measured in this view (a single merged blob belongs to neither).
fn assign<'a>(
    blobs: &'a [Blob],
    view: &View,
    last: &[Option<[f64; 2]>; 2],
) -> [Option<&'a Blob>; 2] {
    let mut sorted: Vec<&Blob> = blobs.iter().collect();
    sorted.sort_by(|p, q| q.area_px.cmp(&p.area_px));
    sorted.truncate(2);
    match sorted.as_slice() {
        [p, q] => {
            if world_x(view, p.centroid) <= world_x(view, q.centroid) {
                [Some(p), Some(q)]
            } else {
                [Some(q), Some(p)]
            }
        }
        [p] if !p.merged => {
            let d = |s: usize| last[s].map(|c| (c[0] - p.centroid[0]).hypot(c[1] - p.centroid[1]));
            match (d(0), d(1)) {
                (Some(da), Some(db)) if da <= db => [Some(p), None],
                (Some(_), Some(_)) => [None, Some(p)],
                (Some(_), None) => [Some(p), None],
                (None, Some(_)) => [None, Some(p)],
                (None, None) => [None, None],
            }
        }
        _ => [None, None],
    }
}
