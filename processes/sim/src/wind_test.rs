//! Tests of `wind`.

use super::*;

#[test]
fn constant_wind_is_the_mean_at_every_time() {
    let w = Wind::new(&WindParams::constant(Vector3::new(5.0, -1.0, 0.0))).unwrap();
    for t in [0.0, 1.0, 123.456] {
        assert_eq!(w.velocity_at(t), Vector3::new(5.0, -1.0, 0.0));
    }
    assert_eq!(Wind::calm().velocity_at(3.0), Vector3::zeros());
}

fn gusty(seed: u64) -> WindParams {
    WindParams {
        mean_m_s: [4.0, 0.0, 0.0],
        gust_std_horizontal_m_s: 1.5,
        gust_std_vertical_m_s: 0.5,
        seed,
        ..WindParams::default()
    }
}

#[test]
fn gusts_are_deterministic_for_a_seed_and_differ_across_seeds() {
    let a = Wind::new(&gusty(7)).unwrap();
    let b = Wind::new(&gusty(7)).unwrap();
    let c = Wind::new(&gusty(8)).unwrap();
    for k in 0..100 {
        let t = k as f64 * 0.37;
        assert_eq!(a.velocity_at(t), b.velocity_at(t));
    }
    assert_ne!(a.velocity_at(1.0), c.velocity_at(1.0));
}

#[test]
fn gusts_have_the_configured_mean_and_standard_deviation() {
    let w = Wind::new(&gusty(3)).unwrap();
    let n = 200_000;
    let dt = 0.05;
    let (mut sum, mut sum_sq) = (Vector3::zeros(), Vector3::zeros());
    for k in 0..n {
        let v = w.velocity_at(k as f64 * dt);
        sum += v;
        sum_sq += v.component_mul(&v);
    }
    let mean = sum / n as f64;
    let std = (sum_sq / n as f64 - mean.component_mul(&mean)).map(f64::sqrt);
    assert!(
        (mean - Vector3::new(4.0, 0.0, 0.0)).norm() < 0.2,
        "{mean:?}"
    );
    assert!((std.x - 1.5).abs() < 0.15, "{std:?}");
    assert!((std.z - 0.5).abs() < 0.05, "{std:?}");
}

#[test]
fn gusts_are_continuous() {
    let w = Wind::new(&gusty(5)).unwrap();
    let dt = 0.002;
    for k in 0..10_000 {
        let t = k as f64 * dt;
        let jump = (w.velocity_at(t + dt) - w.velocity_at(t)).norm();
        assert!(jump < 0.05, "jump {jump} at {t}");
    }
}

#[test]
fn validation_rejects_bad_values() {
    let p = WindParams {
        gust_std_horizontal_m_s: -1.0,
        ..WindParams::default()
    };
    assert_eq!(
        p.validate().unwrap_err().to_string(),
        "gust_std_horizontal_m_s = -1: must be >= 0"
    );
    let p = WindParams {
        components: 0,
        ..WindParams::default()
    };
    assert!(p.validate().is_err());
    assert!(toml::from_str::<WindParams>("mean = [1.0, 0.0, 0.0]").is_err());
}
