//! Tests of the camera's relative track.

use nalgebra::Vector3;

use super::{MAX_AGE_NS, RelativeTrack};

const FRAME_NS: u64 = 33_333_333;

#[test]
fn a_steady_relative_motion_reads_as_its_velocity_whatever_the_bias() {
    let mut track = RelativeTrack::default();
    let v = Vector3::new(0.12, -0.05, 0.0);
    let bias = Vector3::new(0.03, -0.02, 0.01);
    for k in 0..10u64 {
        let t = 1_000_000_000 + k * FRAME_NS;
        track.push(t, bias + v * (k as f64 * FRAME_NS as f64 * 1e-9));
    }
    let now = 1_000_000_000 + 9 * FRAME_NS + 20_000_000;
    let got = track.velocity(now).expect("a velocity");
    assert!((got - v).norm() < 1e-9, "{got}");
}

#[test]
fn too_few_or_too_old_observations_give_no_velocity() {
    let mut track = RelativeTrack::default();
    for k in 0..4u64 {
        track.push(k * FRAME_NS, Vector3::zeros());
    }
    assert_eq!(track.velocity(4 * FRAME_NS), None, "four points");
    track.push(4 * FRAME_NS, Vector3::zeros());
    assert!(track.velocity(4 * FRAME_NS).is_some());
    assert_eq!(track.velocity(4 * FRAME_NS + MAX_AGE_NS + 1), None, "stale");
}

#[test]
fn the_fit_forgets_what_is_older_than_its_window() {
    let mut track = RelativeTrack::default();
    // Half a second moving at 1 m/s, then still: the window holds only the stillness.
    for k in 0..15u64 {
        track.push(
            k * FRAME_NS,
            Vector3::new(k as f64 * FRAME_NS as f64 * 1e-9, 0.0, 0.0),
        );
    }
    let x = 14.0 * FRAME_NS as f64 * 1e-9;
    for k in 15..30u64 {
        track.push(k * FRAME_NS, Vector3::new(x, 0.0, 0.0));
    }
    let got = track.velocity(29 * FRAME_NS).expect("a velocity");
    assert!(got.norm() < 1e-9, "{got}");
}

#[test]
fn out_of_order_and_non_finite_observations_are_ignored() {
    let mut track = RelativeTrack::default();
    for k in 0..6u64 {
        track.push(k * FRAME_NS, Vector3::new(0.1 * k as f64, 0.0, 0.0));
    }
    track.push(2 * FRAME_NS, Vector3::new(9.0, 9.0, 9.0));
    track.push(7 * FRAME_NS, Vector3::new(f64::NAN, 0.0, 0.0));
    let got = track.velocity(6 * FRAME_NS).expect("a velocity");
    assert!(
        (got.x - 0.1 / (FRAME_NS as f64 * 1e-9)).abs() < 1e-6,
        "{got}"
    );
}
