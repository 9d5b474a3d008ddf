//! The views' maps as calibrate parametrises them — the direct view by its scale and roll, the
//! mirror by its scale and its turns about x, y and z, each by its camera's inverse distance —
//! and back to the config's `[geometry]` (a matrix, or a projection where perspective was found).

use super::Fitted;
use crate::analysis::geometry::{ViewKind, V3};
use crate::config::ViewGeometry;

/// Direct view: M = s·[[cos φ, −sin φ, 0], [−sin φ, −cos φ, 0]] (φ: gravity's image turned
/// from straight down towards +u).
pub(super) fn direct_matrix(s: f64, phi: f64) -> [[f64; 3]; 2] {
    let (sp, cp) = phi.sin_cos();
    [[s * cp, -s * sp, 0.0], [-s * sp, -s * cp, 0.0]]
}

/// M = s·N·Qᵀ: the nominal mirror rows N = [[sx, 0, 0], [0, 0, f]] (u along ±x, v along ±z)
/// with the view turned by Q, the rotation by `turn` rad about world (x, y, z).
pub(super) fn mirror_matrix(s: f64, turn: [f64; 3], sx: f64, f: f64) -> [[f64; 3]; 2] {
    let q = nalgebra::Rotation3::from_scaled_axis(V3::from(turn));
    let n = [V3::new(sx, 0.0, 0.0), V3::new(0.0, 0.0, f)];
    n.map(|r| {
        let t = q * r;
        [s * t.x, s * t.y, s * t.z]
    })
}

/// The unit vector from the scene towards a view's camera, from its map's rows (u × v is the
/// line of sight for a camera, reversed by a mirror).
pub(super) fn facing_of(m: &[[f64; 3]; 2], kind: ViewKind) -> V3 {
    let c = V3::from(m[0]).cross(&V3::from(m[1])).normalize();
    match kind {
        ViewKind::Direct => -c,
        ViewKind::Mirror => c,
    }
}

/// The camera's distance 1/κ with its σ, when the fit found perspective: κ beyond 4σ and
/// beyond 1e-4 /mm (a camera nearer than 10 m, whose scale changes by 0.2 % over 20 mm of depth).
pub(super) fn distance(kappa: Fitted) -> Option<Fitted> {
    (kappa.value.abs() > 4.0 * kappa.sigma && kappa.value.abs() > 1e-4).then(|| Fitted {
        value: 1.0 / kappa.value,
        sigma: kappa.sigma / (kappa.value * kappa.value),
    })
}

/// A view's map as config: a matrix, or where perspective was found the pinhole
/// [[m1 − u0·κ·f, u0], [m2 − v0·κ·f, v0], [−κ·f, 1]] (camera at 1/κ along f).
pub(super) fn view_geometry(
    region: [u32; 4],
    m: [[f64; 3]; 2],
    origin: [f64; 2],
    kind: ViewKind,
    kappa: Fitted,
) -> ViewGeometry {
    if distance(kappa).is_none() {
        return ViewGeometry::affine(region, m, origin);
    }
    let (k, f) = (kappa.value, facing_of(&m, kind));
    let row = |r: [f64; 3], o: f64| [0, 1, 2].map(|i| r[i] - o * k * f[i]);
    let [a, b] = [row(m[0], origin[0]), row(m[1], origin[1])];
    ViewGeometry {
        region,
        projection: Some([
            [a[0], a[1], a[2], origin[0]],
            [b[0], b[1], b[2], origin[1]],
            [-k * f[0], -k * f[1], -k * f[2], 1.0],
        ]),
        ..Default::default()
    }
}
