//! Whether each view sees the hemisphere of a sphere its config says it does.
//!
//! A view's map (`[u, v] = M·p + origin`) does not say which side of the scene its camera is
//! on: a camera in front whose image is flipped and a camera behind give the same map. What
//! decides is whether the image is mirrored (`image_mirrored`: by default the mirror view's is
//! and the direct view's is not), and that decides the depth each marker is lifted to. Lifted
//! to the wrong hemisphere, one view's markers turn as the reflection of the sphere's spin.
//! Each view alone cannot tell (the reflected spin explains its own tracks exactly), but the
//! two views then disagree about one spin, and the spin fit settles between them with a σ
//! from the tracks' scatter: on the independent renders flipped left to right and analysed
//! with the default, spins came out 70 rad/s off at 34σ; and five of the eight renders have a
//! mirror view that is not a mirror image, where the default lifted its markers to the wrong
//! side (docs/accuracy.md, session 46).
//!
//! So each phase's sightings, of both views, are fitted with one constant ω as lifted and with
//! either view's (or both views') depths reflected, and the misfits summed over the phases
//! compared. Where another way fits clearly better, the markers are lifted that way and the
//! report warns, naming the key to set: a lab whose config is wrong gets the spins its markers
//! show, and is told. Where another way fits only somewhat better (a view with one dot track a
//! phase hardly constrains the spin), the spins stay as configured, each σ widened by its
//! difference from the other way's spin, and the report says so.

use super::geometry::View;
use super::spin::SpinMeasurement;
use super::spin_tracks::{self, Sighting};
use super::tracking::FrameObs;
use nalgebra::Vector3;

type V3 = Vector3<f64>;

/// How much smaller the summed misfit of another handedness must be than the configured one's
/// for the configured one to be called wrong. Measured (docs/accuracy.md, session 46): on the
/// 190 varied-look hw-sim recordings, every look family, whose configs are right, the
/// configured one's misfit was never above 1.03× the best other's (median 0.49×); on the
/// eight independent renders rightly configured, at most 0.93×; on 21 wrongly configured ones
/// (the renders with the mirror's default where its image is not mirrored, flipped left to
/// right, each view upside down), 1.06–36×, the best other being the truth in every one. A
/// marker track mislocated or wrongly assigned costs every way alike, so a wrong handedness
/// shows as a ratio, not noise.
const CLEARLY_BETTER: f64 = 1.5;

/// Below `CLEARLY_BETTER` and above this, the markers cannot tell which way is right: another
/// way fits somewhat better (the flipped renders whose mirror view has one dot track a phase:
/// 1.15–1.49×, their spins 2–34σ off as configured), where a right config never did better
/// than 1.03× (above). The spins are then reported as configured, each widened by its
/// difference from the spin the other way gives, and the report says so.
const IN_DOUBT: f64 = 1.1;

/// The index of the doubt's term among a spin's error sources (`SpinFit::frame_influence`):
/// one for all four phases, since one fact (which side a view sees) moves them all; far from
/// every frame's, model term's and impulse term's index.
const DOUBT_SOURCE: usize = usize::MAX / 4;

/// The fewest tracks (`spin_tracks::effective_tracks`) each view must have in a phase for that
/// phase to take part: one view's tracks alone cannot tell, and one track of three sightings
/// or more draws an arc whose sense of turn the other view's must share.
const MIN_TRACKS_PER_VIEW: f64 = 1.0;

/// What the markers say about the views' handedness.
#[derive(Clone, Debug, PartialEq)]
pub struct Verdict {
    /// Which views' hemispheres fitted best reflected (by view index).
    pub reflected: Vec<usize>,
    /// The configured handedness's summed misfit over the best one's.
    pub misfit_ratio: f64,
}

impl Verdict {
    /// The markers clearly turn the other way (`CLEARLY_BETTER`): they are lifted so. Else the
    /// verdict is a doubt, carried in the spins' σ (`widen_by_doubt`).
    pub fn clear(&self) -> bool {
        self.misfit_ratio > CLEARLY_BETTER
    }
}

/// Compares the configured handedness with the others on the measured phases' sightings.
/// None where no phase has enough tracks in two views, or where the configured one fits as
/// well as any other (within `IN_DOUBT`).
pub fn check(measured: &[SpinMeasurement], views: &[View]) -> Option<Verdict> {
    if views.len() != 2 {
        return None;
    }
    // Summed misfits of: as lifted, view 0 reflected, view 1 reflected, both.
    let mut sums = [0.0f64; 4];
    let mut phases = 0;
    for m in measured {
        let per_view = |v: usize| {
            let own: Vec<Sighting> = m
                .sightings
                .iter()
                .filter(|s| s.track.0 == v)
                .copied()
                .collect();
            spin_tracks::effective_tracks(&own)
        };
        if per_view(0) < MIN_TRACKS_PER_VIEW || per_view(1) < MIN_TRACKS_PER_VIEW {
            continue;
        }
        let omega = m.fit.as_ref().map_or(V3::zeros(), |f| f.omega);
        let mut costs = [0.0; 4];
        let mut ok = true;
        for (h, cost) in costs.iter_mut().enumerate() {
            let flip = [h & 1 != 0, h & 2 != 0];
            let lifted: Vec<Sighting> = m
                .sightings
                .iter()
                .map(|s| {
                    if flip.get(s.track.0).copied().unwrap_or(false) {
                        reflected(s)
                    } else {
                        *s
                    }
                })
                .collect();
            // Starts: the linear one `misfit` makes from the sightings themselves (no guess,
            // so as good for a reflected view's tracks as for the others) and the measured spin.
            let starts = [omega];
            match spin_tracks::misfit(&lifted, &starts) {
                Some(c) if c.is_finite() => *cost = c,
                _ => ok = false,
            }
        }
        if ok {
            phases += 1;
            for (s, c) in sums.iter_mut().zip(costs) {
                *s += c;
            }
        }
    }
    if phases == 0 {
        return None;
    }
    let (best, best_sum) = (1..4)
        .map(|h| (h, sums[h]))
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    (sums[0] > IN_DOUBT * best_sum).then(|| Verdict {
        reflected: (0..2).filter(|v| best & (1 << v) != 0).collect(),
        misfit_ratio: sums[0] / best_sum.max(f64::MIN_POSITIVE),
    })
}

/// The sighting lifted to the other hemisphere of its view: its depth along the line of sight
/// reversed.
fn reflected(s: &Sighting) -> Sighting {
    let t = s.toward;
    Sighting {
        rel_mm: s.rel_mm - t * (2.0 * s.rel_mm.dot(&t)),
        toward: -t,
        ..*s
    }
}

/// The views with the verdict's reflected ones seeing the other hemisphere: their markers
/// lifted the other way.
pub fn reflected_views(views: &[View], verdict: &Verdict) -> Vec<View> {
    let mut out = views.to_vec();
    for &i in &verdict.reflected {
        if let Some(v) = out.get_mut(i) {
            v.facing = -v.facing;
            v.mirrored = !v.mirrored;
        }
    }
    out
}

/// Each spin measured as configured widened by its difference from the same phase's spin
/// measured with the doubted views' markers on the other side (`other`), as one more error
/// source shared by the four phases: the markers do not settle which it is.
pub fn widen_by_doubt(measured: &mut [SpinMeasurement], other: &[SpinMeasurement]) {
    for (m, o) in measured.iter_mut().zip(other) {
        if let (Some(fit), Some(alt)) = (m.fit.as_mut(), o.fit.as_ref()) {
            let d = alt.omega - fit.omega;
            if d.iter().all(|x| x.is_finite()) {
                fit.cov += d * d.transpose();
                fit.frame_influence.push((DOUBT_SOURCE, d));
            }
        }
    }
}

/// The frames' markers as the verdict's reflected views would have lifted them: each one's
/// depth along its line of sight reversed. The same as lifting them again (the lift is
/// √(R² − ρ²) along the line of sight, which a reflection only turns round).
pub fn reflect_markers(obs: &mut [FrameObs], verdict: &Verdict) {
    for f in obs.iter_mut() {
        for sphere in f.spheres.iter_mut() {
            for &vi in &verdict.reflected {
                let Some(Some(m)) = sphere.get_mut(vi) else {
                    continue;
                };
                for mk in m.markers.iter_mut() {
                    let t = mk.toward;
                    mk.rel_mm -= t * (2.0 * mk.rel_mm.dot(&t));
                    mk.toward = -t;
                }
            }
        }
    }
}

/// The warning for a verdict, naming the key that would settle it.
pub fn warning(v: &Verdict, views: &[View]) -> String {
    let named: Vec<&View> = v.reflected.iter().filter_map(|&i| views.get(i)).collect();
    let seen: Vec<String> = named
        .iter()
        .map(|view| {
            format!(
                "the {} view's image were {}mirrored",
                view.kind.name(),
                if view.mirrored { "not " } else { "" }
            )
        })
        .collect();
    let keys: Vec<String> = named
        .iter()
        .map(|view| {
            format!(
                "geometry.{}.image_mirrored = {}",
                view.kind.name(),
                !view.mirrored
            )
        })
        .collect();
    if v.clear() {
        format!(
            "the markers turn as if {} (one rigid turn fits both views' marker tracks {:.1}x better so), and the spins are measured so: if it is, set {}; if not, check the views' maps",
            seen.join(" and "),
            v.misfit_ratio,
            keys.join(" and ")
        )
    } else {
        format!(
            "the markers cannot tell whether {} (one rigid turn fits both views' marker tracks {:.1}x better so, which does not settle it): each spin's σ includes its difference from the spin measured so; if it is, set {}",
            seen.join(" and "),
            v.misfit_ratio,
            keys.join(" and ")
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::geometry::views;
    use crate::config::Config;
    use nalgebra::Rotation3;

    /// Four phases of a 6.35 mm sphere turning at ω, twelve dots spread over it, each sighting
    /// in every view whose camera it faces (away from the limb), with a few µm of noise across
    /// the line of sight; the views in `reflect` lift theirs to the hemisphere they do not see.
    fn phases(omega: V3, views: &[View], reflect: &[usize]) -> Vec<SpinMeasurement> {
        let r = 3.175;
        let mut sightings = Vec::new();
        for j in 0..12 {
            let z = 1.0 - (j as f64 + 0.5) / 6.0;
            let phi = j as f64 * 2.399_963;
            let p = V3::new(
                (1.0 - z * z).sqrt() * phi.cos(),
                (1.0 - z * z).sqrt() * phi.sin(),
                z,
            ) * r;
            for k in 0..15 {
                let t = k as f64 * 1e-3;
                let q = Rotation3::from_scaled_axis(omega * t) * p;
                for (vi, v) in views.iter().enumerate() {
                    let f = v.facing;
                    if q.dot(&f) <= 0.3 * r {
                        continue;
                    }
                    let wobble = V3::new(
                        ((j * 7 + k * 3 + vi) % 5) as f64 - 2.0,
                        ((j * 3 + k * 5 + 2 * vi) % 5) as f64 - 2.0,
                        ((j + k * 2 + vi) % 5) as f64 - 2.0,
                    ) * 0.004;
                    let noise = wobble - f * wobble.dot(&f);
                    let (rel, toward) = if reflect.contains(&vi) {
                        (q - f * (2.0 * q.dot(&f)), -f)
                    } else {
                        (q, f)
                    };
                    sightings.push(Sighting {
                        frame: k,
                        time_s: t,
                        track: (vi, j),
                        rel_mm: rel + noise,
                        weight: 1.0,
                        toward,
                    });
                }
            }
        }
        sightings.sort_by_key(|s| (s.frame, s.track));
        (0..4)
            .map(|_| SpinMeasurement {
                sightings: sightings.clone(),
                ..Default::default()
            })
            .collect()
    }

    /// Lifted as the views see, nothing is said; with a view's (or both views') markers on the
    /// wrong side, the check names that view (those views), whatever the spin's axis.
    #[test]
    fn a_view_lifting_its_markers_to_the_far_hemisphere_is_named() {
        let v = views(&Config::default_config());
        for omega in [
            V3::new(40.0, -30.0, 80.0),
            V3::new(-60.0, 10.0, 25.0),
            V3::new(15.0, 70.0, -40.0),
        ] {
            assert_eq!(check(&phases(omega, &v, &[]), &v), None, "ω {omega:?}");
            for reflect in [vec![0], vec![1], vec![0, 1]] {
                let verdict = check(&phases(omega, &v, &reflect), &v)
                    .unwrap_or_else(|| panic!("ω {omega:?}, {reflect:?} reflected: not seen"));
                assert_eq!(verdict.reflected, reflect, "ω {omega:?}");
                assert!(verdict.misfit_ratio > CLEARLY_BETTER);
            }
        }
    }

    /// A doubt widens each spin by its difference from the other way's, as one error source
    /// the four phases share; a clear verdict is no doubt.
    #[test]
    fn a_doubt_widens_each_spin_by_the_other_ways() {
        use crate::analysis::rotation::SpinFit;
        let fit = |w: V3| SpinMeasurement {
            fit: Some(SpinFit {
                omega: w,
                cov: nalgebra::Matrix3::identity(),
                pairs: 0,
                frame_influence: vec![(0, V3::new(1.0, 0.0, 0.0))],
            }),
            ..Default::default()
        };
        let mut measured = vec![fit(V3::new(1.0, 2.0, 3.0)), SpinMeasurement::default()];
        let other = vec![fit(V3::new(1.0, 2.0, -27.0)), fit(V3::zeros())];
        widen_by_doubt(&mut measured, &other);
        let widened = measured[0].fit.as_ref().unwrap();
        assert_eq!(widened.cov[(2, 2)], 1.0 + 900.0);
        assert_eq!(widened.cov[(0, 0)], 1.0);
        assert_eq!(
            widened.frame_influence.last(),
            Some(&(DOUBT_SOURCE, V3::new(0.0, 0.0, -30.0)))
        );
        assert!(measured[1].fit.is_none());
        let doubt = |r: f64| Verdict {
            reflected: vec![1],
            misfit_ratio: r,
        };
        assert!(!doubt(1.2).clear() && doubt(2.0).clear());
        let w = warning(&doubt(1.2), &views(&Config::default_config()));
        assert!(
            w.contains("cannot tell") && w.contains("image_mirrored = false"),
            "{w}"
        );
    }

    /// The views the verdict names see the other hemisphere, and the warning names the key
    /// that says so.
    #[test]
    fn reflected_views_see_the_other_hemisphere_and_the_warning_names_the_key() {
        let v = views(&Config::default_config());
        let verdict = Verdict {
            reflected: vec![1],
            misfit_ratio: 2.0,
        };
        let turned = reflected_views(&v, &verdict);
        assert_eq!(turned[0].facing, v[0].facing);
        assert_eq!(turned[1].facing, -v[1].facing);
        assert_eq!(turned[1].mirrored, !v[1].mirrored);
        let w = warning(&verdict, &v);
        assert!(w.contains("geometry.mirror.image_mirrored = false"), "{w}");
    }
}
