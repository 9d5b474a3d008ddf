//! Spin from whole marker tracks: one constant ω and each tracked marker's place on the sphere,
//! fitted together to every sighting of it (physics.md §4).
//!
//! The frame-pair rotations (`rotation::fit_spin`) need two markers that both frames of a pair
//! show. A sphere lit or painted so that a view finds one or two markers a frame — fast spin
//! carries them over the limb within a few frames — leaves too few such pairs, and its spin went
//! unmeasured. One marker followed over three or more frames draws an arc whose plane and rate
//! fix ω by themselves; this fit uses every such arc, of every view, at once.
//!
//! Model: sighting i of track j, seen in view v at time t, is
//! q_i = R(ω·(t − t_ref)) p_j + J_i b_v + noise, where b_v is a constant offset of all the
//! view's markers from the centre they are measured against in the image (a disc centre biased
//! by the light, or marker centroids pushed along the shading's gradient) and a radius error of
//! their lift, and J_i what that does to the lifted point (`offset_jacobian`). Without it, such
//! an offset reads as a tilt of the spin axis (a marker's circle about a tilted axis is
//! displaced in proportion to its height), and on side-lit and specular looks spins came out
//! 2–2.5 rad/s off across the axis at 5–6σ, the same in both flight phases. For a given ω the
//! places and offsets are linear least squares (each p_j the weighted mean of its sightings less
//! J_i b_v, rotated back), so only ω is searched (variable projection); its covariance is
//! clustered by frame and by track, and comes with each frame's influence for the same uses as
//! the pair fit's.

use super::rotation::{SpinFit, MIN_SPIN_FRAMES, V3};
use nalgebra::{Matrix3, Rotation3};
use std::collections::BTreeMap;

/// One marker seen in one frame: the frame, its time, the track it belongs to (unique over the
/// views), where it is relative to the sphere centre (world mm) and its weight.
#[derive(Clone, Copy, Debug)]
pub struct Sighting {
    pub frame: usize,
    pub time_s: f64,
    pub track: (usize, usize),
    pub rel_mm: V3,
    pub weight: f64,
    /// Unit vector towards the view that saw it: the direction its depth was lifted along.
    pub toward: V3,
}

/// A sighting this far from where the fit puts it was assigned to the wrong track (the same
/// bound as a frame pair's marker outlier in `spin.rs`).
const MARKER_OUTLIER_MM: f64 = 0.35;
/// The fewest sightings a track needs to count. A track seen once fixes only its own place;
/// one seen twice adds a single frame pair, which the pair rotations use anyway, and a false
/// marker or a wrong assignment is then as good as a true one. On independent backlit renders
/// with faint markers (validation v04) the fit leaning on such pairs put a spin 270 rad/s off
/// at 20σ; from three sightings on, an arc must also bend the way a rotation does.
const MIN_TRACK_SIGHTINGS: usize = 3;

/// The fewest tracks a reported spin rests on, counted by `effective_tracks` (two tracks of 11
/// and 3 sightings count 1.5). One track's sightings share its mislocation (a marker's centroid
/// drifts as it crosses the shading), and the covariance, clustered by track, cannot see that
/// from one: on an independent render (validation v03) b's spin after the impact from one
/// mirror track of 16 sightings, each found 0.03–0.16 px off in a drift along it, came out
/// with ω's x 12 rad/s off at σ 1.5, and a's from two direct-view tracks of 11 and 3 sightings
/// 7.5 rad/s off at σ 1.2. Such a phase's spin is reported from the other phase and the
/// impulse, or not at all; the fit still carries dots for the second pass.
pub const MIN_EFFECTIVE_TRACKS: f64 = 2.0;

/// How many tracks the sightings amount to: (Σ n)²/Σ n² over the tracks seen at least
/// `MIN_TRACK_SIGHTINGS` times, n each one's sightings (k tracks of equal length count k).
pub fn effective_tracks(sightings: &[Sighting]) -> f64 {
    let (n1, n2) = tracks_of(sightings).values().fold((0.0, 0.0), |(a, b), v| {
        let n = v.len() as f64;
        (a + n, b + n * n)
    });
    if n2 > 0.0 {
        n1 * n1 / n2
    } else {
        0.0
    }
}

/// Which offset each view's sightings carry in the fit (`offset_jacobian`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Offsets {
    /// None at all.
    None,
    /// The same 3-D vector added to every lifted sighting.
    Constant,
    /// An offset in the image, carried through the lift.
    Lifted,
}

struct Problem<'a> {
    /// Sightings grouped by track, each with τ = t − t_ref.
    tracks: Vec<Vec<(&'a Sighting, f64)>>,
    /// Per track, each sighting's offset Jacobian (`offset_jacobian` for the lifted model, the
    /// identity otherwise): fixed by the sightings, so made once, not on every evaluation.
    jacs: Vec<Vec<Matrix3<f64>>>,
    /// The distinct τ of all sightings, and per track each sighting's index among them: the
    /// tracks of one phase share their frames, so each evaluation makes one rotation a frame,
    /// not one a sighting (the rotations were a fifth of the fit's time on the independent
    /// renders). The same τ gives the same rotation, bit for bit.
    taus: Vec<f64>,
    tau_of: Vec<Vec<usize>>,
    /// Whether each view's sightings carry an offset, fitted too, and of which model.
    offsets: Offsets,
}

impl Problem<'_> {
    /// Residuals (3 per sighting, each scaled by √w) at ω, in track order.
    ///
    /// (The hot path of the spin fits, six calls a descent step: where J is the identity it is
    /// not multiplied by, and without offsets M is not made, which changes no bit of the
    /// result; the views' normal equations are a short list, not a map.)
    fn residuals(&self, omega: &V3, out: &mut Vec<f64>) {
        out.clear();
        let with_offsets = self.offsets != Offsets::None;
        let jac_is_identity = self.offsets != Offsets::Lifted;
        // Per track: its rotations, each sighting's offset Jacobian J, its place p̂ as if no
        // offset, and M = Σ w Rᵀ J / W, with which the place given an offset b is p̂ − M b.
        let mut per_track = Vec::with_capacity(self.tracks.len());
        // Per view: A b = c, the offset's normal equations with the places eliminated.
        let mut normal: Vec<(usize, Matrix3<f64>, V3)> = Vec::new();
        let all_rots: Vec<Rotation3<f64>> = self
            .taus
            .iter()
            .map(|tau| Rotation3::from_scaled_axis(omega * *tau))
            .collect();
        for ((t, jacs), idx) in self.tracks.iter().zip(&self.jacs).zip(&self.tau_of) {
            let rots = || idx.iter().map(|&i| &all_rots[i]);
            let (mut sum, mut m, mut wsum) = (V3::zeros(), Matrix3::zeros(), 0.0);
            for (((s, _), r), j) in t.iter().zip(rots()).zip(jacs) {
                sum += s.weight * r.inverse_transform_vector(&s.rel_mm);
                if jac_is_identity {
                    if with_offsets {
                        m += s.weight * r.matrix().transpose();
                    }
                } else {
                    m += s.weight * r.matrix().transpose() * j;
                }
                wsum += s.weight;
            }
            let (p, m) = (sum / wsum, m / wsum);
            if with_offsets {
                let view = t[0].0.track.0;
                let at = match normal.iter().position(|(v, _, _)| *v == view) {
                    Some(at) => at,
                    None => {
                        normal.push((view, Matrix3::zeros(), V3::zeros()));
                        normal.len() - 1
                    }
                };
                let (_, a, c) = &mut normal[at];
                for (((s, _), r), j) in t.iter().zip(rots()).zip(jacs) {
                    let e = j - r.matrix() * m;
                    *a += s.weight * e.transpose() * e;
                    *c += s.weight * e.transpose() * (s.rel_mm - r * p);
                }
            }
            per_track.push((idx, jacs, p, m));
        }
        // An offset along the spin axis is a place's own component: nothing fixes it, and the
        // small ridge sets it to zero.
        let offsets: Vec<(usize, V3)> = normal
            .into_iter()
            .map(|(v, a, c)| {
                let ridge = Matrix3::identity() * (1e-6 * a.trace() / 3.0);
                let b = (a + ridge).try_inverse().map_or(V3::zeros(), |inv| inv * c);
                (v, b)
            })
            .collect();
        for (t, (idx, jacs, p, m)) in self.tracks.iter().zip(&per_track) {
            let view = t[0].0.track.0;
            let b = offsets
                .iter()
                .find(|(v, _)| *v == view)
                .map_or_else(V3::zeros, |(_, b)| *b);
            let place = if with_offsets { p - m * b } else { *p };
            for (((s, _), r), j) in t
                .iter()
                .zip(idx.iter().map(|&i| &all_rots[i]))
                .zip(jacs.iter())
            {
                let jb = if jac_is_identity { b } else { j * b };
                let d = (s.rel_mm - r * place - jb) * s.weight.sqrt();
                out.extend_from_slice(d.as_slice());
            }
        }
    }

    /// The residuals' Jacobian by ω (the profile over the p_j is smooth): by central
    /// differences, or with `at` (the residuals at ω) by forward ones, half the evaluations.
    /// Why both: the descent only needs a direction, and the Jacobian's error (relative, about
    /// h) moves where it stops by that fraction of the residuals' pull, far below any σ; the
    /// covariance takes the central one.
    fn jacobian(&self, omega: &V3, r0_len: usize, at: Option<&[f64]>) -> Vec<[f64; 3]> {
        let mut jac = vec![[0.0; 3]; r0_len];
        let (mut plus, mut minus) = (Vec::new(), Vec::new());
        for c in 0..3 {
            let h = 1e-4 * (1.0 + omega.norm());
            let mut d = V3::zeros();
            d[c] = h;
            self.residuals(&(omega + d), &mut plus);
            match at {
                Some(at) => {
                    for (row, (a, b)) in jac.iter_mut().zip(plus.iter().zip(at)) {
                        row[c] = (a - b) / h;
                    }
                }
                None => {
                    self.residuals(&(omega - d), &mut minus);
                    for (row, (a, b)) in jac.iter_mut().zip(plus.iter().zip(&minus)) {
                        row[c] = (a - b) / (2.0 * h);
                    }
                }
            }
        }
        jac
    }

    fn cost(&self, omega: &V3, buf: &mut Vec<f64>) -> f64 {
        self.residuals(omega, buf);
        buf.iter().map(|x| x * x).sum()
    }

    /// A start that needs no guess: for two sightings of a track Δt apart, the Rodrigues
    /// vector g = tan(θ/2)·axis of the rotation between them satisfies g × (q_a + q_b) =
    /// q_b − q_a exactly, and g ≈ ω·Δt/2 while θ is small, so ω × (q_a + q_b) ≈ 2 (q_b − q_a)/Δt
    /// is linear in ω (4 % off at 0.7 rad between sightings; the fit then goes the rest of the
    /// way). Least squares over each track's consecutive sightings.
    fn linear_start(&self) -> Option<V3> {
        let (mut ata, mut atb) = (Matrix3::zeros(), V3::zeros());
        for t in &self.tracks {
            for w in t.windows(2) {
                let ((a, ta), (b, tb)) = (w[0], w[1]);
                let dt = tb - ta;
                if dt <= 0.0 {
                    continue;
                }
                let weight = a.weight.min(b.weight);
                // ω × m = −[m]× ω.
                let m = a.rel_mm + b.rel_mm;
                let am = -m.cross_matrix();
                let rhs = (b.rel_mm - a.rel_mm) * (2.0 / dt);
                ata += weight * am.transpose() * am;
                atb += weight * am.transpose() * rhs;
            }
        }
        let omega = ata.try_inverse()? * atb;
        omega.iter().all(|x| x.is_finite()).then_some(omega)
    }

    /// Levenberg–Marquardt over ω from `start`.
    fn solve(&self, start: V3) -> Option<V3> {
        let mut omega = start;
        let mut r = Vec::new();
        let mut cost = self.cost(&omega, &mut r);
        let mut lambda = 1e-3;
        for _ in 0..100 {
            let jac = self.jacobian(&omega, r.len(), Some(&r));
            let (mut jtj, mut jtr) = (Matrix3::zeros(), V3::zeros());
            for (row, ri) in jac.iter().zip(&r) {
                let j = V3::from(*row);
                jtj += j * j.transpose();
                jtr += j * *ri;
            }
            let mut improved = false;
            for _ in 0..20 {
                let mut a = jtj;
                for c in 0..3 {
                    a[(c, c)] *= 1.0 + lambda;
                }
                let step = a.try_inverse()? * -jtr;
                let trial = omega + step;
                let mut rt = Vec::new();
                let c = self.cost(&trial, &mut rt);
                if c.is_finite() && c <= cost {
                    let small = step.norm() <= 1e-9 * (1.0 + omega.norm());
                    omega = trial;
                    cost = c;
                    r = rt;
                    lambda = (lambda * 0.3).max(1e-12);
                    improved = !small;
                    break;
                }
                lambda *= 10.0;
            }
            if !improved {
                break;
            }
        }
        omega.iter().all(|x| x.is_finite()).then_some(omega)
    }
}

/// How a view's offset b moves one lifted sighting: the dot is found in the image and its depth
/// lifted from how far it lies from the disc centre, √(R² − ρ²). An offset b square to the line
/// of sight t (a disc centre biased by the light, or dots pushed along the shading) moves the
/// lifted point across by b and along t by −(a·b)/d, a the point's part across and d its
/// depth; b's part along t moves nothing (the ridge in `residuals` sets it to zero). A constant
/// 3-D offset (J = I) left the depth's part as a tilt of the axis: on the bench's side-lit and
/// specular looks, fast spins about the view's axis came out 0.5–1° tilted, the same in both
/// flight phases, at 5–10σ. (Dots found a little outward or inward scale every lifted point
/// alike, which the places absorb, plus a depth change R²ε/d that for a spin about t is
/// constant along each track, the places' own too.) Depth is held at least a fifth of R, where
/// `markers` stops lifting anyway. With `toward` zero (no line of sight known) J is the
/// identity: a plain 3-D offset.
fn offset_jacobian(s: &Sighting) -> Matrix3<f64> {
    let t = s.toward;
    let radius = s.rel_mm.norm();
    let depth = s.rel_mm.dot(&t).max(0.2 * radius);
    let across = s.rel_mm - t * s.rel_mm.dot(&t);
    Matrix3::identity() - t * t.transpose() - t * across.transpose() / depth
}

/// Indices in `frame_influence` for the lifted model's term (`fit`), one per phase and sphere:
/// far from any frame, from the other model term's and from the impulse's.
const LIFTED_SOURCES: std::ops::Range<usize> = (usize::MAX / 2 - (1 << 40))..(usize::MAX / 2 + 1);

/// `fit`'s `sources` for the phase starting at frame `first` of sphere `s`: the without-offsets
/// term's index and the lifted model's, each distinct from any frame, from the impulse's terms
/// and from every other phase's and sphere's.
pub fn model_sources(first: usize, s: usize) -> [usize; 2] {
    [
        (usize::MAX - 64).saturating_sub(2 * first + s),
        (usize::MAX / 2).saturating_sub((2 * first + s).min(1 << 39)),
    ]
}

/// `fit`'s covariance without the lifted model's term: for carrying dots from frame to frame
/// (`second_pass`), where a tilt of the axis by the bias that term stands for (under a degree)
/// moves a dot far less than the term's share of ω's σ, accumulated over the carry, says; with
/// it, dots that should have been masked were not, and centres on defocused looks got worse.
pub fn cov_for_carry(fit: &SpinFit) -> Matrix3<f64> {
    fit.frame_influence
        .iter()
        .filter(|(k, _)| LIFTED_SOURCES.contains(k))
        .fold(fit.cov, |c, (_, r)| c - r * r.transpose())
}

/// Constant ω fitted to whole marker tracks, started at `start` (the pair fit's ω, or the
/// prediction the tracks were followed with). None where fewer than `MIN_SPIN_FRAMES` frames
/// show a marker seen three times or more. Arcs too short to fix an axis show as a large σ.
///
/// The fit is made with a constant offset per view, and compared with two others:
/// - without the offsets. Where a view's offset is real the two differ by the tilt it caused;
///   where it is not, by the scatter the offsets add; but where short arcs let an offset trade
///   against the rate, the two can land far apart, and then neither σ knows it. So the part of
///   their difference beyond twice the scatter expected of it (the variance the offsets add,
///   along the difference) is added to the covariance, as one more independent source of error
///   with the index `sources[0]` in `frame_influence`. On 190 varied-look recordings that took
///   the estimates beyond 5σ from 26 to 17.
/// - with each view's offset taken in the image and carried through the lift
///   (`offset_jacobian`), which a constant 3-D offset only approximates: that fit has no tilt
///   from the offset, but an offset in the image and a tilt of the axis then look much alike,
///   and its σ is 2–5× the constant model's across the axis. The part of its difference from
///   the reported fit beyond twice the scatter expected of it is the constant model's bias
///   showing, and is added to the covariance in the same way (index `sources[1]`; with the
///   threshold at once the scatter, noise alone pushed ±1σ coverage to 85 % in the tests
///   below). Reporting the lifted fit itself doubled the median spin error on the bench.
pub fn fit(sightings: &[Sighting], start: V3, sources: [usize; 2]) -> Option<SpinFit> {
    let mut with = fit_with(sightings, start, Offsets::Constant)?;
    let base = with.clone();
    for (other, factor, source) in [
        (Offsets::None, 4.0, sources[0]),
        (Offsets::Lifted, 4.0, sources[1]),
    ] {
        let Some(other) = fit_with(sightings, start, other) else {
            continue;
        };
        let d = base.omega - other.omega;
        let n = d.norm();
        if n > 0.0 {
            let u = d / n;
            let scatter = u.dot(&((base.cov - other.cov) * u)).abs();
            let excess = n * n - factor * scatter;
            if excess > 0.0 {
                let r = u * excess.sqrt();
                with.cov += r * r.transpose();
                with.frame_influence.push((source, r));
            }
        }
    }
    Some(with)
}

/// `fit`'s spin without the fits it is compared with: the same ω (and `None` where `fit`
/// gives none), its covariance not widened. For a fit that only predicts where the markers
/// go next (the wide gate before the narrow one, `spin::follow`): the two fits left out were
/// two thirds of that gate's spin-fit time.
pub fn fit_spin_only(sightings: &[Sighting], start: V3) -> Option<SpinFit> {
    fit_with(sightings, start, Offsets::Constant)
}

/// How well one rigid turn explains the sightings: the least sum of squared (weighted)
/// residuals of a constant ω with each view's constant offset, from the linear start and each
/// of `starts`. No sighting is dropped, so that ways of lifting the same sightings compare on
/// the same ones (`handedness`).
pub fn misfit(sightings: &[Sighting], starts: &[V3]) -> Option<f64> {
    let problem = build(sightings, Offsets::Constant)?;
    let mut buf = Vec::new();
    problem
        .linear_start()
        .into_iter()
        .chain(starts.iter().copied())
        .filter_map(|s| problem.solve(s))
        .map(|w| problem.cost(&w, &mut buf))
        .min_by(f64::total_cmp)
}

/// One fit, with or without each view's constant offset (`fit` makes both and reports the
/// first, widened by how far the second lies from it).
fn fit_with(sightings: &[Sighting], start: V3, offsets: Offsets) -> Option<SpinFit> {
    let mut kept: Vec<Sighting> = sightings.to_vec();
    // Drop the worst misfit while it is beyond the outlier bound (a marker followed onto its
    // neighbour), refitting each time; at most a tenth of the sightings.
    let limit = kept.len() / 10;
    let mut omega = start;
    for round in 0..=limit {
        let problem = build(&kept, offsets)?;
        // From the linear start and from the caller's, whichever ends lower.
        let mut buf = Vec::new();
        omega = [problem.linear_start(), Some(omega)]
            .into_iter()
            .flatten()
            .filter_map(|s| problem.solve(s))
            .map(|w| (problem.cost(&w, &mut buf), w))
            .min_by(|a, b| a.0.total_cmp(&b.0))?
            .1;
        let mut r = Vec::new();
        problem.residuals(&omega, &mut r);
        let order: Vec<&Sighting> = problem.tracks.iter().flatten().map(|(s, _)| *s).collect();
        let (worst, err) = r
            .chunks(3)
            .zip(&order)
            .map(|(c, s)| V3::new(c[0], c[1], c[2]).norm() / s.weight.sqrt().max(1e-12))
            .enumerate()
            .fold((0, 0.0), |acc, (i, e)| if e > acc.1 { (i, e) } else { acc });
        if err < MARKER_OUTLIER_MM || round == limit {
            break;
        }
        let bad = *order[worst];
        kept.retain(|s| !(s.frame == bad.frame && s.track == bad.track));
    }
    let problem = build(&kept, offsets)?;
    covariance(&problem, omega)
}

/// The usable sightings (a weight, a finite place) by track, of the tracks seen at least
/// `MIN_TRACK_SIGHTINGS` times: what a fit rests on.
fn tracks_of(sightings: &[Sighting]) -> BTreeMap<(usize, usize), Vec<&Sighting>> {
    let mut by_track: BTreeMap<(usize, usize), Vec<&Sighting>> = BTreeMap::new();
    for s in sightings {
        if s.weight > 0.0 && s.rel_mm.iter().all(|x| x.is_finite()) {
            by_track.entry(s.track).or_default().push(s);
        }
    }
    by_track.retain(|_, v| v.len() >= MIN_TRACK_SIGHTINGS);
    by_track
}

fn build(kept: &[Sighting], offsets: Offsets) -> Option<Problem<'_>> {
    let by_track = tracks_of(kept);
    let all: Vec<&Sighting> = by_track.values().flatten().copied().collect();
    let wsum: f64 = all.iter().map(|s| s.weight).sum();
    if all.is_empty() || wsum <= 0.0 {
        return None;
    }
    let t_ref = all.iter().map(|s| s.weight * s.time_s).sum::<f64>() / wsum;
    let tracks: Vec<Vec<(&Sighting, f64)>> = by_track
        .into_values()
        .map(|v| v.into_iter().map(|s| (s, s.time_s - t_ref)).collect())
        .collect();
    let jacs = tracks
        .iter()
        .map(|t| {
            t.iter()
                .map(|(s, _)| match offsets {
                    Offsets::Lifted => offset_jacobian(s),
                    _ => Matrix3::identity(),
                })
                .collect()
        })
        .collect();
    let mut taus: Vec<f64> = tracks.iter().flatten().map(|(_, tau)| *tau).collect();
    // Sorted and deduplicated by the same order the search below uses, so every τ is found.
    taus.sort_by(f64::total_cmp);
    taus.dedup_by(|a, b| a.total_cmp(b).is_eq());
    let tau_of = tracks
        .iter()
        .map(|t| {
            t.iter()
                .map(|(_, tau)| {
                    taus.binary_search_by(|x| x.total_cmp(tau))
                        .unwrap_or_default()
                })
                .collect()
        })
        .collect();
    Some(Problem {
        offsets,
        tracks,
        jacs,
        taus,
        tau_of,
    })
}

/// ω's covariance clustered by frame (the same sandwich and small-sample factor as
/// `rotation::fit_spin`): each frame's influence is (J̃ᵀJ̃)⁻¹ Σ over its sightings of J̃ᵢᵀ rᵢ,
/// with J̃ the Jacobian of the residuals profiled over the tracks' places.
fn covariance(problem: &Problem, omega: V3) -> Option<SpinFit> {
    let mut r = Vec::new();
    problem.residuals(&omega, &mut r);
    let jac = problem.jacobian(&omega, r.len(), None);
    let order: Vec<&Sighting> = problem.tracks.iter().flatten().map(|(s, _)| *s).collect();
    let mut jtj = Matrix3::zeros();
    let mut per_frame: BTreeMap<usize, V3> = BTreeMap::new();
    for (i, s) in order.iter().enumerate() {
        for k in 0..3 {
            let j = V3::from(jac[3 * i + k]);
            jtj += j * j.transpose();
            *per_frame.entry(s.frame).or_insert_with(V3::zeros) += j * r[3 * i + k];
        }
    }
    if per_frame.len() < MIN_SPIN_FRAMES {
        return None;
    }
    let inv = jtj.try_inverse()?;
    let n = per_frame.len() as f64;
    // Clustered by frame and by track (two-way: V_frame + V_track − V_sighting). A marker's
    // mislocation drifts as it crosses the shading, so one track's sightings err together, which
    // clustering by frame alone does not see: with frames only, 15 of 450 spin components of
    // the bench's varied looks landed beyond 5σ. The excess over the frame-clustered variance
    // is carried as one factor on the frames' influences, the largest over the axes, so that
    // `frame_influence` still sums to the covariance.
    let mut per_track: BTreeMap<(usize, usize), V3> = BTreeMap::new();
    let mut v_sighting = Matrix3::zeros();
    for (i, s) in order.iter().enumerate() {
        let mut g = V3::zeros();
        for k in 0..3 {
            g += V3::from(jac[3 * i + k]) * r[3 * i + k];
        }
        *per_track.entry(s.track).or_insert_with(V3::zeros) += g;
        let u = inv * g;
        v_sighting += u * u.transpose();
    }
    let outer = |gs: &mut dyn Iterator<Item = &V3>| {
        gs.fold(Matrix3::zeros(), |c, g| {
            let u = inv * g;
            c + u * u.transpose()
        })
    };
    let v_frame = outer(&mut per_frame.values());
    let v_two_way = v_frame + outer(&mut per_track.values()) - v_sighting;
    let excess = (0..3)
        .map(|i| v_two_way[(i, i)] / v_frame[(i, i)])
        .filter(|x| x.is_finite())
        .fold(1.0f64, f64::max);
    // n/(n − 3) as in `rotation::fit_spin`: the clustered covariance's small-sample factor
    // times Student's t variance.
    let scale = (n / (n - 3.0) * excess).sqrt();
    let frame_influence: Vec<(usize, V3)> = per_frame
        .into_iter()
        .map(|(f, g)| (f, inv * g * scale))
        .collect();
    let cov = frame_influence
        .iter()
        .fold(Matrix3::zeros(), |c, (_, d)| c + d * d.transpose());
    cov.iter().all(|x| x.is_finite()).then_some(SpinFit {
        omega,
        cov,
        pairs: order.len(),
        frame_influence,
    })
}

#[cfg(test)]
mod tests;
