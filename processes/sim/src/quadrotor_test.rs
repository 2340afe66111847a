//! Tests of `quadrotor`.

use super::*;

const DT: f64 = 0.002;

fn hover_commands(params: &AirframeParams) -> MotorCommands {
    MotorCommands::uniform(params.hover_thrust_normalized())
}

#[test]
fn default_airframe_is_a_valid_p450_with_thrust_to_weight_above_2_5() {
    let p = AirframeParams::default();
    p.validate().unwrap();
    assert!((p.mass_kg - 1.5).abs() < 0.2);
    assert!(p.thrust_to_weight() >= 2.5, "{}", p.thrust_to_weight());
}

#[test]
fn racer_airframe_is_valid_with_thrust_to_weight_near_4_5_and_lower_drag() {
    let r = AirframeParams::racer();
    r.validate().unwrap();
    assert!(
        (r.thrust_to_weight() - 4.5).abs() < 0.3,
        "{}",
        r.thrust_to_weight()
    );
    let d = AirframeParams::default();
    assert!(r.drag_coefficients_n_s_m[0] < d.drag_coefficients_n_s_m[0]);
}

#[test]
fn validation_names_the_field_and_the_rule() {
    let p = AirframeParams {
        mass_kg: -1.0,
        ..AirframeParams::default()
    };
    assert_eq!(
        p.validate().unwrap_err().to_string(),
        "mass_kg = -1: must be > 0"
    );
    let p = AirframeParams {
        motor_speed_max_rad_s: 100.0,
        ..AirframeParams::default()
    };
    let msg = p.validate().unwrap_err().to_string();
    assert!(msg.starts_with("motor_speed_max_rad_s = 100"), "{msg}");
    let p = AirframeParams {
        thrust_coefficient: 1e-7,
        ..AirframeParams::default()
    };
    assert!(
        p.validate()
            .unwrap_err()
            .to_string()
            .contains("thrust-to-weight")
    );
}

#[test]
fn airframe_parses_from_toml_and_rejects_unknown_fields() {
    let p: AirframeParams = toml::from_str("mass_kg = 2.0\narm_length_m = 0.3").unwrap();
    assert_eq!(p.mass_kg, 2.0);
    assert_eq!(
        p.thrust_coefficient,
        AirframeParams::default().thrust_coefficient
    );
    assert!(toml::from_str::<AirframeParams>("mass = 2.0").is_err());
}

#[test]
fn resting_on_the_ground_with_motors_off_stays_exactly_still() {
    let start = VehicleState::at_rest(Vector3::new(1.0, 2.0, 0.0), 0.3);
    let mut q = Quadrotor::new(AirframeParams::default(), start, &Surface::ground()).unwrap();
    for _ in 0..5000 {
        let r = q
            .step(DT, &MotorCommands::off(), &Environment::default())
            .unwrap();
        assert_eq!(r.contact, ContactState::Resting { surface_id: 0 });
        assert!(r.impact.is_none());
    }
    let s = q.state();
    assert!((s.position - start.position).norm() < 1e-12);
    assert!(s.velocity.norm() < 1e-12);
    assert!((s.yaw_rad() - 0.3).abs() < 1e-9);
}

#[test]
fn resting_on_the_ground_in_wind_with_idle_motors_stays_still() {
    let start = VehicleState::at_rest(Vector3::zeros(), 0.0);
    let mut q = Quadrotor::new(AirframeParams::default(), start, &Surface::ground()).unwrap();
    let env = Environment {
        wind_world: Vector3::new(8.0, 0.0, 0.0),
        ..Environment::default()
    };
    for _ in 0..2000 {
        q.step(DT, &MotorCommands::uniform(0.0), &env).unwrap();
    }
    assert!(q.state().position.norm() < 1e-12);
    assert!(
        q.state()
            .motor_speeds
            .iter()
            .all(|w| (w - 120.0).abs() < 1.0)
    );
}

#[test]
fn hover_thrust_holds_a_free_vehicle_nearly_still() {
    let p = AirframeParams::default();
    let mut start = VehicleState::at_rest(Vector3::new(0.0, 0.0, 2.0), 0.0);
    let w = (p.hover_thrust_normalized()).sqrt() * p.motor_speed_max_rad_s;
    start.motor_speeds = [w; 4];
    let mut q = Quadrotor::new(p.clone(), start, &Surface::ground()).unwrap();
    for _ in 0..500 {
        q.step(DT, &hover_commands(&p), &Environment::default())
            .unwrap();
    }
    let s = q.state();
    assert!((s.position.z - 2.0).abs() < 1e-6, "{}", s.position.z);
    assert!(s.body_rates.norm() < 1e-9);
}

#[test]
fn full_thrust_climbs_with_the_expected_acceleration() {
    let p = AirframeParams::default();
    let start = VehicleState::at_rest(Vector3::zeros(), 0.0);
    let mut q = Quadrotor::new(p.clone(), start, &Surface::ground()).unwrap();
    let mut lifted = false;
    for _ in 0..500 {
        let r = q
            .step(DT, &MotorCommands::uniform(1.0), &Environment::default())
            .unwrap();
        lifted |= r.lifted_off;
    }
    assert!(lifted);
    assert_eq!(q.contact(), ContactState::Airborne);
    // After 1 s the motors are at full speed; vertical acceleration is
    // (T/W - 1) g minus drag.
    let expected = (p.thrust_to_weight() - 1.0) * GRAVITY_M_S2;
    let v = q.state().velocity.z;
    assert!(v > 0.6 * expected && v < expected, "v {v}, a {expected}");
}

#[test]
fn differential_thrust_rolls_and_yaw_torque_yaws_the_expected_way() {
    let p = AirframeParams::default();
    let h = p.hover_thrust_normalized();
    let mut start = VehicleState::at_rest(Vector3::new(0.0, 0.0, 5.0), 0.0);
    start.motor_speeds = [h.sqrt() * p.motor_speed_max_rad_s; 4];
    // More thrust on the left motors (indices 1 and 2) rolls right: +x rotation in FLU.
    let mut q = Quadrotor::new(p.clone(), start, &Surface::ground()).unwrap();
    let cmd = MotorCommands {
        armed: true,
        thrust: [h - 0.05, h + 0.05, h + 0.05, h - 0.05],
    };
    for _ in 0..50 {
        q.step(DT, &cmd, &Environment::default()).unwrap();
    }
    assert!(q.state().body_rates.x > 0.1, "{:?}", q.state().body_rates);
    // More thrust on the clockwise motors (2, 3) yaws left (+z in FLU).
    let mut q = Quadrotor::new(p.clone(), start, &Surface::ground()).unwrap();
    let cmd = MotorCommands {
        armed: true,
        thrust: [h - 0.05, h - 0.05, h + 0.05, h + 0.05],
    };
    for _ in 0..50 {
        q.step(DT, &cmd, &Environment::default()).unwrap();
    }
    assert!(q.state().body_rates.z > 0.01, "{:?}", q.state().body_rates);
    assert!(q.state().body_rates.xy().norm() < 1e-6);
}

#[test]
fn wind_pushes_a_hovering_vehicle_downwind_through_drag() {
    let p = AirframeParams::default();
    let mut start = VehicleState::at_rest(Vector3::new(0.0, 0.0, 10.0), 0.0);
    start.motor_speeds = [p.hover_thrust_normalized().sqrt() * p.motor_speed_max_rad_s; 4];
    let mut q = Quadrotor::new(p.clone(), start, &Surface::ground()).unwrap();
    let env = Environment {
        wind_world: Vector3::new(0.0, 5.0, 0.0),
        ..Environment::default()
    };
    q.step(DT, &hover_commands(&p), &env).unwrap();
    let a = q.state().velocity.y / DT;
    let expected = p.drag_coefficients_n_s_m[1] * 5.0 / p.mass_kg;
    assert!(
        (a - expected).abs() < 0.01 * expected,
        "a {a} expected {expected}"
    );
}

#[test]
fn quaternion_stays_normalized_while_spinning() {
    let p = AirframeParams::default();
    let mut start = VehicleState::at_rest(Vector3::new(0.0, 0.0, 100.0), 0.0);
    start.body_rates = Vector3::new(3.0, -2.0, 1.0);
    let mut q = Quadrotor::new(p, start, &Surface::ground()).unwrap();
    for _ in 0..2000 {
        q.step(DT, &MotorCommands::off(), &Environment::default())
            .unwrap();
        let n = q.state().world_from_body.into_inner().norm();
        assert!((n - 1.0).abs() < 1e-12);
    }
}

#[test]
fn a_spinning_body_conserves_angular_momentum_without_torque() {
    // Motors off, no drag: only the gyroscopic coupling acts.
    let p = AirframeParams {
        inertia_diag_kg_m2: [0.01, 0.02, 0.03],
        angular_drag_coefficients_n_m_s: [0.0; 3],
        ..AirframeParams::default()
    };
    let mut start = VehicleState::at_rest(Vector3::new(0.0, 0.0, 1000.0), 0.0);
    start.body_rates = Vector3::new(0.1, 2.0, 0.1);
    let mut q = Quadrotor::new(p.clone(), start, &Surface::ground()).unwrap();
    let h0 = start.world_from_body * (p.inertia_matrix() * start.body_rates);
    for _ in 0..1000 {
        q.step(DT, &MotorCommands::off(), &Environment::default())
            .unwrap();
    }
    let s = q.state();
    let h1 = s.world_from_body * (p.inertia_matrix() * s.body_rates);
    assert!((h1 - h0).norm() < 1e-6 * h0.norm(), "{h0:?} {h1:?}");
}

#[test]
fn falling_onto_the_ground_reports_the_impact_velocity_and_stops_without_bouncing() {
    let start = VehicleState::at_rest(Vector3::new(0.0, 0.0, 1.0), 0.0);
    let mut q = Quadrotor::new(AirframeParams::default(), start, &Surface::ground()).unwrap();
    let mut impact = None;
    for _ in 0..1000 {
        let r = q
            .step(DT, &MotorCommands::off(), &Environment::default())
            .unwrap();
        if r.impact.is_some() {
            assert!(impact.is_none(), "only one impact");
            impact = r.impact;
        }
        assert!(q.state().position.z >= 0.0);
    }
    let impact = impact.unwrap();
    let free_fall = (2.0 * GRAVITY_M_S2 * 1.0_f64).sqrt();
    assert!((impact.relative_velocity.z + free_fall).abs() < 0.15 * free_fall);
    assert_eq!(q.state().position.z, 0.0);
    assert_eq!(q.state().velocity, Vector3::zeros());
}

#[test]
fn a_vehicle_on_a_moving_tilted_pad_rides_with_it() {
    let rot = UnitQuaternion::from_euler_angles(0.05, 0.0, 0.4);
    let mut surface = Surface {
        id: 1,
        world_from_surface: Isometry3::from_parts(Translation3::new(0.0, 0.0, 0.4), rot),
        linear_velocity: Vector3::new(3.0, 1.0, 0.0),
        angular_velocity: Vector3::new(0.0, 0.0, 0.2),
    };
    let start = VehicleState::at_rest(Vector3::new(0.0, 0.0, 0.4), 0.0);
    let mut q = Quadrotor::new(AirframeParams::default(), start, &surface).unwrap();
    assert_eq!(q.contact(), ContactState::Resting { surface_id: 1 });
    let rel0 = surface
        .world_from_surface
        .inverse_transform_point(&q.state().position.into());
    for k in 1..=1000 {
        let t = k as f64 * DT;
        let yaw = 0.4 + 0.2 * t;
        surface.world_from_surface = Isometry3::from_parts(
            Translation3::new(3.0 * t, 1.0 * t, 0.4),
            UnitQuaternion::from_euler_angles(0.05, 0.0, yaw),
        );
        let env = Environment {
            surface,
            ..Environment::default()
        };
        let r = q.step(DT, &MotorCommands::off(), &env).unwrap();
        assert_eq!(r.contact, ContactState::Resting { surface_id: 1 });
    }
    let rel1 = surface
        .world_from_surface
        .inverse_transform_point(&q.state().position.into());
    assert!((rel1 - rel0).norm() < 1e-9);
    let body_up = q.state().world_from_body * Vector3::z();
    assert!((body_up - surface.normal()).norm() < 1e-9);
}

#[test]
fn invalid_step_inputs_are_errors_and_leave_the_state_untouched() {
    let start = VehicleState::at_rest(Vector3::new(0.0, 0.0, 3.0), 0.0);
    let mut q = Quadrotor::new(AirframeParams::default(), start, &Surface::ground()).unwrap();
    let before = *q.state();
    assert!(
        q.step(f64::NAN, &MotorCommands::off(), &Environment::default())
            .is_err()
    );
    assert!(
        q.step(0.0, &MotorCommands::off(), &Environment::default())
            .is_err()
    );
    let bad = MotorCommands {
        armed: true,
        thrust: [f64::NAN, 0.5, 0.5, 0.5],
    };
    assert!(q.step(DT, &bad, &Environment::default()).is_err());
    let env = Environment {
        wind_world: Vector3::new(f64::INFINITY, 0.0, 0.0),
        ..Environment::default()
    };
    assert!(q.step(DT, &MotorCommands::off(), &env).is_err());
    assert_eq!(*q.state(), before);
}

#[test]
fn motor_speeds_follow_commands_with_the_configured_lag_and_limits() {
    let p = AirframeParams::default();
    let start = VehicleState::at_rest(Vector3::new(0.0, 0.0, 50.0), 0.0);
    let mut q = Quadrotor::new(p.clone(), start, &Surface::ground()).unwrap();
    let steps = (p.motor_time_constant_s / DT).round() as usize;
    for _ in 0..steps {
        q.step(DT, &MotorCommands::uniform(2.0), &Environment::default())
            .unwrap();
    }
    let w = q.state().motor_speeds[0];
    let t = steps as f64 * DT;
    let expected = p.motor_speed_max_rad_s * (1.0 - (-t / p.motor_time_constant_s).exp());
    assert!((w - expected).abs() < 0.01 * expected, "{w} vs {expected}");
    for _ in 0..500 {
        q.step(DT, &MotorCommands::uniform(2.0), &Environment::default())
            .unwrap();
    }
    assert!(q.state().motor_speeds[0] <= p.motor_speed_max_rad_s + 1e-9);
}
