//! What calibrate prints: the `[geometry]` TOML with every parameter's value, σ and the
//! residuals in comments, and the PNG of the regions and axes on the impact frame.

use super::{Calibrated, Fitted};
use crate::analysis::{
    self,
    geometry::{View, ViewKind, V3},
};

impl Calibrated {
    /// The `[geometry]` TOML, each parameter's value and σ and the residuals in comments above.
    pub fn toml(&self) -> String {
        let p = |f: &Fitted, unit: &str, d: usize| {
            format!("{:.d$} ± {:.d$} {unit}", f.value, f.sigma, d = d)
        };
        let d = &self.direct;
        let mut out = format!(
            "# impactcam calibrate: {}{}, {} frames. The world origin is the config's (a choice).\n\
             # direct: scale {} from free fall, {} from the diameter, {} from both views' flights,\n\
             #   {} used ({});\n\
             #   roll {} (image direction of gravity); parabola residuals {:.3} px RMS\n",
            self.source,
            if self.recordings > 1 {
                format!(" and {} more recording(s)", self.recordings - 1)
            } else {
                String::new()
            },
            self.frames,
            p(&d.scale_from_free_fall, "px/mm", 4),
            p(&d.scale_from_diameter, "px/mm", 4),
            p(&d.scale_from_flights, "px/mm", 4),
            p(&d.scale, "px/mm", 4),
            match d.diameter_disagrees_sigma {
                None => "the flights' and the diameter's, weighed by their σ".to_string(),
                Some(z) => format!(
                    "WARNING: the flights' alone, the diameter's lies {z:+.1}σ from it — defocus, or a lamp the disc's model does not follow"
                ),
            },
            p(&d.roll_deg, "deg", 3),
            d.residual_rms_px
        );
        out += &format!("# regions: {}\n", self.regions);
        // A camera found behind the view (its distance negative: nearer spheres image smaller)
        // is a view whose image is mirrored other than the config says: the side a view's
        // camera is on is set by `image_mirrored`, which no flight tells, but perspective does.
        let persp = |d: &Option<Fitted>| {
            match d {
            Some(d) if d.value < 0.0 => format!(
                "a pinhole {} — WARNING: behind the view, so its image is likely mirrored other than `image_mirrored` says (it decides which hemisphere the markers are on)",
                p(d, "mm away", 0)
            ),
            Some(d) => format!("a pinhole {}", p(d, "mm away", 0)),
            None => "no perspective found (orthographic)".into(),
        }
        };
        out += &format!("#   direct camera: {}\n", persp(&d.camera_distance_mm));
        if let Some(m) = &self.mirror {
            out += &format!("#   mirror camera: {}\n", persp(&m.camera_distance_mm));
            out += &format!(
                "# mirror: scale {} (diameter: {}); turned about x (tilt, twice the mirror's from 45°)\n\
                 #   {}, about y (roll) {}, about z (yaw) {}; x {}; origin {} {};\n\
                 #   residuals {:.3} px RMS over {} centres\n",
                p(&m.scale, "px/mm", 4),
                p(&m.scale_from_diameter, "px/mm", 4),
                p(&m.tilt_deg, "deg", 3),
                p(&m.roll_deg, "deg", 3),
                p(&m.yaw_deg, "deg", 3),
                if m.x_reversed { "reversed" } else { "not reversed" },
                if m.x_along_v { "v" } else { "u" },
                p(&m.origin_x_px, "px", 2),
                m.residual_rms_px,
                m.points
            );
        }
        match &self.grid {
            Some(g) => {
                // The grid's scale against the flights': a wrong g, frame rate or grid pitch, or
                // flights that fitted badly, show here. (Under perspective the card's central
                // dot is a little off the world origin's depth: 0.2 % for 0.7 mm at 300 mm.)
                let z = (g.scale_px_per_mm.value - d.scale_from_flights.value)
                    / g.scale_px_per_mm.sigma.hypot(d.scale_from_flights.sigma);
                out += &format!(
                    "# lens: k1 {} (the fractional displacement at the frame's corners, about its centre)\n\
                     #   from the dot grid ({} dots, residuals {:.3} px RMS), written into both views and held\n\
                     #   while the flights fit the rest; k1's σ is not carried into the estimates' uncertainty\n\
                     #   the grid's scale {} at its central dot, {:+.1}σ from the flights' {}{}\n",
                    p(&g.lens_k1, "", 5),
                    g.dots,
                    g.residual_rms_px,
                    p(&g.scale_px_per_mm, "px/mm", 4),
                    z,
                    p(&d.scale_from_flights, "px/mm", 4),
                    if z.abs() > 3.0 {
                        ": they DISAGREE (g, the frame rate or the grid's pitch?)"
                    } else {
                        ""
                    },
                );
            }
            None => {
                out += &format!(
                    "# lens: k1 {} (the fractional displacement at the frame's corners, about its centre);\n\
                     #   {}\n",
                    p(&self.lens_k1, "", 5),
                    match (&self.lens_refused, self.lens_kept) {
                        (Some(why), _) => format!(
                            "NOT written: {why};\n\
                             #   so the maps were fitted again without a lens (their σ do not take in one)"
                        ),
                        (None, true) => "beyond 3σ, so written into both views; its σ is not carried into the estimates' uncertainty".into(),
                        (None, false) => "within 3σ of none, so the maps were fitted again without a lens; each map parameter's σ\n\
                         #   takes in how far a lens fitted moves it, and goes into the estimates' uncertainty".into(),
                    },
                );
            }
        }
        out += &format!(
            "# px_per_mm_uncertainty_percent and turn_uncertainty_deg (about world x, y, z) are\n\
             #   the σ above; the analysis carries them into every estimate's uncertainty. The\n\
             #   direct camera's pitch and yaw (about x, y) cannot be found from free flight: it is\n\
             #   taken as square, 0 ± {} deg each (edit if it is known better).\n",
            super::DIRECT_SQUARE_DEG
        );
        for (name, v) in [
            ("direct", &self.geometry.direct),
            ("mirror", &self.geometry.mirror),
        ] {
            let Some(v) = v else { continue };
            if let Some(p) = v.projection {
                let row =
                    |r: [f64; 4]| format!("[{:.6}, {:.6}, {:.9}, {:.4}]", r[0], r[1], r[2], r[3]);
                let row3 =
                    |r: [f64; 4]| format!("[{:.9}, {:.9}, {:.9}, {:.1}]", r[0], r[1], r[2], r[3]);
                out +=
                    &format!(
                    "\n[geometry.{name}]\nregion = [{}, {}, {}, {}]\nprojection = [{}, {}, {}]\n",
                    v.region[0], v.region[1], v.region[2], v.region[3],
                    row(p[0]), row(p[1]), row3(p[2])
                );
                out += &uncertainty_keys(v);
                continue;
            }
            let (Some(m), Some(o)) = (v.matrix_px_per_mm, v.origin_px) else {
                continue;
            };
            let row = |r: [f64; 3]| format!("[{:.6}, {:.6}, {:.6}]", r[0], r[1], r[2]);
            out += &format!(
                "\n[geometry.{name}]\nregion = [{}, {}, {}, {}]\nmatrix_px_per_mm = [{}, {}]\norigin_px = [{:.4}, {:.4}]\n",
                v.region[0],
                v.region[1],
                v.region[2],
                v.region[3],
                row(m[0]),
                row(m[1]),
                o[0],
                o[1]
            );
            out += &uncertainty_keys(v);
        }
        out
    }

    /// A PNG of frame `img` with the regions outlined and each view's world axes drawn from its
    /// origin (x red, the other axis green, 10 mm long).
    pub fn png(&self, img: &analysis::image::GreyImage) -> Result<Vec<u8>, String> {
        use crate::figures::canvas::{Canvas, Raster};
        let mut r = Raster::from_grey(img.width, img.height, &img.data);
        for (kind, v) in [
            (ViewKind::Direct, &self.geometry.direct),
            (ViewKind::Mirror, &self.geometry.mirror),
        ] {
            let Some(g) = v else { continue };
            let view = View::from_config(kind, g);
            let [x, y, w, h] = g.region.map(f64::from);
            let (x0, y0, x1, y1) = (x - 0.5, y - 0.5, x + w - 0.5, y + h - 0.5);
            for (a, b) in [
                ((x0, y0), (x1, y0)),
                ((x1, y0), (x1, y1)),
                ((x1, y1), (x0, y1)),
                ((x0, y1), (x0, y0)),
            ] {
                r.line(a, b, [255, 200, 0], 1.0);
            }
            let o = view.project(&V3::zeros());
            // y for the direct view, z for the mirror.
            let mut second = V3::zeros();
            second[3 - kind.depth_axis()] = 10.0;
            for (end, colour) in [
                (V3::new(10.0, 0.0, 0.0), [230, 40, 40]),
                (second, [40, 200, 40]),
            ] {
                let q = view.project(&end);
                r.line((o[0], o[1]), (q[0], q[1]), colour, 1.0);
            }
        }
        r.png().map_err(|e| format!("PNG: {e}"))
    }
}

/// The keys that say how well a view's map is known (none where calibrate set none), its lens
/// where one was found, and whether its image is mirrored where the config said.
fn uncertainty_keys(v: &crate::config::ViewGeometry) -> String {
    let mut out = String::new();
    if let Some(m) = v.image_mirrored {
        out += &format!("image_mirrored = {m}\n");
    }
    if let (Some(k1), Some(c), Some(r)) = (v.lens_k1, v.lens_centre_px, v.lens_radius_px) {
        out += &format!(
            "lens_k1 = {k1:.6}\nlens_centre_px = [{:.2}, {:.2}]\nlens_radius_px = {r:.4}\n",
            c[0], c[1]
        );
    }
    if let Some(p) = v.px_per_mm_uncertainty_percent {
        out += &format!("px_per_mm_uncertainty_percent = {p:.4}\n");
    }
    if let Some([x, y, z]) = v.turn_uncertainty_deg {
        out += &format!("turn_uncertainty_deg = [{x:.4}, {y:.4}, {z:.4}]\n");
    }
    out
}
