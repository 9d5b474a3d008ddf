//! The pixels a grey-level fit uses: the band round each disc's edge, off the dots, the other
//! sphere and the view's border, each with what a disc hides there and how its area is averaged.

use super::super::edge::sectors_covered;
use super::super::{CircleFit, DotMask, GreyImage, View};
use super::{dist, PROFILE_BAND_PX};

/// The pixels within `PROFILE_BAND_PX` outside and `inner_px` inside any of the discs' edges,
/// inside the view, off the dots and not `excluded`; None unless each disc keeps
/// `min_sectors` of its ring's 36 sectors and at least 40 pixels.
pub(super) fn ring_pixels(
    img: &GreyImage,
    view: &View,
    discs: &[&CircleFit],
    dots: &[DotMask],
    excluded: impl Fn(f64, f64) -> bool,
    min_sectors: usize,
    inner_px: f64,
) -> Option<Vec<RingPixel>> {
    if img.width == 0 || img.height == 0 || discs.is_empty() {
        return None;
    }
    let reach = |d: &CircleFit| d.radius + PROFILE_BAND_PX + 1.0;
    let span = |lo: f64, hi: f64, len: usize| -> Option<(usize, usize)> {
        let lo = lo.floor().max(0.0);
        let hi = hi.ceil().min((len - 1) as f64);
        (lo <= hi).then_some((lo as usize, hi as usize))
    };
    let lo = |i: usize| {
        discs
            .iter()
            .map(|d| d.centre[i] - reach(d))
            .fold(f64::MAX, f64::min)
    };
    let hi = |i: usize| {
        discs
            .iter()
            .map(|d| d.centre[i] + reach(d))
            .fold(f64::MIN, f64::max)
    };
    let (u_lo, u_hi) = span(lo(0), hi(0), img.width)?;
    let (v_lo, v_hi) = span(lo(1), hi(1), img.height)?;
    let on_ring = |d: &CircleFit, u: f64, v: f64| {
        let out = dist(u - d.centre[0], v - d.centre[1]) - d.radius;
        out <= PROFILE_BAND_PX && out >= -inner_px
    };
    let mut pixels: Vec<RingPixel> = Vec::new();
    for v in v_lo..=v_hi {
        for u in u_lo..=u_hi {
            let (uf, vf) = (u as f64, v as f64);
            if !discs.iter().any(|d| on_ring(d, uf, vf)) {
                continue;
            }
            // A disc cut by the view's border is fitted on the part of its ring inside: the
            // sector count below asks for more than half of it. Beyond lies another view.
            if !view.contains(uf, vf) || excluded(uf, vf) {
                continue;
            }
            // An overexposed pixel's level is only a floor: the shading model would be pulled
            // down to the camera's ceiling (overexposed side-lit spheres: ψ off by 0.03, spins
            // at 6σ, against 0.003 exposed right). Left out, as a dot is.
            if img.unmeasured_at(u, v) {
                continue;
            }
            if dots
                .iter()
                .any(|d| dist(uf - d.centre_px[0], vf - d.centre_px[1]) < d.radius_px)
            {
                continue;
            }
            let to_edge = discs
                .iter()
                .map(|d| (dist(uf - d.centre[0], vf - d.centre[1]) - d.radius).abs())
                .fold(f64::INFINITY, f64::min);
            pixels.push(RingPixel {
                u: uf,
                v: vf,
                grey: img.at(u, v) as f64,
                hidden: img.ground_at(u, v) as f64,
                area: if to_edge < EDGE_ZONE_PX {
                    Area::Fine
                } else {
                    Area::Whole
                },
            });
        }
    }
    for d in discs {
        let ring: Vec<[f64; 2]> = pixels
            .iter()
            .filter(|q| on_ring(d, q.u, q.v))
            .map(|q| [q.u, q.v])
            .collect();
        if ring.len() < 40 || sectors_covered(&ring, d.centre) < min_sectors {
            return None;
        }
    }
    Some(pixels)
}

/// The centres of a pixel's three strips, px from the pixel's centre across them, over which
/// the model is averaged where an edge crosses the pixel (each strip 1/3 px thick; see
/// `fit_grey_levels`). They replaced 3 × 3 parts, which on noise-free renders did as well as
/// 4 × 4 point samples.
pub(super) const STRIP_OFFSETS: [f64; 3] = [-1.0 / 3.0, 0.0, 1.0 / 3.0];

/// Pixels whose centre lies within this of an edge are averaged over in strips
/// (`STRIP_OFFSETS`), px; the rest of the band as one box. The box average along the edge's
/// normal matches a square's spread across an edge but not its shape (a step across a side, a
/// ramp across a diagonal), which matters where the edge crosses the pixel: 2 × 2 parts there
/// left noise-free centres with masked rim dots scattered 0.0025 px instead of 0.0023.
const EDGE_ZONE_PX: f64 = 1.0;

/// How a ring pixel's model is averaged over its area in the final round.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Area {
    /// An edge crosses it: in strips.
    Fine,
    /// As one box.
    Whole,
}

/// One pixel of a ring: its centre (u, v), grey level, what a disc covering it hides
/// (`GreyImage::ground`), and how its area is integrated.
#[derive(Clone, Copy, Debug)]
pub(super) struct RingPixel {
    pub(super) u: f64,
    pub(super) v: f64,
    pub(super) grey: f64,
    pub(super) hidden: f64,
    pub(super) area: Area,
}

impl RingPixel {
    /// Whether the model is averaged over this pixel in strips: in the last round
    /// (`area`), where an edge crosses it.
    pub(super) fn in_parts(&self, area: bool) -> bool {
        area && self.area == Area::Fine
    }
}
