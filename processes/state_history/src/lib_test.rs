use super::*;

fn pose(t: u64, x: f64, yaw: f64) -> TimedPose {
    TimedPose {
        time_ns: t,
        world_from_body: Isometry3::new(Vector3::new(x, 0.0, 1.0), Vector3::z() * yaw),
        velocity: Vector3::new(2.0, 0.0, 0.0),
    }
}

#[test]
fn a_capture_time_between_two_states_interpolates_position_and_yaw() {
    let mut h = StateHistory::new(8, 20_000_000);
    assert!(h.push(pose(0, 0.0, 0.0)));
    assert!(h.push(pose(100_000_000, 1.0, 0.2)));
    let p = h.at(25_000_000).unwrap();
    assert!((p.translation.x - 0.25).abs() < 1e-12);
    assert!((p.rotation.euler_angles().2 - 0.05).abs() < 1e-9);
}

#[test]
fn a_frame_newer_than_the_stream_extrapolates_only_within_the_allowance() {
    let mut h = StateHistory::new(8, 20_000_000);
    h.push(pose(0, 0.0, 0.0));
    let p = h.at(10_000_000).unwrap();
    assert!((p.translation.x - 0.02).abs() < 1e-12);
    assert_eq!(h.at(30_000_000), Err(HistoryError::Stale(30_000_000)));
}

#[test]
fn frames_older_than_the_window_and_an_empty_history_are_errors() {
    let mut h = StateHistory::new(2, 0);
    assert_eq!(h.at(5), Err(HistoryError::Empty));
    h.push(pose(10, 0.0, 0.0));
    h.push(pose(20, 0.0, 0.0));
    h.push(pose(30, 0.0, 0.0));
    assert_eq!(h.len(), 2);
    assert_eq!(h.at(15), Err(HistoryError::TooOld(5)));
}

#[test]
fn out_of_order_and_non_finite_states_are_refused() {
    let mut h = StateHistory::new(4, 0);
    assert!(h.push(pose(10, 0.0, 0.0)));
    assert!(!h.push(pose(10, 1.0, 0.0)));
    assert!(!h.push(pose(5, 1.0, 0.0)));
    assert!(!h.push(pose(20, f64::NAN, 0.0)));
    assert_eq!(h.len(), 1);
}

#[test]
fn the_newest_state_a_pose_uses_is_the_one_after_it_or_the_newest() {
    let mut h = StateHistory::new(8, 20_000_000);
    assert_eq!(h.newest_used_ns(5), None);
    h.push(pose(0, 0.0, 0.0));
    // Extrapolated from the newest.
    assert_eq!(h.newest_used_ns(10_000_000), Some(0));
    h.push(pose(100_000_000, 1.0, 0.0));
    h.push(pose(200_000_000, 2.0, 0.0));
    // Interpolated towards the first state after it; the later one plays no part.
    assert_eq!(h.newest_used_ns(25_000_000), Some(100_000_000));
    assert_eq!(h.newest_used_ns(100_000_000), Some(200_000_000));
    assert_eq!(h.newest_used_ns(250_000_000), Some(200_000_000));
}
