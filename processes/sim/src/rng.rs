//! A tiny seeded random number generator.
//!
//! The simulator must give the same result for the same seed on every machine
//! and every version of its dependencies, so it carries its own generator
//! (PCG-XSH-RR 64/32, O'Neill 2014) and its own Gaussian sampler (Box-Muller)
//! instead of depending on the `rand` crate.

/// A deterministic pseudo-random generator (PCG-XSH-RR with 64-bit state).
///
/// Used for estimator noise and wind gusts so runs are reproducible from a seed.
#[derive(Debug, Clone)]
pub struct Pcg32 {
    state: u64,
    increment: u64,
    spare_normal: Option<f64>,
}

const PCG_MULTIPLIER: u64 = 6_364_136_223_846_793_005;

impl Pcg32 {
    /// Creates a generator from a seed; every seed (including 0) is valid.
    pub fn new(seed: u64) -> Self {
        Self::with_stream(seed, 0x0da3_e39c_b94b_95bd)
    }

    /// Creates a generator from a seed and a stream id, so that independent
    /// consumers seeded alike (e.g. wind axes) do not draw the same numbers.
    pub fn with_stream(seed: u64, stream: u64) -> Self {
        let mut rng = Self {
            state: 0,
            increment: (stream << 1) | 1,
            spare_normal: None,
        };
        rng.next_u32();
        rng.state = rng.state.wrapping_add(seed);
        rng.next_u32();
        rng
    }

    /// Returns the next 32 uniformly distributed bits.
    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old
            .wrapping_mul(PCG_MULTIPLIER)
            .wrapping_add(self.increment);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        let rot = (old >> 59) as u32;
        xorshifted.rotate_right(rot)
    }

    /// Returns the next 64 uniformly distributed bits.
    pub fn next_u64(&mut self) -> u64 {
        (u64::from(self.next_u32()) << 32) | u64::from(self.next_u32())
    }

    /// Returns a uniform sample in `[0, 1)` with 53 bits of resolution.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Returns a standard normal sample (mean 0, standard deviation 1), by Box-Muller.
    pub fn normal(&mut self) -> f64 {
        if let Some(z) = self.spare_normal.take() {
            return z;
        }
        // 1 - uniform() is in (0, 1], so the logarithm is finite.
        let u1 = 1.0 - self.uniform();
        let u2 = self.uniform();
        let radius = (-2.0 * u1.ln()).sqrt();
        let angle = std::f64::consts::TAU * u2;
        self.spare_normal = Some(radius * angle.sin());
        radius * angle.cos()
    }
}

#[cfg(test)]
#[path = "rng_test.rs"]
mod tests;
