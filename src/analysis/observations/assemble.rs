//! The report put together from what the steps before measured: estimates with their σ, each
//! sphere's results, the per-frame tracks and the quality section.

use super::super::geometry::{View, ViewKind};
use super::super::kinematics::{self, Derived, Fits, SideFit, V3};
use super::super::report::*;
use super::super::tracking::FrameObs;
use super::super::uncertainty::spin_estimate;
use super::spins::PhaseSpins;

/// Everything the report is made of.
pub(super) struct Parts<'a> {
    pub(super) info: Source,
    pub(super) views: &'a [View],
    pub(super) obs: &'a [FrameObs],
    pub(super) fits: &'a Fits,
    pub(super) derived: &'a Derived,
    /// The σ of each of `derived`'s members.
    pub(super) sigma: &'a Derived,
    /// Where the phases were split, s on the source's clock (the fits' reference time).
    pub(super) split: f64,
    /// Gravity, mm/s².
    pub(super) g: f64,
    pub(super) contact_mm: f64,
    pub(super) three_d: bool,
    pub(super) beta: Option<Scalar>,
    pub(super) spins: &'a PhaseSpins,
    pub(super) frames_dropped: u64,
    pub(super) calibration: Option<Calibration>,
    pub(super) unmeasured: Vec<Unmeasured>,
    pub(super) warnings: Vec<String>,
}

fn est3(v: V3, s: V3) -> Estimate<[f64; 3]> {
    Estimate {
        value: [v.x, v.y, v.z],
        uncertainty: [s.x, s.y, s.z],
    }
}

/// 3-D RMS distance of the centres from the fitted trajectory, mm.
fn rms(f: &SideFit) -> f64 {
    f.axes
        .iter()
        .flatten()
        .map(|l| l.rms * l.rms)
        .sum::<f64>()
        .sqrt()
}

/// Which Walton branch the data suggest, from the sign of ψ2 alone: sliding keeps the slip's
/// direction (ψ2 > 0 unless just above the break point), sticking with β0 > 0 reverses it. Null
/// when ψ2 is within two standard deviations of zero.
fn branch_hint(psi2: f64, sigma: f64) -> Option<String> {
    if psi2.abs() <= 2.0 * sigma {
        None
    } else if psi2 > 0.0 {
        Some("sliding".into())
    } else {
        Some("sticking".into())
    }
}

fn has_a_sphere(f: &FrameObs) -> bool {
    f.spheres.iter().any(|s| s.iter().any(|m| m.is_some()))
}

impl Parts<'_> {
    /// Sphere `s`'s imaged diameter in the `kind` view: the median over the frames, σ from the
    /// median deviation.
    fn diameters(&self, s: usize, kind: ViewKind) -> Option<Scalar> {
        let vi = self.views.iter().position(|v| v.kind == kind)?;
        let mut ds: Vec<f64> = self
            .obs
            .iter()
            .filter_map(|f| f.spheres[s][vi].as_ref().map(|m| m.diameter_px))
            .collect();
        if ds.is_empty() {
            return None;
        }
        ds.sort_by(f64::total_cmp);
        let med = ds[ds.len() / 2];
        let mut dev: Vec<f64> = ds.iter().map(|x| (x - med).abs()).collect();
        dev.sort_by(f64::total_cmp);
        let sigma = 1.4826 * dev[dev.len() / 2];
        Some(Estimate {
            value: med,
            uncertainty: sigma / (ds.len() as f64).sqrt(),
        })
    }

    fn position_at_impact(&self, s: usize) -> Estimate<[f64; 3]> {
        let fit = &self.fits[s];
        let p = kinematics::pos_vel(fit, self.derived.tau_c, self.g).0;
        let sd = |i: usize| {
            fit.axes[i]
                .map(|l| l.cov[(0, 0)].max(0.0).sqrt())
                .unwrap_or(0.0)
        };
        Estimate {
            value: [p.x, p.y, p.z],
            uncertainty: [sd(0), sd(1), sd(2)],
        }
    }

    fn sphere(&self, s: usize, tracked_frames: &[usize]) -> SphereResult {
        let (d, sd, spins) = (self.derived, self.sigma, self.spins);
        SphereResult {
            position_impact_mm: Some(self.position_at_impact(s)),
            velocity_pre_mm_s: est3(d.velocities[s], sd.velocities[s]),
            velocity_post_mm_s: est3(d.velocities[2 + s], sd.velocities[2 + s]),
            spin_pre_rad_s: spins.reconciled[s].as_ref().map(spin_estimate),
            spin_post_rad_s: spins.reconciled[2 + s].as_ref().map(spin_estimate),
            spin_check: spins.checks[s].clone(),
            diameter_px: ViewValues {
                direct: self.diameters(s, ViewKind::Direct),
                mirror: self.diameters(s, ViewKind::Mirror),
            },
            markers_tracked: tracked_frames
                .iter()
                .map(|&k| {
                    spins.measured[s]
                        .markers_per_frame
                        .get(&k)
                        .or_else(|| spins.measured[2 + s].markers_per_frame.get(&k))
                        .copied()
                        .unwrap_or(0)
                })
                .collect(),
        }
    }

    /// Sphere `s` in frame `f`, each view's circle and the world centre they give.
    fn sphere_track(&self, f: &FrameObs, s: usize) -> Option<SphereTrack> {
        let views = self.views;
        let per_view = |kind: ViewKind| {
            let vi = views.iter().position(|v| v.kind == kind)?;
            f.spheres[s][vi].as_ref().map(|m| ViewTrack {
                centre_px: m.centre_px,
                uncertainty_px: m.sigma_px,
                diameter_px: m.diameter_px,
                markers_px: m.markers.iter().map(|k| k.centre_px).collect(),
            })
        };
        let (direct, mirror) = (per_view(ViewKind::Direct), per_view(ViewKind::Mirror));
        if direct.is_none() && mirror.is_none() {
            return None;
        }
        let mut centre: [Option<f64>; 3] = [None; 3];
        for (vi, view) in views.iter().enumerate().rev() {
            if let Some(m) = &f.spheres[s][vi] {
                for (axis, val) in view.unproject(m.centre_px, f.position_mm[s].as_ref()) {
                    centre[axis] = Some(val);
                }
            }
        }
        Some(SphereTrack {
            direct,
            mirror,
            centre_mm: centre,
        })
    }

    pub(super) fn report(self) -> Report {
        let (d, sd, fits) = (self.derived, self.sigma, self.fits);
        let t_c = self.split + d.tau_c;
        let impact_frame = self
            .obs
            .iter()
            .min_by(|p, q| (p.time_s - t_c).abs().total_cmp(&(q.time_s - t_c).abs()))
            .map(|f| f.index)
            .unwrap_or(0);
        let tracked_frames: Vec<usize> = self
            .obs
            .iter()
            .filter(|f| has_a_sphere(f))
            .map(|f| f.index as usize)
            .collect();
        let tracks: Vec<TrackFrame> = self
            .obs
            .iter()
            .filter(|f| has_a_sphere(f))
            .map(|f| TrackFrame {
                frame: f.index,
                frame_id: f.frame_id,
                time_s: f.time_s,
                a: self.sphere_track(f, 0),
                b: self.sphere_track(f, 1),
            })
            .collect();
        let spheres = Spheres {
            a: self.sphere(0, &tracked_frames),
            b: self.sphere(1, &tracked_frames),
        };
        let used = |k: usize| fits[k].axes[0].map(|l| l.n as u64).unwrap_or(0);
        Report {
            schema: REPORT_SCHEMA.into(),
            software: Software {
                name: "impactcam".into(),
                version: env!("CARGO_PKG_VERSION").into(),
            },
            source: self.info,
            dimensionality: if self.three_d { "3d" } else { "2d" }.into(),
            impact: Impact {
                time_s: Estimate {
                    value: t_c,
                    uncertainty: sd.tau_c,
                },
                frame: impact_frame,
                time_intersection_s: self.split + d.tau_intersection,
                contact_distance_mm: self.contact_mm,
            },
            normal: est3(d.normal, sd.normal),
            e: Some(Estimate {
                value: d.e,
                uncertainty: sd.e,
            }),
            beta: self.beta,
            psi1: d
                .psi1
                .zip(sd.psi1)
                .map(|(value, uncertainty)| Estimate { value, uncertainty }),
            psi2: d
                .psi2
                .zip(sd.psi2)
                .map(|(value, uncertainty)| Estimate { value, uncertainty }),
            branch_hint: d.psi2.zip(sd.psi2).and_then(|(v, u)| branch_hint(v, u)),
            spheres,
            tracks,
            quality: Quality {
                frames_total: self.obs.len() as u64,
                frames_dropped: self.frames_dropped,
                frames_used_pre: PerSphere {
                    a: used(0),
                    b: used(1),
                },
                frames_used_post: PerSphere {
                    a: used(2),
                    b: used(3),
                },
                fit_residual_rms_mm: FitResiduals {
                    a_pre: rms(&fits[0]),
                    b_pre: rms(&fits[1]),
                    a_post: rms(&fits[2]),
                    b_post: rms(&fits[3]),
                },
                calibration: self.calibration,
                unmeasured: self.unmeasured,
                warnings: self.warnings,
            },
        }
    }
}
