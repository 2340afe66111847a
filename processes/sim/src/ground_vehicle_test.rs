//! Tests of `ground_vehicle`.

use super::*;

fn vehicle(path: PathParams, speed: SpeedProfile) -> GroundVehicle {
    GroundVehicle::new(GroundVehicleParams {
        path,
        speed,
        ..GroundVehicleParams::default()
    })
    .unwrap()
}

fn constant(speed_m_s: f64) -> SpeedProfile {
    SpeedProfile::Constant { speed_m_s }
}

fn wrap(a: f64) -> f64 {
    (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
}

fn translation(s: &PadState) -> Vector3<f64> {
    s.world_from_pad.translation.vector
}

#[test]
fn straight_line_has_the_right_speed_heading_and_pad_height() {
    let v = vehicle(
        PathParams::Straight {
            start_m: [1.0, -2.0],
            heading_rad: 0.3,
        },
        constant(5.0),
    );
    let s = v.state_at(10.0);
    let expected = Vector3::new(1.0 + 50.0 * 0.3f64.cos(), -2.0 + 50.0 * 0.3f64.sin(), 0.4);
    assert!((translation(&s) - expected).norm() < 1e-9);
    assert!((s.linear_velocity.norm() - 5.0).abs() < 1e-12);
    assert!((s.linear_velocity.y.atan2(s.linear_velocity.x) - 0.3).abs() < 1e-12);
    assert!((s.world_from_pad.rotation.euler_angles().2 - 0.3).abs() < 1e-12);
    assert_eq!(s.angular_velocity, Vector3::zeros());
}

#[test]
fn circle_keeps_its_radius_and_turns_at_speed_over_radius() {
    for clockwise in [false, true] {
        let v = vehicle(
            PathParams::Circle {
                centre_m: [3.0, 4.0],
                radius_m: 10.0,
                start_angle_rad: 0.5,
                clockwise,
            },
            constant(4.0),
        );
        for k in 1..200 {
            let s = v.state_at(k as f64 * 0.5);
            let r = translation(&s).xy() - Vector2::new(3.0, 4.0);
            assert!((r.norm() - 10.0).abs() < 1e-9);
            assert!(r.dot(&s.linear_velocity.xy()).abs() < 1e-9);
            let expected_rate = if clockwise { -0.4 } else { 0.4 };
            assert!((s.angular_velocity.z - expected_rate).abs() < 1e-12);
            assert!((s.linear_acceleration.norm() - 1.6).abs() < 1e-9);
        }
    }
}

#[test]
fn speeds_above_60_km_h_are_rejected() {
    let too_fast = GroundVehicleParams {
        speed: constant(61.0 / 3.6),
        ..GroundVehicleParams::default()
    };
    let msg = too_fast.validate().unwrap_err().to_string();
    assert!(msg.starts_with("speed.speed_m_s = 16.9"), "{msg}");
    assert!(msg.contains("60 km/h"), "{msg}");
    let ok = GroundVehicleParams {
        speed: constant(60.0 / 3.6),
        ..GroundVehicleParams::default()
    };
    ok.validate().unwrap();
    let gusty = GroundVehicleParams {
        speed: SpeedProfile::Sinusoidal {
            mean_m_s: 15.0,
            amplitude_m_s: 2.0,
            period_s: 10.0,
        },
        ..GroundVehicleParams::default()
    };
    assert!(gusty.validate().is_err());
    let ramp = GroundVehicleParams {
        speed: SpeedProfile::PiecewiseLinear {
            points: vec![[0.0, 0.0], [10.0, 20.0]],
        },
        ..GroundVehicleParams::default()
    };
    assert!(ramp.validate().is_err());
}

#[test]
fn negative_speeds_are_rejected() {
    let p = GroundVehicleParams {
        speed: constant(-1.0),
        ..GroundVehicleParams::default()
    };
    assert!(p.validate().is_err());
    let p = GroundVehicleParams {
        speed: SpeedProfile::Sinusoidal {
            mean_m_s: 1.0,
            amplitude_m_s: 2.0,
            period_s: 10.0,
        },
        ..GroundVehicleParams::default()
    };
    assert!(p.validate().is_err());
}

#[test]
fn figure_eight_is_continuous_in_position_and_heading() {
    let v = vehicle(
        PathParams::FigureEight {
            centre_m: [0.0, 0.0],
            lobe_radius_m: 8.0,
            heading_rad: 0.7,
        },
        constant(6.0),
    );
    let dt = 0.01;
    let mut prev = v.state_at(0.0);
    let mut max_left: f64 = 0.0;
    let mut max_right: f64 = 0.0;
    for k in 1..(40.0 / dt) as usize {
        let s = v.state_at(k as f64 * dt);
        let jump = (translation(&s) - translation(&prev)).norm();
        assert!(jump <= 6.0 * dt * 1.0001, "jump {jump}");
        let dyaw = wrap(
            s.world_from_pad.rotation.euler_angles().2
                - prev.world_from_pad.rotation.euler_angles().2,
        );
        assert!(dyaw.abs() <= 6.0 / 8.0 * dt * 1.0001, "heading jump {dyaw}");
        let side = Vector2::new(-0.7f64.sin(), 0.7f64.cos()).dot(&translation(&s).xy());
        max_left = max_left.max(side);
        max_right = max_right.max(-side);
        prev = s;
    }
    // Both lobes are driven, each 2 r wide.
    assert!((max_left - 16.0).abs() < 0.01 && (max_right - 16.0).abs() < 0.01);
    // One full figure eight is 4 pi r long and returns to the start.
    let period = 4.0 * std::f64::consts::PI * 8.0 / 6.0;
    assert!((translation(&v.state_at(period)) - translation(&v.state_at(0.0))).norm() < 1e-9);
}

#[test]
fn waypoints_are_followed_at_path_speed_and_the_vehicle_stops_at_the_end() {
    let v = vehicle(
        PathParams::Waypoints {
            points_m: vec![[0.0, 0.0], [10.0, 0.0], [10.0, 5.0]],
            closed: false,
        },
        constant(2.0),
    );
    let s = v.state_at(2.5);
    assert!((translation(&s).xy() - Vector2::new(5.0, 0.0)).norm() < 1e-9);
    assert!((s.linear_velocity - Vector3::new(2.0, 0.0, 0.0)).norm() < 1e-12);
    let s = v.state_at(6.0);
    assert!((translation(&s).xy() - Vector2::new(10.0, 2.0)).norm() < 1e-9);
    assert!((s.linear_velocity - Vector3::new(0.0, 2.0, 0.0)).norm() < 1e-12);
    let s = v.state_at(100.0);
    assert!((translation(&s).xy() - Vector2::new(10.0, 5.0)).norm() < 1e-9);
    assert_eq!(s.linear_velocity, Vector3::zeros());
    let closed = vehicle(
        PathParams::Waypoints {
            points_m: vec![[0.0, 0.0], [10.0, 0.0], [10.0, 5.0]],
            closed: true,
        },
        constant(2.0),
    );
    let lap = (10.0 + 5.0 + 125f64.sqrt()) / 2.0;
    let s = closed.state_at(lap + 1.0);
    assert!((translation(&s).xy() - Vector2::new(2.0, 0.0)).norm() < 1e-9);
}

#[test]
fn waypoints_need_two_distinct_points() {
    let p = GroundVehicleParams {
        path: PathParams::Waypoints {
            points_m: vec![[1.0, 1.0], [1.0, 1.0]],
            closed: false,
        },
        ..GroundVehicleParams::default()
    };
    assert!(p.validate().is_err());
}

#[test]
fn the_vehicle_waits_for_its_start_delay() {
    let v = GroundVehicle::new(GroundVehicleParams {
        start_delay_s: 5.0,
        speed: constant(3.0),
        ..GroundVehicleParams::default()
    })
    .unwrap();
    let s = v.state_at(4.0);
    assert_eq!(translation(&s), Vector3::new(0.0, 0.0, 0.4));
    assert_eq!(s.linear_velocity, Vector3::zeros());
    let s = v.state_at(7.0);
    assert!((translation(&s).x - 6.0).abs() < 1e-12);
}

#[test]
fn varying_speed_profiles_integrate_to_the_right_distance() {
    let sin = vehicle(
        PathParams::Straight {
            start_m: [0.0, 0.0],
            heading_rad: 0.0,
        },
        SpeedProfile::Sinusoidal {
            mean_m_s: 5.0,
            amplitude_m_s: 2.0,
            period_s: 8.0,
        },
    );
    // Whole periods: the sinusoid integrates to zero.
    assert!((sin.state_at(16.0).distance_m - 80.0).abs() < 1e-9);
    let pw = vehicle(
        PathParams::Straight {
            start_m: [0.0, 0.0],
            heading_rad: 0.0,
        },
        SpeedProfile::PiecewiseLinear {
            points: vec![[0.0, 0.0], [4.0, 8.0], [6.0, 8.0], [8.0, 4.0]],
        },
    );
    // 16 + 16 + 12 + 4 * 2 (held after the end).
    assert!((pw.state_at(10.0).distance_m - 52.0).abs() < 1e-9);
    assert!((pw.state_at(2.0).speed_m_s - 4.0).abs() < 1e-12);
    assert!((pw.state_at(2.0).linear_acceleration.x - 2.0).abs() < 1e-12);
}

#[test]
fn velocities_match_the_change_of_pose_on_every_path() {
    let paths = [
        PathParams::Straight {
            start_m: [0.0, 0.0],
            heading_rad: -1.0,
        },
        PathParams::Circle {
            centre_m: [0.0, 0.0],
            radius_m: 7.0,
            start_angle_rad: 0.0,
            clockwise: true,
        },
        PathParams::FigureEight {
            centre_m: [1.0, 1.0],
            lobe_radius_m: 5.0,
            heading_rad: 0.0,
        },
    ];
    for path in paths {
        let v = GroundVehicle::new(GroundVehicleParams {
            path,
            speed: SpeedProfile::Sinusoidal {
                mean_m_s: 6.0,
                amplitude_m_s: 3.0,
                period_s: 7.0,
            },
            oscillation: Some(PadOscillation {
                roll_amplitude_rad: 0.05,
                pitch_amplitude_rad: 0.08,
                frequency_hz: 0.7,
            }),
            ..GroundVehicleParams::default()
        })
        .unwrap();
        let h = 1e-5;
        for k in 0..50 {
            let t = 0.37 * k as f64 + 0.01;
            let a = v.state_at(t - h);
            let b = v.state_at(t + h);
            let s = v.state_at(t);
            let v_fd = (translation(&b) - translation(&a)) / (2.0 * h);
            assert!((v_fd - s.linear_velocity).norm() < 1e-5, "t {t}");
            let dq = b.world_from_pad.rotation * a.world_from_pad.rotation.inverse();
            let w_fd = dq.scaled_axis() / (2.0 * h);
            assert!((w_fd - s.angular_velocity).norm() < 1e-5, "t {t}");
        }
    }
}

#[test]
fn pad_oscillation_tilts_the_pad_by_its_amplitude() {
    let v = GroundVehicle::new(GroundVehicleParams {
        oscillation: Some(PadOscillation {
            roll_amplitude_rad: 0.1,
            pitch_amplitude_rad: 0.0,
            frequency_hz: 1.0,
        }),
        ..GroundVehicleParams::default()
    })
    .unwrap();
    let s = v.state_at(0.25);
    let n = s.world_from_pad.rotation * Vector3::z();
    assert!((n.z.acos() - 0.1).abs() < 1e-9);
}

#[test]
fn the_footprint_test_uses_the_pad_frame() {
    let v = GroundVehicle::new(GroundVehicleParams {
        path: PathParams::Straight {
            start_m: [0.0, 0.0],
            heading_rad: std::f64::consts::FRAC_PI_2,
        },
        pad_half_size_m: [1.0, 0.3],
        ..GroundVehicleParams::default()
    })
    .unwrap();
    let s = v.state_at(0.0);
    // Pad x points north: 0.8 m north is inside, 0.8 m east is not.
    assert!(v.is_over_pad(&s, &Vector3::new(0.0, 0.8, 2.0)));
    assert!(!v.is_over_pad(&s, &Vector3::new(0.8, 0.0, 2.0)));
}

#[test]
fn parses_from_toml() {
    let p: GroundVehicleParams = toml::from_str(
        r#"
        start_delay_s = 2.0
        path = { type = "circle", centre_m = [0.0, 0.0], radius_m = 20.0 }
        speed = { type = "piecewise_linear", points = [[0.0, 0.0], [5.0, 10.0]] }
        oscillation = { roll_amplitude_rad = 0.02, pitch_amplitude_rad = 0.03, frequency_hz = 0.5 }
        "#,
    )
    .unwrap();
    p.validate().unwrap();
    assert_eq!(p.pad_height_m, 0.4);
    let bad = toml::from_str::<GroundVehicleParams>(
        r#"
        path = { type = "straight", start_m = [0.0, 0.0], heading_rad = 0.0, radius_m = 3.0 }
        speed = { type = "constant", speed_m_s = 1.0 }
        "#,
    );
    assert!(bad.is_err());
}

fn east(speed_m_s: f64) -> PathParams {
    let _ = speed_m_s;
    PathParams::Straight {
        start_m: [0.0, 0.0],
        heading_rad: 0.0,
    }
}

fn driven(path: PathParams, speed: SpeedProfile, seed: u64) -> GroundVehicle {
    GroundVehicle::new(GroundVehicleParams {
        path,
        speed,
        driver: Some(DriverParams {
            seed,
            ..DriverParams::default()
        }),
        ..GroundVehicleParams::default()
    })
    .unwrap()
}

/// Position differences over 1 ms match the reported velocity (and the speed's
/// derivative the acceleration), so the pad filter and the contact see one motion.
fn assert_consistent(g: &GroundVehicle, from_s: f64, to_s: f64) {
    let dt = 1e-3;
    let mut t = from_s + 0.01;
    while t < to_s {
        let (a, b) = (g.state_at(t), g.state_at(t + dt));
        let v = (translation(&b) - translation(&a)) / dt;
        let reported = (a.linear_velocity + b.linear_velocity) / 2.0;
        assert!(
            (v - reported).norm() < 2e-3,
            "t {t}: moved {v:?}, reported {reported:?}"
        );
        let acc = (b.linear_velocity - a.linear_velocity) / dt;
        let reported = (a.linear_acceleration + b.linear_acceleration) / 2.0;
        assert!(
            (acc - reported).norm() < 2e-2,
            "t {t}: {acc:?} vs {reported:?}"
        );
        t += 0.37;
    }
}

#[test]
fn a_driver_wanders_in_speed_and_heading_around_the_profile_smoothly() {
    let g = driven(east(0.9), constant(0.9), 3);
    let speeds: Vec<f64> = (0..600)
        .map(|k| g.state_at(k as f64 * 0.1).speed_m_s)
        .collect();
    let mean = speeds.iter().sum::<f64>() / speeds.len() as f64;
    let std = (speeds.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / speeds.len() as f64).sqrt();
    assert!((mean - 0.9).abs() < 0.05, "mean {mean}");
    assert!(
        std > 0.04 && std < 0.14,
        "speed std {std} (10 % of 0.9 expected)"
    );
    let heading_off: Vec<f64> = (0..600)
        .map(|k| {
            wrap(
                g.state_at(k as f64 * 0.1)
                    .world_from_pad
                    .rotation
                    .euler_angles()
                    .2,
            )
        })
        .collect();
    let max_off = heading_off.iter().fold(0.0f64, |m, h| m.max(h.abs()));
    assert!(
        max_off > 0.005 && max_off < 0.08,
        "heading wander {max_off} rad"
    );
    let max_acc = (0..600)
        .map(|k| g.state_at(k as f64 * 0.1).linear_acceleration.norm())
        .fold(0.0f64, f64::max);
    assert!(max_acc < 0.3, "gentle: {max_acc} m/s^2");
    assert_consistent(&g, 0.0, 60.0);
}

#[test]
fn the_driver_is_the_same_for_a_seed_and_differs_between_seeds() {
    let at = |seed| translation(&driven(east(0.9), constant(0.9), seed).state_at(30.0));
    assert_eq!(at(4), at(4));
    assert!((at(4) - at(5)).norm() > 0.01);
}

#[test]
fn a_parked_vehicle_with_a_driver_stays_parked() {
    let g = driven(east(0.0), constant(0.0), 3);
    for k in 0..100 {
        let s = g.state_at(k as f64 * 0.3);
        assert!(translation(&s).xy().norm() < 1e-12 && s.linear_velocity.norm() < 1e-12);
    }
}

#[test]
fn braking_to_a_stop_through_a_driver_ends_parked() {
    let g = driven(
        east(0.9),
        SpeedProfile::PiecewiseLinear {
            points: vec![[0.0, 0.9], [10.0, 0.9], [12.0, 0.0]],
        },
        7,
    );
    let stopped = g.state_at(40.0);
    assert!(stopped.speed_m_s < 1e-9, "{}", stopped.speed_m_s);
    assert_eq!(
        translation(&g.state_at(40.0)),
        translation(&g.state_at(50.0))
    );
}

#[test]
fn a_corner_turns_ninety_degrees_on_its_arc_and_drives_on() {
    let g = vehicle(
        PathParams::Corner {
            start_m: [0.0, 0.0],
            heading_rad: 0.0,
            straight_m: 5.0,
            radius_m: 3.0,
            turn_rad: std::f64::consts::FRAC_PI_2,
        },
        constant(1.0),
    );
    let before = g.state_at(4.0);
    assert!((translation(&before) - Vector3::new(4.0, 0.0, 0.4)).norm() < 1e-9);
    // Half way round the arc (5 m + 3 pi / 4 m).
    let mid = g.state_at(5.0 + 3.0 * std::f64::consts::FRAC_PI_4);
    let h = mid.world_from_pad.rotation.euler_angles().2;
    assert!((h - std::f64::consts::FRAC_PI_4).abs() < 1e-9, "{h}");
    assert!((mid.angular_velocity.z - 1.0 / 3.0).abs() < 1e-9);
    // After it: heading north from (8, 3).
    let after = g.state_at(5.0 + 3.0 * std::f64::consts::FRAC_PI_2 + 2.0);
    assert!(
        (translation(&after) - Vector3::new(8.0, 5.0, 0.4)).norm() < 1e-9,
        "{after:?}"
    );
    assert!(
        (after.world_from_pad.rotation.euler_angles().2 - std::f64::consts::FRAC_PI_2).abs() < 1e-9
    );
    assert_consistent(&g, 0.0, 15.0);
}

#[test]
fn a_lane_change_moves_the_vehicle_sideways_smoothly_and_stays_there() {
    let g = GroundVehicle::new(GroundVehicleParams {
        path: east(0.9),
        speed: constant(0.9),
        lane_change: Some(LaneChange {
            at_s: 5.0,
            offset_m: 1.0,
            duration_s: 3.0,
        }),
        ..GroundVehicleParams::default()
    })
    .unwrap();
    assert!(translation(&g.state_at(4.9)).y.abs() < 1e-12);
    let mid = g.state_at(6.5);
    assert!((translation(&mid).y - 0.5).abs() < 1e-9);
    assert!(
        mid.world_from_pad.rotation.euler_angles().2 > 0.3,
        "it heads left while moving over"
    );
    assert!((translation(&g.state_at(9.0)).y - 1.0).abs() < 1e-12);
    assert_consistent(&g, 0.0, 12.0);
}
