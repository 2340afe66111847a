use super::*;

fn hover(x: f64) -> VehicleState {
    let mut s = VehicleState::at_rest(Vector3::new(x, 2.0, 1.5), 0.4);
    s.velocity = Vector3::new(1.0, 0.0, 0.0);
    s
}

fn exact() -> VioParams {
    VioParams {
        position_std_m: 0.0,
        velocity_std_m_s: 0.0,
        attitude_std_rad: 0.0,
        drift_m_per_sqrt_s: 0.0,
        yaw_drift_rad_per_sqrt_s: 0.0,
        ..VioParams::default()
    }
}

#[test]
fn an_error_free_vio_reports_the_true_pose_after_its_latency() {
    let mut vio = Vio::new(exact(), 1);
    vio.step(&hover(3.0), 0);
    assert!(vio.take_due(14_000_000).is_none(), "15 ms latency");
    let s = vio.take_due(15_000_000).expect("due at 15 ms");
    assert_eq!(s.msg.capture_ns, 0);
    assert!((s.odom_from_body.translation[0] - 3.0).abs() < 1e-12);
    assert!((s.velocity[0] - 1.0).abs() < 1e-12);
    let q = s.odom_from_body.rotation_xyzw;
    let yaw = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[3], q[0], q[1], q[2]))
        .euler_angles()
        .2;
    assert!((yaw - 0.4).abs() < 1e-9);
    assert_eq!(s.reset_counter, 0);
    assert!(s.position_variance.iter().all(|v| *v > 0.0));
}

#[test]
fn samples_come_at_the_configured_rate() {
    let mut vio = Vio::new(VioParams::default(), 1);
    let mut n = 0;
    for k in 0..500u64 {
        let t = k * 2_000_000;
        vio.step(&hover(0.0), t);
        while vio.take_due(t).is_some() {
            n += 1;
        }
    }
    // One second at 30 Hz (the last ones still in flight).
    assert!((29..=31).contains(&n), "{n}");
}

#[test]
fn the_frame_drifts_and_resets_jump_it_with_the_counter() {
    let params = VioParams {
        reset_interval_s: 2.0,
        ..exact()
    };
    let mut vio = Vio::new(params, 3);
    let mut last = None;
    let mut jumps = 0;
    for k in 0..10_000u64 {
        let t = k * 2_000_000;
        vio.step(&hover(0.0), t);
        while let Some(s) = vio.take_due(t) {
            if let Some((counter, x)) = last {
                let moved: f64 = s.odom_from_body.translation[0] - x;
                if s.reset_counter != counter {
                    jumps += 1;
                } else {
                    assert!(
                        moved.abs() < 1e-9,
                        "no drift configured, no reset: no motion"
                    );
                }
            }
            last = Some((s.reset_counter, s.odom_from_body.translation[0]));
        }
    }
    // 20 s at one reset per 2 s on average.
    assert!((4..=20).contains(&jumps), "{jumps}");
    assert_eq!(vio.resets(), last.map_or(0, |(c, _)| c));
}

#[test]
fn a_vio_out_of_range_is_refused_naming_the_field() {
    let bad = VioParams {
        latency_ms: -1.0,
        ..VioParams::default()
    };
    assert!(
        bad.validate()
            .unwrap_err()
            .to_string()
            .contains("vio.latency_ms")
    );
}
