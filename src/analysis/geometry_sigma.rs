//! The configured geometry's own uncertainty, carried into every estimate. The fits take the
//! config's maps as exact, but the maps come from a measurement (`impactcam calibrate`, a ruler,
//! a target) that knows them only so well. Where the config says how well
//! (`px_per_mm_uncertainty_percent`, `turn_uncertainty_deg`, which calibrate writes), each such
//! parameter is stepped by its σ, the analysis after the per-frame measurement is run again with
//! the stepped view, and each estimate's change is added to its variance. A config that says
//! nothing is taken as exact, as before; the recording's own checks of the geometry
//! (`calibration::check_geometry`) still warn when it is not.

use super::geometry::{View, ViewKind};
use super::report::{GeometryTerm, Report, Scalar, Vector};
use crate::config::Geometry;
use nalgebra::{Matrix3, Rotation3, Vector3};

/// One parameter of a view's map and its one-σ step.
#[derive(Clone, Debug)]
pub(super) struct Term {
    view: ViewKind,
    /// World axis the view is turned about, or None for its scale.
    axis: Option<usize>,
    /// The step: rad for a turn, a fraction for the scale.
    size: f64,
    /// The config key it comes from.
    key: String,
    /// The direct view's yaw stepped as the whole world's, every view turned with it
    /// (`turned_views`); its other term turns the direct view alone.
    whole_world: bool,
}

/// The parameters whose uncertainty the config gives (zeros left out).
pub(super) fn terms(geometry: &Geometry) -> Vec<Term> {
    let mut out = Vec::new();
    for (kind, name, v) in [
        (ViewKind::Direct, "direct", &geometry.direct),
        (ViewKind::Mirror, "mirror", &geometry.mirror),
    ] {
        let Some(v) = v else { continue };
        if let Some(p) = v.px_per_mm_uncertainty_percent.filter(|p| *p > 0.0) {
            out.push(Term {
                view: kind,
                axis: None,
                size: p / 100.0,
                key: format!("geometry.{name}.px_per_mm_uncertainty_percent"),
                whole_world: false,
            });
        }
        for (i, d) in v
            .turn_uncertainty_deg
            .unwrap_or_default()
            .iter()
            .enumerate()
        {
            if *d > 0.0 {
                out.push(Term {
                    view: kind,
                    axis: Some(i),
                    size: d.to_radians(),
                    key: format!("geometry.{name}.turn_uncertainty_deg[{i}]"),
                    whole_world: false,
                });
                // Only about the vertical: a turn about x or z would tilt gravity, which the
                // flights fix (calibrate's world has g along −y), so only the yaw is free.
                if kind == ViewKind::Direct && i == 1 {
                    out.push(Term {
                        view: kind,
                        axis: Some(i),
                        size: d.to_radians(),
                        key: format!("geometry.{name}.turn_uncertainty_deg[{i}], every view"),
                        whole_world: true,
                    });
                }
            }
        }
    }
    out
}

/// Every view through the general map, the one `term` names turned by its step (none turned
/// without a term: the baseline the turned runs are compared with). The direct view's turn
/// about the vertical (y) is stepped twice (`terms`): alone, and with every view turned by it
/// (`Term::whole_world`). Why both: the direct camera's yaw is both how it lies against the
/// mirror, which moves e and ψ as the views then disagree, and how the world the maps describe
/// lies about the vertical (calibrate takes the camera as square, 0 ± `DIRECT_SQUARE_DEG`, and
/// fits the mirror to it), which turns the velocities and spins, x into z. With the direct
/// view's step alone, on rigs whose direct camera was yawed by 1–1.6°, calibrated, the z
/// velocities came out 8–16 mm/s off with σ about 1 mm/s; with the world's step alone, e came
/// out up to 4.4σ off (docs/accuracy.md, session 48). A pitch shears z into y instead, and
/// gravity fixes the world's vertical: its velocities' errors followed x, not y.
pub(super) fn turned_views(views: &[View], term: Option<&Term>) -> Vec<View> {
    views
        .iter()
        .map(|v| {
            let (r, scale) = match term {
                Some(t) if t.view == v.kind || t.whole_world => match t.axis {
                    Some(i) => {
                        let axis = Vector3::ith_axis(i);
                        (Rotation3::from_axis_angle(&axis, t.size).into_inner(), 1.0)
                    }
                    None => (Matrix3::identity(), 1.0 + t.size),
                },
                _ => (Matrix3::identity(), 1.0),
            };
            v.turned(&r, scale)
        })
        .collect()
}

/// Adds to each estimate's variance the squared change each turned run made to it (against
/// the unturned run through the same formulas), and records the terms in the calibration.
/// A run that failed, or an estimate one run lacks, adds nothing for that term.
pub(super) fn widen(
    report: &mut Report,
    terms: &[Term],
    baseline: &Report,
    turned: &[Option<Report>],
) {
    let zero = values(baseline);
    let runs: Vec<Option<Vec<Option<f64>>>> =
        turned.iter().map(|r| r.as_ref().map(values)).collect();
    let shift = |k: usize, i: usize| -> Option<f64> {
        let t = runs.get(k)?.as_ref()?;
        let d = t.get(i).copied().flatten()? - zero.get(i).copied().flatten()?;
        d.is_finite().then_some(d)
    };
    let mut i = 0;
    visit(report, &mut |e| {
        if let Some((_, sigma)) = e {
            let extra: f64 = (0..runs.len())
                .filter_map(|k| shift(k, i))
                .map(|d| d * d)
                .sum();
            *sigma = (*sigma * *sigma + extra).sqrt();
        }
        i += 1;
    });
    // Index of e among the visited components: impact time, then the normal's three.
    let e_index = 4;
    if let Some(c) = report.quality.calibration.as_mut() {
        c.geometry_uncertainty = terms
            .iter()
            .enumerate()
            .map(|(k, t)| GeometryTerm {
                parameter: t.key.clone(),
                step: t.size,
                e_change: shift(k, e_index).map(f64::abs),
            })
            .collect();
    }
}

/// Every estimate's value in the fixed order `visit` walks them (None where it is null).
fn values(r: &Report) -> Vec<Option<f64>> {
    let mut r = r.clone();
    let mut out = Vec::new();
    visit(&mut r, &mut |e| out.push(e.map(|(v, _)| *v)));
    out
}

type Visitor<'a> = dyn FnMut(Option<(&mut f64, &mut f64)>) + 'a;

/// Walks every estimate component of a report in a fixed order, a null one as None (one call
/// per component it would have), so that two reports' walks line up.
fn visit(r: &mut Report, f: &mut Visitor) {
    fn scalar(e: Option<&mut Scalar>, f: &mut Visitor) {
        f(e.map(|e| (&mut e.value, &mut e.uncertainty)));
    }
    fn vector(e: Option<&mut Vector>, f: &mut Visitor) {
        match e {
            Some(e) => {
                for (v, s) in e.value.iter_mut().zip(e.uncertainty.iter_mut()) {
                    f(Some((v, s)));
                }
            }
            None => (0..3).for_each(|_| f(None)),
        }
    }
    scalar(Some(&mut r.impact.time_s), f);
    vector(Some(&mut r.normal), f);
    scalar(r.e.as_mut(), f);
    scalar(r.beta.as_mut(), f);
    scalar(r.psi1.as_mut(), f);
    scalar(r.psi2.as_mut(), f);
    for s in [&mut r.spheres.a, &mut r.spheres.b] {
        vector(s.position_impact_mm.as_mut(), f);
        vector(Some(&mut s.velocity_pre_mm_s), f);
        vector(Some(&mut s.velocity_post_mm_s), f);
        vector(s.spin_pre_rad_s.as_mut(), f);
        vector(s.spin_post_rad_s.as_mut(), f);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;

    #[test]
    fn the_configs_uncertainties_become_steps_and_a_step_turns_the_world_the_view_sees() {
        let mut cfg = Config::default_config();
        let direct = cfg.geometry.direct.as_mut().unwrap();
        direct.px_per_mm_uncertainty_percent = Some(0.5);
        direct.turn_uncertainty_deg = Some([0.0, 0.2, 0.0]);
        cfg.geometry.mirror.as_mut().unwrap().turn_uncertainty_deg = Some([0.3, 0.0, 0.0]);
        let terms = terms(&cfg.geometry);
        let keys: Vec<&str> = terms.iter().map(|t| t.key.as_str()).collect();
        assert_eq!(
            keys,
            [
                "geometry.direct.px_per_mm_uncertainty_percent",
                "geometry.direct.turn_uncertainty_deg[1]",
                "geometry.direct.turn_uncertainty_deg[1], every view",
                "geometry.mirror.turn_uncertainty_deg[0]",
            ]
        );
        assert!((terms[0].size - 0.005).abs() < 1e-15);
        assert!((terms[1].size - 0.2f64.to_radians()).abs() < 1e-15);

        let views = super::super::geometry::views(&cfg);
        let p = nalgebra::Vector3::new(7.0, -3.0, 2.0);
        // Unturned through the general map: where the shorthand puts every point.
        for (a, b) in views.iter().zip(turned_views(&views, None)) {
            let (x, y) = (a.project(&p), b.project(&p));
            assert!((x[0] - y[0]).abs() < 1e-9 && (x[1] - y[1]).abs() < 1e-9);
        }
        // The direct view's yaw's steps: the direct view alone sees the world turned about
        // y; then every view does (the direct camera's yaw is how the world lies about the
        // vertical too).
        let r = Rotation3::from_axis_angle(&Vector3::y_axis(), 0.2f64.to_radians());
        let turned = turned_views(&views, Some(&terms[1]));
        let (want, got) = (views[0].project(&(r * p)), turned[0].project(&p));
        assert!((want[0] - got[0]).abs() < 1e-9 && (want[1] - got[1]).abs() < 1e-9);
        assert!(
            (want[0] - views[0].project(&p)[0]).abs() > 1e-3,
            "the step moves it"
        );
        let (m0, m1) = (views[1].project(&p), turned[1].project(&p));
        assert!((m0[0] - m1[0]).abs() < 1e-9 && (m0[1] - m1[1]).abs() < 1e-9);
        let turned = turned_views(&views, Some(&terms[2]));
        for (v, t) in views.iter().zip(&turned) {
            let (want, got) = (v.project(&(r * p)), t.project(&p));
            assert!((want[0] - got[0]).abs() < 1e-9 && (want[1] - got[1]).abs() < 1e-9);
            assert!(
                (want[0] - v.project(&p)[0]).abs() + (want[1] - v.project(&p)[1]).abs() > 1e-3,
                "the step moves it"
            );
        }
        // The mirror's own turn: the mirror alone.
        let turned = turned_views(&views, Some(&terms[3]));
        let r = Rotation3::from_axis_angle(&Vector3::x_axis(), 0.3f64.to_radians());
        let (want, got) = (views[1].project(&(r * p)), turned[1].project(&p));
        assert!((want[0] - got[0]).abs() < 1e-9 && (want[1] - got[1]).abs() < 1e-9);
        let (d0, d1) = (views[0].project(&p), turned[0].project(&p));
        assert!((d0[0] - d1[0]).abs() < 1e-9 && (d0[1] - d1[1]).abs() < 1e-9);
        // The scale's step.
        let scaled = turned_views(&views, Some(&terms[0]));
        let (want, got) = (views[0].project(&(p * 1.005)), scaled[0].project(&p));
        assert!((want[0] - got[0]).abs() < 1e-9 && (want[1] - got[1]).abs() < 1e-9);
    }
}
