//! The `[geometry]` section: each view's region and its map between world millimetres and
//! image pixels (the shorthand, an affine matrix or a pinhole projection, a lens), and how well
//! calibrate says it is known. Checked by `validate`; used through `analysis::geometry`.

use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Geometry {
    #[serde(default)]
    pub direct: Option<ViewGeometry>,
    #[serde(default)]
    pub mirror: Option<ViewGeometry>,
}

#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ViewGeometry {
    /// u, v, width, height of this view inside the frame, px.
    pub region: [u32; 4],
    /// Shorthand (with `u_axis`, `v_axis`): an axis-aligned orthographic view.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub px_per_mm: Option<f64>,
    /// Image (u, v) of the world origin (shorthand and `matrix_px_per_mm`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub origin_px: Option<[f64; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub u_axis: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub v_axis: Option<String>,
    /// General affine view: [u, v] = M·[x, y, z]_mm + origin_px.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub matrix_px_per_mm: Option<[[f64; 3]; 2]>,
    /// Pinhole view: world mm → homogeneous px, 3×4 (DLT convention).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub projection: Option<[[f64; 4]; 3]>,
    /// How well this view's scale is known, % (one σ; `impactcam calibrate` writes it, or a
    /// ruler's reading). The analysis carries it into every estimate's uncertainty.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub px_per_mm_uncertainty_percent: Option<f64>,
    /// How well this view's turn is known, deg (one σ), about world x, y and z: a turn of the
    /// world before the view images it. The analysis carries it into every estimate's
    /// uncertainty.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub turn_uncertainty_deg: Option<[f64; 3]>,
    /// The lens's radial distortion (all three keys or none): an ideal image point p of the
    /// map above is recorded at c + (p − c)·(1 + k1·|p − c|²/R²), c = `lens_centre_px`,
    /// R = `lens_radius_px`; so k1 is the fractional displacement at distance R (negative:
    /// barrel). `impactcam calibrate` writes them when it finds a lens.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lens_k1: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lens_centre_px: Option<[f64; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lens_radius_px: Option<f64>,
    /// The image is a mirror image of what a camera at the view's place would record: the view
    /// is seen by way of a mirror, or the camera flips its image (a readout setting many
    /// high-speed cameras have). It decides which hemisphere of a sphere the view sees, so the
    /// depth its markers are lifted to: no map tells a flipped image from a camera on the other
    /// side. Default: true for the mirror view, false for the direct view.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub image_mirrored: Option<bool>,
}

impl ViewGeometry {
    /// The shorthand: scale, the image of the world origin, and the world axes along u and v.
    pub fn shorthand(
        region: [u32; 4],
        px_per_mm: f64,
        origin_px: [f64; 2],
        u_axis: &str,
        v_axis: &str,
    ) -> ViewGeometry {
        ViewGeometry {
            region,
            px_per_mm: Some(px_per_mm),
            origin_px: Some(origin_px),
            u_axis: Some(u_axis.into()),
            v_axis: Some(v_axis.into()),
            ..Default::default()
        }
    }

    /// A general affine view.
    pub fn affine(region: [u32; 4], matrix_px_per_mm: [[f64; 3]; 2], origin_px: [f64; 2]) -> Self {
        ViewGeometry {
            region,
            origin_px: Some(origin_px),
            matrix_px_per_mm: Some(matrix_px_per_mm),
            ..Default::default()
        }
    }

    /// The map's linear part and offset at the world origin, px per mm and px: exact for the
    /// shorthand and a matrix, the tangent map for a projection. None without a complete map.
    pub fn local_affine(&self) -> Option<([[f64; 3]; 2], [f64; 2])> {
        if let Some(p) = &self.projection {
            let w = p[2][3];
            if w == 0.0 {
                return None;
            }
            let o = [p[0][3] / w, p[1][3] / w];
            let row = |i: usize| [0, 1, 2].map(|j| (p[i][j] - o[i] * p[2][j]) / w);
            return Some(([row(0), row(1)], o));
        }
        if let Some(m) = self.matrix_px_per_mm {
            return Some((m, self.origin_px?));
        }
        let s = self.px_per_mm?;
        let ua = parse_axis(self.u_axis.as_deref()?)?;
        let va = parse_axis(self.v_axis.as_deref()?)?;
        Some(([ua.map(|x| s * x), va.map(|x| s * x)], self.origin_px?))
    }
}

impl Geometry {
    /// The thesis's layout, as in the embedded default.
    pub fn thesis() -> Geometry {
        Geometry {
            direct: Some(ViewGeometry::shorthand(
                [0, 0, 240, 96],
                2.1576,
                [119.5, 44.0],
                "+x",
                "-y",
            )),
            mirror: Some(ViewGeometry::shorthand(
                [0, 96, 240, 96],
                2.1175,
                [121.0, 144.0],
                "+x",
                "+z",
            )),
        }
    }
}

/// A world axis with sign, as written in the config ("+x", "-z", …).
pub fn parse_axis(s: &str) -> Option<[f64; 3]> {
    let (sign, axis) = match s.as_bytes() {
        [b'+', a] => (1.0, *a),
        [b'-', a] => (-1.0, *a),
        _ => return None,
    };
    Some(match axis {
        b'x' => [sign, 0.0, 0.0],
        b'y' => [0.0, sign, 0.0],
        b'z' => [0.0, 0.0, sign],
        _ => return None,
    })
}
