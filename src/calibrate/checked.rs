//! What `calibrate` hands back is checked as the config's reader checks a geometry
//! (`config::check_geometry`): a map the analysis would refuse is never printed or written.
//!
//! Why: on a side-lit recording (an independent render's look drawn at random, seed 7) the
//! flights gave a lens of k1 = −0.18 ± 0.01, beyond 3σ and so kept, and with it a mirror turned
//! 25–31° about y and z; the `[geometry]` written was refused when analysed ("this view does not
//! see the world x–z plane"). A lens that bends the flights into another rig is not one they
//! show: the maps are then fitted again without it, and where even those are refused the error
//! names the key.

use super::{CalibrateError, Calibrated};

/// `first` where its maps pass the config's checks. Where they do not and it kept a lens the
/// flights alone showed (no dot grid: `lens_from_grid` false), `again()` — the same fit with no
/// lens — with `lens_refused` saying why; else the refusal as an error.
pub(super) fn settled(
    first: Calibrated,
    lens_from_grid: bool,
    again: impl FnOnce() -> Result<Calibrated, CalibrateError>,
) -> Result<Calibrated, CalibrateError> {
    let Some(why) = refused(&first) else {
        return Ok(first);
    };
    if !first.lens_kept || lens_from_grid {
        return Err(error(&first, &why));
    }
    let second = again()?;
    match refused(&second) {
        None => Ok(Calibrated {
            lens_refused: Some(format!(
                "k1 {:.5} ± {:.5} was beyond 3σ, but the maps fitted with it are refused ({why})",
                first.lens_k1.value, first.lens_k1.sigma
            )),
            ..second
        }),
        Some(why) => Err(error(&second, &why)),
    }
}

/// Why the config's reader would refuse `c`'s geometry, if it would.
fn refused(c: &Calibrated) -> Option<String> {
    crate::config::check_geometry(&c.geometry).err()
}

fn error(c: &Calibrated, why: &str) -> CalibrateError {
    CalibrateError::Data {
        source_name: c.source.clone(),
        message: format!("the maps fitted would be refused by the analysis: {why}"),
    }
}

#[cfg(test)]
mod tests {
    use super::super::{DirectFit, Fitted};
    use super::*;
    use crate::config::{Geometry, ViewGeometry};

    fn fitted(value: f64) -> Fitted {
        Fitted { value, sigma: 0.01 }
    }

    /// A calibration whose mirror map is `mirror` (rows of px per mm), a lens kept or not.
    fn calibrated(mirror: [[f64; 3]; 2], lens_kept: bool) -> Calibrated {
        let direct = ViewGeometry::affine(
            [0, 0, 240, 96],
            [[2.1, 0.0, 0.0], [0.0, -2.1, 0.0]],
            [120.0, 44.0],
        );
        let mirror = ViewGeometry::affine([0, 96, 240, 96], mirror, [120.0, 144.0]);
        Calibrated {
            source: "frames.tif".into(),
            recordings: 1,
            frames: 40,
            impact_frame: 20,
            regions: String::new(),
            direct: DirectFit {
                scale_from_free_fall: fitted(2.1),
                scale_from_diameter: fitted(2.1),
                scale_from_flights: fitted(2.1),
                scale: fitted(2.1),
                diameter_disagrees_sigma: None,
                roll_deg: fitted(0.0),
                residual_rms_px: 0.05,
                camera_distance_mm: None,
            },
            mirror: None,
            lens_k1: fitted(if lens_kept { -0.18 } else { 0.0 }),
            lens_kept,
            lens_refused: None,
            grid: None,
            geometry: Geometry {
                direct: Some(direct),
                mirror: Some(mirror),
            },
        }
    }

    /// A mirror view that sees x and z, and one turned until it sees x and y.
    const SEES_XZ: [[f64; 3]; 2] = [[2.1, 0.0, 0.0], [0.0, 0.1, 2.1]];
    const SEES_XY: [[f64; 3]; 2] = [[2.1, 0.0, 0.0], [0.0, 2.1, 0.1]];

    #[test]
    fn maps_the_analysis_accepts_are_kept_as_fitted() {
        let got = settled(calibrated(SEES_XZ, true), false, || {
            panic!("fitted again where the first maps were accepted")
        });
        assert!(matches!(got, Ok(c) if c.lens_kept && c.lens_refused.is_none()));
    }

    #[test]
    fn a_lens_whose_maps_are_refused_is_fitted_again_without_and_says_why() {
        let got = settled(calibrated(SEES_XY, true), false, || {
            Ok(calibrated(SEES_XZ, false))
        });
        let Ok(c) = got else {
            panic!("{got:?}");
        };
        let why = c.lens_refused.unwrap_or_default();
        assert!(!c.lens_kept, "{why}");
        assert!(
            why.starts_with("k1 -0.18000 ± 0.01000 was beyond 3σ")
                && why.contains("geometry.mirror.matrix_px_per_mm")
                && why.contains("x–z plane"),
            "{why}"
        );
    }

    #[test]
    fn maps_refused_without_a_lens_or_with_a_grids_are_an_error_naming_the_key() {
        let again_never = || -> Result<Calibrated, CalibrateError> {
            panic!("no second fit: the lens was not the flights' own")
        };
        for (cal, grid) in [
            (calibrated(SEES_XY, false), false),
            (calibrated(SEES_XY, true), true),
        ] {
            let err = settled(cal, grid, again_never).err().map(|e| e.to_string());
            let msg = err.unwrap_or_default();
            assert!(
                msg.starts_with("frames.tif: the maps fitted would be refused by the analysis: geometry.mirror.matrix_px_per_mm"),
                "{msg}"
            );
        }
        // Refused again without the lens: the second fit's refusal.
        let err = settled(calibrated(SEES_XY, true), false, || {
            Ok(calibrated(SEES_XY, false))
        })
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
        assert!(err.contains("would be refused"), "{err}");
    }
}
