use super::*;

/// Sightings of markers on a sphere of radius 3.175 mm spinning at `omega`, each marker seen
/// only while on the hemisphere facing +z and `visible(frame, marker)` allows, with
/// independent noise of `noise_mm` on each coordinate.
fn sightings(
    omega: V3,
    markers: &[V3],
    frames: usize,
    noise_mm: f64,
    visible: &dyn Fn(usize, usize) -> bool,
    rng: &mut hw_sim::Rng,
) -> Vec<Sighting> {
    let mut out = Vec::new();
    for k in 0..frames {
        let t = k as f64 * 1e-3;
        let r = Rotation3::from_scaled_axis(omega * t);
        for (m, p) in markers.iter().enumerate() {
            let q = r * p;
            if q.z > 0.5 && visible(k, m) {
                let e = V3::new(rng.gaussian(), rng.gaussian(), rng.gaussian()) * noise_mm;
                out.push(Sighting {
                    frame: k,
                    time_s: t,
                    track: (0, m),
                    rel_mm: q + e,
                    weight: 1.0,
                    toward: V3::z(),
                });
            }
        }
    }
    out
}

fn on_sphere(dirs: &[[f64; 3]]) -> Vec<V3> {
    dirs.iter()
        .map(|d| V3::from(*d).normalize() * 3.175)
        .collect()
}

/// One marker a frame, never two in the same frame: no frame pair shares two markers, so
/// the pair fit has nothing, and the arcs alone must give ω to within a few σ.
#[test]
fn one_marker_a_frame_gives_the_spin() {
    let omega = V3::new(-14.0, 12.0, 230.0);
    let markers = on_sphere(&[[0.3, 0.2, 1.0], [-0.5, 0.4, 0.8], [0.1, -0.6, 0.7]]);
    let mut rng = hw_sim::Rng::new(3);
    // Marker m shows in frames m, m + 3, m + 6, …: one at a time.
    let s = sightings(omega, &markers, 30, 0.0, &|k, m| k % 3 == m, &mut rng);
    let per_frame = |k: usize| s.iter().filter(|x| x.frame == k).count();
    assert!((0..30).all(|k| per_frame(k) <= 1));
    let fit = fit(&s, V3::zeros(), model_sources(0, 0)).expect("three tracks over 30 frames");
    assert!((fit.omega - omega).norm() < 1e-6, "{:?}", fit.omega);
}

/// Errors of the fitted ω in σ (each component), over 300 draws of five markers seen for
/// 4–9 frames each (tracks that come and go), with independent noise of `noise_mm` and,
/// per track, an offset drifting linearly along it by `drift_mm` a frame; and how many
/// draws gave a fit.
fn z_scores(seed: u64, noise_mm: f64, drift_mm: f64) -> (Vec<f64>, usize) {
    let omega = V3::new(20.0, -35.0, 180.0);
    let markers = on_sphere(&[
        [0.3, 0.2, 1.0],
        [-0.5, 0.4, 0.8],
        [0.1, -0.6, 0.7],
        [0.7, 0.1, 0.4],
        [-0.2, -0.3, 0.9],
    ]);
    let mut rng = hw_sim::Rng::new(seed);
    let (mut z, mut fitted) = (Vec::new(), 0);
    for trial in 0..TRIALS {
        let phase = trial % 7;
        let mut s = sightings(
            omega,
            &markers,
            24,
            noise_mm,
            &|k, m| (k + 3 * m + phase) % 11 < 4 + m,
            &mut rng,
        );
        if drift_mm > 0.0 {
            let drift: Vec<V3> = (0..markers.len())
                .map(|_| V3::new(rng.gaussian(), rng.gaussian(), rng.gaussian()) * drift_mm)
                .collect();
            for x in s.iter_mut() {
                x.rel_mm += drift[x.track.1] * x.frame as f64;
            }
        }
        let Some(fit) = fit(&s, V3::zeros(), model_sources(0, 0)) else {
            continue;
        };
        fitted += 1;
        z.extend((0..3).map(|i| (fit.omega[i] - omega[i]) / fit.cov[(i, i)].sqrt()));
    }
    (z, fitted)
}

const TRIALS: usize = 300;

fn share(z: &[f64], within: f64) -> f64 {
    z.iter().filter(|x| x.abs() <= within).count() as f64 / z.len() as f64
}

fn beyond(z: &[f64], k: f64) -> usize {
    z.iter().filter(|x| x.abs() > k).count()
}

/// With noise, ±1σ covers the true ω about as often as it should and nothing lands beyond
/// 5σ, on tracks that come and go (markers seen for 4–9 frames).
#[test]
fn the_covariance_covers_noisy_tracks() {
    let (z, fitted) = z_scores(17, 0.04, 0.0);
    assert!(fitted >= TRIALS * 9 / 10, "fitted {fitted} of {TRIALS}");
    let coverage = share(&z, 1.0);
    assert!((0.55..=0.85).contains(&coverage), "±1σ coverage {coverage}");
    assert_eq!(beyond(&z, 5.0), 0);
}

/// A marker's mislocation drifts along its track (it crosses the shading): each track's
/// sightings err together, by an offset that grows along the track (0.005 mm a frame).
/// Clustered by frame alone, the covariance misses that and puts errors far beyond 5σ;
/// clustered by frame and by track it must not.
#[test]
fn errors_shared_along_a_track_are_covered() {
    let (z, fitted) = z_scores(29, 0.01, 0.005);
    assert!(fitted >= TRIALS * 9 / 10, "fitted {fitted} of {TRIALS}");
    let coverage = share(&z, 1.0);
    assert!(coverage >= 0.55, "±1σ coverage {coverage}");
    assert!(
        beyond(&z, 5.0) <= z.len() / 200,
        "{} of {} beyond 5σ",
        beyond(&z, 5.0),
        z.len()
    );
}

/// One marker seen for 16 frames is one track's worth, one for 11 and another for 3 is
/// 1.5, two of 12 sightings each are two; sightings of a track seen twice do not count.
#[test]
fn the_tracks_a_spin_rests_on_are_counted() {
    let omega = V3::new(-5.0, 12.0, 108.0);
    let markers = on_sphere(&[[0.3, 0.2, 1.0], [-0.5, 0.4, 0.8]]);
    let mut rng = hw_sim::Rng::new(7);
    let one = sightings(omega, &markers, 16, 0.01, &|_, m| m == 0, &mut rng);
    assert_eq!(effective_tracks(&one), 1.0);
    let lopsided = sightings(omega, &markers, 11, 0.01, &|k, m| m == 0 || k < 3, &mut rng);
    assert_eq!(
        effective_tracks(&lopsided),
        14.0 * 14.0 / (11.0 * 11.0 + 9.0)
    );
    let two = sightings(omega, &markers, 12, 0.01, &|_, _| true, &mut rng);
    assert_eq!(effective_tracks(&two), 2.0);
    let short = sightings(omega, &markers, 12, 0.01, &|k, m| m == 0 || k < 2, &mut rng);
    assert_eq!(effective_tracks(&short), 1.0);
}

/// Each sighting found in the image `shift_mm` off (across the line of sight, +z) and a
/// factor `scale` further from the centre than it is, then lifted again onto the sphere as
/// `markers::lift` does: what a disc centre biased by the light, and dots found a little
/// outward, do to the lifted points.
fn found_off(s: &mut [Sighting], shift_mm: V3, scale: f64) {
    for x in s.iter_mut() {
        let radius = x.rel_mm.norm();
        let across = V3::new(x.rel_mm.x, x.rel_mm.y, 0.0) * scale + shift_mm;
        let depth = (radius * radius - across.norm_squared()).max(0.0).sqrt();
        x.rel_mm = across + V3::z() * depth;
    }
}

/// All of a view's markers found 0.03 mm off the centre in the image and 2 % further out
/// (a disc centre biased by the light, dots pushed outward along the shading), then lifted:
/// without the offset in the model the spin axis tilts and ω lands many σ off across it;
/// with a constant 3-D offset still beyond 5σ (the lift turns a shift in the image into
/// depths that differ from dot to dot); with the lift's own Jacobian, within a few σ.
#[test]
fn markers_found_off_centre_in_the_image_do_not_tilt_the_axis() {
    let omega = V3::new(7.0, -3.0, 185.0);
    let markers = on_sphere(&[
        [0.3, 0.2, 1.0],
        [-0.5, 0.4, 0.8],
        [0.1, -0.6, 0.7],
        [0.7, 0.1, 0.4],
        [-0.2, -0.3, 0.9],
        [0.5, -0.5, 0.6],
    ]);
    let mut rng = hw_sim::Rng::new(41);
    let mut s = sightings(
        omega,
        &markers,
        30,
        0.01,
        &|k, m| (k + 2 * m) % 9 < 6,
        &mut rng,
    );
    found_off(&mut s, V3::new(0.03, -0.02, 0.0), 1.02);
    let worst_z = |f: &SpinFit| {
        (0..3)
            .map(|i| ((f.omega[i] - omega[i]) / f.cov[(i, i)].sqrt()).abs())
            .fold(0.0, f64::max)
    };
    let without = fit_with(&s, V3::zeros(), Offsets::None).expect("enough tracks");
    let with = fit(&s, V3::zeros(), model_sources(0, 0)).expect("enough tracks");
    assert!(
        worst_z(&without) > 5.0,
        "without offsets: {}",
        worst_z(&without)
    );
    // A constant 3-D offset alone (J = I) is no cure; the lifted model's disagreement with
    // it, added to the reported covariance, keeps the reported ω within a few σ.
    let constant = fit_with(&s, V3::zeros(), Offsets::Constant).expect("enough tracks");
    assert!(
        worst_z(&constant) > 5.0,
        "constant 3-D offset: {}",
        worst_z(&constant)
    );
    let lifted = fit_with(&s, V3::zeros(), Offsets::Lifted).expect("enough tracks");
    assert!(worst_z(&lifted) < 3.0, "lifted offsets: {:?}", lifted.omega);
    assert!(worst_z(&with) < 3.0, "reported: {:?}", with.omega);
    // The dots' carry leaves the lifted model's term out, and only that.
    let carry = cov_for_carry(&with);
    let lifted_terms: Vec<&V3> = with
        .frame_influence
        .iter()
        .filter(|(k, _)| *k == model_sources(0, 0)[1])
        .map(|(_, r)| r)
        .collect();
    assert_eq!(lifted_terms.len(), 1, "the lifted model's term is there");
    let back = carry + lifted_terms[0] * lifted_terms[0].transpose();
    assert!((back - with.cov).norm() <= 1e-12 * with.cov.norm());
    assert!(carry.trace() < with.cov.trace());
    // The reported σ also covers the two models' disagreement, whichever is right.
    for i in 0..3 {
        let apart = (with.omega[i] - without.omega[i]).abs();
        assert!(
            apart <= 2.0 * with.cov[(i, i)].sqrt(),
            "axis {i}: the models differ by {apart}, σ {}",
            with.cov[(i, i)].sqrt()
        );
    }
}
