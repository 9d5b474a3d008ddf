//! The views' maps as calibrate parametrises them — the direct view by its scale and roll, the
//! mirror by its scale and its turns about x, y and z, each by its camera's inverse distance —
//! and back to the config's `[geometry]` (a matrix, or a projection where perspective was found).

use super::provisional::MirrorAxes;
use super::Fitted;
use crate::analysis::geometry::V3;
use crate::config::ViewGeometry;

/// Direct view: M = s·[[cos φ, −sin φ, 0], [−sin φ, −cos φ, 0]] (φ: gravity's image turned
/// from straight down towards +u), its x column times `x_sign`: −1 where the config's direct
/// view is a mirror image of the x–y plane (a camera that flips its image, `image_mirrored`),
/// so that the world calibrate fits is the config's and the mirror's x is matched to it alike.
pub(super) fn direct_matrix(s: f64, phi: f64, x_sign: f64) -> [[f64; 3]; 2] {
    let (sp, cp) = phi.sin_cos();
    [
        [x_sign * s * cp, -s * sp, 0.0],
        [-x_sign * s * sp, -s * cp, 0.0],
    ]
}

/// `direct_matrix`'s x sign for the config's direct view: −1 where its image of the x–y plane
/// is a mirror image (u × v along +z: x to the left with gravity down, or gravity up with x to
/// the right), else 1. The roll, from gravity's image, does the rest.
pub(super) fn x_sign(view: &crate::analysis::geometry::View) -> f64 {
    let (u, v) = (view.u_axis, view.v_axis);
    if u.x * v.y - u.y * v.x > 0.0 {
        -1.0
    } else {
        1.0
    }
}

/// M = s·N·Qᵀ: the nominal mirror rows N (x along one image axis with sign `sx`, z along the
/// other with sign `f`: u along ±x and v along ±z on the thesis's rig, the other way round on
/// a camera turned on its side) with the view turned by Q, the rotation by `turn` rad about
/// world (x, y, z).
pub(super) fn mirror_matrix(s: f64, turn: [f64; 3], axes: MirrorAxes) -> [[f64; 3]; 2] {
    let q = nalgebra::Rotation3::from_scaled_axis(V3::from(turn));
    let mut n = [V3::zeros(); 2];
    n[axes.x_along] = V3::new(axes.sx, 0.0, 0.0);
    n[1 - axes.x_along] = V3::new(0.0, 0.0, axes.f);
    n.map(|r| {
        let t = q * r;
        [s * t.x, s * t.y, s * t.z]
    })
}

/// The unit vector from the scene towards a view's camera, from its map's rows (u × v is the
/// line of sight for a camera, reversed in a mirror image: `View::mirrored`, the mirror view
/// by default). (Taken from the kind of view alone, a mirror view whose image is not reversed
/// had its camera's distance printed negative: an independent render's, −332 mm for 300.)
pub(super) fn facing_of(m: &[[f64; 3]; 2], mirrored: bool) -> V3 {
    let c = V3::from(m[0]).cross(&V3::from(m[1])).normalize();
    if mirrored {
        c
    } else {
        -c
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
    mirrored: bool,
    kappa: Fitted,
) -> ViewGeometry {
    if distance(kappa).is_none() {
        return ViewGeometry::affine(region, m, origin);
    }
    let (k, f) = (kappa.value, facing_of(&m, mirrored));
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::geometry::views;
    use crate::config::Config;

    /// A config whose direct view is a mirror image (a camera set to flip its image, x to the
    /// left) is fitted as one: the matrix at no roll is the config's own, gravity's image is
    /// straight down either way, and an unflipped config keeps x to the right.
    #[test]
    fn a_flipped_direct_view_is_fitted_flipped() {
        let mut cfg = Config::default_config();
        let plain = views(&cfg)[0].clone();
        assert_eq!(x_sign(&plain), 1.0);
        if let Some(d) = cfg.geometry.direct.as_mut() {
            d.u_axis = Some("-x".into());
            d.image_mirrored = Some(true);
        }
        let flipped = views(&cfg)[0].clone();
        assert_eq!(x_sign(&flipped), -1.0);
        let s = 2.1576;
        let m = direct_matrix(s, 0.0, x_sign(&flipped));
        for (row, axis) in m.iter().zip([flipped.u_axis, flipped.v_axis]) {
            for k in 0..3 {
                assert!((row[k] - s * axis[k]).abs() < 1e-12, "{m:?}");
            }
        }
        // Gravity (−y) images along +v, turned towards +u by the roll, flipped or not.
        for sign in [1.0, -1.0] {
            let m = direct_matrix(s, 0.1, sign);
            let g = [-m[0][1], -m[1][1]];
            assert!((g[0].atan2(g[1]) - 0.1).abs() < 1e-12, "{sign}: {g:?}");
        }
    }
}
