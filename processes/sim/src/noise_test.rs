//! Tests of `noise`.

use super::*;

#[test]
fn pixel_noise_has_zero_mean_and_unit_variance() {
    let mut n = PixelNoise::new(7);
    n.new_frame();
    let mut sum = 0.0f64;
    let mut sum2 = 0.0f64;
    let mut count = 0;
    for _ in 0..10 {
        for &v in n.slice(20_000) {
            sum += f64::from(v);
            sum2 += f64::from(v).powi(2);
            count += 1;
        }
    }
    let mean = sum / f64::from(count);
    let var = sum2 / f64::from(count) - mean * mean;
    assert!(mean.abs() < 0.02, "mean {mean}");
    assert!((var - 1.0).abs() < 0.03, "variance {var}");
}

#[test]
fn slices_are_full_length_across_the_wrap() {
    let mut n = PixelNoise::new(3);
    for _ in 0..100 {
        assert_eq!(n.slice(MAX_SLICE).len(), MAX_SLICE);
    }
    assert_eq!(n.slice(MAX_SLICE + 5).len(), MAX_SLICE);
}
