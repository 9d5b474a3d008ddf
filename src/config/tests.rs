use super::*;

#[test]
fn embedded_default_is_valid_and_round_trips() {
    let c = Config::default_config();
    let again = Config::from_toml_str(&c.to_toml(), "round trip").unwrap();
    assert_eq!(c, again);
    assert!(c.geometry.direct.is_some() && c.geometry.mirror.is_some());
}

#[test]
fn struct_defaults_equal_the_embedded_default() {
    // A partial config is filled from the structs' defaults; they must say what the embedded
    // file says, or `run` and `run --config partial.toml` would disagree silently.
    assert_eq!(
        Config::from_toml_str("", "empty").unwrap(),
        Config::default_config()
    );
}

#[test]
fn typo_key_is_named() {
    let e = Config::from_toml_str("[camera]\nfram_rate_hz = 100.0\n", "x.toml")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("fram_rate_hz") && e.contains("x.toml") && e.contains("line 2"),
        "{e}"
    );
}

#[test]
fn negative_frame_rate_is_named() {
    let e = Config::from_toml_str("[camera]\nframe_rate_hz = -5.0\n", "x.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("camera.frame_rate_hz"), "{e}");
}

#[test]
fn pulse_above_max_is_refused() {
    let e = Config::from_toml_str("[trigger]\nrelay_pulse_ms = 900.0\n", "x.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("relay_pulse_ms_max"), "{e}");
}

#[test]
fn one_view_only_is_allowed() {
    let t = "[geometry.direct]\nregion=[0,0,240,96]\npx_per_mm=2.0\norigin_px=[120.0,48.0]\nu_axis=\"+x\"\nv_axis=\"-y\"\n";
    let c = Config::from_toml_str(t, "x.toml").unwrap();
    assert!(c.geometry.mirror.is_none());
}

/// A config of one mirror view with the given map keys: the error, if any.
fn mirror_with(keys: &str) -> Option<String> {
    let t = format!("[geometry.mirror]\nregion=[0,96,240,96]\n{keys}\n");
    Config::from_toml_str(&t, "x.toml")
        .err()
        .map(|e| e.to_string())
}

#[test]
fn general_maps_are_accepted_and_bad_ones_named() {
    // A tilted mirror (v takes in a little y) and a pinhole 300 mm away are maps.
    let affine = "matrix_px_per_mm=[[2.1, 0.0, 0.05],[0.0, -0.2, 2.1]]\norigin_px=[120.0,144.0]";
    assert_eq!(mirror_with(affine), None);
    let pinhole = "projection=[[2.1,0.0,-0.4,121.0],[0.0,0.0,-2.1,144.0],[0.0,0.0033,0.0,1.0]]";
    assert_eq!(mirror_with(pinhole), None);
    for (keys, expect) in [
            // Shorthand and matrix in one view.
            ("px_per_mm=2.0\nu_axis=\"+x\"\nv_axis=\"+z\"\nmatrix_px_per_mm=[[2.1,0,0],[0,0,2.1]]\norigin_px=[1.0,1.0]", "px_per_mm/u_axis/v_axis and matrix_px_per_mm given together"),
            // Rank 1: parallel rows.
            ("matrix_px_per_mm=[[2.0,0.0,1.0],[4.0,0.0,2.0]]\norigin_px=[1.0,1.0]", "geometry.mirror.matrix_px_per_mm: rank below 2"),
            // The x–y plane in the mirror view.
            ("matrix_px_per_mm=[[2.0,0.0,0.0],[0.0,-2.0,0.1]]\norigin_px=[1.0,1.0]", "geometry.mirror.matrix_px_per_mm: this view does not see the world x–z plane"),
            // A matrix without its offset; a projection with one.
            ("matrix_px_per_mm=[[2.1,0,0],[0,0,2.1]]", "geometry.mirror.origin_px: missing"),
            ("projection=[[2.1,0,0,121],[0,0,2.1,144],[0,0,0,1]]\norigin_px=[1.0,1.0]", "geometry.mirror.origin_px: not used with projection"),
            ("projection=[[2.1,0,0,121],[0,0,2.1,144],[0,1,0,0]]", "geometry.mirror.projection: the world origin is on the camera's focal plane"),
            ("px_per_mm=2.0\nu_axis=\"+x\"", "geometry.mirror.origin_px, v_axis: missing"),
            ("region_px=1", "unknown field"),
            ("", "geometry.mirror: no map"),
        ] {
            let e = mirror_with(keys).unwrap_or_else(|| panic!("{keys}: accepted"));
            assert!(e.contains(expect), "{keys}: {e}");
        }
}

#[test]
fn how_well_a_map_is_known_is_read_and_bad_values_named() {
    let map = "px_per_mm=2.0\norigin_px=[120.0,140.0]\nu_axis=\"+x\"\nv_axis=\"+z\"";
    let t = format!("[geometry.mirror]\nregion=[0,96,240,96]\n{map}\npx_per_mm_uncertainty_percent = 0.2\nturn_uncertainty_deg = [0.1, 0.0, 0.05]\n");
    let c = Config::from_toml_str(&t, "x.toml").unwrap();
    let m = c.geometry.mirror.as_ref().unwrap();
    assert_eq!(m.px_per_mm_uncertainty_percent, Some(0.2));
    assert_eq!(m.turn_uncertainty_deg, Some([0.1, 0.0, 0.05]));
    assert_eq!(Config::from_toml_str(&c.to_toml(), "again").unwrap(), c);
    for (keys, expect) in [
        (
            "px_per_mm_uncertainty_percent = -1.0",
            "geometry.mirror.px_per_mm_uncertainty_percent: -1 is out of range",
        ),
        (
            "px_per_mm_uncertainty_percent = 25.0",
            "geometry.mirror.px_per_mm_uncertainty_percent: 25 is out of range",
        ),
        (
            "turn_uncertainty_deg = [0.1, 12.0, 0.0]",
            "geometry.mirror.turn_uncertainty_deg: [0.1, 12.0, 0.0] is out of range",
        ),
        // (serde's own words, with the file and line)
        (
            "turn_uncertainty_deg = [0.1, 0.2]",
            "x.toml: invalid length 2, expected an array of length 3 (line",
        ),
    ] {
        let e =
            mirror_with(&format!("{map}\n{keys}")).unwrap_or_else(|| panic!("{keys}: accepted"));
        assert!(e.contains(expect), "{keys}: {e}");
    }
}

#[test]
fn a_lens_is_read_and_bad_or_partial_lenses_named() {
    let map = "px_per_mm=2.0\norigin_px=[120.0,140.0]\nu_axis=\"+x\"\nv_axis=\"+z\"";
    let lens = "lens_k1 = -0.02\nlens_centre_px = [119.5, 95.5]\nlens_radius_px = 153.7";
    let t = format!("[geometry.mirror]\nregion=[0,96,240,96]\n{map}\n{lens}\n");
    let c = Config::from_toml_str(&t, "x.toml").unwrap();
    let m = c.geometry.mirror.as_ref().unwrap();
    assert_eq!(
        (m.lens_k1, m.lens_centre_px, m.lens_radius_px),
        (Some(-0.02), Some([119.5, 95.5]), Some(153.7))
    );
    assert_eq!(Config::from_toml_str(&c.to_toml(), "again").unwrap(), c);
    for (keys, expect) in [
            (
                "lens_k1 = -0.02",
                "geometry.mirror.lens_k1, geometry.mirror.lens_centre_px, geometry.mirror.lens_radius_px: give all three or none",
            ),
            (
                "lens_k1 = 0.3\nlens_centre_px = [119.5, 95.5]\nlens_radius_px = 153.7",
                "geometry.mirror.lens_k1: 0.3 is out of range",
            ),
            (
                "lens_k1 = 0.01\nlens_centre_px = [119.5, 95.5]\nlens_radius_px = 0.0",
                "geometry.mirror.lens_radius_px: 0 is out of range",
            ),
            (
                "lens_k1 = 0.01\nlens_centre_px = [119.5, 1e9]\nlens_radius_px = 150.0",
                "geometry.mirror.lens_centre_px",
            ),
        ] {
            let e = mirror_with(&format!("{map}\n{keys}"))
                .unwrap_or_else(|| panic!("{keys}: accepted"));
            assert!(e.contains(expect), "{keys}: {e}");
        }
}

#[test]
fn mirror_axes_must_be_x_z() {
    let t = "[geometry.mirror]\nregion=[0,96,240,96]\npx_per_mm=2.0\norigin_px=[120.0,140.0]\nu_axis=\"+x\"\nv_axis=\"-y\"\n";
    let e = Config::from_toml_str(t, "x.toml").unwrap_err().to_string();
    assert!(e.contains("geometry.mirror"), "{e}");
}

#[test]
fn the_experiment_label_round_trips_and_bad_ones_are_named() {
    let t =
        "[experiment]\ncampaign = \"glass 3 mm\"\ntube_angle_deg = 32.5\nnotes = \"new tubes\"\n";
    let c = Config::from_toml_str(t, "x.toml").unwrap();
    assert_eq!(c.experiment.campaign.as_deref(), Some("glass 3 mm"));
    assert_eq!(Config::from_toml_str(&c.to_toml(), "again").unwrap(), c);
    // No label, no section: a config without one writes what it always wrote.
    assert!(!Config::default_config().to_toml().contains("[experiment]"));
    let long = format!(
        "[experiment]\nnotes = \"{}\"\n",
        "x".repeat(MAX_NOTES_CHARS + 1)
    );
    for (t, expect) in [
        ("[experiment]\ncampaign = \"../x\"\n", "experiment.campaign"),
        ("[experiment]\ncampaign = \"\"\n", "experiment.campaign"),
        (
            "[experiment]\ntube_angle_deg = 120.0\n",
            "experiment.tube_angle_deg",
        ),
        (long.as_str(), "experiment.notes"),
        ("[experiment]\nangle = 3.0\n", "unknown field"),
    ] {
        let e = Config::from_toml_str(t, "x.toml").unwrap_err().to_string();
        assert!(e.contains(expect), "{t}: {e}");
    }
}
