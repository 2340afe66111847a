//! Fast seeded Gaussian pixel noise for the simulated cameras.
//!
//! A Box-Muller draw per pixel (a log, a square root and a cosine) would cost
//! more than rendering the pixel, so the cameras draw from a table of 65536
//! standard-normal samples made once from the seed, indexed by 16 random bits
//! per pixel. The empirical distribution of 65536 draws is Gaussian for any
//! purpose a detector can tell, and the stream stays deterministic per seed.

use crate::rng::Pcg32;

const TABLE_BITS: u32 = 16;
const TABLE_SIZE: usize = 1 << TABLE_BITS;

/// A seeded source of standard-normal samples, cheap enough for every pixel.
#[derive(Debug, Clone)]
pub struct PixelNoise {
    table: Vec<f32>,
    rng: Pcg32,
}

impl PixelNoise {
    /// Builds the table and the index stream from `seed`.
    pub fn new(seed: u64) -> Self {
        let mut table_rng = Pcg32::with_stream(seed, 0x6e6f_6973_6520_7462);
        let table = (0..TABLE_SIZE).map(|_| table_rng.normal() as f32).collect();
        Self {
            table,
            rng: Pcg32::with_stream(seed, 0x7069_7865_6c73),
        }
    }

    /// Two independent standard-normal samples (one 32-bit draw).
    #[inline]
    pub fn pair(&mut self) -> (f32, f32) {
        let r = self.rng.next_u32();
        let mask = (TABLE_SIZE - 1) as u32;
        // Both indices are masked below the table size.
        let a = self.table.get((r & mask) as usize).copied().unwrap_or(0.0);
        let b = self
            .table
            .get(((r >> TABLE_BITS) & mask) as usize)
            .copied()
            .unwrap_or(0.0);
        (a, b)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixel_noise_has_zero_mean_and_unit_variance() {
        let mut n = PixelNoise::new(7);
        let mut sum = 0.0f64;
        let mut sum2 = 0.0f64;
        let count = 200_000;
        for _ in 0..count / 2 {
            let (a, b) = n.pair();
            sum += f64::from(a) + f64::from(b);
            sum2 += f64::from(a).powi(2) + f64::from(b).powi(2);
        }
        let mean = sum / count as f64;
        let var = sum2 / count as f64 - mean * mean;
        assert!(mean.abs() < 0.02, "mean {mean}");
        assert!((var - 1.0).abs() < 0.03, "variance {var}");
    }
}
