//! A mains-driven lamp's flicker: its light over one exposure against its mean.
//!
//! Fluorescent tubes, cheap LED drivers and even halogen lamps follow the mains: their light
//! rises and falls at twice its frequency, and a camera at 1000 fps sees every frame at another
//! phase of it. The ground and the spheres, lit by the same lamps, brighten and dim together;
//! the sensor's read noise does not.

use crate::config::LabConfig;
use crate::rng::Rng;

/// Mixed into the seed for the flicker's phase, so that drawing it leaves every other stream
/// (noise, markers, drops) as it was.
const PHASE_STREAM: u64 = 0xF11C_4E20_0000_0001;

pub(super) struct Flicker {
    /// Modulation depth: the light is 1 + depth·sin(2π·hz·t + phase) of its mean.
    depth: f64,
    hz: f64,
    phase_rad: f64,
}

impl Flicker {
    /// None for a steady lamp (`sim.flicker_percent` 0).
    pub(super) fn new(cfg: &LabConfig, seed: u64) -> Option<Flicker> {
        (cfg.flicker_percent > 0.0).then(|| Flicker {
            depth: cfg.flicker_percent / 100.0,
            hz: cfg.flicker_hz,
            phase_rad: std::f64::consts::TAU * Rng::new(seed ^ PHASE_STREAM).uniform(),
        })
    }

    /// The light's mean over an exposure of `exposure_s` centred on `t_mid_s`, against the
    /// lamp's mean: the sinusoid averaged over the exposure is itself at the middle times
    /// sin(x)/x, x = π·hz·exposure.
    pub(super) fn gain(&self, t_mid_s: f64, exposure_s: f64) -> f64 {
        let x = std::f64::consts::PI * self.hz * exposure_s;
        let smooth = if x.abs() < 1e-9 { 1.0 } else { x.sin() / x };
        let angle = std::f64::consts::TAU * self.hz * t_mid_s + self.phase_rad;
        1.0 + self.depth * smooth * angle.sin()
    }
}

#[cfg(test)]
mod tests {
    use super::Flicker;

    /// The gain swings by the depth about 1 at the flicker's frequency, and an exposure of a
    /// whole period averages it away.
    #[test]
    fn the_gain_swings_by_the_depth_and_a_whole_period_averages_it_out() {
        let f = Flicker {
            depth: 0.3,
            hz: 100.0,
            phase_rad: 0.4,
        };
        let gains: Vec<f64> = (0..1000).map(|i| f.gain(i as f64 * 1e-5, 1e-6)).collect();
        let (lo, hi) = gains
            .iter()
            .fold((f64::MAX, f64::MIN), |(a, b), &g| (a.min(g), b.max(g)));
        assert!(
            (hi - 1.3).abs() < 1e-3 && (lo - 0.7).abs() < 1e-3,
            "{lo}..{hi}"
        );
        // One period later, the same.
        assert!((f.gain(0.0123, 1e-4) - f.gain(0.0223, 1e-4)).abs() < 1e-12);
        assert!((f.gain(0.0123, 0.01) - 1.0).abs() < 1e-12);
    }
}
