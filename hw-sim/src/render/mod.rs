//! Rendering of the rig's views into a camera frame: orthographic projection of each sphere into
//! each view, Lambertian shading lit from the view's camera, dark markers, supersampled
//! anti-aliasing, finer where a limb or a dot's rim crosses the pixel (so sub-pixel truth is
//! meaningful: a coarse regular grid draws the limb as a staircase), motion blur over the
//! exposure, read and shot noise, and quantisation to 8 or 16 bits.
//!
//! The background noise comes from a pre-noised table copied at a random offset per frame: it is
//! what lets the simulator keep up with 640×480 at 2000 fps, where drawing a fresh Gaussian per
//! pixel per frame would not.

mod flicker;
mod look;
mod project;

use crate::config::{LabConfig, Scene, ViewSpec};
use crate::physics::Body;
use crate::rng::Rng;
use crate::V3;
use look::LookState;
use project::discs_in;
pub(crate) use project::hit;
pub use project::{project, radius_px};

const TABLE_PIXELS: usize = 1 << 20;

pub struct Renderer {
    scene: Scene,
    cfg: LabConfig,
    bytes_per_pixel: usize,
    /// Quantised background + noise, TABLE_PIXELS + frame pixels long so a frame is one copy.
    background: Vec<u8>,
    noise: Vec<f32>,
    rng: Rng,
    /// Present when the config gives a look (`sim.look`); None is the original render.
    look: Option<LookState>,
    /// The lamps' flicker, when the config gives one (`sim.flicker_percent`).
    flicker: Option<flicker::Flicker>,
    /// The sensor's stuck pixels (`sim.stuck_pixels`): frame index, and whether hot (else dead).
    stuck: Vec<(usize, bool)>,
}

/// What one sphere looks like during one sub-exposure instant.
pub(crate) struct Pose {
    centre_mm: V3,
    radius_mm: f64,
    markers_world: Vec<V3>,
}

impl Renderer {
    pub fn new(scene: Scene, cfg: LabConfig, seed: u64) -> Renderer {
        let mut rng = Rng::new(seed ^ 0xA5A5_1234);
        let bytes_per_pixel = if scene.bit_depth > 8 { 2 } else { 1 };
        let npx = (scene.width * scene.height) as usize;
        let noise: Vec<f32> = (0..TABLE_PIXELS).map(|_| rng.gaussian() as f32).collect();
        let bg_sigma = total_sigma(&cfg, cfg.background_grey);
        let mut background = Vec::with_capacity((TABLE_PIXELS + npx) * bytes_per_pixel);
        for _ in 0..TABLE_PIXELS + npx {
            let v = cfg.background_grey + bg_sigma * rng.gaussian();
            push_pixel(&mut background, v, bytes_per_pixel);
        }
        let look = cfg.look.clone().map(|l| LookState::new(l, &scene, &cfg));
        let flicker = flicker::Flicker::new(&cfg, seed);
        // From a generator of their own: the other draws stay as they were.
        let stuck = stuck_places(seed ^ 0x57AC_D0E5, cfg.stuck_pixels as usize, npx);
        Renderer {
            scene,
            cfg,
            bytes_per_pixel,
            background,
            noise,
            rng,
            look,
            flicker,
            stuck,
        }
    }

    /// Where the spheres leave their tubes (centre at the exit, downhill direction), for a look
    /// that shows the tube ends; redraws the backdrop when they moved.
    pub fn set_tube_exits(&mut self, exits: [(V3, V3); 2]) {
        if let Some(l) = self.look.as_mut() {
            l.set_tubes(&self.scene, &self.cfg, exits);
        }
    }

    pub fn frame_bytes(&self) -> usize {
        (self.scene.width * self.scene.height) as usize * self.bytes_per_pixel
    }

    /// Renders the frame whose exposure is centred on `t_mid_s`; `state_at` gives both spheres
    /// (and their marker directions in world coordinates) at any instant.
    pub fn render(
        &mut self,
        t_mid_s: f64,
        state_at: &dyn Fn(f64) -> ([Body; 2], [Vec<V3>; 2]),
        out: &mut Vec<u8>,
    ) {
        let npx = (self.scene.width * self.scene.height) as usize;
        let bpp = self.bytes_per_pixel;
        let off = (self.rng.next_u64() as usize) % TABLE_PIXELS;
        out.clear();
        out.extend_from_slice(&self.background[off * bpp..(off + npx) * bpp]);

        let exposure = self.cfg.exposure_ms / 1000.0;
        let (mid, _) = state_at(t_mid_s);
        let px_per_mm = self
            .scene
            .views
            .iter()
            .map(|v| v.px_per_mm)
            .fold(0.0, f64::max);
        let max_px_per_exposure =
            px_per_mm * mid.iter().map(|b| b.vel_mm_s.norm()).fold(0.0, f64::max) * exposure;
        // Instants 0.5 px apart up to a pixel of smear (the default exposure's, which recorded
        // sessions were made with); beyond, 0.25 px apart: at 0.5 px apart a sphere smeared by
        // 3–4 px was a staircase of copies, not a streak. At most 16 for a sphere of the lab's
        // 240 × 192 size (6.85 px in radius), fewer (not below 8) as its area grows: the
        // renderer must keep up with the camera's clock, and at 640 × 480 sixteen instants of a
        // 1 ms exposure did not (the recorder gave up after a second without a frame).
        let sphere_px = px_per_mm * mid.iter().map(|b| b.radius_mm).fold(0.0, f64::max);
        let most = ((16.0 * (6.85 / sphere_px.max(1e-9)).powi(2)) as usize).clamp(8, 16);
        let substeps = if max_px_per_exposure <= 1.0 {
            ((max_px_per_exposure * 2.0).ceil() as usize).clamp(1, 8)
        } else {
            ((max_px_per_exposure * 4.0).ceil() as usize).clamp(4, most)
        };
        let poses: Vec<[Pose; 2]> = (0..substeps)
            .map(|k| {
                let t = if substeps == 1 {
                    t_mid_s
                } else {
                    t_mid_s - exposure / 2.0 + exposure * (k as f64 + 0.5) / substeps as f64
                };
                let (bodies, markers) = state_at(t);
                let [m0, m1] = markers;
                [
                    Pose {
                        centre_mm: bodies[0].pos_mm,
                        radius_mm: bodies[0].radius_mm,
                        markers_world: m0,
                    },
                    Pose {
                        centre_mm: bodies[1].pos_mm,
                        radius_mm: bodies[1].radius_mm,
                        markers_world: m1,
                    },
                ]
            })
            .collect();
        if self.look.is_some() {
            let gain = self
                .flicker
                .as_ref()
                .map_or(1.0, |f| f.gain(t_mid_s, exposure));
            self.render_with_look(&poses, gain, out);
        } else {
            for vi in 0..self.scene.views.len() {
                self.render_view(vi, &poses, out);
            }
        }
        let bpp = self.bytes_per_pixel;
        for &(i, hot) in &self.stuck {
            let level: u16 = if hot { u16::MAX } else { 0 };
            if let Some(px) = out.get_mut(i * bpp..(i + 1) * bpp) {
                if bpp == 1 {
                    px[0] = if hot { u8::MAX } else { 0 };
                } else {
                    px.copy_from_slice(&level.to_le_bytes());
                }
            }
        }
    }

    /// The frame under a look: the (defocused) backdrop with fresh noise everywhere, then each
    /// view's sphere boxes drawn noise-free over the sharp backdrop, blurred, and noised. `gain`:
    /// the lamps' light over this exposure against their mean (1 without flicker).
    fn render_with_look(&mut self, poses: &[[Pose; 2]], gain: f64, out: &mut Vec<u8>) {
        let Some(st) = self.look.as_ref() else {
            return;
        };
        let npx = (self.scene.width * self.scene.height) as usize;
        let bpp = self.bytes_per_pixel;
        let width = self.scene.width as usize;
        out.clear();
        out.resize(npx * bpp, 0);
        let off = (self.rng.next_u64() as usize) % TABLE_PIXELS;
        for (i, &g) in st.blurred().iter().enumerate() {
            let k = (off + i) % TABLE_PIXELS;
            look::write_noisy(
                &self.cfg,
                out,
                i,
                gain * g as f64,
                self.noise[k] as f64,
                bpp,
            );
        }
        let margin = st.margin_px();
        let ss = self.cfg.supersample.max(1) as usize;
        let ss_edge = (self.cfg.edge_supersample as usize).max(ss);
        for (vi, view) in self.scene.views.iter().enumerate() {
            let [rx, ry, rw, rh] = view.region;
            let (x0, y0) = (rx as i64, ry as i64);
            let (x1, y1) = (
                (rx + rw).min(self.scene.width) as i64 - 1,
                (ry + rh).min(self.scene.height) as i64 - 1,
            );
            let discs = discs_in(view, poses);
            // One box round every pose of both spheres when theirs overlap, else one each.
            let mut boxes: Vec<[i64; 4]> = Vec::new();
            for s in 0..2 {
                let mut b = [i64::MAX, i64::MAX, i64::MIN, i64::MIN];
                for &(u, v, r) in discs.iter().skip(s).step_by(2) {
                    let r = r + 1.5 + margin as f64;
                    b = [
                        b[0].min((u - r).floor() as i64),
                        b[1].min((v - r).floor() as i64),
                        b[2].max((u + r).ceil() as i64),
                        b[3].max((v + r).ceil() as i64),
                    ];
                }
                let b = [b[0].max(x0), b[1].max(y0), b[2].min(x1), b[3].min(y1)];
                if b[0] > b[2] || b[1] > b[3] {
                    continue;
                }
                match boxes.iter_mut().find(|o| {
                    !(b[0] > o[2] + margin
                        || b[2] + margin < o[0]
                        || b[1] > o[3] + margin
                        || b[3] + margin < o[1])
                }) {
                    Some(o) => {
                        *o = [
                            o[0].min(b[0]),
                            o[1].min(b[1]),
                            o[2].max(b[2]),
                            o[3].max(b[3]),
                        ];
                    }
                    None => boxes.push(b),
                }
            }
            for b in boxes {
                // The blur reads `margin` px beyond the box.
                let e = [
                    (b[0] - margin).max(x0),
                    (b[1] - margin).max(y0),
                    (b[2] + margin).min(x1),
                    (b[3] + margin).min(y1),
                ];
                let bw = (e[2] - e[0] + 1) as usize;
                let bh = (e[3] - e[1] + 1) as usize;
                let mut buf = vec![0f32; bw * bh];
                for v in e[1]..=e[3] {
                    for u in e[0]..=e[2] {
                        let idx = v as usize * width + u as usize;
                        let on_limb = discs.iter().any(|&(cu, cv, r)| {
                            ((u as f64 - cu).hypot(v as f64 - cv) - r).abs() < 0.75
                        });
                        let near = discs
                            .iter()
                            .any(|&(cu, cv, r)| (u as f64 - cu).hypot(v as f64 - cv) < r + 1.0);
                        let mut value = st.sharp(idx);
                        if near {
                            let n = if on_limb { ss_edge } else { ss };
                            let (mut sum, mut hits, mut kinds) =
                                sample_look(st, vi, view, &self.cfg, poses, u, v, n);
                            let mut n = n;
                            if kinds == Kinds::Mixed && n < ss_edge {
                                (sum, hits, kinds) =
                                    sample_look(st, vi, view, &self.cfg, poses, u, v, ss_edge);
                                n = ss_edge;
                            }
                            if kinds != Kinds::None {
                                let total = (n * n * poses.len()) as f64;
                                value = (sum * st.illum(idx)
                                    + (total - hits as f64) * st.sharp(idx))
                                    / total;
                            }
                        }
                        buf[(v - e[1]) as usize * bw + (u - e[0]) as usize] = value as f32;
                    }
                }
                look::blur(&mut buf, bw, [0, 0, bw, bh], st.defocus_sigma_px());
                for v in b[1]..=b[3] {
                    for u in b[0]..=b[2] {
                        let idx = v as usize * width + u as usize;
                        let val = gain * buf[(v - e[1]) as usize * bw + (u - e[0]) as usize] as f64;
                        let k = (self.rng.next_u64() as usize) % TABLE_PIXELS;
                        look::write_noisy(&self.cfg, out, idx, val, self.noise[k] as f64, bpp);
                    }
                }
            }
        }
    }

    fn render_view(&mut self, vi: usize, poses: &[[Pose; 2]], out: &mut [u8]) {
        let view = &self.scene.views[vi];
        let [rx, ry, rw, rh] = view.region;
        let (x0, y0) = (rx as i64, ry as i64);
        let (x1, y1) = (
            (rx + rw).min(self.scene.width) as i64,
            (ry + rh).min(self.scene.height) as i64,
        );
        // Pixel boxes each sphere can touch during the exposure.
        let mut boxes: Vec<(i64, i64, i64, i64)> = Vec::new();
        for s in 0..2 {
            let (mut bu0, mut bv0, mut bu1, mut bv1) = (i64::MAX, i64::MAX, i64::MIN, i64::MIN);
            for p in poses {
                let (u, v) = project(view, &p[s].centre_mm);
                let r = radius_px(view, &p[s].centre_mm, p[s].radius_mm) + 1.5;
                bu0 = bu0.min((u - r).floor() as i64);
                bv0 = bv0.min((v - r).floor() as i64);
                bu1 = bu1.max((u + r).ceil() as i64);
                bv1 = bv1.max((v + r).ceil() as i64);
            }
            let b = (bu0.max(x0), bv0.max(y0), bu1.min(x1 - 1), bv1.min(y1 - 1));
            if b.0 <= b.2 && b.1 <= b.3 {
                boxes.push(b);
            }
        }
        let ss = self.cfg.supersample.max(1) as usize;
        let ss_edge = (self.cfg.edge_supersample as usize).max(ss);
        let width = self.scene.width as usize;
        let discs = discs_in(view, poses);
        for (bi, b) in boxes.iter().enumerate() {
            for v in b.1..=b.3 {
                for u in b.0..=b.2 {
                    // A pixel in an earlier box was already drawn with both spheres.
                    if boxes[..bi]
                        .iter()
                        .any(|p| u >= p.0 && u <= p.2 && v >= p.1 && v <= p.3)
                    {
                        continue;
                    }
                    // The pixel's corners are within √½ px of its centre: a limb closer than
                    // that crosses it. Elsewhere a marker's rim is found by the coarse grid.
                    let on_limb = discs.iter().any(|&(cu, cv, r)| {
                        ((u as f64 - cu).hypot(v as f64 - cv) - r).abs() < 0.75
                    });
                    let (mut sum, mut kinds, mut n) = if on_limb {
                        let (sum, kinds) = self.sample_pixel(view, poses, u, v, ss_edge);
                        (sum, kinds, ss_edge)
                    } else {
                        let (sum, kinds) = self.sample_pixel(view, poses, u, v, ss);
                        (sum, kinds, ss)
                    };
                    if kinds == Kinds::Mixed && n < ss_edge {
                        (sum, kinds) = self.sample_pixel(view, poses, u, v, ss_edge);
                        n = ss_edge;
                    }
                    if kinds == Kinds::None {
                        continue;
                    }
                    let mean = sum / (n * n * poses.len()) as f64;
                    let sigma = total_sigma(&self.cfg, mean);
                    let k = (self.rng.next_u64() as usize) % TABLE_PIXELS;
                    let val = mean + sigma * self.noise[k] as f64;
                    let idx = v as usize * width + u as usize;
                    write_pixel(out, idx, val, self.bytes_per_pixel);
                }
            }
        }
    }

    /// Sum of the grey levels at an ss×ss grid in pixel (u, v) over the poses, and whether the
    /// samples saw nothing but background, one surface only, or a mix (limb or marker rim).
    fn sample_pixel(
        &self,
        view: &ViewSpec,
        poses: &[[Pose; 2]],
        u: i64,
        v: i64,
        ss: usize,
    ) -> (f64, Kinds) {
        let mut sum = 0.0;
        let mut kinds = Kinds::None;
        let mut first: Option<Surface> = None;
        for p in poses {
            for sy in 0..ss {
                for sx in 0..ss {
                    let su = u as f64 - 0.5 + (sx as f64 + 0.5) / ss as f64;
                    let sv = v as f64 - 0.5 + (sy as f64 + 0.5) / ss as f64;
                    let hit = shade(view, &self.cfg, p, su, sv);
                    let surface = hit.map(|(_, s)| s).unwrap_or(Surface::Background);
                    match hit {
                        Some((val, _)) => sum += val,
                        None => sum += self.cfg.background_grey,
                    }
                    if hit.is_some() && kinds == Kinds::None {
                        kinds = Kinds::Uniform;
                    }
                    match first {
                        None => first = Some(surface),
                        Some(f) if f != surface => kinds = Kinds::Mixed,
                        _ => {}
                    }
                }
            }
        }
        (sum, kinds)
    }
}

/// Under a look: the sum of the sphere samples' grey levels (before the illumination field) at
/// an ss×ss grid in pixel (u, v) over the poses, how many samples hit a sphere, and what kinds
/// of surface they saw.
#[allow(clippy::too_many_arguments)]
fn sample_look(
    st: &LookState,
    vi: usize,
    view: &ViewSpec,
    cfg: &LabConfig,
    poses: &[[Pose; 2]],
    u: i64,
    v: i64,
    ss: usize,
) -> (f64, usize, Kinds) {
    let (mut sum, mut hits) = (0.0, 0usize);
    let mut kinds = Kinds::None;
    let mut first: Option<Surface> = None;
    for p in poses {
        for sy in 0..ss {
            for sx in 0..ss {
                let su = u as f64 - 0.5 + (sx as f64 + 0.5) / ss as f64;
                let sv = v as f64 - 0.5 + (sy as f64 + 0.5) / ss as f64;
                let surface = match st.shade(vi, view, cfg, p, su, sv) {
                    Some((grey, i, marker)) => {
                        sum += grey;
                        hits += 1;
                        if kinds == Kinds::None {
                            kinds = Kinds::Uniform;
                        }
                        if marker {
                            Surface::Marker(i)
                        } else {
                            Surface::Sphere(i)
                        }
                    }
                    None => Surface::Background,
                };
                match first {
                    None => first = Some(surface),
                    Some(f) if f != surface => kinds = Kinds::Mixed,
                    _ => {}
                }
            }
        }
    }
    (sum, hits, kinds)
}

/// What the samples of one pixel saw.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Kinds {
    /// Background only: the pixel keeps the background frame's value.
    None,
    /// One surface throughout (it may be shaded).
    Uniform,
    /// A boundary crosses the pixel.
    Mixed,
}

/// Which surface a sample lands on.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Surface {
    Background,
    Sphere(usize),
    Marker(usize),
}

/// Grey level of the nearest sphere surface under image point (su, sv) and which surface it is,
/// or None for background.
fn shade(
    view: &ViewSpec,
    cfg: &LabConfig,
    pose: &[Pose; 2],
    su: f64,
    sv: f64,
) -> Option<(f64, Surface)> {
    let mut best: Option<(f64, f64, Surface)> = None; // (depth towards camera, grey, surface)
    for (i, p) in pose.iter().enumerate() {
        let Some((depth, normal, nz)) = hit(view, &p.centre_mm, p.radius_mm, su, sv) else {
            continue;
        };
        if best.is_some_and(|(d, _, _)| d >= depth) {
            continue;
        }
        let ang_r = cfg.marker_diameter_mm / 2.0 / p.radius_mm;
        let on_marker = p
            .markers_world
            .iter()
            .any(|m| normal.dot(&((m - p.centre_mm) / p.radius_mm)) > ang_r.cos());
        let (grey, surface) = if on_marker {
            (cfg.marker_grey, Surface::Marker(i))
        } else {
            (cfg.sphere_grey * (0.55 + 0.45 * nz), Surface::Sphere(i))
        };
        best = Some((depth, grey, surface));
    }
    best.map(|(_, g, s)| (g, s))
}

pub(crate) fn total_sigma(cfg: &LabConfig, grey: f64) -> f64 {
    let shot = if cfg.shot_noise_e_per_grey > 0.0 {
        grey.max(0.0) / cfg.shot_noise_e_per_grey
    } else {
        0.0
    };
    (cfg.noise_sigma_grey * cfg.noise_sigma_grey + shot).sqrt()
}

fn push_pixel(buf: &mut Vec<u8>, grey8: f64, bpp: usize) {
    if bpp == 1 {
        buf.push(grey8.round().clamp(0.0, 255.0) as u8);
    } else {
        let v = (grey8 * 256.0).round().clamp(0.0, 65535.0) as u16;
        buf.extend_from_slice(&v.to_le_bytes());
    }
}

pub(crate) fn write_pixel(buf: &mut [u8], idx: usize, grey8: f64, bpp: usize) {
    if bpp == 1 {
        buf[idx] = grey8.round().clamp(0.0, 255.0) as u8;
    } else {
        let v = (grey8 * 256.0).round().clamp(0.0, 65535.0) as u16;
        buf[2 * idx..2 * idx + 2].copy_from_slice(&v.to_le_bytes());
    }
}

#[cfg(test)]
mod golden;

/// `n` distinct pixels of a frame of `npx` (at most every one), drawn from `seed`, each with
/// whether it is stuck hot (at the top of the range) or dead (at 0), alternately: a sensor's
/// defective pixels, for `sim.stuck_pixels` and for a bench that saves other frames so.
pub fn stuck_places(seed: u64, n: usize, npx: usize) -> Vec<(usize, bool)> {
    let mut rng = Rng::new(seed);
    let n = n.min(npx);
    let mut taken = std::collections::HashSet::with_capacity(n);
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        let k = (rng.next_u64() % npx as u64) as usize;
        if taken.insert(k) {
            out.push((k, out.len().is_multiple_of(2)));
        }
    }
    out
}
