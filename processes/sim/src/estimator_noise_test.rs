//! Tests of `estimator_noise`.

use super::*;

fn moving_truth(t: f64) -> VehicleState {
    let mut s = VehicleState::at_rest(Vector3::new(t, 2.0 * t, 3.0), 0.3 * t);
    s.velocity = Vector3::new(1.0, 2.0, 0.1);
    s.body_rates = Vector3::new(0.1, -0.2, 0.3);
    s
}

#[test]
fn zero_noise_estimate_equals_truth_exactly() {
    let mut n = EstimatorNoise::new(EstimatorNoiseParams::zero()).unwrap();
    for k in 0..1000 {
        let truth = moving_truth(k as f64 * 0.002);
        let est = n.apply(0.002, &truth, false);
        assert_eq!(est.position, truth.position);
        assert_eq!(est.velocity, truth.velocity);
        assert_eq!(est.world_from_body, truth.world_from_body);
        assert_eq!(est.body_rates, truth.body_rates);
    }
}

#[test]
fn the_same_seed_gives_the_same_estimates() {
    let mut a = EstimatorNoise::new(EstimatorNoiseParams::default()).unwrap();
    let mut b = EstimatorNoise::new(EstimatorNoiseParams::default()).unwrap();
    for k in 0..1000 {
        let truth = moving_truth(k as f64 * 0.002);
        assert_eq!(a.apply(0.002, &truth, false), b.apply(0.002, &truth, false));
    }
}

#[test]
fn different_seeds_give_different_estimates() {
    let mut a = EstimatorNoise::new(EstimatorNoiseParams::default()).unwrap();
    let mut b = EstimatorNoise::new(EstimatorNoiseParams {
        seed: 2,
        ..EstimatorNoiseParams::default()
    })
    .unwrap();
    let truth = moving_truth(0.0);
    assert_ne!(a.apply(0.002, &truth, false), b.apply(0.002, &truth, false));
}

#[test]
fn noise_has_the_configured_standard_deviation() {
    let params = EstimatorNoiseParams {
        position_drift_m_per_sqrt_s: 0.0,
        yaw_drift_rad_per_sqrt_s: 0.0,
        correlation_time_s: 0.0,
        ..EstimatorNoiseParams::default()
    };
    let mut n = EstimatorNoise::new(params.clone()).unwrap();
    let truth = moving_truth(0.0);
    let count = 20_000;
    let mut sum_sq = 0.0;
    for _ in 0..count {
        let e = n.apply(0.002, &truth, false).position - truth.position;
        sum_sq += e.x * e.x;
    }
    let std = (sum_sq / count as f64).sqrt();
    assert!(
        (std - params.position_std_m).abs() < 0.05 * params.position_std_m,
        "{std}"
    );
}

#[test]
fn drift_grows_like_a_random_walk() {
    let params = EstimatorNoiseParams {
        position_drift_m_per_sqrt_s: 0.1,
        ..EstimatorNoiseParams::zero()
    };
    // Across seeds, the drift after 100 s has std 0.1 * sqrt(100) = 1 m per axis.
    let mut sum_sq = 0.0;
    let runs = 200;
    for seed in 0..runs {
        let mut n = EstimatorNoise::new(EstimatorNoiseParams {
            seed,
            ..params.clone()
        })
        .unwrap();
        let truth = moving_truth(0.0);
        for _ in 0..1000 {
            n.apply(0.1, &truth, false);
        }
        sum_sq += n.position_drift().x.powi(2);
    }
    let std = (sum_sq / runs as f64).sqrt();
    assert!((std - 1.0).abs() < 0.2, "{std}");
}

#[test]
fn yaw_drift_turns_the_reported_heading_and_velocity() {
    let params = EstimatorNoiseParams {
        yaw_drift_rad_per_sqrt_s: 0.05,
        ..EstimatorNoiseParams::zero()
    };
    let mut n = EstimatorNoise::new(params).unwrap();
    let truth = moving_truth(1.0);
    let mut est = n.apply(0.01, &truth, false);
    for _ in 0..1000 {
        est = n.apply(0.01, &truth, false);
    }
    let drift = n.yaw_drift();
    assert!(drift.abs() > 1e-4);
    let dyaw = est.world_from_body.euler_angles().2 - truth.yaw_rad();
    assert!((dyaw - drift).abs() < 1e-9);
    assert!((est.velocity.norm() - truth.velocity.norm()).abs() < 1e-12);
}

#[test]
fn validation_rejects_negative_noise() {
    let p = EstimatorNoiseParams {
        velocity_std_m_s: -0.1,
        ..EstimatorNoiseParams::default()
    };
    assert_eq!(
        p.validate().unwrap_err().to_string(),
        "velocity_std_m_s = -0.1: must be >= 0"
    );
}
