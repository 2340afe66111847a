//! Tests of `quadrotor`.

use super::*;
use nalgebra::Translation3;

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
    let sunk = Vector3::new(0.0, 0.0, AirframeParams::default().static_deflection_m());
    assert!((s.position - (start.position - sunk)).norm() < 1e-12);
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
    // The drag leans on the gear's friction springs: it gives, it does not slide.
    let sunk = AirframeParams::default().static_deflection_m();
    assert!(
        q.state().position.xy().norm() < 1e-3,
        "{:?}",
        q.state().position
    );
    assert!((q.state().position.z + sunk).abs() < 1e-3);
    assert!(q.state().velocity.norm() < 1e-6);
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
fn falling_onto_the_ground_reports_the_impact_velocity_and_bounces_by_the_gear_restitution() {
    let start = VehicleState::at_rest(Vector3::new(0.0, 0.0, 0.3), 0.0);
    let p = AirframeParams::default();
    let mut q = Quadrotor::new(p.clone(), start, &Surface::ground()).unwrap();
    let (mut impacts, mut rebound) = (Vec::new(), 0.0_f64);
    for _ in 0..2000 {
        let r = q
            .step(DT, &MotorCommands::off(), &Environment::default())
            .unwrap();
        impacts.extend(r.impact);
        if impacts.len() == 1 {
            rebound = rebound.max(q.state().velocity.z);
        }
    }
    // Air drag takes a few percent off the free fall.
    let free_fall = (2.0 * GRAVITY_M_S2 * 0.3_f64).sqrt();
    let first = impacts[0];
    assert!(
        (first.relative_velocity.z + free_fall).abs() < 0.05 * free_fall,
        "{first:?}"
    );
    // It leaves the ground again at about the restitution times the impact speed.
    assert!(impacts.len() >= 2, "{impacts:?}");
    let e = rebound / free_fall;
    assert!((e - p.gear_restitution).abs() < 0.1, "restitution {e}");
    // And comes to rest on its gear.
    assert_eq!(q.contact(), ContactState::Resting { surface_id: 0 });
    assert!((q.state().position.z + p.static_deflection_m()).abs() < 1e-4);
    assert!(q.state().velocity.norm() < 1e-3);
}

fn pad_surface(t: f64, velocity: Vector3<f64>, yaw_rate: f64) -> Surface {
    Surface {
        id: 1,
        world_from_surface: Isometry3::from_parts(
            Translation3::new(velocity.x * t, velocity.y * t, 0.4),
            UnitQuaternion::from_euler_angles(0.05, 0.0, 0.4 + yaw_rate * t),
        ),
        linear_velocity: velocity,
        angular_velocity: Vector3::new(0.0, 0.0, yaw_rate),
        half_extent_m: Some([0.5, 0.5]),
    }
}

#[test]
fn a_vehicle_on_a_moving_tilted_pad_rides_with_it() {
    let velocity = Vector3::new(3.0, 1.0, 0.0);
    let mut surface = pad_surface(0.0, velocity, 0.2);
    let start = VehicleState::at_rest(Vector3::new(0.0, 0.0, 0.4), 0.0);
    let mut q = Quadrotor::new(AirframeParams::default(), start, &surface).unwrap();
    assert_eq!(q.contact(), ContactState::Resting { surface_id: 1 });
    let rel0 = surface
        .world_from_surface
        .inverse_transform_point(&q.state().position.into());
    for k in 1..=1000 {
        surface = pad_surface(k as f64 * DT, velocity, 0.2);
        let env = Environment {
            platform: Some(surface),
            ..Environment::default()
        };
        let r = q.step(DT, &MotorCommands::off(), &env).unwrap();
        assert_eq!(r.contact, ContactState::Resting { surface_id: 1 });
    }
    let rel1 = surface
        .world_from_surface
        .inverse_transform_point(&q.state().position.into());
    // Friction holds it: the gear's springs give a millimetre, it does not slide.
    assert!((rel1 - rel0).norm() < 2e-3, "{rel0:?} -> {rel1:?}");
    let body_up = q.state().world_from_body * Vector3::z();
    assert!((body_up - surface.normal()).norm() < 1e-2);
}

/// Drops the vehicle from 2 cm onto the ground moving sideways at `speed` along
/// body x, motors off; returns the state after `seconds`.
fn touch_down_sliding(params: AirframeParams, speed: f64, seconds: f64) -> (VehicleState, f64) {
    let mut start = VehicleState::at_rest(Vector3::new(0.0, 0.0, 0.02), 0.0);
    start.velocity = Vector3::new(speed, 0.0, 0.0);
    let mut q = Quadrotor::new(params, start, &Surface::ground()).unwrap();
    let mut max_tilt = 0.0_f64;
    for _ in 0..(seconds / DT) as usize {
        q.step(DT, &MotorCommands::off(), &Environment::default())
            .unwrap();
        max_tilt = max_tilt.max(q.state().tilt_rad());
    }
    (*q.state(), max_tilt.to_degrees())
}

#[test]
fn a_touchdown_at_2_m_s_sideways_slides_to_a_stop_by_coulomb_friction() {
    // No air drag, so friction alone stops it.
    let p = AirframeParams {
        drag_coefficients_n_s_m: [0.0; 3],
        ..AirframeParams::default()
    };
    let (end, max_tilt) = touch_down_sliding(p.clone(), 2.0, 2.0);
    let expected = 2.0_f64.powi(2) / (2.0 * p.gear_friction * GRAVITY_M_S2);
    assert!(
        (end.position.x - expected).abs() < 0.25 * expected,
        "slid {} m, Coulomb says {expected} m",
        end.position.x
    );
    assert!(end.velocity.norm() < 1e-2, "{:?}", end.velocity);
    assert!(max_tilt < 20.0, "rocked {max_tilt} deg");
}

#[test]
fn a_touchdown_at_3_m_s_sideways_on_grippy_ground_tips_the_vehicle_over() {
    let p = AirframeParams {
        gear_friction: 1.5,
        ..AirframeParams::default()
    };
    let (_, max_tilt) = touch_down_sliding(p, 3.0, 1.5);
    assert!(max_tilt > 60.0, "tilted only {max_tilt} deg");
}

#[test]
fn a_pad_braking_harder_than_friction_holds_lets_the_vehicle_slide_forward() {
    // The pad drives at 5 m/s along x and brakes at 8 m/s^2 (more than mu g = 4.9).
    let brake = |t: f64| {
        let v = (5.0 - 8.0 * t).max(0.0);
        let x = if t < 5.0 / 8.0 {
            5.0 * t - 4.0 * t * t
        } else {
            25.0 / 16.0
        };
        Surface {
            id: 1,
            world_from_surface: Isometry3::translation(x, 0.0, 0.4),
            linear_velocity: Vector3::new(v, 0.0, 0.0),
            angular_velocity: Vector3::zeros(),
            half_extent_m: Some([5.0, 0.5]),
        }
    };
    let mut start = VehicleState::at_rest(Vector3::new(0.0, 0.0, 0.4), 0.0);
    start.velocity = Vector3::new(5.0, 0.0, 0.0);
    // No air drag, so friction alone decelerates it.
    let p = AirframeParams {
        drag_coefficients_n_s_m: [0.0; 3],
        ..AirframeParams::default()
    };
    let mut q = Quadrotor::new(p, start, &brake(0.0)).unwrap();
    for k in 1..=1000 {
        let env = Environment {
            platform: Some(brake(k as f64 * DT)),
            ..Environment::default()
        };
        q.step(DT, &MotorCommands::off(), &env).unwrap();
    }
    let pad = brake(2.0);
    let rel = pad
        .world_from_surface
        .inverse_transform_point(&q.state().position.into());
    // Sliding at mu g while the pad stops at 8 m/s^2: 25/(2 mu g) - 25/16 m ahead.
    let mu_g = AirframeParams::default().gear_friction * GRAVITY_M_S2;
    let expected = 25.0 / (2.0 * mu_g) - 25.0 / 16.0;
    assert!(
        (rel.x - expected).abs() < 0.25 * expected,
        "slid {} m along the pad, Coulomb says {expected} m",
        rel.x
    );
    assert!((q.state().velocity).norm() < 1e-2);
}

#[test]
fn a_vehicle_with_its_centre_of_mass_past_the_roof_edge_tips_off_it() {
    let roof = Surface {
        id: 1,
        world_from_surface: Isometry3::translation(0.0, 0.0, 0.4),
        linear_velocity: Vector3::zeros(),
        angular_velocity: Vector3::zeros(),
        half_extent_m: Some([0.5, 0.5]),
    };
    // Centre 0.55 m out: two feet over the roof (x = 0.45), two beyond it.
    let start = VehicleState::at_rest(Vector3::new(0.55, 0.0, 0.4), 0.0);
    let mut q = Quadrotor::new(AirframeParams::default(), start, &roof).unwrap();
    let env = Environment {
        platform: Some(roof),
        ..Environment::default()
    };
    for _ in 0..1000 {
        q.step(DT, &MotorCommands::off(), &env).unwrap();
    }
    assert_eq!(q.contact(), ContactState::Resting { surface_id: 0 });
    assert!(q.state().position.z < 0.05, "{:?}", q.state().position);
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
