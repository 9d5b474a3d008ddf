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
        for (axis, val) in view.unproject(px, None) {
            assert!((val - p[axis]).abs() < 1e-12);
        }
    }
}

/// `image_mirrored` turns the hemisphere a view sees and nothing else: a direct view whose
/// camera flips its image (x leftwards) still faces +z, where without the key the same map
/// is a camera behind; a mirror view that is not a mirror image faces the other way.
#[test]
fn image_mirrored_says_which_hemisphere_a_view_sees() {
    let flipped = "px_per_mm=2.1576\norigin_px=[119.5,44.0]\nu_axis=\"-x\"\nv_axis=\"-y\"";
    let behind = config_view(ViewKind::Direct, flipped);
    let said = config_view(ViewKind::Direct, &format!("{flipped}\nimage_mirrored=true"));
    assert_eq!(behind.facing, V3::new(0.0, 0.0, -1.0));
    assert_eq!(said.facing, V3::new(0.0, 0.0, 1.0));
    assert!(said.mirrored && !behind.mirrored);
    let p = V3::new(3.0, -2.0, 1.5);
    assert_eq!(said.project(&p), behind.project(&p));
    let mirror = "px_per_mm=2.1175\norigin_px=[121.0,144.0]\nu_axis=\"+x\"\nv_axis=\"+z\"";
    let unflipped = config_view(ViewKind::Mirror, &format!("{mirror}\nimage_mirrored=false"));
    assert_eq!(unflipped.facing, V3::new(0.0, 1.0, 0.0));
    // The turned copies the geometry's uncertainty re-runs keep it.
    let turned = said.turned(&nalgebra::Matrix3::identity(), 1.0);
    assert_eq!(turned.facing, said.facing);
}

fn config_view(kind: ViewKind, keys: &str) -> View {
    let name = kind.name();
    let t = format!("[geometry.{name}]\nregion=[0,0,240,96]\n{keys}\n");
    let cfg = Config::from_toml_str(&t, "x.toml").unwrap();
    views(&cfg).remove(0)
}

#[test]
fn a_turned_view_measures_its_coordinates_given_the_one_it_cannot_see() {
    // A mirror tilted so that its v takes in world y: alone it cannot tell y, so its z is
    // right only with y from elsewhere.
    let view = config_view(
        ViewKind::Mirror,
        "matrix_px_per_mm=[[2.1, 0.02, 0.05],[-0.03, -0.2, 2.1]]\norigin_px=[120.0,44.0]",
    );
    assert!(!view.aligned);
    assert_eq!(view.axes, [0, 2]);
    let p = V3::new(3.0, -7.0, 1.5);
    let px = view.project(&p);
    let q = view.solve(px, Some(&V3::new(0.0, p.y, 0.0)));
    assert!((q - p).norm() < 1e-12, "{q} vs {p}");
    let blind = view.solve(px, None);
    assert!((blind.z - p.z).abs() > 0.5, "y = −7 mm moves z by 0.67 mm");
    // Both views together place it without any guess.
    let direct = config_view(
        ViewKind::Direct,
        "matrix_px_per_mm=[[2.15, 0.05, 0.01],[0.05, -2.15, 0.0]]\norigin_px=[120.0,44.0]",
    );
    let both = [(&direct, direct.project(&p)), (&view, px)];
    let t = triangulate(&both, &V3::zeros()).unwrap();
    assert!((t - p).norm() < 1e-12);
    // One turned view alone leaves its line of sight unseen: no point, rather than one
    // anywhere along that line (AᵀA's rounding made it invertible).
    assert_eq!(triangulate(&[(&view, px)], &V3::zeros()), None);
    assert_eq!(triangulate(&[(&direct, direct.project(&p))], &p), None);
    // Rescaling by (a, b) when the view measured a·x + b: the rescaled view reads the old
    // view's image of p as (p − b·x̂)/a, the whole point scaled, not x alone.
    let mut r = view.clone();
    assert!(r.rescale(1.01, 0.3));
    let scaled = (p - V3::x() * 0.3) / 1.01;
    let q = r.solve(view.project(&p), Some(&scaled));
    assert!((q - scaled).norm() < 1e-12, "{q} vs {scaled}");
    // The same for the shorthand, x along u (the thesis's mirror) and along v (a camera
    // turned on its side): the origin moves along the image of x, whichever axis that is
    // (it moved along u, which there images z).
    for keys in [
        "px_per_mm=2.1175\norigin_px=[121.0,144.0]\nu_axis=\"+x\"\nv_axis=\"+z\"",
        "px_per_mm=2.1175\norigin_px=[144.0,121.0]\nu_axis=\"+z\"\nv_axis=\"-x\"",
    ] {
        let view = config_view(ViewKind::Mirror, keys);
        assert!(view.aligned, "{keys}");
        let mut r = view.clone();
        assert!(r.rescale(1.01, 0.3));
        let q = r.solve(view.project(&p), Some(&scaled));
        assert!((q - scaled).norm() < 1e-12, "{keys}: {q} vs {scaled}");
    }
}

/// A view with a lens records each world point where the lens moves the map's image of it,
/// and solves a recorded point back to the world point exactly, for the shorthand, a matrix
/// and a pinhole; its local Jacobian is the recorded image's derivative.
#[test]
fn a_view_with_a_lens_projects_through_it_and_solves_back() {
    let lens = "lens_k1 = -0.05\nlens_centre_px = [119.5, 95.5]\nlens_radius_px = 153.7";
    let pinhole = pinhole_300mm_keys();
    let p = V3::new(30.0, -15.0, 4.0);
    for keys in [
        "px_per_mm=2.1576\norigin_px=[119.5,44.0]\nu_axis=\"+x\"\nv_axis=\"-y\"".to_string(),
        "matrix_px_per_mm=[[2.15, 0.05, 0.01],[0.05, -2.15, 0.0]]\norigin_px=[120.0,44.0]"
            .to_string(),
        pinhole,
    ] {
        let plain = config_view(ViewKind::Direct, &keys);
        let view = config_view(ViewKind::Direct, &format!("{keys}\n{lens}"));
        let (ideal, recorded) = (plain.project(&p), view.project(&p));
        let l = view.lens.unwrap();
        let want = l.distort(ideal);
        assert!((recorded[0] - want[0]).abs() < 1e-12 && (recorded[1] - want[1]).abs() < 1e-12);
        // About 0.9 px at this point: a shift the analysis works to a hundredth of.
        let moved = (recorded[0] - ideal[0]).hypot(recorded[1] - ideal[1]);
        assert!(moved > 0.5, "{keys}: moved {moved}");
        let q = view.solve(recorded, Some(&V3::new(0.0, 0.0, p.z)));
        assert!((q - p).norm() < 1e-9, "{keys}: {q} vs {p}");
        let (j, _) = view.local_at(&p);
        let h = 1e-4;
        for k in 0..3 {
            let mut dp = V3::zeros();
            dp[k] = h;
            let (a, b) = (view.project(&(p + dp)), view.project(&(p - dp)));
            for i in 0..2 {
                let fd = (a[i] - b[i]) / (2.0 * h);
                assert!(
                    (fd - j[(i, k)]).abs() < 1e-6,
                    "{keys}: ∂{i}/∂{k} {fd} vs {}",
                    j[(i, k)]
                );
            }
        }
        // A turned view keeps its lens.
        let turned = view.turned(&nalgebra::Matrix3::identity(), 1.0);
        assert_eq!(turned.lens, view.lens);
    }
}

#[test]
fn a_pinhole_view_projects_and_solves_exactly() {
    // 300 mm away along +z: closer points image larger about the principal point.
    let keys = pinhole_300mm_keys();
    let view = config_view(ViewKind::Direct, &keys);
    assert!((view.px_per_mm - 2.1576).abs() < 1e-12);
    assert_eq!(view.facing, V3::new(0.0, 0.0, 1.0));
    let p = V3::new(10.0, -5.0, 8.0);
    let px = view.project(&p);
    let scale = 300.0 / (300.0 - 8.0);
    assert!((px[0] - (119.5 + 2.1576 * 10.0 * scale)).abs() < 1e-9);
    let q = view.solve(px, Some(&V3::new(0.0, 0.0, 8.0)));
    assert!((q - p).norm() < 1e-9, "{q}");
}

/// A direct view's `projection` key: a pinhole 300 mm away along +z, 2.1576 px per mm at the
/// plane z = 0, its principal point at (119.5, 44.0).
fn pinhole_300mm_keys() -> String {
    let f = 2.1576 * 300.0;
    format!(
        "projection=[[{f}, 0.0, -119.5, {}],[0.0, {}, -44.0, {}],[0.0, 0.0, -1.0, 300.0]]",
        119.5 * 300.0,
        -f,
        44.0 * 300.0
    )
}
