//! What the rig looks like beyond its geometry: the light on each view, the spheres' surface,
//! the markers' paint, the background and what else stands in view (tube ends, a ruler), focus.
//!
//! Why it exists: an analysis tuned on one look measures that look. Real rigs are lit from the
//! side, shiny, backlit, cluttered and defocused, so the simulator draws all of that, and
//! `Look::draw` picks a look at random from a family and a seed so that accuracy can be measured
//! over many. No look (`sim.look` absent) is the original render, kept bit-for-bit so that
//! sessions recorded before looks existed are reproduced exactly.

use crate::rng::Rng;
use serde::{Deserialize, Serialize};

/// How a sphere's surface returns light.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum SurfaceKind {
    /// Matte: albedo × (ambient + (1 − ambient)·max(0, l·n)).
    Lambertian,
    /// The same grey everywhere on the disc (a lamp at the camera, or a diffuse dome).
    Flat,
    /// Lambertian plus a Blinn–Phong highlight, as glass and steel show.
    Specular,
}

/// How the markers are painted.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum MarkerPaint {
    /// One fixed grey (`sim.marker_grey`) whatever the light.
    Grey,
    /// Dark paint: the local shading times `marker_factor`.
    Multiplicative,
}

/// The light and illumination field of one view.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct ViewLook {
    /// Angle between the light and the view's axis.
    pub light_off_axis_deg: f64,
    /// Direction of that tilt in the image, from +u towards +v.
    pub light_azimuth_deg: f64,
    /// Everything in the view (background, spheres, clutter) is multiplied by this: a mirror
    /// view is typically 10–15 % dimmer.
    pub gain: f64,
    /// Linear illumination change across the view, fraction per 100 px along u and along v.
    pub gradient_per_100px: [f64; 2],
    /// Fraction of the light lost at the view's corners (quadratic fall-off from its centre).
    pub vignetting: f64,
}

impl Default for ViewLook {
    fn default() -> Self {
        ViewLook {
            light_off_axis_deg: 0.0,
            light_azimuth_deg: 0.0,
            gain: 1.0,
            gradient_per_100px: [0.0, 0.0],
            vignetting: 0.0,
        }
    }
}

/// `[sim.look]`: everything that decides how the rig looks, apart from its geometry.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct Look {
    /// The family it was drawn from (`Look::FAMILIES`), or "custom".
    pub family: String,
    /// Per view, in the order of the scene's views (direct, then mirror); missing views are
    /// lit on axis with no gradient.
    pub views: Vec<ViewLook>,
    pub surface: SurfaceKind,
    /// The shading's floor at the limb and on the side away from the light, fraction of albedo.
    pub ambient: f64,
    /// Peak of the specular highlight, grey levels (8-bit scale).
    pub specular_grey: f64,
    /// Blinn–Phong exponent: larger is a smaller, sharper highlight.
    pub shininess: f64,
    /// Dark spheres on a bright background (a light behind the spheres); markers are not seen
    /// unless `backlit_front_light`.
    pub backlit: bool,
    /// With `backlit`: a lamp in front too, so the dark spheres show their own shading
    /// (`sim.sphere_grey` as albedo, the views' lights and `ambient`) and their markers, dark
    /// paint on a dark surface (faint; multiplicative paint keeps `marker_factor` of it).
    pub backlit_front_light: bool,
    pub marker_paint: MarkerPaint,
    /// For multiplicative paint: the fraction of the local shading a marker keeps.
    pub marker_factor: f64,
    /// Markers only on the hemisphere that faces the direct camera at the tube exit (a rig
    /// whose painter saw one side), instead of all over.
    pub markers_one_hemisphere: bool,
    /// Gaussian blur of the whole view (defocus), px.
    pub defocus_sigma_px: f64,
    /// The ends of both tubes, where the spheres leave them, in every view.
    pub tube_ends: bool,
    /// Grey level of the tubes (8-bit scale).
    pub tube_grey: f64,
    /// A ruler along the bottom of the direct view: a light strip with dark ticks each mm.
    pub ruler: bool,
}

impl Default for Look {
    fn default() -> Self {
        Look {
            family: "custom".into(),
            views: Vec::new(),
            surface: SurfaceKind::Lambertian,
            ambient: 0.55,
            specular_grey: 0.0,
            shininess: 40.0,
            backlit: false,
            backlit_front_light: false,
            marker_paint: MarkerPaint::Grey,
            marker_factor: 0.2,
            markers_one_hemisphere: false,
            defocus_sigma_px: 0.0,
            tube_ends: false,
            tube_grey: 110.0,
            ruler: false,
        }
    }
}

/// The levels a look draws for the lab's greys (`sim.background_grey`, `sphere_grey`,
/// `marker_grey`), which `Look::draw` returns beside the look.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Levels {
    pub background_grey: f64,
    pub sphere_grey: f64,
    pub marker_grey: f64,
}

impl Look {
    /// The families `draw` knows. `side_lit`: a lamp 10–40° off each view's axis, ambient
    /// floor, gradient and vignetting, mirror dimmer, multiplicative markers. `specular`: the
    /// same with a highlight. `backlit`: dark silhouettes on a bright ground, half of them lit
    /// from the front too (faint shading and dots). `cluttered`:
    /// side-lit with tube ends and a ruler in view. `defocus`: side-lit and blurred. `paint`:
    /// side-lit with markers of one fixed grey, all over. `mixed`: each of those features
    /// drawn independently.
    pub const FAMILIES: [&'static str; 7] = [
        "side_lit",
        "specular",
        "backlit",
        "cluttered",
        "defocus",
        "paint",
        "mixed",
    ];

    /// Families `draw` knows that "varied" does not draw from (so that the varied draws stay
    /// as they were): `overexposed`, side-lit spheres of grey 215 with the direct view's gain
    /// 1.45–1.7 and the mirror's 0.85–0.9 of that, so that every sphere's lit side sits at the
    /// camera's ceiling (255) in both views; `grey_ground`, side-lit spheres (25–40° off the
    /// axis, ambient floor 0.2–0.3) over a grey ground of 80–115, so that every sphere's
    /// shaded limb is darker than the ground while its lit side is brighter.
    pub const EXTRA_FAMILIES: [&'static str; 2] = ["overexposed", "grey_ground"];

    /// A look drawn at random from `family` (one of `FAMILIES` or `EXTRA_FAMILIES`, or
    /// "varied": one of `FAMILIES` drawn first) with the lab's grey levels to go with it; the
    /// same seed gives the same look.
    pub fn draw(family: &str, seed: u64) -> Result<(Look, Levels), String> {
        let mut rng = Rng::new(seed ^ 0x100C_5EED);
        let family = if family == "varied" {
            let k = (rng.uniform() * Self::FAMILIES.len() as f64) as usize;
            Self::FAMILIES[k.min(Self::FAMILIES.len() - 1)]
        } else if Self::FAMILIES.contains(&family) || Self::EXTRA_FAMILIES.contains(&family) {
            family
        } else {
            return Err(format!(
                "sim.look_family: unknown family {family:?}, expected varied or one of {}, {}",
                Self::FAMILIES.join(", "),
                Self::EXTRA_FAMILIES.join(", ")
            ));
        };
        let mut u = |lo: f64, hi: f64| lo + (hi - lo) * rng.uniform();
        let mut look = Look {
            family: family.into(),
            ..Look::default()
        };
        let mut levels = Levels {
            background_grey: u(10.0, 35.0),
            sphere_grey: u(170.0, 215.0),
            marker_grey: 40.0,
        };
        for vi in 0..2 {
            look.views.push(ViewLook {
                light_off_axis_deg: u(10.0, 40.0),
                light_azimuth_deg: u(0.0, 360.0),
                gain: if vi == 0 { 1.0 } else { u(0.85, 0.9) },
                gradient_per_100px: [u(-0.15, 0.15), u(-0.15, 0.15)],
                vignetting: u(0.0, 0.2),
            });
        }
        look.ambient = u(0.3, 0.5);
        look.marker_paint = MarkerPaint::Multiplicative;
        look.marker_factor = u(0.14, 0.3);
        look.markers_one_hemisphere = true;
        match family {
            "specular" => {
                look.surface = SurfaceKind::Specular;
                look.specular_grey = u(30.0, 90.0);
                look.shininess = u(20.0, 120.0);
            }
            "backlit" => {
                look.backlit = true;
                levels.background_grey = u(170.0, 230.0);
                levels.sphere_grey = u(10.0, 45.0);
                // Half the draws have a lamp in front too: the spheres show faint shading and
                // faint dots (the paint keeps 40–65 % of the dark surface's light).
                look.backlit_front_light = u(0.0, 1.0) < 0.5;
                if look.backlit_front_light {
                    look.ambient = u(0.6, 0.9);
                    look.marker_factor = u(0.4, 0.65);
                } else {
                    look.views
                        .iter_mut()
                        .for_each(|v| v.light_off_axis_deg = 0.0);
                }
            }
            "cluttered" => {
                look.tube_ends = true;
                look.ruler = true;
                look.tube_grey = u(60.0, 150.0);
            }
            "defocus" => look.defocus_sigma_px = u(0.5, 1.2),
            "overexposed" => {
                // Drawn after everything else, so the side-lit draws above stay the same.
                let gain = u(1.45, 1.7);
                look.views[0].gain = gain;
                look.views[1].gain *= gain;
                levels.sphere_grey = 215.0;
            }
            "grey_ground" => {
                // Drawn after everything else, so the side-lit draws above stay the same.
                levels.background_grey = u(80.0, 115.0);
                look.ambient = u(0.2, 0.3);
                for v in look.views.iter_mut() {
                    v.light_off_axis_deg = u(25.0, 40.0);
                }
            }
            "paint" => {
                look.marker_paint = MarkerPaint::Grey;
                look.markers_one_hemisphere = false;
                levels.marker_grey = u(20.0, 60.0);
            }
            "mixed" => {
                if u(0.0, 1.0) < 0.4 {
                    look.surface = SurfaceKind::Specular;
                    look.specular_grey = u(30.0, 90.0);
                    look.shininess = u(20.0, 120.0);
                } else if u(0.0, 1.0) < 0.2 {
                    look.surface = SurfaceKind::Flat;
                }
                look.tube_ends = u(0.0, 1.0) < 0.5;
                look.ruler = u(0.0, 1.0) < 0.5;
                look.tube_grey = u(60.0, 150.0);
                look.defocus_sigma_px = if u(0.0, 1.0) < 0.5 { u(0.3, 1.0) } else { 0.0 };
                if u(0.0, 1.0) < 0.5 {
                    look.marker_paint = MarkerPaint::Grey;
                    levels.marker_grey = u(20.0, 60.0);
                }
                look.markers_one_hemisphere = u(0.0, 1.0) < 0.5;
            }
            _ => {}
        }
        Ok((look, levels))
    }

    /// Checks every value; the error names the key (`sim.look.…`) and what was expected.
    pub fn validate(&self) -> Result<(), String> {
        let range = |key: &str, v: f64, lo: f64, hi: f64| -> Result<(), String> {
            if v.is_finite() && v >= lo && v <= hi {
                Ok(())
            } else {
                Err(format!(
                    "sim.look.{key}: {v} is out of range, expected {lo} to {hi}"
                ))
            }
        };
        if self.views.len() > 8 {
            return Err(format!(
                "sim.look.views: {} views, expected at most 8",
                self.views.len()
            ));
        }
        for (i, v) in self.views.iter().enumerate() {
            range(
                &format!("views[{i}].light_off_axis_deg"),
                v.light_off_axis_deg,
                0.0,
                80.0,
            )?;
            range(
                &format!("views[{i}].light_azimuth_deg"),
                v.light_azimuth_deg,
                -360.0,
                360.0,
            )?;
            range(&format!("views[{i}].gain"), v.gain, 0.1, 4.0)?;
            for (k, g) in v.gradient_per_100px.iter().enumerate() {
                range(
                    &format!("views[{i}].gradient_per_100px[{k}]"),
                    *g,
                    -0.5,
                    0.5,
                )?;
            }
            range(&format!("views[{i}].vignetting"), v.vignetting, 0.0, 0.6)?;
        }
        range("ambient", self.ambient, 0.0, 1.0)?;
        range("specular_grey", self.specular_grey, 0.0, 255.0)?;
        range("shininess", self.shininess, 1.0, 1000.0)?;
        range("marker_factor", self.marker_factor, 0.0, 1.0)?;
        range("defocus_sigma_px", self.defocus_sigma_px, 0.0, 5.0)?;
        range("tube_grey", self.tube_grey, 0.0, 255.0)?;
        Ok(())
    }

    /// The look of view `i` (neutral where none is given).
    pub fn view(&self, i: usize) -> ViewLook {
        self.views.get(i).cloned().unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_family_is_drawn_by_varied_and_draws_are_repeatable() {
        let mut seen = std::collections::HashSet::new();
        for seed in 0..200 {
            let (look, _) = Look::draw("varied", seed).expect("varied is a family");
            look.validate().expect("a drawn look is valid");
            assert_eq!(Look::draw("varied", seed).expect("again").0, look);
            seen.insert(look.family);
        }
        assert_eq!(seen.len(), Look::FAMILIES.len(), "families drawn: {seen:?}");
    }

    /// An overexposed look lights every sphere's brightest point past the camera's ceiling in
    /// both views (albedo × gain above 255), and "varied" never draws it.
    #[test]
    fn overexposed_looks_saturate_both_views() {
        for seed in 0..50 {
            let (look, levels) = Look::draw("overexposed", seed).expect("a family");
            look.validate().expect("a drawn look is valid");
            assert_eq!(look.family, "overexposed");
            for v in &look.views {
                assert!(
                    levels.sphere_grey * v.gain > 255.0 * 1.02,
                    "seed {seed}: {v:?}"
                );
            }
            assert_ne!(
                Look::draw("varied", seed).expect("varied").0.family,
                "overexposed"
            );
        }
    }

    /// A grey-ground look puts every sphere's shaded limb (its ambient floor) below the ground
    /// and its brightest point above it, in both views, and "varied" never draws it.
    #[test]
    fn grey_ground_looks_have_limbs_darker_than_the_ground() {
        for seed in 0..50 {
            let (look, levels) = Look::draw("grey_ground", seed).expect("a family");
            look.validate().expect("a drawn look is valid");
            assert_eq!(look.family, "grey_ground");
            assert!(
                levels.sphere_grey * look.ambient < levels.background_grey - 10.0
                    && levels.sphere_grey > levels.background_grey + 50.0,
                "seed {seed}: {levels:?}, ambient {}",
                look.ambient
            );
            assert_ne!(
                Look::draw("varied", seed).expect("varied").0.family,
                "grey_ground"
            );
        }
    }

    #[test]
    fn an_unknown_family_is_named_in_the_error() {
        let err = Look::draw("neon", 1).expect_err("unknown family");
        assert!(
            err.contains("sim.look_family") && err.contains("neon"),
            "{err}"
        );
    }
}
