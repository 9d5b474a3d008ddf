//! The sectors of a disc's ring that something darker than the ground lies against outside: a
//! shadow the sphere casts on a backdrop close behind it, under a lamp off the camera's axis.
//!
//! Why: the grey-level model blends the disc's shading with a flat ground at its edge; where a
//! shadow lies against the limb, the pixels there blend it with the shadow, and the fit moves
//! the disc towards it (where the shadow lies against the dark limb, the model takes it for the
//! limb). On `scripts/rerender-looks.py`'s cast shadows (half as dark as a ground of 80, lamp
//! 30° off axis, backdrop 15 mm behind), one sphere came out 1.1–1.5 px off in most frames of
//! a view with a claimed σ of 0.03–0.06 px (docs/accuracy.md, session 52). Those sectors are
//! left out of the fit, as the other sphere's side is; the edge points, the fit's start, leave
//! out such rays themselves (`edge::edge_points`).

use super::super::{CircleFit, GreyImage, View};

/// Sectors of the ring, as in `sectors_covered`.
const SECTORS: usize = 36;
/// How far outside the edge the ground is read, px: past a sharp edge's blur, and within
/// the reach of a shadow that touches the limb. (A blurred disc's light there only lifts the
/// readings; a blurred limb darker than the ground lowers the nearest, which the sector's
/// lower quartile of twelve readings passes over.)
const OUTSIDE_PX: [f64; 4] = [1.5, 2.5, 3.5, 4.5];
/// A sector is shadowed where its ground lies below the ground by more than this share of the
/// disc's contrast (and than the noise allows).
const DEPTH_OF_CONTRAST: f64 = 0.1;
/// … and by more than this many σ of a pixel's noise.
const DEPTH_NOISE_SIGMA: f64 = 4.0;

/// The shadowed sectors of a disc's ring (bit k: the sector from 10k° to 10(k + 1)°, angles
/// from the u axis towards v, about `centre`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Shadowed {
    centre: [f64; 2],
    sectors: u64,
}

impl Shadowed {
    pub(super) const NONE: Shadowed = Shadowed {
        centre: [0.0; 2],
        sectors: 0,
    };

    /// The sectors of `disc`'s ring whose ground, read just outside its edge (off `excluded`
    /// pixels and the view's border), lies darker than `background`. None at all where more
    /// than half the ring does: a lamp's shadow falls on one side, and a ring darker all round
    /// is something else (a camera's sharpening halo), which leaving out would leave no fit.
    pub(super) fn find(
        img: &GreyImage,
        view: &View,
        disc: &CircleFit,
        background: f64,
        excluded: &dyn Fn(f64, f64) -> bool,
    ) -> Shadowed {
        let [cu, cv] = disc.centre;
        let r = disc.radius;
        if !(r > 2.0 && cu.is_finite() && cv.is_finite()) {
            return Shadowed::NONE;
        }
        let at = |a: f64, d: f64| {
            let (u, v) = (cu + d * a.cos(), cv + d * a.sin());
            if !view.contains(u, v) || excluded(u, v) {
                return None;
            }
            img.sample(u, v)
        };
        // The disc's contrast: the median of its inside against the ground.
        let mut inside: Vec<f64> = (0..SECTORS)
            .flat_map(|k| {
                let a = std::f64::consts::TAU * k as f64 / SECTORS as f64;
                [0.3, 0.5, 0.7].map(|f| at(a, f * r))
            })
            .flatten()
            .collect();
        if inside.len() < SECTORS {
            return Shadowed::NONE;
        }
        let mid = inside.len() / 2;
        let contrast = (*inside.select_nth_unstable_by(mid, f64::total_cmp).1 - background).abs();
        // Each sector's ground outside, and the spread of its readings.
        let mut medians = [f64::NAN; SECTORS];
        let mut spread: Vec<f64> = Vec::with_capacity(SECTORS * 12);
        let mut readings: Vec<f64> = Vec::with_capacity(12);
        for (k, m) in medians.iter_mut().enumerate() {
            readings.clear();
            for j in 1..=3 {
                let a = std::f64::consts::TAU * (k as f64 + 0.25 * j as f64) / SECTORS as f64;
                readings.extend(OUTSIDE_PX.iter().filter_map(|&d| at(a, r + d)));
            }
            if readings.len() < 6 {
                continue;
            }
            readings.sort_by(f64::total_cmp);
            // The lower quartile: a shadow's thin end darkens only the nearer readings.
            *m = readings[readings.len() / 4];
            let median = readings[readings.len() / 2];
            spread.extend(readings.iter().map(|x| (x - median).abs()));
        }
        if spread.len() < SECTORS {
            return Shadowed::NONE;
        }
        let mid = spread.len() / 2;
        let sigma = 1.4826 * *spread.select_nth_unstable_by(mid, f64::total_cmp).1;
        let depth = (DEPTH_OF_CONTRAST * contrast)
            .max(DEPTH_NOISE_SIGMA * sigma)
            .max(1.0);
        let mut sectors = 0u64;
        for (k, m) in medians.iter().enumerate() {
            if background - m > depth {
                sectors |= 1 << k;
            }
        }
        // A shadow is one piece: a sector between two shadowed ones is shadowed too (its
        // reading missed by a level or two).
        let all = (1u64 << SECTORS) - 1;
        let rot = |x: u64, k: usize| ((x << k) | (x >> (SECTORS - k))) & all;
        sectors |= rot(sectors, 1) & rot(sectors, SECTORS - 1);
        if sectors.count_ones() as usize > SECTORS / 2 {
            return Shadowed::NONE;
        }
        Shadowed {
            centre: disc.centre,
            sectors,
        }
    }

    /// Whether pixel (u, v) lies in a shadowed sector.
    pub(super) fn covers(&self, u: f64, v: f64) -> bool {
        if self.sectors == 0 {
            return false;
        }
        let a = (v - self.centre[1])
            .atan2(u - self.centre[0])
            .rem_euclid(std::f64::consts::TAU);
        let k = ((a / std::f64::consts::TAU * SECTORS as f64) as usize).min(SECTORS - 1);
        self.sectors & (1 << k) != 0
    }
}
