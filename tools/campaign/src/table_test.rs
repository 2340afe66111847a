use super::*;

#[test]
fn the_wilson_interval_of_300_of_300_bounds_the_failure_rate_by_about_1_3_percent() {
    let [lo, hi] = wilson95(300, 300);
    assert!((lo - 0.987_36).abs() < 1e-4, "{lo}");
    assert_eq!(hi, 1.0);
    // A textbook value: 8 of 10.
    let [lo, hi] = wilson95(8, 10);
    assert!(
        (lo - 0.4902).abs() < 1e-3 && (hi - 0.9433).abs() < 1e-3,
        "{lo} {hi}"
    );
    assert_eq!(wilson95(0, 0), [0.0, 1.0]);
    let [lo, _] = wilson95(0, 20);
    assert_eq!(lo, 0.0);
}

#[test]
fn quantiles_interpolate_between_ranks() {
    let v = [4.0, 1.0, 3.0, 2.0, f64::NAN];
    assert_eq!(quantile(&v, 0.5), Some(2.5));
    assert_eq!(quantile(&v, 0.0), Some(1.0));
    assert_eq!(quantile(&v, 1.0), Some(4.0));
    assert_eq!(quantile(&[], 0.5), None);
}
