//! Bilinear sampling of an 8-bit image at fixed-point coordinates, as OpenCV's
//! `remap` (`INTER_LINEAR`, 16SC2 + 16UC1 maps) computes it, without the maps
//! leaving the cache.
//!
//! The down camera fills the coordinates of a 16-row strip and samples it at
//! once: the maps of a whole band went to memory and back through `remap` (a
//! quarter of a mission's time). Every pixel is the byte `remap` gives (tested
//! against it): OpenCV's bilinear weights for a fraction (fx, fy) in 1/32 steps
//! are 32 (32 - fx)(32 - fy) and the like, exactly (products of multiples of
//! 1/32 in float), except at (0, 0) where 32768 saturates to 32767 and the last
//! weight takes the 1 back, which gives the same byte; so the result is
//! ((32 - fy)((32 - fx) s00 + fx s01) + fy((32 - fx) s10 + fx s11) + 512) >> 10.
//! Only in-range points are sampled (the caller's coordinates never reach the
//! image's last row or column, so `remap`'s border rule never applied).

/// Bits of the fraction: 1/32 texel (`INTER_BITS`).
const FRACTION_BITS: u32 = 5;
const ONE: i32 = 1 << FRACTION_BITS;

/// A grey image held for sampling, each texel beside the one below it: a 4-byte
/// load at texel (x, y) gives (x, y), (x, y + 1), (x + 1, y), (x + 1, y + 1),
/// the four a bilinear sample reads, so the vector path gathers once per point.
#[derive(Debug, Clone)]
pub(crate) struct Image {
    pairs: Vec<u8>,
    cols: usize,
    rows: usize,
}

impl Image {
    /// `data` is `rows` rows of `cols` bytes (missing bytes read 0).
    pub(crate) fn new(data: &[u8], cols: usize, rows: usize) -> Self {
        let texel =
            |x: usize, y: usize| data.get(y.min(rows.saturating_sub(1)) * cols + x).copied();
        let mut pairs = Vec::with_capacity(2 * cols * rows + 4);
        for y in 0..rows {
            for x in 0..cols {
                pairs.push(texel(x, y).unwrap_or(0));
                pairs.push(texel(x, y + 1).unwrap_or(0));
            }
        }
        // Slack: a 4-byte load at the last texel stays inside the buffer.
        pairs.extend([0; 4]);
        Self { pairs, cols, rows }
    }
}

/// Image point (u, v) (both >= 0 and far below 2^15, as every atlas coordinate
/// is) to the fixed-point pair [`sample`] takes, rounded as OpenCV's `convertMaps`
/// rounds (to nearest, ties to even), so the image is the one float maps gave:
/// the integer texel (x, y) as two 16-bit halves, x low (the layout of OpenCV's
/// 16SC2 map), and the fraction index `fy << 5 | fx`. Words, not 16-bit lanes, so
/// a vectorized filler stores them as computed.
#[inline(always)]
pub(crate) fn point(u: f32, v: f32) -> (u32, u32) {
    // 1.5 * 2^23: adding it leaves the rounded value in the low mantissa bits.
    const ROUND: f32 = 12_582_912.0;
    const SCALE: f32 = ONE as f32;
    const MASK: u32 = (1 << 22) - 1;
    const FRACTION: u32 = (1 << FRACTION_BITS) - 1;
    let x = ((u * SCALE).max(0.0) + ROUND).to_bits() & MASK;
    let y = ((v * SCALE).max(0.0) + ROUND).to_bits() & MASK;
    (
        ((x >> FRACTION_BITS) & 0xffff) | ((y >> FRACTION_BITS) & 0xffff) << 16,
        ((y & FRACTION) << FRACTION_BITS) | (x & FRACTION),
    )
}

/// Samples `image` at every point, as [`point`] gives them: `xy` the integer texel,
/// `fxy` the fraction index. Points are clamped to the image (one texel in from its
/// last row and column), which in-range points never feel.
pub(crate) fn sample(image: &Image, xy: &[u32], fxy: &[u32], out: &mut [u8]) {
    let n = xy.len().min(fxy.len()).min(out.len());
    if image.cols < 2 || image.rows < 2 || image.cols > i32::MAX as usize / (2 * image.rows) {
        out[..n].fill(0);
        return;
    }
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        let whole = n - n % 8;
        // SAFETY: the CPU has AVX2 (checked above); sample_avx2 reads only the
        // image's buffer at clamped texels (its slack covers the 4-byte loads).
        unsafe { sample_avx2(image, &xy[..whole], &fxy[..whole], &mut out[..whole]) };
        sample_scalar(image, &xy[whole..n], &fxy[whole..n], &mut out[whole..n]);
        return;
    }
    sample_scalar(image, &xy[..n], &fxy[..n], &mut out[..n]);
}

/// One point at a time (the reference, and the tail of the vector path).
pub(crate) fn sample_scalar(image: &Image, xy: &[u32], fxy: &[u32], out: &mut [u8]) {
    let (cols, pairs) = (image.cols, image.pairs.as_slice());
    let (xmax, ymax) = (cols as i32 - 2, image.rows as i32 - 2);
    for ((o, &p), &f) in out.iter_mut().zip(xy).zip(fxy) {
        let (x, y) = (p as u16 as i16, (p >> 16) as u16 as i16);
        let x = i32::from(x).clamp(0, xmax) as usize;
        let y = i32::from(y).clamp(0, ymax) as usize;
        let f = (f & 0x3ff) as i32;
        let (fx, fy) = (f & (ONE - 1), (f >> FRACTION_BITS) & (ONE - 1));
        let p = 2 * (y * cols + x);
        let texel = |k: usize| i32::from(pairs.get(p + k).copied().unwrap_or(0));
        let left = (ONE - fy) * texel(0) + fy * texel(1);
        let right = (ONE - fy) * texel(2) + fy * texel(3);
        let sum = (ONE - fx) * left + fx * right;
        *o = ((sum + (1 << (2 * FRACTION_BITS - 1))) >> (2 * FRACTION_BITS)).clamp(0, 255) as u8;
    }
}

/// Eight points per step: one 4-byte gather brings each point's four texels,
/// two `madd`s weigh them (columns, then across).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn sample_avx2(image: &Image, xy: &[u32], fxy: &[u32], out: &mut [u8]) {
    use std::arch::x86_64::*;
    let base = image.pairs.as_ptr().cast::<i32>();
    let cols = _mm256_set1_epi32(image.cols as i32);
    let xmax = _mm256_set1_epi32(image.cols as i32 - 2);
    let ymax = _mm256_set1_epi32(image.rows as i32 - 2);
    let zero = _mm256_setzero_si256();
    // Per 4-byte lane: bytes 0 and 1 (x) or 2 and 3 (x + 1) into two i16.
    // (`shuffle_epi8` indexes within each 16-byte half; 0x80 writes a zero).
    let control = |first: i32| {
        let lane = |k: i32| (4 * k + first) | 0x80 << 8 | (4 * k + first + 1) << 16 | (0x80 << 24);
        _mm256_setr_epi32(
            lane(0),
            lane(1),
            lane(2),
            lane(3),
            lane(0),
            lane(1),
            lane(2),
            lane(3),
        )
    };
    let (left_bytes, right_bytes) = (control(0), control(2));
    let fraction = _mm256_set1_epi32(ONE - 1);
    let one = _mm256_set1_epi32(ONE);
    let half = _mm256_set1_epi32(1 << (2 * FRACTION_BITS - 1));
    for ((xy, f), o) in xy
        .chunks_exact(8)
        .zip(fxy.chunks_exact(8))
        .zip(out.chunks_exact_mut(8))
    {
        // SAFETY: each chunk holds 8 points (32 bytes of xy and of fxy) and 8
        // output bytes; loads and stores are unaligned; the gather reads 4 bytes at
        // a clamped texel, inside the buffer by its slack.
        unsafe {
            let p = _mm256_loadu_si256(xy.as_ptr().cast());
            // x is the low i16 of each lane, y the high one (both signed).
            let x = _mm256_srai_epi32(_mm256_slli_epi32(p, 16), 16);
            let y = _mm256_srai_epi32(p, 16);
            let x = _mm256_min_epi32(_mm256_max_epi32(x, zero), xmax);
            let y = _mm256_min_epi32(_mm256_max_epi32(y, zero), ymax);
            let at = _mm256_slli_epi32(_mm256_add_epi32(_mm256_mullo_epi32(y, cols), x), 1);
            // Bytes: (x, y), (x, y + 1), (x + 1, y), (x + 1, y + 1).
            let g = _mm256_i32gather_epi32::<1>(base, at);
            let f = _mm256_loadu_si256(f.as_ptr().cast());
            let fx = _mm256_and_si256(f, fraction);
            let fy = _mm256_and_si256(_mm256_srli_epi32(f, FRACTION_BITS as i32), fraction);
            // i16 pairs: (32 - fy, fy) and (32 - fx, fx).
            let wy = _mm256_or_si256(_mm256_sub_epi32(one, fy), _mm256_slli_epi32(fy, 16));
            let wx = _mm256_or_si256(_mm256_sub_epi32(one, fx), _mm256_slli_epi32(fx, 16));
            // Texel columns as i16 pairs: (top, bottom) at x and at x + 1.
            let left = _mm256_madd_epi16(_mm256_shuffle_epi8(g, left_bytes), wy);
            let right = _mm256_madd_epi16(_mm256_shuffle_epi8(g, right_bytes), wy);
            // Each column sum is at most 32 * 255: both fit an i16 of one lane.
            let columns = _mm256_or_si256(left, _mm256_slli_epi32(right, 16));
            let sum = _mm256_madd_epi16(columns, wx);
            let v = _mm256_srai_epi32(_mm256_add_epi32(sum, half), 2 * FRACTION_BITS as i32);
            let words = _mm_packus_epi32(_mm256_castsi256_si128(v), _mm256_extracti128_si256(v, 1));
            let bytes = _mm_packus_epi16(words, words);
            _mm_storel_epi64(o.as_mut_ptr().cast(), bytes);
        }
    }
}

#[cfg(test)]
#[path = "bilinear_test.rs"]
mod tests;
