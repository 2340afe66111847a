//! Tests of `rng`.

use super::*;

#[test]
fn same_seed_gives_same_sequence() {
    let mut a = Pcg32::new(42);
    let mut b = Pcg32::new(42);
    for _ in 0..100 {
        assert_eq!(a.next_u64(), b.next_u64());
    }
}

#[test]
fn different_seeds_give_different_sequences() {
    let mut a = Pcg32::new(1);
    let mut b = Pcg32::new(2);
    let same = (0..100).filter(|_| a.next_u32() == b.next_u32()).count();
    assert!(same < 3);
}

#[test]
fn uniform_stays_in_unit_interval_with_mean_one_half() {
    let mut rng = Pcg32::new(7);
    let n = 100_000;
    let mut sum = 0.0;
    for _ in 0..n {
        let u = rng.uniform();
        assert!((0.0..1.0).contains(&u));
        sum += u;
    }
    assert!((sum / n as f64 - 0.5).abs() < 0.01);
}

#[test]
fn normal_samples_have_unit_variance_and_zero_mean() {
    let mut rng = Pcg32::new(3);
    let n = 200_000;
    let (mut sum, mut sum_sq) = (0.0, 0.0);
    for _ in 0..n {
        let z = rng.normal();
        assert!(z.is_finite());
        sum += z;
        sum_sq += z * z;
    }
    let mean = sum / n as f64;
    let var = sum_sq / n as f64 - mean * mean;
    assert!(mean.abs() < 0.01, "mean {mean}");
    assert!((var - 1.0).abs() < 0.02, "variance {var}");
}
