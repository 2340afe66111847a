//! Tests of `autopilot`.

use super::*;

fn level_state(position: Vector3<f64>) -> EstimatedState {
    EstimatedState {
        position,
        velocity: Vector3::zeros(),
        world_from_body: UnitQuaternion::identity(),
        body_rates: Vector3::zeros(),
        landed: false,
    }
}

/// An autopilot already flying (PX4 boots landed; these tests start in the air).
fn flying() -> Autopilot {
    let mut ap = Autopilot::new(AutopilotParams::default()).unwrap();
    ap.place(true);
    ap
}

#[test]
fn default_params_are_valid_and_match_px4_defaults() {
    let p = AutopilotParams::default();
    p.validate().unwrap();
    assert_eq!(p.mpc_xy_p, 0.95);
    assert_eq!(p.mc_roll_p, 6.5);
    assert!((p.mc_rollrate_p - 0.15).abs() < 1e-12);
    AutopilotParams::racer().validate().unwrap();
}

#[test]
fn params_parse_from_toml_with_px4_names() {
    let p: AutopilotParams = toml::from_str("MPC_XY_P = 1.2\nMPC_TILTMAX_AIR = 30.0").unwrap();
    assert_eq!(p.mpc_xy_p, 1.2);
    assert_eq!(p.mpc_tiltmax_air, 30.0);
    assert!(toml::from_str::<AutopilotParams>("MPC_XY_PP = 1.0").is_err());
}

#[test]
fn validation_rejects_a_hover_thrust_outside_the_thrust_limits() {
    let p = AutopilotParams {
        mpc_thr_hover: 1.5,
        ..AutopilotParams::default()
    };
    let msg = p.validate().unwrap_err().to_string();
    assert!(msg.starts_with("MPC_THR_HOVER = 1.5"), "{msg}");
    let p = AutopilotParams {
        mpc_tiltmax_air: 95.0,
        ..AutopilotParams::default()
    };
    assert!(p.validate().is_err());
}

#[test]
fn mixer_gives_hover_thrust_on_every_motor_without_torque() {
    let m = mix(0.4, &Vector3::zeros());
    assert!(m.motors.iter().all(|u| (u - 0.4).abs() < 1e-12));
    assert!(!m.saturated);
}

#[test]
fn mixer_keeps_roll_and_pitch_before_yaw_when_saturated() {
    let torque = Vector3::new(0.3, 0.0, 0.8);
    let m = mix(0.5, &torque);
    let cols = mixer_columns();
    let roll: f64 = (0..4).map(|i| cols[0][i] * m.motors[i]).sum::<f64>() / 2.0;
    let yaw: f64 = (0..4).map(|i| cols[2][i] * m.motors[i]).sum::<f64>() / 4.0;
    assert!((roll - 0.3).abs() < 1e-9, "roll {roll}");
    assert!(yaw < 0.8 && yaw > 0.0, "yaw {yaw}");
    assert!(m.saturated);
    assert!(m.motors.iter().all(|u| (0.0..=1.0).contains(u)));
}

#[test]
fn mixer_never_raises_thrust_to_unsaturate() {
    let m = mix(0.05, &Vector3::new(0.5, 0.0, 0.0));
    let mean: f64 = m.motors.iter().sum::<f64>() / 4.0;
    assert!(mean <= 0.05 + 1e-9, "mean {mean}");
    assert!(m.saturation.positive[0]);
}

#[test]
fn attitude_from_thrust_is_level_for_vertical_thrust_and_keeps_the_heading() {
    let q = attitude_from_thrust(&Vector3::new(0.0, 0.0, 0.5), 1.0);
    assert!((yaw_of(&q) - 1.0).abs() < 1e-12);
    assert!(((q * Vector3::z()) - Vector3::z()).norm() < 1e-12);
    // Thrust toward +x (east) with heading east: nose down, pitch positive in FLU.
    let q = attitude_from_thrust(&Vector3::new(0.2, 0.0, 0.5), 0.0);
    let (_, pitch, yaw) = q.euler_angles();
    assert!(pitch > 0.0 && yaw.abs() < 1e-12);
}

#[test]
fn tilt_is_limited_to_the_maximum() {
    let z = limit_tilt(&Vector3::new(1.0, 0.0, 0.1).normalize(), 45f64.to_radians());
    assert!((z.z.acos() - 45f64.to_radians()).abs() < 1e-12);
    assert!((z.norm() - 1.0).abs() < 1e-12);
}

#[test]
fn constrain_xy_prefers_the_position_correction_over_feed_forward() {
    use nalgebra::Vector2;
    let v = constrain_xy(&Vector2::new(3.0, 0.0), &Vector2::new(0.0, 10.0), 5.0);
    assert!((v.norm() - 5.0).abs() < 1e-9);
    assert!((v.x - 3.0).abs() < 1e-9);
    let v = constrain_xy(&Vector2::new(8.0, 0.0), &Vector2::new(0.0, 10.0), 5.0);
    assert!((v - Vector2::new(5.0, 0.0)).norm() < 1e-9);
}

#[test]
fn attitude_error_produces_a_correcting_rate() {
    let ap = Autopilot::new(AutopilotParams::default()).unwrap();
    let q = UnitQuaternion::from_euler_angles(0.1, 0.0, 0.0);
    let rate = ap.attitude_control(&q, &UnitQuaternion::identity(), 0.0);
    assert!(rate.x < -0.5, "{rate:?}");
    assert!(rate.y.abs() < 1e-9 && rate.z.abs() < 1e-9);
}

#[test]
fn yaw_error_is_corrected_with_reduced_priority() {
    let ap = Autopilot::new(AutopilotParams::default()).unwrap();
    let q = UnitQuaternion::from_euler_angles(0.0, 0.0, 0.1);
    let rate = ap.attitude_control(&q, &UnitQuaternion::identity(), 0.0);
    // Small errors: yaw weight 0.4 cancels the division of MC_YAW_P by it.
    assert!((rate.z + 0.1 * 2.8).abs() < 0.02, "{rate:?}");
}

#[test]
fn hover_setpoint_at_the_current_position_gives_hover_thrust() {
    let mut ap = flying();
    let out = ap.update(
        0.002,
        &level_state(Vector3::new(0.0, 0.0, 2.0)),
        &Setpoint::position(Vector3::new(0.0, 0.0, 2.0), 0.0),
    );
    let hover = ap.params().mpc_thr_hover;
    assert!(
        out.motors.iter().all(|u| (u - hover).abs() < 1e-9),
        "{:?}",
        out.motors
    );
    assert!(!out.status.any());
}

#[test]
fn an_empty_setpoint_brakes_and_is_flagged() {
    let mut ap = flying();
    let mut s = level_state(Vector3::new(0.0, 0.0, 2.0));
    s.velocity = Vector3::new(2.0, 0.0, 0.0);
    let out = ap.update(0.002, &s, &Setpoint::default());
    assert!(out.status.incomplete_setpoint);
    assert!(out.acceleration_setpoint.x < -1.0);
    assert_eq!(out.velocity_setpoint, Vector3::zeros());
}

#[test]
fn the_velocity_setpoint_respects_the_speed_limits() {
    let mut ap = flying();
    let s = level_state(Vector3::new(0.0, 0.0, 2.0));
    let out = ap.update(
        0.002,
        &s,
        &Setpoint::position(Vector3::new(100.0, 0.0, -50.0), 0.0),
    );
    assert!((out.velocity_setpoint.xy().norm() - 12.0).abs() < 1e-9);
    assert!((out.velocity_setpoint.z + 1.5).abs() < 1e-9);
    let tilt = out.attitude_setpoint.angle();
    assert!(tilt <= 45f64.to_radians() + 1e-9);
}

#[test]
fn landed_vehicles_do_not_wind_up_their_integrators() {
    let mut ap = Autopilot::new(AutopilotParams::default()).unwrap();
    let mut s = level_state(Vector3::zeros());
    s.landed = true;
    for _ in 0..5000 {
        ap.update(
            0.002,
            &s,
            &Setpoint::position(Vector3::new(0.0, 0.0, -1.0), 0.0),
        );
    }
    assert_eq!(ap.velocity_integral, Vector3::zeros());
    assert_eq!(ap.rate_integral, Vector3::zeros());
}

#[test]
fn reset_clears_the_integrators() {
    let mut ap = flying();
    let s = level_state(Vector3::zeros());
    for _ in 0..100 {
        ap.update(
            0.002,
            &s,
            &Setpoint::position(Vector3::new(1.0, 1.0, 1.0), 0.5),
        );
    }
    assert_ne!(ap.velocity_integral, Vector3::zeros());
    ap.reset();
    assert_eq!(ap.velocity_integral, Vector3::zeros());
    assert_eq!(ap.rate_integral, Vector3::zeros());
    assert_eq!(ap.yaw_hold, None);
}

fn assert_all_finite(out: &ControlOutput) {
    assert!(output_is_finite(out), "{out:?}");
    assert!(out.motors.iter().all(|m| (0.0..=1.0).contains(m)));
}

#[test]
fn non_finite_inputs_never_produce_nan_outputs() {
    let bad_values = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY];
    let mut ap = flying();
    let good = level_state(Vector3::new(1.0, 2.0, 3.0));
    let sp = Setpoint::position(Vector3::new(0.0, 0.0, 3.0), 0.2)
        .with_velocity(Vector3::new(1.0, 0.0, 0.0))
        .with_acceleration(Vector3::new(0.0, 0.5, 0.0));
    for bad in bad_values {
        for field in 0..5 {
            for axis in 0..3 {
                let mut s = good;
                match field {
                    0 => s.position[axis] = bad,
                    1 => s.velocity[axis] = bad,
                    2 => s.body_rates[axis] = bad,
                    3 => {
                        let mut q = s.world_from_body.into_inner();
                        q.coords[axis] = bad;
                        s.world_from_body = UnitQuaternion::new_unchecked(q);
                    }
                    _ => {}
                }
                for dt in [0.002, bad, 0.0, -1.0] {
                    let out = ap.update(dt, &s, &sp);
                    assert_all_finite(&out);
                    assert!(out.status.any() || field == 4 && dt == 0.002);
                    // The controller recovers on the next good input.
                    let out = ap.update(0.002, &good, &sp);
                    assert_all_finite(&out);
                }
            }
        }
        for axis in 0..3 {
            let mut bad_sp = sp;
            bad_sp.position[axis] = Some(bad);
            bad_sp.velocity[(axis + 1) % 3] = Some(bad);
            bad_sp.acceleration[(axis + 2) % 3] = Some(bad);
            bad_sp.yaw = Some(bad);
            bad_sp.yaw_rate = Some(bad);
            let out = ap.update(0.002, &good, &bad_sp);
            assert_all_finite(&out);
            assert!(out.status.invalid_setpoint);
        }
    }
}

#[test]
fn a_lost_attitude_gives_level_hover_thrust_and_a_flag() {
    let mut ap = Autopilot::new(AutopilotParams::default()).unwrap();
    let mut s = level_state(Vector3::zeros());
    s.world_from_body =
        UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(0.0, 0.0, 0.0, 0.0));
    let out = ap.update(0.002, &s, &Setpoint::default());
    assert!(out.status.attitude_lost);
    let hover = ap.params().mpc_thr_hover;
    assert!(out.motors.iter().all(|m| *m == hover));
}

#[test]
fn extreme_but_finite_inputs_stay_within_limits() {
    let mut ap = flying();
    let mut s = level_state(Vector3::new(1e12, -1e12, 1e9));
    s.velocity = Vector3::new(1e9, 1e9, -1e9);
    s.body_rates = Vector3::new(1e6, -1e6, 1e6);
    s.world_from_body = UnitQuaternion::from_euler_angles(3.0, 1.0, -2.0);
    let sp = Setpoint::position(Vector3::new(-1e12, 1e12, -1e9), 1e9)
        .with_acceleration(Vector3::new(1e15, 0.0, -1e15));
    for _ in 0..100 {
        let out = ap.update(0.002, &s, &sp);
        assert_all_finite(&out);
    }
}

#[test]
fn a_decoupled_tilt_sheds_horizontal_thrust_while_accelerating_down() {
    // PX4's MPC_ACC_DECOUPLE: 1 (its default) sets the tilt against gravity alone, so
    // the collective's cut for a descent cuts the horizontal thrust by the same share;
    // 0 tilts further and keeps it. In wind, a drop onto the pad drifts downwind with 1.
    let horizontal = |decouple: u8| {
        let params = AutopilotParams {
            mpc_acc_decouple: decouple,
            ..AutopilotParams::default()
        };
        let mut ap = Autopilot::new(params).unwrap();
        ap.place(true);
        let sp = Setpoint {
            velocity: [Some(1.0), Some(0.0), Some(-1.5)],
            ..Setpoint::default()
        };
        let out = ap.update(0.002, &level_state(Vector3::new(0.0, 0.0, 2.0)), &sp);
        let a = out.acceleration_setpoint;
        (out.thrust_setpoint.xy().norm(), a.z)
    };
    let (kept, az) = horizontal(0);
    let (shed, _) = horizontal(1);
    assert!(az < -1.0, "the descent asks {az} m/s^2");
    let share = 1.0 + az / GRAVITY_M_S2;
    assert!(
        (shed / kept - share).abs() < 0.02,
        "decoupled {shed:.4}, coupled {kept:.4}: {:.3} of it, the collective's share {share:.3}",
        shed / kept
    );
}
