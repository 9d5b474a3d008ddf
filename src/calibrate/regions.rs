//! The views' regions found from the frames: where the mirror's edge lies.
//!
//! The whole frame is surveyed as one view (backdrop removed, so tube ends and the mirror's
//! frame drop out) and the spheres' blobs are collected over the recording. The edge runs
//! between two groups of blobs, across rows or across columns, that no blob straddles; of the
//! candidate gaps, the one whose two sides show the same x (the spheres' coordinate along the
//! edge on one side a straight-line function of theirs on the other, as a mirror view shows
//! them) in the most frames is the mirror's edge. Within that gap, the edge is where the still background steps
//! (a mirror reflects less than all of the light, and its frame shows); where nothing steps, at
//! the gap's end on the side whose spheres are cut off there (the direct view's when none are).
//!
//! Whether the views lie above each other or side by side, and which side is the direct view,
//! are the config's to say (the side its direct region's middle lies on), as the mirror's axes
//! are: the spheres fall in both views when the mirror is tilted, over a 40-frame recording
//! round the impact the direct view's fall need not show, and two spheres that collide leave a
//! gap of a pixel or two between them across which each side pairs as well as two views do.

use crate::analysis::detect::Blob;
use crate::analysis::{self, AnalysisError, FrameSource};
use crate::config::Config;

/// Frames surveyed for blobs and sampled for the background's profile, at most.
const SURVEY_FRAMES: usize = 80;
/// Each side of the edge must hold at least this share of the blobs.
const MIN_SIDE_SHARE: f64 = 0.15;
/// The two sides' coordinates along the edge must follow a straight line this closely (r²) to be
/// taken for two views of the same spheres.
const MIN_SHARED_R2: f64 = 0.9;
/// Rows (or columns) averaged on each side of a candidate edge for the background's level.
const LEVEL_ROWS: usize = 4;
/// A background step stands out when it is this many times the profile's robust row-to-row
/// scatter.
const STEP_SIGNIFICANCE: f64 = 6.0;

/// Where the frame splits into the two views.
#[derive(Clone, Debug, PartialEq)]
pub struct FoundSplit {
    /// The edge runs along a row (views above each other) or along a column (side by side).
    pub across_rows: bool,
    /// The first row (or column) of the second view.
    pub edge_px: u32,
    /// The background's change of level across the edge, grey levels, when one stood out.
    pub step_grey: Option<f64>,
    /// Without a step: the side whose spheres are cut off at the gap (the edge is put there).
    pub cut_side: Option<Side>,
    /// The direct view's side (the one the config's direct region lies on).
    pub direct_side: Side,
    /// The rows (or columns) no sphere crossed, first and last edge positions.
    pub gap_px: (u32, u32),
    /// Frames pairing the two sides' spheres, and how closely their u agree (r²).
    pub pairs: usize,
    pub shared_r2: f64,
}

impl FoundSplit {
    /// The direct view's region and the mirror's, [u, v, width, height] px.
    pub fn regions(&self, width: u32, height: u32) -> ([u32; 4], [u32; 4]) {
        let e = self.edge_px;
        let (first, second) = if self.across_rows {
            ([0, 0, width, e], [0, e, width, height - e])
        } else {
            ([0, 0, e, height], [e, 0, width - e, height])
        };
        if self.direct_side == Side::Before {
            (first, second)
        } else {
            (second, first)
        }
    }

    /// One line for the calibration's output.
    pub fn describe(&self) -> String {
        let line = if self.across_rows { "row" } else { "column" };
        let how = match (self.step_grey, self.cut_side) {
            (Some(s), _) => format!("where the background steps by {s:.1} grey levels"),
            (None, Some(_)) => format!(
                "where one view's spheres are cut off, at the end of {line}s {}–{} that no sphere crosses (no step in the background)",
                self.gap_px.0, self.gap_px.1
            ),
            (None, None) => format!(
                "against the direct view's spheres, at the end of {line}s {}–{} that no sphere crosses (no step in the background)",
                self.gap_px.0, self.gap_px.1
            ),
        };
        format!(
            "the mirror's edge at {line} {} ({how}); {} frames show both views' spheres at one x (r² {:.3})",
            self.edge_px,
            self.pairs,
            self.shared_r2
        )
    }
}

/// One side of the edge: before it (above, or left) or after it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    Before,
    After,
}

/// The side whose spheres are cut off where they meet the gap: near the gap (within a
/// diameter), at least two blobs smaller than 0.8 of the spheres' median size, and none such
/// on the other side. A mirror's edge hides the spheres of the view it cuts across; the other
/// view's spheres stay whole.
fn cut_side(blobs: &[Vec<Blob>], k: usize, gap: (u32, u32)) -> Option<Side> {
    let mut sizes: Vec<f64> = blobs.iter().flatten().map(Blob::diameter_px).collect();
    if sizes.is_empty() {
        return None;
    }
    sizes.sort_by(f64::total_cmp);
    let d_med = sizes[sizes.len() / 2];
    let (start, end) = (f64::from(gap.0), f64::from(gap.1));
    let (mut before, mut after) = (0, 0);
    for b in blobs.iter().flatten() {
        if b.diameter_px() >= 0.8 * d_med {
            continue;
        }
        let (first, last) = (b.extent_px[k] as f64, b.extent_px[k + 2] as f64);
        if last < start && last >= start - d_med {
            before += 1;
        } else if first >= end && first < end + d_med {
            after += 1;
        }
    }
    match (before >= 2, after >= 2) {
        (true, false) if after == 0 => Some(Side::Before),
        (false, true) if before == 0 => Some(Side::After),
        _ => None,
    }
}

/// What the whole-frame survey found: the spheres' blobs per frame, and the split if there is
/// one.
#[derive(Clone, Debug)]
pub struct Survey {
    pub blobs: Vec<Vec<Blob>>,
    pub split: Option<FoundSplit>,
}

impl Survey {
    /// Whether the given regions keep every sphere the survey saw wholly inside one of them
    /// (a blob or two may graze an edge) and each region holds its share: regions typed by the
    /// user that do this are kept.
    pub fn separates(&self, regions: &[[u32; 4]]) -> bool {
        let all: Vec<&Blob> = self.blobs.iter().flatten().collect();
        if all.is_empty() {
            return false;
        }
        let mut held = vec![0usize; regions.len()];
        let mut outside = 0usize;
        for b in &all {
            let [u0, v0, u1, v1] = b.extent_px.map(|x| x as u64);
            let inside = regions.iter().position(|g| {
                let [x, y, w, h] = g.map(u64::from);
                u0 >= x && u1 < x + w && v0 >= y && v1 < y + h
            });
            match inside {
                Some(i) => held[i] += 1,
                None => outside += 1,
            }
        }
        let n = all.len() as f64;
        outside as f64 <= (0.02 * n).max(1.0)
            && held.iter().all(|&k| k as f64 >= MIN_SIDE_SHARE * n)
    }
}

/// Surveys the whole frame and finds where it splits into the two views.
pub fn survey(src: &mut dyn FrameSource, cfg: &Config) -> Result<Survey, AnalysisError> {
    let (width, height) = src.dimensions();
    let mut whole = cfg.clone();
    let Some(d) = whole.geometry.direct.as_mut() else {
        return Ok(Survey {
            blobs: Vec::new(),
            split: None,
        });
    };
    d.region = [0, 0, width, height];
    whole.geometry.mirror = None;
    let mut blobs: Vec<Vec<Blob>> = analysis::blobs(src, &whole, SURVEY_FRAMES)?
        .into_iter()
        .map(|f| f.into_iter().next().unwrap_or_default())
        .collect();
    // Specks (dust, noise) are not spheres: keep blobs at least half the median diameter.
    let mut sizes: Vec<f64> = blobs.iter().flatten().map(Blob::diameter_px).collect();
    if sizes.is_empty() {
        return Ok(Survey { blobs, split: None });
    }
    sizes.sort_by(f64::total_cmp);
    let floor = 0.5 * sizes[sizes.len() / 2];
    for f in blobs.iter_mut() {
        f.retain(|b| b.diameter_px() >= floor);
    }
    let profiles = edge_profiles(src)?;
    let mut best: Option<FoundSplit> = None;
    for across_rows in layouts(cfg) {
        let len = if across_rows { height } else { width };
        let profile = if across_rows {
            &profiles.0
        } else {
            &profiles.1
        };
        for gap in gaps(&blobs, across_rows, len) {
            // The direct view's side: where the config's direct region's middle lies.
            let mid = 0.5 * f64::from(gap.0 + gap.1) - 0.5;
            let direct_side = match &cfg.geometry.direct {
                Some(d) => {
                    let k = usize::from(across_rows);
                    let centre = f64::from(d.region[k]) + 0.5 * f64::from(d.region[k + 2]);
                    if centre < mid {
                        Side::Before
                    } else {
                        Side::After
                    }
                }
                None => Side::Before,
            };
            let Some(found) = split_at(&blobs, across_rows, gap, profile, direct_side) else {
                continue;
            };
            // The views' edge pairs the spheres of most frames (a gap between two heights of
            // one view's spheres pairs only the odd frame).
            let score = |f: &FoundSplit| (f.pairs, f.shared_r2);
            if best.as_ref().is_none_or(|b| {
                score(&found).partial_cmp(&score(b)) == Some(std::cmp::Ordering::Greater)
            }) {
                best = Some(found);
            }
        }
    }
    Ok(Survey { blobs, split: best })
}

/// The regions calibrate measures with, and a line saying how they were chosen: the config's
/// where they keep each view's spheres whole and apart (`Survey::separates`), else those the
/// mirror's edge found in the frames gives (`survey`); the config's where no edge was found.
pub fn settle(src: &mut dyn FrameSource, cfg: &Config) -> Result<(String, Config), AnalysisError> {
    let found = survey(src, cfg)?;
    let typed: Vec<[u32; 4]> = [&cfg.geometry.direct, &cfg.geometry.mirror]
        .into_iter()
        .flatten()
        .map(|v| v.region)
        .collect();
    let mut settled = cfg.clone();
    let note = match &found.split {
        Some(split) if found.separates(&typed) => {
            format!("{}; the config's regions keep each view's spheres whole and apart, and are kept: {typed:?}", split.describe())
        }
        Some(split) => {
            let (w, h) = src.dimensions();
            let (d, m) = split.regions(w, h);
            if let Some(v) = settled.geometry.direct.as_mut() {
                v.region = d;
            }
            let mirror = match settled.geometry.mirror.as_mut() {
                Some(v) => {
                    v.region = m;
                    format!("mirror {m:?}")
                }
                None => "the config has no [geometry.mirror] for the other side".into(),
            };
            format!(
                "{}; the config's regions cut through a view's spheres, so these are used: direct {d:?}, {mirror}",
                split.describe()
            )
        }
        None => "the mirror's edge was not found (no two groups of spheres that share x); the config's regions are kept".into(),
    };
    Ok((note, settled))
}

/// Whether the views lie above each other (the edge along a row: true) or side by side, as the
/// config's regions have them; both when it has one view. The layout is the config's to say,
/// like which side is which: two spheres that collide in one view leave a gap between them of
/// a pixel or two in every frame, across which each side shows one sphere in both views, and
/// those pair as well as two views do.
fn layouts(cfg: &Config) -> Vec<bool> {
    let (Some(d), Some(m)) = (&cfg.geometry.direct, &cfg.geometry.mirror) else {
        return vec![true, false];
    };
    let overlap = |a0: u32, a1: u32, b0: u32, b1: u32| {
        i64::from(a0.saturating_add(a1).min(b0.saturating_add(b1))) - i64::from(a0.max(b0))
    };
    let columns = overlap(d.region[0], d.region[2], m.region[0], m.region[2]);
    let rows = overlap(d.region[1], d.region[3], m.region[1], m.region[3]);
    vec![columns >= rows]
}

/// The still background's step at each edge position, grey levels: for rows, entry s − 1 is the
/// mean over the sampled frames of the interquartile mean over columns of row s less row s − 1
/// (and the same for columns). A mirror's edge runs across the whole frame, so the interquartile
/// mean keeps it; a tube end or a sphere covers only part of a row, and drops out.
fn edge_profiles(src: &mut dyn FrameSource) -> Result<(Vec<f64>, Vec<f64>), AnalysisError> {
    let n = src.len();
    let k = n.min(31);
    let (mut rows, mut cols): (Vec<Vec<f64>>, Vec<Vec<f64>>) = (Vec::new(), Vec::new());
    let mut img = analysis::image::GreyImage::new();
    let mut line = Vec::new();
    for j in 0..k {
        let i = if k > 1 { j * (n - 1) / (k - 1) } else { 0 };
        src.read(i, &mut img)?;
        let (w, h) = (img.width, img.height);
        if w < 2 || h < 2 {
            continue;
        }
        if rows.is_empty() {
            rows = vec![Vec::with_capacity(k); h - 1];
            cols = vec![Vec::with_capacity(k); w - 1];
        }
        if rows.len() != h - 1 || cols.len() != w - 1 {
            continue;
        }
        for (s, out) in rows.iter_mut().enumerate() {
            line.clear();
            line.extend((0..w).map(|u| f64::from(img.at(u, s + 1) - img.at(u, s))));
            out.push(interquartile_mean(&mut line));
        }
        for (s, out) in cols.iter_mut().enumerate() {
            line.clear();
            line.extend((0..h).map(|v| f64::from(img.at(s + 1, v) - img.at(s, v))));
            out.push(interquartile_mean(&mut line));
        }
    }
    Ok((
        rows.iter_mut().map(|x| interquartile_mean(x)).collect(),
        cols.iter_mut().map(|x| interquartile_mean(x)).collect(),
    ))
}

/// The mean of the middle half: robust to what covers less than a quarter of a line (a tube
/// end, a sphere), and not stepped to whole grey levels as a median of integer frames is.
fn interquartile_mean(x: &mut [f64]) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    x.sort_by(f64::total_cmp);
    let (lo, hi) = (x.len() / 4, x.len() - x.len() / 4);
    let mid = &x[lo..hi.max(lo + 1)];
    mid.iter().sum::<f64>() / mid.len() as f64
}

/// The runs of edge positions (the first row or column of the second side) that split the
/// blobs into two populated sides with none straddling (a blob or two may graze), as
/// (first, last) inclusive.
fn gaps(blobs: &[Vec<Blob>], across_rows: bool, len: u32) -> Vec<(u32, u32)> {
    let k = usize::from(across_rows);
    let all: Vec<&Blob> = blobs.iter().flatten().collect();
    let n = all.len();
    let allowed = ((0.02 * n as f64) as usize).max(1);
    let mut out = Vec::new();
    let mut run: Option<(u32, u32)> = None;
    for s in 1..len as usize {
        let (mut before, mut after, mut straddle) = (0usize, 0usize, 0usize);
        for b in &all {
            if b.extent_px[k + 2] < s {
                before += 1;
            } else if b.extent_px[k] >= s {
                after += 1;
            } else {
                straddle += 1;
            }
        }
        let s = s as u32;
        let ok = straddle <= allowed
            && before as f64 >= MIN_SIDE_SHARE * n as f64
            && after as f64 >= MIN_SIDE_SHARE * n as f64;
        run = match (ok, run) {
            (true, Some((a, _))) => Some((a, s)),
            (true, None) => Some((s, s)),
            (false, Some(r)) => {
                out.push(r);
                None
            }
            (false, None) => None,
        };
    }
    out.extend(run);
    out
}

/// The blobs an edge at `s` (the first row or column of the second side) would cut through.
fn straddling(blobs: &[Vec<Blob>], k: usize, s: u32) -> usize {
    let s = s as usize;
    blobs
        .iter()
        .flatten()
        .filter(|b| b.extent_px[k] < s && b.extent_px[k + 2] >= s)
        .count()
}

/// The split within one gap, if its two sides show the same spheres at one x.
fn split_at(
    blobs: &[Vec<Blob>],
    across_rows: bool,
    gap: (u32, u32),
    steps: &[f64],
    direct_side: Side,
) -> Option<FoundSplit> {
    let k = usize::from(across_rows);
    let mid = 0.5 * f64::from(gap.0 + gap.1) - 0.5;
    // The two sides' coordinate along the edge (u for views above each other, v side by side:
    // a camera turned on its side images x down its rows), paired in order of it in frames
    // where both show the same one or two spheres.
    let along = 1 - k;
    let mut pairs: Vec<(f64, f64)> = Vec::new();
    let mut frames = 0;
    for f in blobs {
        let (mut a, mut b): (Vec<&Blob>, Vec<&Blob>) = f.iter().partition(|x| x.centroid[k] < mid);
        if a.len() != b.len() || a.is_empty() || a.len() > 2 {
            continue;
        }
        a.sort_by(|p, q| p.centroid[along].total_cmp(&q.centroid[along]));
        b.sort_by(|p, q| p.centroid[along].total_cmp(&q.centroid[along]));
        pairs.extend(
            a.iter()
                .zip(&b)
                .map(|(p, q)| (p.centroid[along], q.centroid[along])),
        );
        frames += 1;
    }
    let r2 = r_squared(&pairs)?;
    if frames < 6 || r2 < MIN_SHARED_R2 {
        return None;
    }
    // The background's step within the gap: the change of level across the edge, each side
    // averaged over `LEVEL_ROWS` rows (a thin line, such as a ruler's or a wire's, changes the
    // level over one row and back, and drops out), against the same measure's scatter over the
    // whole frame.
    let mut level = Vec::with_capacity(steps.len() + 1);
    level.push(0.0);
    for d in steps {
        level.push(level.last().copied().unwrap_or(0.0) + d);
    }
    let across = |s: usize| -> Option<f64> {
        let (lo, hi) = (s.checked_sub(LEVEL_ROWS)?, s + LEVEL_ROWS);
        let after = level.get(s..hi)?;
        let before = level.get(lo..s)?;
        let mean = |x: &[f64]| x.iter().sum::<f64>() / x.len() as f64;
        Some(mean(after) - mean(before))
    };
    let mut all: Vec<f64> = (0..level.len()).filter_map(across).map(f64::abs).collect();
    all.sort_by(f64::total_cmp);
    let scatter = 1.4826 * all.get(all.len() / 2).copied().unwrap_or(0.0);
    let (mut edge, mut step) = (None, 0.0);
    for s in gap.0..=gap.1 {
        let d = across(s as usize).map_or(0.0, f64::abs);
        if d > step {
            (edge, step) = (Some(s), d);
        }
    }
    let stands_out = step > (STEP_SIGNIFICANCE * scatter).max(0.5);
    let cut = cut_side(blobs, k, gap);
    // Without a step, the view whose spheres are cut off at the edge ends there (its cut
    // blobs then touch the region's border and are left out, as a clipped sphere should be);
    // with no cut seen, the direct view's, whose spheres fall through the frame while the
    // mirror's keep their depth. Anywhere in the gap keeps every whole sphere on its side.
    // (The gap may let a grazing blob or two straddle; the closing edge straddles none.)
    let clear = |s: &u32| straddling(blobs, k, *s) == 0;
    let middle = ((gap.0 + gap.1) as f64 / 2.0).round() as u32;
    let edge_px = match (edge, cut.unwrap_or(direct_side)) {
        (Some(e), _) if stands_out => e,
        (_, Side::Before) => (gap.0..=gap.1).find(clear).unwrap_or(middle),
        (_, Side::After) => (gap.0..=gap.1).rev().find(clear).unwrap_or(middle),
    };
    Some(FoundSplit {
        across_rows,
        edge_px,
        cut_side: cut,
        direct_side,
        step_grey: stands_out.then_some(step),
        gap_px: gap,
        pairs: frames,
        shared_r2: r2,
    })
}

/// r² of a straight-line fit of y on x; None without spread.
fn r_squared(p: &[(f64, f64)]) -> Option<f64> {
    if p.len() < 3 {
        return None;
    }
    let n = p.len() as f64;
    let (mx, my) = (
        p.iter().map(|q| q.0).sum::<f64>() / n,
        p.iter().map(|q| q.1).sum::<f64>() / n,
    );
    let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
    for (x, y) in p {
        sxx += (x - mx).powi(2);
        syy += (y - my).powi(2);
        sxy += (x - mx) * (y - my);
    }
    (sxx > 0.0 && syy > 0.0).then(|| sxy * sxy / (sxx * syy))
}

#[cfg(test)]
mod tests;
