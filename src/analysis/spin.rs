//! Spin of each sphere before and after the impact, from its markers: markers are tracked from
//! frame to frame within each view (predicted with the current spin estimate, assigned nearest
//! first within a gate, so markers may appear and vanish at the limb), and one constant ω is
//! fitted per flight phase to the whole tracks (`spin_tracks`); where they are too few, to the
//! rotations between frame pairs from the markers both frames share (`rotation::fit_spin`, also
//! the thesis baseline's way).

use super::markers::MarkerObs;
use super::rotation::{self, PairRotation, RotationMethod, SpinFit, V3};
use super::spin_search;
use super::spin_tracks::{self, Sighting};
use super::tracking::FrameObs;
use nalgebra::Rotation3;
use std::collections::HashMap;

/// Marker positions (relative to the centre, mm), weights and the directions they were lifted
/// along, per frame, keyed by (view, track id).
type Tracked = Vec<(usize, HashMap<(usize, usize), (V3, f64, V3)>)>;

/// Furthest frame gap used for a pair, and the largest rotation a pair may span.
const MAX_GAP: usize = 4;
const MAX_PAIR_ANGLE_RAD: f64 = 1.2;
/// A marker this far from where the pair's rotation puts it was mis-assigned.
const MARKER_OUTLIER_MM: f64 = 0.35;

fn track(obs: &[FrameObs], frames: &[usize], s: usize, omega: V3, gate_mm: f64) -> Tracked {
    let views = obs.first().map(|f| f.spheres[s].len()).unwrap_or(0);
    let mut out: Tracked = frames.iter().map(|&k| (k, HashMap::new())).collect();
    for vi in 0..views {
        // (id, last position, last time)
        let mut active: Vec<(usize, V3, f64)> = Vec::new();
        let mut next_id = 0;
        for (slot, &k) in frames.iter().enumerate() {
            let f = &obs[k];
            let Some(m) = &f.spheres[s][vi] else { continue };
            let dets: &[MarkerObs] = &m.markers;
            let mut cand: Vec<(f64, usize, usize)> = Vec::new();
            for (ti, (_, p, t)) in active.iter().enumerate() {
                let pred = Rotation3::from_scaled_axis(omega * (f.time_s - t)) * p;
                for (di, d) in dets.iter().enumerate() {
                    let dist = (d.rel_mm - pred).norm();
                    if dist < gate_mm {
                        cand.push((dist, ti, di));
                    }
                }
            }
            cand.sort_by(|a, b| a.0.total_cmp(&b.0));
            let (mut t_used, mut d_used) = (vec![false; active.len()], vec![false; dets.len()]);
            for (_, ti, di) in cand {
                if t_used[ti] || d_used[di] {
                    continue;
                }
                t_used[ti] = true;
                d_used[di] = true;
                active[ti].1 = dets[di].rel_mm;
                active[ti].2 = f.time_s;
                out[slot].1.insert(
                    (vi, active[ti].0),
                    (dets[di].rel_mm, dets[di].weight, dets[di].toward),
                );
            }
            for (di, d) in dets.iter().enumerate() {
                if !d_used[di] {
                    active.push((next_id, d.rel_mm, f.time_s));
                    out[slot]
                        .1
                        .insert((vi, next_id), (d.rel_mm, d.weight, d.toward));
                    next_id += 1;
                }
            }
            // Forget markers unseen for a few frames (gone over the limb).
            let now = f.time_s;
            let period = if slot > 0 {
                now - obs[frames[slot - 1]].time_s
            } else {
                0.0
            };
            active.retain(|(_, _, t)| now - t <= 3.5 * period.max(1e-9));
        }
    }
    out
}

/// Every marker sighting of the tracked frames, for the whole-track fit.
fn sightings(obs: &[FrameObs], tracked: &Tracked) -> Vec<Sighting> {
    let mut out = Vec::new();
    for (k, markers) in tracked {
        for (key, (rel_mm, weight, toward)) in markers {
            out.push(Sighting {
                frame: *k,
                time_s: obs[*k].time_s,
                track: *key,
                rel_mm: *rel_mm,
                weight: *weight,
                toward: *toward,
            });
        }
    }
    // HashMap order is not fixed: sort, so that the fit (and the report) is bit-exact.
    out.sort_by_key(|s| (s.frame, s.track));
    out
}

/// Two markers (with the sphere centre) fix a rotation; the thesis's 9-parameter fit needs three.
fn min_markers(method: RotationMethod) -> usize {
    match method {
        RotationMethod::Kabsch => 2,
        RotationMethod::Thesis => 3,
    }
}

fn pair_rotations(tracked: &Tracked, method: RotationMethod) -> Vec<PairRotation> {
    let mut pairs = Vec::new();
    for a in 0..tracked.len() {
        for b in a + 1..(a + 1 + MAX_GAP).min(tracked.len()) {
            let (ka, ma) = &tracked[a];
            let (kb, mb) = &tracked[b];
            let mut keys: Vec<&(usize, usize)> =
                ma.keys().filter(|key| mb.contains_key(key)).collect();
            keys.sort();
            if keys.len() < min_markers(method) {
                continue;
            }
            let mut p: Vec<V3> = keys.iter().map(|k| ma[k].0).collect();
            let mut q: Vec<V3> = keys.iter().map(|k| mb[k].0).collect();
            let mut w: Vec<f64> = keys.iter().map(|k| ma[k].1.min(mb[k].1)).collect();
            let Some(mut rv) = rotation::estimate(method, &p, &q, &w) else {
                continue;
            };
            // A mis-assigned marker spoils a pair: drop the worst while it is far off and enough
            // remain (the thesis baseline keeps every point, as the thesis did).
            while method == RotationMethod::Kabsch && p.len() > 3 {
                let r = Rotation3::from_scaled_axis(rv);
                let (worst, err) = p
                    .iter()
                    .zip(&q)
                    .map(|(a, b)| (r * a - b).norm())
                    .enumerate()
                    .fold((0, 0.0), |acc, (i, e)| if e > acc.1 { (i, e) } else { acc });
                if err < MARKER_OUTLIER_MM {
                    break;
                }
                p.remove(worst);
                q.remove(worst);
                w.remove(worst);
                match rotation::estimate(method, &p, &q, &w) {
                    Some(v) => rv = v,
                    None => break,
                }
            }
            if rv.norm() > MAX_PAIR_ANGLE_RAD {
                continue;
            }
            pairs.push(PairRotation {
                frame_a: *ka,
                frame_b: *kb,
                dt_s: 0.0,
                rotvec: rv,
                markers: p.len(),
            });
        }
    }
    pairs
}

/// What the spin measurement of one sphere over one flight phase found.
#[derive(Clone, Debug, Default)]
pub struct SpinMeasurement {
    pub fit: Option<SpinFit>,
    /// Markers tracked in each frame (by frame index).
    pub markers_per_frame: HashMap<usize, u32>,
    /// The frame-pair rotations the fit rests on.
    pub pairs: Vec<PairRotation>,
    /// How many marker tracks the fit rests on (`spin_tracks::effective_tracks`); infinite for
    /// the thesis's method, which is kept as the thesis had it.
    pub effective_tracks: f64,
    /// The spin was followed from a search over rotations per frame (`spin_search`), not from
    /// rest: the markers turned too far between frames for the first pass's gate.
    pub searched: bool,
    /// The marker sightings the whole-track fit was given (the last gate's tracks; none for the
    /// thesis's method): what `handedness` lifts again.
    pub sightings: Vec<Sighting>,
}

impl SpinMeasurement {
    /// The fit, where it may be reported: resting on at least
    /// `spin_tracks::MIN_EFFECTIVE_TRACKS` tracks. (The others still carry dots for the second
    /// pass: a spin too weak to report still says where a dot has turned to better than none.)
    pub fn reportable(&self) -> Option<&SpinFit> {
        self.fit
            .as_ref()
            .filter(|_| self.effective_tracks >= spin_tracks::MIN_EFFECTIVE_TRACKS)
    }
}

/// Frame-pair rotations of sphere `s` over the given frames, tracked with `omega` as the
/// prediction; returns them with the markers tracked per frame.
pub fn pairs(
    obs: &[FrameObs],
    frames: &[usize],
    s: usize,
    method: RotationMethod,
    omega: V3,
    gate_mm: f64,
) -> (Vec<PairRotation>, HashMap<usize, u32>) {
    let (tracked, pairs) = tracked_pairs(obs, frames, s, method, omega, gate_mm);
    (pairs, markers_per_frame(&tracked))
}

/// The tracks of sphere `s`'s markers over the given frames, and the frame-pair rotations
/// they give (with the time between each pair's frames).
fn tracked_pairs(
    obs: &[FrameObs],
    frames: &[usize],
    s: usize,
    method: RotationMethod,
    omega: V3,
    gate_mm: f64,
) -> (Tracked, Vec<PairRotation>) {
    let tracked = track(obs, frames, s, omega, gate_mm);
    let mut pairs = pair_rotations(&tracked, method);
    for p in pairs.iter_mut() {
        p.dt_s = obs[p.frame_b].time_s - obs[p.frame_a].time_s;
    }
    (tracked, pairs)
}

fn markers_per_frame(tracked: &Tracked) -> HashMap<usize, u32> {
    tracked.iter().map(|(k, m)| (*k, m.len() as u32)).collect()
}

/// Spin of sphere `s` over the given frames (one flight phase): followed from rest, and where a
/// search over rotations per frame (`spin_search`) finds a spin that carries clearly more
/// markers onto the next frame's, followed from that spin instead.
pub fn measure(
    obs: &[FrameObs],
    frames: &[usize],
    s: usize,
    method: RotationMethod,
) -> SpinMeasurement {
    // First pass without prediction and a wide gate; then predicted with the spin found.
    let from_rest = follow(obs, frames, s, method, V3::zeros(), [1.3, 0.6]);
    if method == RotationMethod::Thesis {
        return from_rest;
    }
    let gate = 0.6;
    let omega_of = |m: &SpinMeasurement| m.fit.as_ref().map_or(V3::zeros(), |f| f.omega);
    let seen = spin_search::PhaseMarkers::of(obs, frames, s);
    let rest_links = seen.links(omega_of(&from_rest), gate);
    // Clearly more: a quarter more links and two besides, so that the search's grid (a coarse
    // start, scored on the phase's first frames only) never displaces a spin followed well.
    let clearly_more = |n: f64| n > 1.25 * rest_links + 2.0;
    // No spin could link clearly more: the search is not needed (nor made: it is a few
    // thousand scorings).
    if !clearly_more(seen.most_links()) {
        return from_rest;
    }
    let Some((start, n)) = seen.search(gate) else {
        return from_rest;
    };
    if !clearly_more(n) {
        return from_rest;
    }
    let searched = follow(obs, frames, s, method, start, [gate, gate]);
    if clearly_more(seen.links(omega_of(&searched), gate)) {
        SpinMeasurement {
            searched: true,
            ..searched
        }
    } else {
        from_rest
    }
}

/// Tracks and fits sphere `s`'s markers over the given frames, once per gate, each pass
/// predicted with the spin the pass before found (the first with `omega`).
fn follow(
    obs: &[FrameObs],
    frames: &[usize],
    s: usize,
    method: RotationMethod,
    mut omega: V3,
    gates: [f64; 2],
) -> SpinMeasurement {
    let mut out = SpinMeasurement::default();
    for (i, gate) in gates.into_iter().enumerate() {
        // Only the last gate's fit is reported; the ones before it only predict the next
        // gate's tracking, so they need the spin, not its widened covariance.
        let reported = i + 1 == gates.len();
        let (tracked, pairs) = tracked_pairs(obs, frames, s, method, omega, gate);
        // Whole marker tracks first: they use every sighting, also of a marker no other shares
        // a frame pair with. The pair rotations where the tracks are too few or too short, and
        // for the thesis's method, which is kept as the thesis had it.
        let fit = match method {
            RotationMethod::Kabsch => {
                let start = rotation::ls_omega_of(&pairs).unwrap_or(omega);
                // Each phase of each sphere its own sources for the model terms' influence.
                let first = frames.first().copied().unwrap_or(0);
                let sources = spin_tracks::model_sources(first, s);
                let seen = sightings(obs, &tracked);
                let fit = if reported {
                    spin_tracks::fit(&seen, start, sources)
                } else {
                    spin_tracks::fit_spin_only(&seen, start)
                };
                let fit = fit.or_else(|| rotation::fit_spin(&pairs));
                let tracks = spin_tracks::effective_tracks(&seen);
                (fit, tracks, seen)
            }
            RotationMethod::Thesis => (rotation::fit_spin(&pairs), f64::INFINITY, Vec::new()),
        };
        let (fit, effective_tracks, sightings) = fit;
        out = SpinMeasurement {
            fit,
            markers_per_frame: markers_per_frame(&tracked),
            pairs,
            effective_tracks,
            searched: false,
            sightings,
        };
        match &out.fit {
            Some(f) => omega = f.omega,
            None => break,
        }
    }
    out
}
