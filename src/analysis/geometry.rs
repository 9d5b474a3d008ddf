//! Views and world coordinates: the config's per-view map (the axis-aligned shorthand, a
//! general affine matrix, or a pinhole projection) between world millimetres and image pixels,
//! and its inverse given the one coordinate a single view cannot see. Each view also carries its
//! local scaled-orthographic shape at the world origin (scale, image axes, the direction it
//! faces), which is what the circle, marker and rim models use. A view with a lens
//! (`analysis::lens`) maps world points to ideal image points and then through the lens: every
//! image point that enters here is a recorded one, and is undistorted before it is solved.

use crate::analysis::lens::Lens;
use crate::config::{Config, ViewGeometry};
use nalgebra::{Matrix2, Matrix2x3, Matrix3x4, Vector2, Vector3};

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

    /// Whether the view's image is a mirror image unless the config says (`image_mirrored`):
    /// the mirror view's is, the direct view's is not.
    pub fn mirrored_by_default(self) -> bool {
        self == ViewKind::Mirror
    }

    /// The world axis along which this view looks (the one it cannot measure): z for the direct
    /// view, y for the mirror.
    pub fn depth_axis(self) -> usize {
        match self {
            ViewKind::Direct => 2,
            ViewKind::Mirror => 1,
        }
    }
}

/// A view's map from world mm to image px.
#[derive(Clone, Debug, PartialEq)]
pub enum Map {
    /// [u, v] = M·p + origin (the shorthand is the axis-aligned case).
    Affine {
        m: Matrix2x3<f64>,
        origin: Vector2<f64>,
    },
    /// [w·u, w·v, w] = P·[p; 1].
    Pinhole { p: Matrix3x4<f64> },
}

#[derive(Clone, Debug)]
pub struct View {
    pub kind: ViewKind,
    /// u, v, width, height inside the frame, px.
    pub region: [u32; 4],
    pub map: Map,
    /// True for the shorthand: each image axis is one world axis, so a view measures its two
    /// coordinates by itself (the formulas of the shorthand are kept exactly).
    pub aligned: bool,
    /// Local scale at the world origin, px per mm (the geometric mean of the two image axes').
    pub px_per_mm: f64,
    /// Image of the world origin.
    pub origin_px: [f64; 2],
    /// World unit vectors along which image u and v increase (at the origin, orthonormalised).
    pub u_axis: V3,
    pub v_axis: V3,
    /// Unit vector from the scene towards this view's (virtual) camera.
    pub facing: V3,
    /// The image is a mirror image of a camera's at the view's place (`image_mirrored`).
    pub mirrored: bool,
    /// The two world axes this view measures, as (axis along u, axis along v).
    pub axes: [usize; 2],
    /// The lens's radial distortion between the map's ideal image and the recorded one.
    pub lens: Option<Lens>,
}

impl View {
    pub fn from_config(kind: ViewKind, g: &ViewGeometry) -> View {
        // Validated by Config::validate: a config that reaches here has a complete map of rank 2.
        let (m, o) = g
            .local_affine()
            .unwrap_or(([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0]], [0.0, 0.0]));
        let map = match &g.projection {
            Some(p) => Map::Pinhole {
                p: Matrix3x4::from_fn(|i, j| p[i][j]),
            },
            None => Map::Affine {
                m: Matrix2x3::from_fn(|i, j| m[i][j]),
                origin: Vector2::from(o),
            },
        };
        let aligned = g.matrix_px_per_mm.is_none() && g.projection.is_none();
        let r1 = V3::from(m[0]);
        let r2 = V3::from(m[1]);
        let px_per_mm = if aligned {
            g.px_per_mm.unwrap_or(1.0)
        } else {
            (r1.norm() * r2.norm()).sqrt()
        };
        // Symmetric orthonormalisation of the two rows: the nearest pair of perpendicular unit
        // axes, so a slightly skewed matrix tilts neither axis more than the other.
        let (a, b) = (r1.normalize(), r2.normalize());
        let (sum, diff) = ((a + b).normalize(), (a - b).normalize());
        let half = std::f64::consts::FRAC_1_SQRT_2;
        let axis = |name: &Option<String>, fallback: V3| {
            name.as_deref()
                .and_then(crate::config::parse_axis)
                .map(V3::from)
                .unwrap_or(fallback)
        };
        let (ua, va) = if aligned {
            // The shorthand's axes exactly (not r/|r|, which may be off by an ulp).
            (axis(&g.u_axis, a), axis(&g.v_axis, b))
        } else {
            ((sum + diff) * half, (sum - diff) * half)
        };
        // A camera's image axes (u right, v down) and its viewing direction d form a right-handed
        // frame: u × v = d. A mirror reverses the image (and so does a camera set to flip it),
        // so there u × v = −d. The visible hemisphere faces back along −d.
        let uxv = ua.cross(&va);
        let mirrored = g.image_mirrored.unwrap_or(kind.mirrored_by_default());
        let facing = if mirrored { uxv } else { -uxv };
        let axes = measured_axes(&r1, &r2, kind.depth_axis());
        View {
            kind,
            region: g.region,
            map,
            aligned,
            px_per_mm,
            origin_px: o,
            u_axis: ua,
            v_axis: va,
            facing,
            mirrored,
            axes,
            lens: Lens::from_config(g),
        }
    }

    /// The recorded image point of world point `p`, px.
    pub fn project(&self, p: &V3) -> [f64; 2] {
        let q = self.project_ideal(p);
        match &self.lens {
            Some(lens) => lens.distort(q),
            None => q,
        }
    }

    /// The ideal image point at which a recorded one lies (itself without a lens).
    fn ideal(&self, px: [f64; 2]) -> [f64; 2] {
        match &self.lens {
            Some(lens) => lens.undistort(px),
            None => px,
        }
    }

    /// The map's image of `p` before the lens.
    fn project_ideal(&self, p: &V3) -> [f64; 2] {
        if self.aligned {
            return [
                self.origin_px[0] + self.px_per_mm * self.u_axis.dot(p),
                self.origin_px[1] + self.px_per_mm * self.v_axis.dot(p),
            ];
        }
        match &self.map {
            Map::Affine { m, origin } => {
                let q = m * p + origin;
                [q[0], q[1]]
            }
            Map::Pinhole { p: pm } => {
                let q = pm * p.push(1.0);
                [q[0] / q[2], q[1] / q[2]]
            }
        }
    }

    /// The map near world point `p`: its Jacobian (px per mm) and the unit vector from `p`
    /// towards the (virtual) camera, i.e. the hemisphere a sphere at `p` shows. The same
    /// everywhere for an affine view; for a pinhole the scale grows towards the camera and the
    /// line of sight turns across the view.
    pub fn local_at(&self, p: &V3) -> (Matrix2x3<f64>, V3) {
        let (j, toward) = self.local_ideal_at(p);
        match &self.lens {
            Some(lens) => (lens.jacobian(self.project_ideal(p)) * j, toward),
            None => (j, toward),
        }
    }

    /// The view's scale at world point `p`, px per mm (the geometric mean of the two image
    /// axes'): `px_per_mm` for an affine view; for a pinhole larger towards the camera, so a
    /// sphere's image radius follows its depth (at 300 mm, ±20 mm of depth is ±7 %).
    pub fn px_per_mm_at(&self, p: &V3) -> f64 {
        match &self.map {
            Map::Pinhole { .. } => {
                let (j, _) = self.local_ideal_at(p);
                (j.row(0).norm() * j.row(1).norm()).sqrt()
            }
            Map::Affine { .. } => self.px_per_mm,
        }
    }

    fn local_ideal_at(&self, p: &V3) -> (Matrix2x3<f64>, V3) {
        match &self.map {
            Map::Affine { m, .. } => (*m, self.facing),
            Map::Pinhole { p: pm } => {
                let w = (pm.row(2).columns(0, 3) * p)[0] + pm[(2, 3)];
                let q = self.project_ideal(p);
                let j = Matrix2x3::from_fn(|i, k| (pm[(i, k)] - q[i] * pm[(2, k)]) / w);
                let m3 = pm.fixed_columns::<3>(0).into_owned();
                let toward = m3
                    .try_inverse()
                    .map(|inv| -(inv * pm.column(3)))
                    .map(|c| c - p)
                    .filter(|d| d.norm() > 0.0)
                    .map(|d| d.normalize())
                    .unwrap_or(self.facing);
                // The camera's side is the one the view faces (a virtual camera behind the
                // mirror included).
                let toward = if toward.dot(&self.facing) < 0.0 {
                    -toward
                } else {
                    toward
                };
                (j, toward)
            }
        }
    }

    /// The two linear equations A·p = b in world mm that an image point puts on the point it
    /// images, in px (a pinhole's rows divided by the homogeneous depth at `near`, so that all
    /// views' rows weigh alike). A recorded point is undistorted first: the equations are in
    /// ideal px, which differ from recorded ones in scale by under |k1| and so weigh alike too.
    pub fn equations(&self, px: [f64; 2], near: &V3) -> (Matrix2x3<f64>, Vector2<f64>) {
        let px = self.ideal(px);
        match &self.map {
            Map::Affine { m, origin } => (*m, Vector2::from(px) - origin),
            Map::Pinhole { p } => {
                let w = (p.row(2).columns(0, 3) * near)[0] + p[(2, 3)];
                let w = if w.abs() > 1e-12 { w } else { 1.0 };
                let a = Matrix2x3::from_fn(|i, j| (p[(i, j)] - px[i] * p[(2, j)]) / w);
                let b = Vector2::from_fn(|i, _| (px[i] * p[(2, 3)] - p[(i, 3)]) / w);
                (a, b)
            }
        }
    }

    /// The world point this image point shows, with the coordinate this view cannot measure
    /// (its depth axis) taken from `near` (0 without one). An aligned view measures its two
    /// coordinates without it.
    pub fn solve(&self, px: [f64; 2], near: Option<&V3>) -> V3 {
        let k = self.kind.depth_axis();
        let mut p = near.copied().unwrap_or_else(V3::zeros);
        if self.aligned {
            for (axis, val) in self.unproject_aligned(self.ideal(px)) {
                p[axis] = val;
            }
            return p;
        }
        let (a, b) = self.equations(px, &p);
        let [i, j] = other_axes(k);
        let sub = Matrix2::new(a[(0, i)], a[(0, j)], a[(1, i)], a[(1, j)]);
        let rhs = b - a.column(k) * p[k];
        if let Some(x) = sub.try_inverse().map(|inv| inv * rhs) {
            p[i] = x[0];
            p[j] = x[1];
        }
        p
    }

    /// The world coordinates this view measures: (axis, value in mm) along its u and v axes,
    /// the coordinate it cannot see taken from `near`.
    pub fn unproject(&self, px: [f64; 2], near: Option<&V3>) -> [(usize, f64); 2] {
        if self.aligned {
            return self.unproject_aligned(self.ideal(px));
        }
        let p = self.solve(px, near);
        self.axes.map(|a| (a, p[a]))
    }

    /// World x of an image point, mm, as `unproject` gives it (both views see x); None for a
    /// view that does not measure x.
    pub fn x_mm(&self, px: [f64; 2], near: Option<&V3>) -> Option<f64> {
        self.unproject(px, near)
            .iter()
            .find(|(axis, _)| *axis == 0)
            .map(|(_, x)| *x)
    }

    fn unproject_aligned(&self, px: [f64; 2]) -> [(usize, f64); 2] {
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

    /// Rescales the view after the shared coordinate showed that the world it measures is
    /// a·(true) + b along x (the mirror calibration): the map's linear part times a, and the
    /// origin moved by b along the image of world x. Not for a pinhole view (returns false).
    pub fn rescale(&mut self, a: f64, b: f64) -> bool {
        if self.aligned {
            // Along whichever image axis shows x: u, or v on a camera turned on its side.
            let k = usize::from(self.v_axis.x.abs() > self.u_axis.x.abs());
            let sign = [self.u_axis, self.v_axis][k].x.signum();
            self.origin_px[k] += sign * b * self.px_per_mm;
            self.px_per_mm *= a;
            self.map = Map::Affine {
                m: Matrix2x3::from_rows(&[
                    (self.u_axis * self.px_per_mm).transpose(),
                    (self.v_axis * self.px_per_mm).transpose(),
                ]),
                origin: Vector2::from(self.origin_px),
            };
            return true;
        }
        let Map::Affine { m, origin } = &mut self.map else {
            return false;
        };
        *origin += m.column(0) * b;
        *m *= a;
        self.px_per_mm *= a;
        self.origin_px = [origin[0], origin[1]];
        true
    }

    /// This view of a world turned by `r` and scaled by `scale` about the world origin before it
    /// is imaged: [u, v] = M·(scale·R·p) + origin. Always a general (not shorthand) map, so
    /// that a turned view and an unturned one compare through the same formulas.
    pub fn turned(&self, r: &nalgebra::Matrix3<f64>, scale: f64) -> View {
        let g = match &self.map {
            Map::Affine { m, origin } => {
                let t = m * r * scale;
                crate::config::ViewGeometry {
                    region: self.region,
                    origin_px: Some([origin[0], origin[1]]),
                    matrix_px_per_mm: Some([0, 1].map(|i| [0, 1, 2].map(|j| t[(i, j)]))),
                    image_mirrored: Some(self.mirrored),
                    ..Default::default()
                }
            }
            Map::Pinhole { p } => {
                let t = p.fixed_columns::<3>(0) * r * scale;
                crate::config::ViewGeometry {
                    region: self.region,
                    projection: Some(
                        [0, 1, 2].map(|i| [t[(i, 0)], t[(i, 1)], t[(i, 2)], p[(i, 3)]]),
                    ),
                    image_mirrored: Some(self.mirrored),
                    ..Default::default()
                }
            }
        };
        let mut out = View::from_config(self.kind, &g);
        out.lens = self.lens;
        out
    }

    pub fn contains(&self, u: f64, v: f64) -> bool {
        let [x, y, w, h] = self.region;
        u >= x as f64 - 0.5
            && v >= y as f64 - 0.5
            && u < (x + w) as f64 - 0.5
            && v < (y + h) as f64 - 0.5
    }
}

/// The two world axes a view with image rows r1, r2 measures, as (along u, along v): the pair
/// other than its depth axis, each matched to the row it dominates.
fn measured_axes(r1: &V3, r2: &V3, depth: usize) -> [usize; 2] {
    let [i, j] = other_axes(depth);
    if r1[i].abs() * r2[j].abs() >= r1[j].abs() * r2[i].abs() {
        [i, j]
    } else {
        [j, i]
    }
}

/// The two world axes other than `k`, in order.
fn other_axes(k: usize) -> [usize; 2] {
    match k {
        0 => [1, 2],
        1 => [0, 2],
        _ => [0, 1],
    }
}

/// The least-squares world point from every view's image of it (each a pair of equations; the
/// first guess `near` sets a pinhole's depth weights). None when the views leave a direction
/// unseen (a single view).
pub fn triangulate(seen: &[(&View, [f64; 2])], near: &V3) -> Option<V3> {
    let mut ata = nalgebra::Matrix3::<f64>::zeros();
    let mut atb = V3::zeros();
    for (view, px) in seen {
        let (a, b) = view.equations(*px, near);
        ata += a.transpose() * a;
        atb += a.transpose() * b;
    }
    // A single turned view's four equations have rank two in exact arithmetic, but rounding
    // leaves AᵀA a determinant of order 1e-16, which `try_inverse` accepts: the point then lies
    // anywhere along the view's line of sight (on v03 with calibrate's maps the mirror-only
    // frames after the impact were placed up to 200 mm off, and e came out +0.69 ± 7). Two
    // views at right angles give eigenvalues of one order; a direction seen by neither gives
    // one twelve orders below the rest.
    let eig = ata.symmetric_eigenvalues();
    let (lo, hi) = (eig.min(), eig.max());
    if hi.is_nan() || lo.is_nan() || hi <= 0.0 || lo < UNSEEN_DIRECTION * hi {
        return None;
    }
    let inv = ata.try_inverse()?;
    Some(inv * atb)
}

/// `triangulate`'s smallest eigenvalue of AᵀA, as a fraction of its largest, below which a
/// direction counts as unseen. Views at any angle a rig can have (the mirror's line of sight
/// a degree or more from the direct camera's plane) are far above it.
const UNSEEN_DIRECTION: f64 = 1e-9;

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

/// One view as the simulator describes it: the view's local scaled-orthographic shape, which
/// is exact for the shorthand and for a matrix whose rows are perpendicular and of one length
/// (a rolled camera, a tilted mirror); the simulator's own non-ideal rigs are drawn in hw-sim.
pub fn sim_view(v: &View) -> hw_sim::ViewSpec {
    hw_sim::ViewSpec {
        name: v.kind.name().into(),
        region: v.region,
        px_per_mm: v.px_per_mm,
        origin_px: v.origin_px,
        u_axis: v.u_axis.into(),
        v_axis: v.v_axis.into(),
        facing: v.facing.into(),
        distance_mm: None,
        lens: v.lens.map(|l| hw_sim::Lens {
            k1: l.k1,
            centre_px: l.centre_px,
            radius_px: l.radius_px,
        }),
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
mod tests;
