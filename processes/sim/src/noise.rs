//! Fast seeded Gaussian pixel noise for the simulated cameras.
//!
//! A Box-Muller draw per pixel (a log, a square root and a cosine) would cost
//! more than rendering the pixel, so the cameras read a field of 2^20
//! standard-normal samples made once from the seed. Each frame starts at a
//! random offset and reads on sequentially (which vectorizes); a band of
//! pixels is one contiguous slice. Successive frames therefore reuse the same
//! samples at other offsets, which no detector can tell from fresh noise, and
//! the stream stays deterministic per seed.

use crate::rng::Pcg32;

const FIELD_BITS: u32 = 20;
const FIELD_SIZE: usize = 1 << FIELD_BITS;

/// Longest slice [`PixelNoise::slice`] returns at once.
pub const MAX_SLICE: usize = 1 << 20;

/// A seeded source of standard-normal samples, cheap enough for every pixel.
#[derive(Debug, Clone)]
pub struct PixelNoise {
    /// `FIELD_SIZE` samples followed by a copy of the first `MAX_SLICE`, so
    /// any slice starting inside the field is contiguous.
    field: Vec<f32>,
    pos: usize,
    rng: Pcg32,
}

impl PixelNoise {
    /// Builds the field and the offset stream from `seed`.
    pub fn new(seed: u64) -> Self {
        let mut field_rng = Pcg32::with_stream(seed, 0x6e6f_6973_6520_7462);
        let mut field: Vec<f32> = (0..FIELD_SIZE).map(|_| field_rng.normal() as f32).collect();
        field.extend_from_within(..MAX_SLICE);
        Self {
            field,
            pos: 0,
            rng: Pcg32::with_stream(seed, 0x7069_7865_6c73),
        }
    }

    /// Starts a new frame at a random offset.
    pub fn new_frame(&mut self) {
        self.pos = (self.rng.next_u32() as usize) & (FIELD_SIZE - 1);
    }

    /// The next `n` samples (`n` is capped at [`MAX_SLICE`]).
    pub fn slice(&mut self, n: usize) -> &[f32] {
        let n = n.min(MAX_SLICE);
        let start = self.pos;
        self.pos = (self.pos + n) & (FIELD_SIZE - 1);
        self.field.get(start..start + n).unwrap_or(&[])
    }
}

#[cfg(test)]
#[path = "noise_test.rs"]
mod tests;
