//! Views and world coordinates: the config's per-view geometry turned into maps between image
//! pixels and world millimetres. Orthographic: each view sees one world plane (direct: x–y,
//! mirror: x–z) at its own scale, offset and orientation.

use crate::config::{parse_axis, Config, ViewGeometry};
use nalgebra::Vector3;

pub type V3 = Vector3<f64>;

#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ViewKind {
    Direct,
    Mirror,
}

impl ViewKind {
    pub fn name(self) -> &'static str {
        match self {
            ViewKind::Direct => "direct",
            ViewKind::Mirror => "mirror",
        }
    }
}

#[derive(Clone, Debug)]
pub struct View {
    pub kind: ViewKind,
    /// u, v, width, height inside the frame, px.
    pub region: [u32; 4],
    pub px_per_mm: f64,
    pub origin_px: [f64; 2],
    pub u_axis: V3,
    pub v_axis: V3,
    /// Unit vector from the scene towards this view's (virtual) camera.
    pub facing: V3,
}

impl View {
    pub fn from_config(kind: ViewKind, g: &ViewGeometry) -> View {
        // Validated by Config::validate; an unparsable axis cannot reach here.
        let ua = V3::from(parse_axis(&g.u_axis).unwrap_or([1.0, 0.0, 0.0]));
        let va = V3::from(parse_axis(&g.v_axis).unwrap_or([0.0, -1.0, 0.0]));
        // A camera's image axes (u right, v down) and its viewing direction d form a right-handed
        // frame: u × v = d. A mirror reverses the image, so there u × v = −d. The visible
        // hemisphere faces back along −d.
        let uxv = ua.cross(&va);
        let facing = match kind {
            ViewKind::Direct => -uxv,
            ViewKind::Mirror => uxv,
        };
        View {
            kind,
            region: g.region,
            px_per_mm: g.px_per_mm,
            origin_px: g.origin_px,
            u_axis: ua,
            v_axis: va,
            facing,
        }
    }

    pub fn project(&self, p: &V3) -> [f64; 2] {
        [
            self.origin_px[0] + self.px_per_mm * self.u_axis.dot(p),
            self.origin_px[1] + self.px_per_mm * self.v_axis.dot(p),
        ]
    }

    /// The world coordinates this view measures: (axis, value in mm) along its u and v axes.
    pub fn unproject(&self, px: [f64; 2]) -> [(usize, f64); 2] {
        let axis = |a: &V3| -> (usize, f64) {
            let i = a.iamax();
            (i, a[i])
        };
        let (iu, su) = axis(&self.u_axis);
        let (iv, sv) = axis(&self.v_axis);
        [
            (iu, su * (px[0] - self.origin_px[0]) / self.px_per_mm),
            (iv, sv * (px[1] - self.origin_px[1]) / self.px_per_mm),
        ]
    }

    pub fn contains(&self, u: f64, v: f64) -> bool {
        let [x, y, w, h] = self.region;
        u >= x as f64 - 0.5
            && v >= y as f64 - 0.5
            && u < (x + w) as f64 - 0.5
            && v < (y + h) as f64 - 0.5
    }
}

/// All views the config describes, direct first.
pub fn views(cfg: &Config) -> Vec<View> {
    let mut out = Vec::new();
    if let Some(g) = &cfg.geometry.direct {
        out.push(View::from_config(ViewKind::Direct, g));
    }
    if let Some(g) = &cfg.geometry.mirror {
        out.push(View::from_config(ViewKind::Mirror, g));
    }
    out
}

/// The rig as the simulator needs it, from the same geometry the analysis uses.
/// One view as the simulator describes it.
pub fn sim_view(v: &View) -> hw_sim::ViewSpec {
    hw_sim::ViewSpec {
        name: v.kind.name().into(),
        region: v.region,
        px_per_mm: v.px_per_mm,
        origin_px: v.origin_px,
        u_axis: v.u_axis.into(),
        v_axis: v.v_axis.into(),
        facing: v.facing.into(),
    }
}

/// A scene of one view and two 6.35 mm spheres, for tests that render still spheres.
#[cfg(test)]
pub fn one_view_scene(view: &View, width: u32, height: u32) -> hw_sim::Scene {
    hw_sim::Scene {
        width,
        height,
        frame_rate_hz: 1000.0,
        bit_depth: 8,
        views: vec![sim_view(view)],
        spheres: [0, 1].map(|_| hw_sim::SphereSpec {
            diameter_mm: 6.35,
            mass_g: 1.0,
        }),
    }
}

pub fn sim_scene(cfg: &Config) -> hw_sim::Scene {
    let spec = sim_view;
    let sphere = |i| {
        let (d, m) = cfg.spheres.sphere(i);
        hw_sim::SphereSpec {
            diameter_mm: d,
            mass_g: m,
        }
    };
    hw_sim::Scene {
        width: cfg.camera.width,
        height: cfg.camera.height,
        frame_rate_hz: cfg.camera.frame_rate_hz,
        bit_depth: 8 * cfg.camera.pixel_format.bytes_per_pixel() as u32,
        views: views(cfg).iter().map(spec).collect(),
        spheres: [sphere(0), sphere(1)],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_views_face_their_cameras() {
        let cfg = Config::default_config();
        let v = views(&cfg);
        assert_eq!(v[0].facing, V3::new(0.0, 0.0, 1.0)); // z towards the direct camera
        assert_eq!(v[1].facing, V3::new(0.0, -1.0, 0.0)); // mirror with v = +z looks up from below
        let p = V3::new(3.0, -2.0, 1.5);
        for view in &v {
            let px = view.project(&p);
            for (axis, val) in view.unproject(px) {
                assert!((val - p[axis]).abs() < 1e-12);
            }
        }
    }
}
