//! Rendering under a `Look`: a static backdrop per view (illumination field, background level,
//! tube ends, a ruler, defocus), spheres shaded by each view's own light (Lambertian, flat or
//! Blinn–Phong) or drawn as backlit silhouettes, markers of fixed or multiplicative paint, and
//! the whole blurred by the defocus before the noise is added.

use super::{project, total_sigma, write_pixel, Pose};
use crate::config::{LabConfig, Scene, ViewSpec};
use crate::look::{Look, MarkerPaint, SurfaceKind};
use crate::V3;

/// Tube length drawn behind each exit, mm, and the tube's outer radius in sphere radii.
const TUBE_LENGTH_MM: f64 = 30.0;
const TUBE_RADIUS_IN_SPHERE_RADII: f64 = 1.3;

/// One view's light, in world coordinates.
#[derive(Clone, Copy, Debug)]
struct ViewLight {
    light: V3,
    /// Blinn–Phong half vector between the light and the view's camera.
    half: V3,
}

/// What a look needs per frame, computed once (and again when the tubes move).
pub(super) struct LookState {
    look: Look,
    lights: Vec<ViewLight>,
    /// Illumination factor per pixel of the frame (gain × gradient × vignetting).
    illum: Vec<f32>,
    /// The noise-free frame without spheres, before defocus and after it.
    sharp: Vec<f32>,
    blurred: Vec<f32>,
    /// The tube exits the backdrop was drawn for.
    tubes: Option<[(V3, V3); 2]>,
    /// The tubes' outer radius, mm.
    tube_radius_mm: f64,
}

impl LookState {
    pub(super) fn new(look: Look, scene: &Scene, cfg: &LabConfig) -> LookState {
        let lights = scene
            .views
            .iter()
            .enumerate()
            .map(|(i, v)| {
                let vl = look.view(i);
                let (off, az) = (
                    vl.light_off_axis_deg.to_radians(),
                    vl.light_azimuth_deg.to_radians(),
                );
                let (ua, va, f) = (V3::from(v.u_axis), V3::from(v.v_axis), V3::from(v.facing));
                let light =
                    (f * off.cos() + (ua * az.cos() + va * az.sin()) * off.sin()).normalize();
                let half = (light + f).normalize();
                ViewLight { light, half }
            })
            .collect();
        let npx = (scene.width * scene.height) as usize;
        let mut illum = vec![1.0f32; npx];
        for (vi, v) in scene.views.iter().enumerate() {
            let vl = look.view(vi);
            let [rx, ry, rw, rh] = v.region;
            let (cu, cv) = (rx as f64 + rw as f64 / 2.0, ry as f64 + rh as f64 / 2.0);
            let corner2 = (rw as f64 / 2.0).powi(2) + (rh as f64 / 2.0).powi(2);
            for (u, vv) in region_pixels(scene, v) {
                let (du, dv) = (u as f64 - cu, vv as f64 - cv);
                let g = vl.gain
                    * (1.0
                        + vl.gradient_per_100px[0] * du / 100.0
                        + vl.gradient_per_100px[1] * dv / 100.0)
                    * (1.0 - vl.vignetting * (du * du + dv * dv) / corner2);
                illum[vv * scene.width as usize + u] = g.max(0.0) as f32;
            }
        }
        let mut state = LookState {
            look,
            lights,
            illum,
            sharp: Vec::new(),
            blurred: Vec::new(),
            tubes: None,
            tube_radius_mm: scene.spheres[0]
                .diameter_mm
                .max(scene.spheres[1].diameter_mm)
                / 2.0
                * TUBE_RADIUS_IN_SPHERE_RADII,
        };
        state.draw_backdrop(scene, cfg, None);
        state
    }

    /// Redraws the backdrop when the tubes' exits differ from those it was drawn for.
    pub(super) fn set_tubes(&mut self, scene: &Scene, cfg: &LabConfig, tubes: [(V3, V3); 2]) {
        if self.look.tube_ends && self.tubes != Some(tubes) {
            self.draw_backdrop(scene, cfg, Some(tubes));
        }
    }

    fn draw_backdrop(&mut self, scene: &Scene, cfg: &LabConfig, tubes: Option<[(V3, V3); 2]>) {
        let w = scene.width as usize;
        self.tubes = tubes;
        self.sharp = self
            .illum
            .iter()
            .map(|&g| (cfg.background_grey * g as f64) as f32)
            .collect();
        for (vi, view) in scene.views.iter().enumerate() {
            for (u, v) in region_pixels(scene, view) {
                let i = v * w + u;
                let g = self.illum[i] as f64;
                let mut val = self.sharp[i] as f64;
                if let (true, Some(tubes)) = (self.look.tube_ends, tubes) {
                    let r_out = scene.spheres[0]
                        .diameter_mm
                        .max(scene.spheres[1].diameter_mm)
                        / 2.0
                        * TUBE_RADIUS_IN_SPHERE_RADII;
                    for (exit, dir) in tubes {
                        let cover = tube_cover(view, exit, dir, r_out, u as f64, v as f64);
                        if cover.0 > 0.0 {
                            let tube = self.tube_grey() * g * cover.1;
                            val = val * (1.0 - cover.0) + tube * cover.0;
                        }
                    }
                }
                if self.look.ruler && vi == 0 {
                    if let Some(r) = ruler_grey(view, u as f64, v as f64) {
                        let strip = if self.look.backlit { 60.0 } else { 150.0 };
                        val = g * (strip - (strip - 25.0) * r.1) * r.0 + val * (1.0 - r.0);
                    }
                }
                self.sharp[i] = val as f32;
            }
        }
        self.blurred = self.sharp.clone();
        let sigma = self.look.defocus_sigma_px;
        if sigma > 0.0 {
            for view in &scene.views {
                let [rx, ry, rw, rh] = view.region;
                let (x1, y1) = ((rx + rw).min(scene.width), (ry + rh).min(scene.height));
                blur(
                    &mut self.blurred,
                    w,
                    [rx, ry, x1, y1].map(|x| x as usize),
                    sigma,
                );
            }
        }
    }

    fn tube_grey(&self) -> f64 {
        if self.look.backlit {
            // A tube in front of the backlight is a silhouette too.
            self.look.tube_grey.min(60.0)
        } else {
            self.look.tube_grey
        }
    }

    /// Blur margin, px: how far the defocus spreads a sphere's light.
    pub(super) fn margin_px(&self) -> i64 {
        let s = self.look.defocus_sigma_px;
        if s > 0.0 {
            (3.0 * s).ceil() as i64 + 1
        } else {
            0
        }
    }

    /// Grey level of the sphere surface under image point (su, sv) of view `vi`, before the
    /// illumination field, and whether it is marker paint; None where no sphere is.
    pub(super) fn shade(
        &self,
        vi: usize,
        view: &ViewSpec,
        cfg: &LabConfig,
        pose: &[Pose; 2],
        su: f64,
        sv: f64,
    ) -> Option<(f64, usize, bool)> {
        let mut best: Option<(f64, V3, usize, &Pose)> = None;
        for (i, p) in pose.iter().enumerate() {
            // A sphere still inside its (opaque) tube is not seen.
            if self.inside_tube(&p.centre_mm) {
                continue;
            }
            let Some((depth, normal, _)) = super::hit(view, &p.centre_mm, p.radius_mm, su, sv)
            else {
                continue;
            };
            if best.is_some_and(|(d, ..)| d >= depth) {
                continue;
            }
            best = Some((depth, normal, i, p));
        }
        let (_, n, i, p) = best?;
        let look = &self.look;
        if look.backlit && !look.backlit_front_light {
            return Some((cfg.sphere_grey, i, false));
        }
        let light = self.lights[vi];
        let diffuse = match look.surface {
            SurfaceKind::Flat => 1.0,
            _ => look.ambient + (1.0 - look.ambient) * light.light.dot(&n).max(0.0),
        };
        let mut grey = cfg.sphere_grey * diffuse;
        if look.surface == SurfaceKind::Specular && light.light.dot(&n) > 0.0 {
            grey += look.specular_grey * n.dot(&light.half).max(0.0).powf(look.shininess);
        }
        let ang_r = cfg.marker_diameter_mm / 2.0 / p.radius_mm;
        let on_marker = p
            .markers_world
            .iter()
            .any(|m| n.dot(&((m - p.centre_mm) / p.radius_mm)) > ang_r.cos());
        if on_marker {
            grey = match look.marker_paint {
                MarkerPaint::Grey => cfg.marker_grey,
                MarkerPaint::Multiplicative => grey * look.marker_factor,
            };
        }
        Some((grey, i, on_marker))
    }

    /// Whether a point lies inside one of the drawn tubes (within its radius of the axis,
    /// between the exit and `TUBE_LENGTH_MM` up the tube).
    fn inside_tube(&self, p: &V3) -> bool {
        let Some(tubes) = self.tubes.filter(|_| self.look.tube_ends) else {
            return false;
        };
        tubes.iter().any(|(exit, dir)| {
            let along = (exit - p).dot(dir);
            let radial = ((p - exit) + dir * along).norm();
            along > 0.0 && along < TUBE_LENGTH_MM && radial < self.tube_radius_mm
        })
    }

    pub(super) fn illum(&self, idx: usize) -> f64 {
        self.illum[idx] as f64
    }

    pub(super) fn sharp(&self, idx: usize) -> f64 {
        self.sharp[idx] as f64
    }

    pub(super) fn blurred(&self) -> &[f32] {
        &self.blurred
    }

    pub(super) fn defocus_sigma_px(&self) -> f64 {
        self.look.defocus_sigma_px
    }
}

/// Every pixel (u, v) of a view's region inside the frame.
fn region_pixels(scene: &Scene, view: &ViewSpec) -> impl Iterator<Item = (usize, usize)> {
    let [rx, ry, rw, rh] = view.region;
    let (x1, y1) = ((rx + rw).min(scene.width), (ry + rh).min(scene.height));
    (ry..y1).flat_map(move |v| (rx..x1).map(move |u| (u as usize, v as usize)))
}

/// How much of pixel (u, v) a tube covers (fraction, anti-aliased over ±½ px across its
/// outline) and the tube's cylindrical shading there; (0, 0) where it is not.
fn tube_cover(view: &ViewSpec, exit: V3, dir: V3, r_out_mm: f64, u: f64, v: f64) -> (f64, f64) {
    let a = project(view, &exit);
    let b = project(view, &(exit - dir * TUBE_LENGTH_MM));
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let len = dx.hypot(dy);
    let r = r_out_mm * view.px_per_mm;
    if len < 1e-9 {
        // Seen end-on: a disc (the tube's bore is not drawn).
        let d = (u - a.0).hypot(v - a.1);
        let c = (r - d + 0.5).clamp(0.0, 1.0);
        return (c, 0.8);
    }
    let (tx, ty) = (dx / len, dy / len);
    let along = (u - a.0) * tx + (v - a.1) * ty;
    let across = (-(u - a.0) * ty + (v - a.1) * tx).abs();
    let c_side = (r - across + 0.5).clamp(0.0, 1.0);
    let c_end = (along + 0.5).clamp(0.0, 1.0) * (len - along + 0.5).clamp(0.0, 1.0);
    let shade = 0.6 + 0.4 * (1.0 - (across / r).min(1.0).powi(2)).sqrt();
    (c_side * c_end, shade)
}

/// A ruler along the bottom of a view: (coverage of the strip, darkness of its ticks) at pixel
/// (u, v); ticks each mm, longer each 5 mm, 0.25 mm wide.
fn ruler_grey(view: &ViewSpec, u: f64, v: f64) -> Option<(f64, f64)> {
    let [_, ry, _, rh] = view.region;
    let bottom = (ry + rh) as f64 - 2.0;
    let top = bottom - 9.0;
    if v < top || v >= bottom {
        return None;
    }
    let ppm = view.px_per_mm;
    let x_mm = (u - view.origin_px[0]) / ppm;
    let k = x_mm.round();
    let half_width_px = 0.125 * ppm;
    let dist_px = (x_mm - k).abs() * ppm;
    let tick = (half_width_px - dist_px + 0.5).clamp(0.0, 1.0);
    let long = (k as i64).rem_euclid(5) == 0;
    let reaches = if long { true } else { v < top + 4.0 };
    Some((1.0, if reaches { tick } else { 0.0 }))
}

/// Separable Gaussian blur of the rectangle [x0, y0, x1, y1) of a row-major image `w` wide,
/// edges clamped to the rectangle.
pub(super) fn blur(img: &mut [f32], w: usize, rect: [usize; 4], sigma: f64) {
    let [x0, y0, x1, y1] = rect;
    if x1 <= x0 || y1 <= y0 || sigma <= 0.0 {
        return;
    }
    let half = (3.0 * sigma).ceil() as i64;
    let kernel: Vec<f64> = (-half..=half)
        .map(|k| (-(k * k) as f64 / (2.0 * sigma * sigma)).exp())
        .collect();
    let norm: f64 = kernel.iter().sum();
    let mut line = Vec::new();
    for y in y0..y1 {
        line.clear();
        line.extend((x0..x1).map(|x| img[y * w + x] as f64));
        for x in x0..x1 {
            let mut acc = 0.0;
            for (j, kv) in kernel.iter().enumerate() {
                let xx = (x as i64 + j as i64 - half).clamp(x0 as i64, x1 as i64 - 1) as usize;
                acc += kv * line[xx - x0];
            }
            img[y * w + x] = (acc / norm) as f32;
        }
    }
    for x in x0..x1 {
        line.clear();
        line.extend((y0..y1).map(|y| img[y * w + x] as f64));
        for y in y0..y1 {
            let mut acc = 0.0;
            for (j, kv) in kernel.iter().enumerate() {
                let yy = (y as i64 + j as i64 - half).clamp(y0 as i64, y1 as i64 - 1) as usize;
                acc += kv * line[yy - y0];
            }
            img[y * w + x] = (acc / norm) as f32;
        }
    }
}

/// Adds the noise to a noise-free grey level and writes the pixel.
pub(super) fn write_noisy(
    cfg: &LabConfig,
    out: &mut [u8],
    idx: usize,
    mean: f64,
    unit_noise: f64,
    bpp: usize,
) {
    let sigma = total_sigma(cfg, mean);
    let linear = mean + sigma * unit_noise;
    // A camera's gamma encodes the sensor's linear signal, noise and all, before quantising.
    let encoded = if cfg.gamma == 1.0 {
        linear
    } else {
        255.0 * (linear.max(0.0) / 255.0).powf(1.0 / cfg.gamma)
    };
    write_pixel(out, idx, encoded, bpp);
}
