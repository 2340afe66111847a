//! Closed-loop behaviour of the autopilot flying the quadrotor model, with
//! PX4-like tolerances. The controller sees the truth (no estimator noise)
//! unless a test says otherwise.

// Test helpers outside #[test] functions may panic too.
#![allow(clippy::unwrap_used)]

use nalgebra::Vector3;
use sim::autopilot::{Autopilot, AutopilotParams, EstimatedState, Setpoint};
use sim::quadrotor::{
    AirframeParams, ContactState, Environment, MotorCommands, Quadrotor, Surface, VehicleState,
};

const DT: f64 = 0.002;

/// A quadrotor and its autopilot, stepped together.
struct Loop {
    quad: Quadrotor,
    autopilot: Autopilot,
    env: Environment,
    time_s: f64,
    max_motor: f64,
    min_motor: f64,
    saturated_steps: usize,
}

impl Loop {
    fn hovering_at(position: Vector3<f64>) -> Self {
        Self::with(
            AirframeParams::default(),
            AutopilotParams::default(),
            position,
        )
    }

    fn with(airframe: AirframeParams, params: AutopilotParams, position: Vector3<f64>) -> Self {
        let mut state = VehicleState::at_rest(position, 0.0);
        let w = airframe.hover_thrust_normalized().sqrt() * airframe.motor_speed_max_rad_s;
        state.motor_speeds = [w; 4];
        let quad = Quadrotor::new(airframe, state, &Surface::ground()).unwrap();
        let mut autopilot = Autopilot::new(params).unwrap();
        // Placed in the air, the autopilot flies at once; PX4 boots landed otherwise.
        autopilot.place(quad.contact() == ContactState::Airborne);
        Self {
            quad,
            autopilot,
            env: Environment::default(),
            time_s: 0.0,
            max_motor: 0.0,
            min_motor: 1.0,
            saturated_steps: 0,
        }
    }

    fn state(&self) -> &VehicleState {
        self.quad.state()
    }

    fn step(&mut self, setpoint: &Setpoint) {
        // Landed is the autopilot's own land detector's word, as in the world.
        let landed = self.autopilot.land_detected().landed;
        let est = EstimatedState::from_truth(self.quad.state(), landed);
        let out = self.autopilot.update(DT, &est, setpoint);
        for m in out.motors {
            assert!(m.is_finite());
            self.max_motor = self.max_motor.max(m);
            self.min_motor = self.min_motor.min(m);
        }
        if out.motors_saturated {
            self.saturated_steps += 1;
        }
        let cmd = MotorCommands {
            armed: true,
            thrust: out.motors,
        };
        self.quad.step(DT, &cmd, &self.env).unwrap();
        self.time_s += DT;
    }

    /// Runs for `seconds`, calling `each` after every step.
    fn run(&mut self, seconds: f64, setpoint: &Setpoint, mut each: impl FnMut(&Self)) {
        let steps = (seconds / DT).round() as usize;
        for _ in 0..steps {
            self.step(setpoint);
            each(self);
        }
    }
}

#[test]
fn hover_holds_altitude_within_5_cm() {
    let target = Vector3::new(0.0, 0.0, 2.0);
    let mut l = Loop::hovering_at(target);
    let sp = Setpoint::position(target, 0.0);
    let mut worst: f64 = 0.0;
    l.run(5.0, &sp, |l| {
        worst = worst.max((l.state().position - target).norm())
    });
    l.run(5.0, &sp, |l| {
        worst = worst.max((l.state().position - target).norm())
    });
    assert!(worst < 0.05, "worst error {worst}");
    assert_eq!(l.saturated_steps, 0);
    assert!(
        l.max_motor < 0.9 && l.min_motor > 0.1,
        "{} {}",
        l.min_motor,
        l.max_motor
    );
}

#[test]
fn altitude_step_of_1_m_settles_within_5_percent_in_under_3_s_with_under_15_percent_overshoot() {
    let start = Vector3::new(0.0, 0.0, 2.0);
    let mut l = Loop::hovering_at(start);
    let hold = Setpoint::position(start, 0.0);
    l.run(1.0, &hold, |_| {});
    let sp = Setpoint::position(start + Vector3::new(0.0, 0.0, 1.0), 0.0);
    let mut peak: f64 = 0.0;
    let mut last_outside = 0.0;
    let t0 = l.time_s;
    l.run(8.0, &sp, |l| {
        let z = l.state().position.z - 2.0;
        peak = peak.max(z);
        if (z - 1.0).abs() > 0.05 {
            last_outside = l.time_s - t0;
        }
    });
    let overshoot = peak - 1.0;
    assert!(overshoot < 0.15, "overshoot {overshoot}");
    assert!(last_outside < 3.0, "settling time {last_outside}");
    eprintln!("altitude step: settling {last_outside:.2} s, overshoot {overshoot:.3} m");
}

#[test]
fn horizontal_move_of_5_m_arrives_within_10_cm_in_under_6_s_without_overshoot_speeding_or_overtilting()
 {
    let start = Vector3::new(0.0, 0.0, 3.0);
    let mut l = Loop::hovering_at(start);
    let params = l.autopilot.params().clone();
    let target = start + Vector3::new(5.0, 0.0, 0.0);
    let sp = Setpoint::position(target, 0.0);
    let mut peak_x: f64 = 0.0;
    let mut max_speed: f64 = 0.0;
    let mut max_tilt: f64 = 0.0;
    let mut last_outside = 0.0;
    l.run(10.0, &sp, |l| {
        let s = l.state();
        peak_x = peak_x.max(s.position.x);
        max_speed = max_speed.max(s.velocity.xy().norm());
        max_tilt = max_tilt.max(s.tilt_rad().to_degrees());
        if (s.position - target).norm() > 0.10 {
            last_outside = l.time_s;
        }
    });
    let overshoot = (peak_x - 5.0) / 5.0;
    eprintln!(
        "5 m move: arrival {last_outside:.2} s, overshoot {:.1} %, speed {max_speed:.2} m/s, tilt {max_tilt:.1} deg",
        overshoot * 100.0
    );
    assert!(last_outside < 6.0, "arrival {last_outside}");
    assert!(overshoot < 0.10, "overshoot {overshoot}");
    assert!(max_speed <= params.mpc_xy_vel_max * 1.05);
    assert!(max_tilt <= params.mpc_tiltmax_air + 3.0, "tilt {max_tilt}");
}

#[test]
fn horizontal_speed_is_limited_to_mpc_xy_vel_max() {
    let params = AutopilotParams {
        mpc_xy_vel_max: 3.0,
        ..AutopilotParams::default()
    };
    let start = Vector3::new(0.0, 0.0, 3.0);
    let mut l = Loop::with(AirframeParams::default(), params, start);
    let sp = Setpoint::position(Vector3::new(30.0, 10.0, 3.0), 0.0);
    let mut max_speed: f64 = 0.0;
    l.run(20.0, &sp, |l| {
        max_speed = max_speed.max(l.state().velocity.xy().norm())
    });
    assert!(max_speed <= 3.0 * 1.05, "speed {max_speed}");
    assert!(max_speed > 2.8, "speed {max_speed}");
}

#[test]
fn velocity_feed_forward_tracks_a_pad_moving_at_5_m_s() {
    let start = Vector3::new(0.0, 0.0, 2.0);
    let mut l = Loop::hovering_at(start);
    let pad_velocity = Vector3::new(5.0 * 0.8, 5.0 * 0.6, 0.0);
    let pad_at = |t: f64| Vector3::new(-3.0, 1.0, 0.4) + pad_velocity * t;
    let offset = Vector3::new(0.0, 0.0, 1.6);
    let mut worst_after_transient: f64 = 0.0;
    for k in 0..(25.0 / DT) as usize {
        let t = k as f64 * DT;
        let sp = Setpoint::position(pad_at(t) + offset, 0.5).with_velocity(pad_velocity);
        l.step(&sp);
        if l.time_s > 10.0 {
            let err = (l.state().position - (pad_at(l.time_s) + offset)).norm();
            worst_after_transient = worst_after_transient.max(err);
        }
    }
    eprintln!("tracking 5 m/s: worst error after 10 s {worst_after_transient:.3} m");
    assert!(worst_after_transient < 0.15, "{worst_after_transient}");
}

#[test]
fn holds_position_within_20_cm_in_5_m_s_wind_after_10_s() {
    let target = Vector3::new(0.0, 0.0, 5.0);
    let mut l = Loop::hovering_at(target);
    l.env.wind_world = Vector3::new(3.0, 4.0, 0.0);
    let sp = Setpoint::position(target, 0.0);
    let mut worst_early: f64 = 0.0;
    l.run(10.0, &sp, |l| {
        worst_early = worst_early.max((l.state().position - target).norm())
    });
    let mut worst: f64 = 0.0;
    l.run(10.0, &sp, |l| {
        worst = worst.max((l.state().position - target).norm())
    });
    eprintln!("wind: worst error first 10 s {worst_early:.3} m, after {worst:.3} m");
    assert!(worst < 0.20, "{worst}");
}

#[test]
fn velocity_only_setpoint_flies_the_velocity() {
    let mut l = Loop::hovering_at(Vector3::new(0.0, 0.0, 5.0));
    let v = Vector3::new(-2.0, 1.0, 0.5);
    l.run(8.0, &Setpoint::velocity(v, None), |_| {});
    assert!(
        (l.state().velocity - v).norm() < 0.05,
        "{:?}",
        l.state().velocity
    );
}

#[test]
fn yaw_setpoint_is_reached_while_holding_position() {
    let target = Vector3::new(0.0, 0.0, 2.0);
    let mut l = Loop::hovering_at(target);
    l.run(6.0, &Setpoint::position(target, 1.5), |_| {});
    assert!(
        (l.state().yaw_rad() - 1.5).abs() < 0.02,
        "{}",
        l.state().yaw_rad()
    );
    assert!((l.state().position - target).norm() < 0.05);
}

#[test]
fn takes_off_from_the_ground_and_lands_back_without_integrator_windup() {
    let mut airframe_state = Loop::hovering_at(Vector3::zeros());
    // Starts resting on the ground (z = 0), motors at hover speed.
    assert!(matches!(
        airframe_state.quad.contact(),
        ContactState::Resting { .. }
    ));
    let up = Setpoint::position(Vector3::new(0.0, 0.0, 2.0), 0.0);
    airframe_state.run(6.0, &up, |_| {});
    assert!((airframe_state.state().position.z - 2.0).abs() < 0.05);
    let down = Setpoint::velocity(Vector3::new(0.0, 0.0, -0.5), Some(0.0));
    airframe_state.run(8.0, &down, |_| {});
    assert!(matches!(
        airframe_state.quad.contact(),
        ContactState::Resting { .. }
    ));
}

#[test]
fn racer_tracks_a_ground_vehicle_at_60_km_h() {
    let start = Vector3::new(0.0, 0.0, 3.0);
    let mut l = Loop::with(AirframeParams::racer(), AutopilotParams::racer(), start);
    let speed = 60.0 / 3.6;
    let pad_velocity = Vector3::new(speed, 0.0, 0.0);
    let mut worst: f64 = 0.0;
    let mut max_tilt: f64 = 0.0;
    for k in 0..(30.0 / DT) as usize {
        let t = k as f64 * DT;
        // The pad accelerates at 2 m/s^2 to 60 km/h, then drives steadily.
        let (pos, vel, acc) = if t < speed / 2.0 {
            (
                Vector3::new(t * t, 0.0, 0.0),
                Vector3::new(2.0 * t, 0.0, 0.0),
                Vector3::new(2.0, 0.0, 0.0),
            )
        } else {
            let t1 = speed / 2.0;
            (
                Vector3::new(t1 * t1 + speed * (t - t1), 0.0, 0.0),
                pad_velocity,
                Vector3::zeros(),
            )
        };
        let sp = Setpoint::position(pos + start, 0.0)
            .with_velocity(vel)
            .with_acceleration(acc);
        l.step(&sp);
        max_tilt = max_tilt.max(l.state().tilt_rad().to_degrees());
        if t > 20.0 {
            worst = worst.max((l.state().position - (pos + start)).norm());
        }
    }
    eprintln!("racer at 60 km/h: worst error {worst:.3} m, max tilt {max_tilt:.1} deg");
    assert!(worst < 0.3, "{worst}");
    assert!(max_tilt < 60.0 + 3.0);
}
