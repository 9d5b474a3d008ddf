//! How well calibrate's maps are known: the σ each parameter is written with, widened where
//! the flights scatter beyond their own σ (`scatter_ratio`), where the two ways to the scale
//! disagree (`combine_scales`) and where a lens left out would move a map (`widened_by`);
//! and the bounds the config puts on them.

use super::{bundle, Fitted};

/// A scale's σ, %, as the config accepts it: at most 20 (a fit that knows the scale worse, or
/// not at all, says 20 rather than writing a config the analysis would refuse).
pub(super) fn percent_known(p: f64) -> f64 {
    if p.is_finite() {
        p.abs().min(20.0)
    } else {
        20.0
    }
}

/// A turn's σ, deg, as the config accepts it: at most 10 (as `percent_known`).
pub(super) fn degrees_known(d: f64) -> f64 {
    if d.is_finite() {
        d.abs().min(10.0)
    } else {
        10.0
    }
}

/// `bundle` with each map parameter's σ widened by how far `other` (the same flights fitted
/// under another model) puts it: σ² + Δ². Not the cameras' 1/distance, whose σ decided
/// whether perspective shows and which the maps were written by.
pub(super) fn widened_by(mut bundle: bundle::Bundle, other: &bundle::Bundle) -> bundle::Bundle {
    let widen = |f: &mut Fitted, o: Fitted| {
        let d = f.value - o.value;
        if d.is_finite() {
            f.sigma = f.sigma.hypot(d);
        }
    };
    widen(&mut bundle.direct_scale, other.direct_scale);
    widen(&mut bundle.direct_roll, other.direct_roll);
    if let (Some(m), Some(o)) = (bundle.mirror.as_mut(), other.mirror.as_ref()) {
        widen(&mut m.scale, o.scale);
        widen(&mut m.tilt_deg, o.tilt_deg);
        widen(&mut m.roll_deg, o.roll_deg);
        widen(&mut m.yaw_deg, o.yaw_deg);
        widen(&mut m.origin_x_px, o.origin_x_px);
    }
    bundle
}

/// Birge's ratio of the flights' accelerations (u, v, px/s², each with its σ per component)
/// about their weighted mean: √(χ²/dof), at least 1 (1 where there is only one).
pub(super) fn scatter_ratio(acc: &[([f64; 2], f64)], mean: [f64; 2]) -> f64 {
    let chi2: f64 = acc
        .iter()
        .map(|(a, s)| ((a[0] - mean[0]).powi(2) + (a[1] - mean[1]).powi(2)) / (s * s))
        .sum();
    let dof = 2 * acc.len().saturating_sub(1);
    if dof > 0 && chi2.is_finite() {
        (chi2 / dof as f64).sqrt().max(1.0)
    } else {
        1.0
    }
}

/// How far apart, in σ of their difference, the flights' and the diameter's scales may lie and
/// still be weighed together.
pub const SCALES_AGREE_SIGMA: f64 = 3.0;

/// The direct view's scale from the flights (free fall, g known) and from the imaged diameter,
/// weighed by their σ; where they disagree beyond `SCALES_AGREE_SIGMA`, the flights' alone
/// (the diameter's rests on where the disc's model puts its edge, the flights' on g and the
/// frame rate) and how far apart they were. Why both: free fall over the 20–40 frames of a
/// short recording knows the scale to 0.4–2 %, the imaged diameter to 0.3–0.5 % (its σ,
/// `flights::diameter_scale`), and a grazing impact's e moves by about ψ1·0.8 times a scale's
/// error (the contact distance is a diameter in mm): on an independent render at ψ1 = 2.5 the
/// flights' scale alone, 0.8 % off (1.1σ), put e 0.049 off.
///
/// The σ says how far apart the two were, not only their own σ: weighed, it is widened by
/// their difference in σ where that is beyond 1 (the Particle Data Group's scale factor for
/// two measurements); the flights' alone take the difference itself into their σ, since
/// nothing here tells which of the two the look misled. Why: on 72 hw-sim rigs drawn at
/// random and calibrated, a side-lit one's flights put the scale 3.8 % high where its diameter
/// was right, a defocused one's 4.0 % with the diameter 2.1σ from them, and their velocities
/// came out up to 6σ off (docs/accuracy.md, session 48).
pub(super) fn combine_scales(flights: Fitted, diameter: Fitted) -> (Fitted, Option<f64>) {
    let z = (diameter.value - flights.value) / flights.sigma.hypot(diameter.sigma);
    let usable = |f: Fitted| f.value.is_finite() && f.sigma.is_finite() && f.sigma > 0.0;
    if !(usable(flights) && usable(diameter)) || z.is_nan() {
        return (flights, None);
    }
    if z.abs() > SCALES_AGREE_SIGMA {
        let apart = diameter.value - flights.value;
        return (
            Fitted {
                value: flights.value,
                sigma: flights.sigma.hypot(apart),
            },
            Some(z),
        );
    }
    let (wf, wd) = (flights.sigma.powi(-2), diameter.sigma.powi(-2));
    (
        Fitted {
            value: (wf * flights.value + wd * diameter.value) / (wf + wd),
            sigma: (wf + wd).recip().sqrt() * z.abs().max(1.0),
        },
        None,
    )
}

#[cfg(test)]
mod tests;
