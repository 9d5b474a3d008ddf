//! A small deterministic random source (SplitMix64): the simulator must give the same lab from
//! the same seed on every machine, and the campaign fit the same bootstrap intervals on every
//! run, so neither uses a platform or crate RNG whose stream may change between versions. The
//! project's one PRNG.

use crate::V3;

#[derive(Clone, Debug)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed ^ 0x5DEE_CE66_D1CE_4E5B)
    }

    /// A generator whose state is `state` as given (no seed scrambling): for streams that
    /// were fixed before `new` was shared, such as the campaign fit's bootstrap.
    pub fn from_state(state: u64) -> Self {
        Rng(state)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Standard normal (Box–Muller).
    pub fn gaussian(&mut self) -> f64 {
        let u1 = 1.0 - self.uniform();
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    /// Uniform on the unit sphere.
    pub fn unit_vector(&mut self) -> V3 {
        loop {
            let v = V3::new(self.gaussian(), self.gaussian(), self.gaussian());
            let n = v.norm();
            if n > 1e-9 {
                return v / n;
            }
        }
    }
}
