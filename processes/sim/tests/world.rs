//! The world as a whole: ground contact, touchdown and crash events,
//! collisions, determinism and robustness to bad inputs.

// Test helpers outside #[test] functions may panic too.
#![allow(clippy::unwrap_used)]

use nalgebra::{UnitQuaternion, Vector3};
use sim::autopilot::Setpoint;
use sim::estimator_noise::EstimatorNoiseParams;
use sim::ground_vehicle::{GroundVehicleParams, PathParams, SpeedProfile};
use sim::quadrotor::{ContactState, MotorCommands, VehicleState};
use sim::world::{Aabb, CrashReason, Event, TimedEvent, World, WorldParams};

const DT_NS: u64 = 2_000_000;

fn quiet() -> WorldParams {
    WorldParams {
        estimator_noise: EstimatorNoiseParams::zero(),
        ..WorldParams::default()
    }
}

fn pad_driving_east(speed_m_s: f64) -> GroundVehicleParams {
    GroundVehicleParams {
        path: PathParams::Straight {
            start_m: [0.0, 0.0],
            heading_rad: 0.0,
        },
        speed: SpeedProfile::Constant { speed_m_s },
        ..GroundVehicleParams::default()
    }
}

/// Runs `seconds` of autopilot steps, collecting events.
fn fly(world: &mut World, seconds: f64) -> Vec<TimedEvent> {
    let mut events = Vec::new();
    for _ in 0..(seconds * 1e9 / DT_NS as f64).round() as usize {
        events.extend_from_slice(world.step(DT_NS).unwrap());
    }
    events
}

/// Runs `seconds` with fixed motor commands, collecting events.
fn drive(world: &mut World, seconds: f64, commands: &MotorCommands) -> Vec<TimedEvent> {
    let mut events = Vec::new();
    for _ in 0..(seconds * 1e9 / DT_NS as f64).round() as usize {
        events.extend_from_slice(world.step_with_motors(DT_NS, commands).unwrap());
    }
    events
}

fn crashes(events: &[TimedEvent]) -> Vec<CrashReason> {
    events
        .iter()
        .filter_map(|e| match e.event {
            Event::Crash { reason } => Some(reason),
            _ => None,
        })
        .collect()
}

#[test]
fn the_quadrotor_resting_on_the_ground_with_motors_off_stays_still() {
    let mut w = World::new(quiet()).unwrap();
    let start = *w.truth();
    let events = fly(&mut w, 10.0);
    assert!(events.is_empty(), "{events:?}");
    assert_eq!(w.contact(), ContactState::Resting { surface_id: 0 });
    assert!((w.truth().position - start.position).norm() < 1e-12);
    assert!(w.truth().velocity.norm() < 1e-12);
    assert!(w.truth().is_finite());
}

#[test]
fn falling_from_5_m_with_motors_off_is_a_crash() {
    let mut w = World::new(WorldParams {
        initial_position_m: [0.0, 0.0, 5.0],
        ..quiet()
    })
    .unwrap();
    let events = drive(&mut w, 3.0, &MotorCommands::off());
    let c = crashes(&events);
    assert_eq!(c.len(), 1, "{events:?}");
    match c[0] {
        CrashReason::HardImpact {
            on_pad: false,
            normal_speed_m_s,
        } => assert!(normal_speed_m_s > 8.0, "{normal_speed_m_s}"),
        other => panic!("{other:?}"),
    }
    assert!(w.crashed());
    assert!(!w.armed());
    // At rest on its gear again after the bounces.
    assert!(
        w.truth().position.z.abs() < 0.01,
        "{:?}",
        w.truth().position
    );
    // A crash is not a touchdown.
    assert!(
        !events
            .iter()
            .any(|e| matches!(e.event, Event::Touchdown { .. }))
    );
}

#[test]
fn touching_down_at_0_3_m_s_on_the_moving_pad_reports_the_relative_velocity() {
    let speed = 3.0;
    let mut w = World::new(WorldParams {
        ground_vehicle: Some(pad_driving_east(speed)),
        ..quiet()
    })
    .unwrap();
    // Start 1.5 m above the pad, already moving with it.
    let mut s = VehicleState::at_rest(Vector3::new(0.1, -0.05, 1.9), 0.0);
    s.velocity = Vector3::new(speed, 0.0, 0.0);
    let air = w.airframe().clone();
    s.motor_speeds = [air.hover_thrust_normalized().sqrt() * air.motor_speed_max_rad_s; 4];
    w.set_vehicle_state(s).unwrap();
    w.set_armed(true);
    let mut touchdown = None;
    for k in 0..(25.0 / 0.002) as usize {
        let pad = w.pad().unwrap();
        let centre = pad.world_from_pad.translation.vector;
        // Follow the pad centre for 8 s (the velocity integrator takes up the
        // drag), then descend onto it at 0.3 m/s relative to it.
        let descend = k as f64 * 0.002 > 8.0;
        let vz = if descend { -0.3 } else { 0.0 };
        let mut sp =
            Setpoint::velocity(pad.linear_velocity + Vector3::new(0.0, 0.0, vz), Some(0.0));
        sp.position = [Some(centre.x), Some(centre.y), (!descend).then_some(1.9)];
        w.set_setpoint(sp);
        for e in w.step(DT_NS).unwrap() {
            if let Event::Touchdown { .. } = e.event {
                touchdown = Some(e.event);
            }
        }
        if touchdown.is_some() {
            break;
        }
    }
    match touchdown {
        Some(Event::Touchdown {
            on_pad: true,
            rel_position_pad: Some(p),
            rel_velocity,
            ..
        }) => {
            eprintln!("touchdown at {p:?} in the pad frame, relative velocity {rel_velocity:?}");
            assert!(p.norm() < 0.1, "position on pad {p:?}");
            assert!((rel_velocity.z + 0.3).abs() < 0.05, "{rel_velocity:?}");
            assert!(rel_velocity.xy().norm() < 0.1, "{rel_velocity:?}");
        }
        other => panic!("expected a touchdown on the pad, got {other:?}"),
    }
    assert!(!w.crashed());
    // Motors off: the vehicle rides on the pad.
    w.set_armed(false);
    fly(&mut w, 2.0);
    let pad = w.pad().unwrap();
    let local = pad
        .world_from_pad
        .inverse_transform_point(&w.truth().position.into());
    let sunk = w.airframe().static_deflection_m();
    assert!(
        local.coords.norm() < 0.1 && (local.z + sunk).abs() < 1e-4,
        "{local:?}"
    );
    assert!((w.truth().velocity - pad.linear_velocity).norm() < 1e-3);
}

#[test]
fn landing_beside_the_pad_is_a_touchdown_on_the_ground_with_the_miss_distance() {
    let mut w = World::new(WorldParams {
        ground_vehicle: Some(pad_driving_east(0.0)),
        initial_position_m: [0.0, 3.0, 1.0],
        ..quiet()
    })
    .unwrap();
    let air = w.airframe().clone();
    let mut s = *w.truth();
    s.motor_speeds = [air.hover_thrust_normalized().sqrt() * air.motor_speed_max_rad_s; 4];
    w.set_vehicle_state(s).unwrap();
    w.set_armed(true);
    w.set_setpoint(Setpoint::velocity(Vector3::new(0.0, 0.0, -0.5), Some(0.0)));
    let events = fly(&mut w, 6.0);
    let td: Vec<_> = events
        .iter()
        .filter_map(|e| match e.event {
            Event::Touchdown {
                on_pad,
                rel_position_pad,
                ..
            } => Some((on_pad, rel_position_pad)),
            _ => None,
        })
        .collect();
    assert_eq!(td.len(), 1, "{events:?}");
    let (on_pad, rel) = td[0];
    assert!(!on_pad);
    let rel = rel.unwrap();
    assert!((rel.y - 3.0).abs() < 0.05, "{rel:?}");
}

#[test]
fn taking_off_reports_a_liftoff_once() {
    let mut w = World::new(quiet()).unwrap();
    w.set_armed(true);
    w.set_setpoint(Setpoint::position(Vector3::new(0.0, 0.0, 2.0), 0.0));
    let events = fly(&mut w, 5.0);
    let lifts: Vec<_> = events
        .iter()
        .filter(|e| matches!(e.event, Event::Liftoff { from_pad: false }))
        .collect();
    assert_eq!(lifts.len(), 1, "{events:?}");
    assert!((w.truth().position.z - 2.0).abs() < 0.05);
}

#[test]
fn hover_with_vio_noise_holds_position_within_10_cm() {
    let mut w = World::new(WorldParams {
        initial_position_m: [0.0, 0.0, 0.0],
        ..WorldParams::default()
    })
    .unwrap();
    w.set_armed(true);
    let target = Vector3::new(0.0, 0.0, 2.0);
    w.set_setpoint(Setpoint::position(target, 0.0));
    fly(&mut w, 6.0);
    let mut worst: f64 = 0.0;
    for _ in 0..(10.0 / 0.002) as usize {
        w.step(DT_NS).unwrap();
        // Error of the estimate-driven controller against truth includes the drift.
        worst = worst.max((w.truth().position - target).norm());
        assert!(!w.last_control().unwrap().motors_saturated);
    }
    assert!(worst < 0.10, "{worst}");
}

#[test]
fn tilted_contact_beyond_60_degrees_is_a_crash() {
    let mut w = World::new(WorldParams {
        initial_position_m: [0.0, 0.0, 0.3],
        ..quiet()
    })
    .unwrap();
    let mut s = *w.truth();
    s.world_from_body = UnitQuaternion::from_euler_angles(70f64.to_radians(), 0.0, 0.0);
    w.set_vehicle_state(s).unwrap();
    let events = drive(&mut w, 1.0, &MotorCommands::off());
    let c = crashes(&events);
    assert!(
        matches!(c.as_slice(), [CrashReason::TiltedContact { on_pad: false, tilt_deg }] if *tilt_deg > 60.0),
        "{events:?}"
    );
}

#[test]
fn flipping_over_in_flight_is_a_crash() {
    let mut w = World::new(WorldParams {
        initial_position_m: [0.0, 0.0, 20.0],
        ..quiet()
    })
    .unwrap();
    let mut s = *w.truth();
    s.body_rates = Vector3::new(8.0, 0.0, 0.0);
    w.set_vehicle_state(s).unwrap();
    let events = drive(&mut w, 1.0, &MotorCommands::off());
    assert!(
        matches!(crashes(&events).as_slice(), [CrashReason::Excessive { .. }]),
        "{events:?}"
    );
}

#[test]
fn flying_into_a_box_raises_one_collision_event() {
    let mut w = World::new(WorldParams {
        obstacles: vec![
            Aabb {
                min_m: [50.0, 50.0, 0.0],
                max_m: [51.0, 51.0, 10.0],
            },
            Aabb {
                min_m: [3.0, -1.0, 0.0],
                max_m: [3.6, 1.0, 1.2],
            },
        ],
        initial_position_m: [0.0, 0.0, 1.0],
        ..quiet()
    })
    .unwrap();
    let air = w.airframe().clone();
    let mut s = *w.truth();
    s.motor_speeds = [air.hover_thrust_normalized().sqrt() * air.motor_speed_max_rad_s; 4];
    w.set_vehicle_state(s).unwrap();
    w.set_armed(true);
    w.set_setpoint(Setpoint::position(Vector3::new(6.0, 0.0, 1.0), 0.0));
    let events = fly(&mut w, 8.0);
    let hits: Vec<_> = events
        .iter()
        .filter_map(|e| match e.event {
            Event::Collision { obstacle_index } => Some(obstacle_index),
            _ => None,
        })
        .collect();
    assert_eq!(hits, vec![1], "{events:?}");
}

#[test]
fn hovering_low_in_the_path_of_the_ground_vehicle_is_a_crash_into_its_side() {
    let mut w = World::new(WorldParams {
        ground_vehicle: Some(GroundVehicleParams {
            path: PathParams::Straight {
                start_m: [-5.0, 0.0],
                heading_rad: 0.0,
            },
            speed: SpeedProfile::Constant { speed_m_s: 2.0 },
            ..GroundVehicleParams::default()
        }),
        ..quiet()
    })
    .unwrap();
    w.set_armed(true);
    w.set_setpoint(Setpoint::position(Vector3::new(0.0, 0.0, 0.2), 0.0));
    let events = fly(&mut w, 4.0);
    assert!(
        crashes(&events).contains(&CrashReason::HitGroundVehicle),
        "{events:?}"
    );
}

#[test]
fn the_same_seed_gives_the_same_flight() {
    let params = WorldParams {
        ground_vehicle: Some(pad_driving_east(2.0)),
        wind: sim::wind::WindParams {
            mean_m_s: [2.0, 1.0, 0.0],
            gust_std_horizontal_m_s: 1.0,
            gust_std_vertical_m_s: 0.3,
            ..sim::wind::WindParams::default()
        },
        ..WorldParams::default()
    };
    let run = |params: WorldParams| {
        let mut w = World::new(params).unwrap();
        w.set_armed(true);
        w.set_setpoint(Setpoint::position(Vector3::new(3.0, 2.0, 2.0), 1.0));
        fly(&mut w, 5.0);
        (*w.truth(), *w.estimate())
    };
    assert_eq!(run(params.clone()), run(params));
}

#[test]
fn non_finite_setpoints_never_produce_nan() {
    let mut w = World::new(WorldParams {
        initial_position_m: [0.0, 0.0, 3.0],
        ..quiet()
    })
    .unwrap();
    w.set_armed(true);
    let bad = Setpoint {
        position: [Some(f64::NAN), Some(f64::INFINITY), Some(3.0)],
        velocity: [None, Some(f64::NEG_INFINITY), Some(f64::NAN)],
        acceleration: [Some(f64::NAN), None, None],
        yaw: Some(f64::NAN),
        yaw_rate: Some(f64::INFINITY),
    };
    w.set_setpoint(bad);
    for _ in 0..2500 {
        w.step(DT_NS).unwrap();
        let c = w.last_control().unwrap();
        assert!(c.motors.iter().all(|m| m.is_finite()));
        assert!(c.status.invalid_setpoint);
        assert!(w.truth().is_finite());
    }
    // What is left of the setpoint (z = 3) is held and x/y are braked.
    assert!((w.truth().position.z - 3.0).abs() < 0.05);
    assert!(w.truth().velocity.norm() < 0.05);
}

#[test]
fn scenario_toml_parses_and_rejects_unknown_fields() {
    let p = WorldParams::from_toml(
        r#"
        initial_position_m = [0.0, 0.0, 0.0]
        [airframe]
        mass_kg = 1.6
        [autopilot]
        MPC_XY_VEL_MAX = 8.0
        [wind]
        mean_m_s = [3.0, 0.0, 0.0]
        [ground_vehicle]
        path = { type = "figure_eight", centre_m = [10.0, 0.0], lobe_radius_m = 15.0, heading_rad = 0.0 }
        speed = { type = "sinusoidal", mean_m_s = 3.0, amplitude_m_s = 1.0, period_s = 20.0 }
        [[obstacles]]
        min_m = [1.0, 1.0, 0.0]
        max_m = [2.0, 2.0, 2.0]
        "#,
    )
    .unwrap();
    let w = World::new(p).unwrap();
    assert_eq!(w.autopilot_params().mpc_xy_vel_max, 8.0);
    assert_eq!(w.obstacles().len(), 1);
    assert!(WorldParams::from_toml("[airframe]\nmas_kg = 1.0").is_err());
    let too_fast = WorldParams::from_toml(
        r#"
        [ground_vehicle]
        path = { type = "straight", start_m = [0.0, 0.0], heading_rad = 0.0 }
        speed = { type = "constant", speed_m_s = 20.0 }
        "#,
    )
    .unwrap();
    let e = World::new(too_fast).unwrap_err().to_string();
    assert!(e.starts_with("ground_vehicle.speed.speed_m_s = 20"), "{e}");
}
