//! A PX4-like cascaded multicopter controller.
//!
//! The simulator stands in for PX4, so the vehicle must respond to setpoints
//! the way a PX4 vehicle does: the same cascade, the same parameter names and
//! defaults where they make sense, the same saturation and anti-windup rules.
//! The structure mirrors PX4's `PositionControl`, `AttitudeControl`,
//! `RateControl` and the multirotor control allocation (sequential
//! desaturation, airmode disabled):
//!
//! ```text
//! position P -> velocity PID (+ velocity and acceleration feed-forward)
//!   -> acceleration to thrust vector and attitude (tilt limit, hover thrust, yaw)
//!   -> quaternion attitude P (reduced yaw priority) -> body-rate PID
//!   -> mixer (roll/pitch before yaw, thrust never raised to unsaturate) -> 4 motors
//! ```
//!
//! Everything is expressed in ENU/FLU (PX4 runs in NED/FRD; the control laws
//! are frame-agnostic, only the signs of "up" differ). The input is the
//! ESTIMATED state, never the truth. Outputs are always finite: non-finite
//! inputs give a defined safe output and a flag in [`ControlStatus`].
//!
//! Like PX4, the autopilot does not know its vehicle: it starts from the airframe
//! file's MPC_THR_HOVER and runs PX4's hover thrust estimator
//! ([`crate::hover_thrust`]), whose valid estimate replaces MPC_THR_HOVER in the
//! position controller (MPC_USE_HTE = 1); and it decides that it has landed with
//! PX4's land detector ([`crate::land_detector`]) from its own estimate and
//! commands. Around the ground it follows PX4's position controller: landed and no
//! setpoint asking to climb, the thrust is zero; in flight with ground contact
//! detected, it is MPC_THR_MIN with the velocity integrators reset, which is what
//! lets the detector go on to "landed".
//!
//! Units follow PX4: angles in parameters are in degrees (MPC_TILTMAX_AIR,
//! MC_*RATE_MAX), the velocity gains are the `_ACC` variants (m/s^2 per m/s),
//! thrust is normalized per motor in `[0, 1]`, torques are normalized.

use nalgebra::{Rotation3, UnitQuaternion, Vector3};

pub use crate::autopilot_params::{AutopilotParams, torque_effectiveness};
use crate::autopilot_params::{MIX_ROLL_PITCH, MIX_YAW};
use crate::hover_thrust::{HoverThrustEstimator, HoverThrustInput};
use crate::land_detector::{LandDetected, LandDetector, LandDetectorInput};
use crate::params::ParamError;
use crate::quadrotor::{GRAVITY_M_S2, QUAD_X_MOTORS, VehicleState};

/// The state estimate the controller works from (never ground truth).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EstimatedState {
    /// Position in world ENU, m.
    pub position: Vector3<f64>,
    /// Velocity in world ENU, m/s.
    pub velocity: Vector3<f64>,
    /// Attitude, maps body FLU to world ENU.
    pub world_from_body: UnitQuaternion<f64>,
    /// Body rates in body FLU, rad/s.
    pub body_rates: Vector3<f64>,
    /// PX4's land-detector output (`vehicle_land_detected.landed`): the autopilot's
    /// own detector's, never the true contact; while landed the integrators are frozen.
    pub landed: bool,
}

impl EstimatedState {
    /// A perfect estimate (truth), for tests and for runs without estimator noise.
    pub fn from_truth(truth: &VehicleState, landed: bool) -> Self {
        Self {
            position: truth.position,
            velocity: truth.velocity,
            world_from_body: truth.world_from_body,
            body_rates: truth.body_rates,
            landed,
        }
    }
}

/// What the vehicle should do, like PX4's trajectory setpoint: any field may
/// be absent, per axis.
///
/// Position gives a P correction on top of the velocity feed-forward, which
/// gives a PID correction on top of the acceleration feed-forward. An axis
/// with nothing at all is braked to zero velocity (and flagged). Yaw absent
/// holds the current heading, with the yaw rate as feed-forward if given.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Setpoint {
    /// Position per axis in world ENU, m.
    pub position: [Option<f64>; 3],
    /// Velocity (feed-forward) per axis in world ENU, m/s.
    pub velocity: [Option<f64>; 3],
    /// Acceleration (feed-forward) per axis in world ENU, m/s^2.
    pub acceleration: [Option<f64>; 3],
    /// Heading, rad (ENU: 0 = east, counter-clockwise positive).
    pub yaw: Option<f64>,
    /// Heading rate feed-forward, rad/s (counter-clockwise positive).
    pub yaw_rate: Option<f64>,
}

fn some3(v: &Vector3<f64>) -> [Option<f64>; 3] {
    [Some(v.x), Some(v.y), Some(v.z)]
}

impl Setpoint {
    /// Hold a position with a heading.
    pub fn position(position: Vector3<f64>, yaw: f64) -> Self {
        Self {
            position: some3(&position),
            yaw: Some(yaw),
            ..Self::default()
        }
    }

    /// Fly a velocity with an optional heading (held if absent).
    pub fn velocity(velocity: Vector3<f64>, yaw: Option<f64>) -> Self {
        Self {
            velocity: some3(&velocity),
            yaw,
            ..Self::default()
        }
    }

    /// Adds a velocity feed-forward on every axis.
    pub fn with_velocity(mut self, velocity: Vector3<f64>) -> Self {
        self.velocity = some3(&velocity);
        self
    }

    /// Adds an acceleration feed-forward on every axis.
    pub fn with_acceleration(mut self, acceleration: Vector3<f64>) -> Self {
        self.acceleration = some3(&acceleration);
        self
    }
}

/// Flags describing how the last update coped with its inputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ControlStatus {
    /// Some part of the estimated state was non-finite and was not used.
    pub invalid_state: bool,
    /// The attitude estimate was unusable: the output is level hover thrust.
    pub attitude_lost: bool,
    /// Some setpoint field was non-finite and was treated as absent.
    pub invalid_setpoint: bool,
    /// Some axis had no position, velocity or acceleration: it is braked.
    pub incomplete_setpoint: bool,
    /// The time step was not a finite positive number: integrators and filters held.
    pub invalid_dt: bool,
}

impl ControlStatus {
    /// True if anything was wrong with the inputs.
    pub fn any(&self) -> bool {
        self.invalid_state
            || self.attitude_lost
            || self.invalid_setpoint
            || self.incomplete_setpoint
            || self.invalid_dt
    }
}

/// Everything the controller computed in one update (the motors plus the
/// intermediate setpoints, for logging and tests). All values are finite.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControlOutput {
    /// Normalized thrust per motor in `[0, 1]`, quad X order.
    pub motors: [f64; 4],
    /// Velocity setpoint after limits, world ENU, m/s (zero on uncontrolled axes).
    pub velocity_setpoint: Vector3<f64>,
    /// Acceleration setpoint after limits, world ENU, m/s^2.
    pub acceleration_setpoint: Vector3<f64>,
    /// Normalized thrust vector, world ENU.
    pub thrust_setpoint: Vector3<f64>,
    /// Attitude setpoint, maps body to world.
    pub attitude_setpoint: UnitQuaternion<f64>,
    /// Body rate setpoint, FLU, rad/s.
    pub rate_setpoint: Vector3<f64>,
    /// Normalized torque setpoint about body x, y, z.
    pub torque_setpoint: Vector3<f64>,
    /// True when the mixer had to clip or desaturate a motor.
    pub motors_saturated: bool,
    /// How the inputs were handled.
    pub status: ControlStatus,
}

/// Which torque directions the mixer could not deliver last time, for the
/// rate-integrator anti-windup (PX4's control-allocator saturation feedback).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct TorqueSaturation {
    positive: [bool; 3],
    negative: [bool; 3],
}

/// A first-order low-pass filtered derivative of a 3-vector.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct FilteredDerivative {
    previous: Option<Vector3<f64>>,
    value: Vector3<f64>,
}

impl FilteredDerivative {
    fn update(&mut self, x: &Vector3<f64>, dt: f64, cutoff_hz: f64) -> Vector3<f64> {
        if dt > 0.0 {
            if let Some(prev) = self.previous {
                let raw = (x - prev) / dt;
                let tau = 1.0 / (std::f64::consts::TAU * cutoff_hz);
                let alpha = dt / (dt + tau);
                self.value += (raw - self.value) * alpha;
            }
            self.previous = Some(*x);
        }
        self.value
    }

    fn reset(&mut self) {
        *self = Self::default();
    }
}

/// PX4's take-off states from "ready for take-off" on (`Takeoff.cpp`; its spool-up is
/// the commander's).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum TakeoffState {
    /// On the ground: zero thrust until a setpoint asks to climb.
    Ready,
    /// Climbing away: normal control, but not yet flying. PX4 ramps the climb over
    /// MPC_TKO_RAMP_T; here the ramp-up ends as soon as the land detector no longer
    /// reports ground contact (the rotors carry the vehicle).
    Rampup,
    /// Flying: ground contact cuts the thrust to MPC_THR_MIN, "landed" ends it.
    Flight,
}

/// The cascaded controller with its integrators and filters, its hover thrust
/// estimator and its land detector.
#[derive(Debug, Clone)]
pub struct Autopilot {
    params: AutopilotParams,
    velocity_integral: Vector3<f64>,
    rate_integral: Vector3<f64>,
    velocity_derivative: FilteredDerivative,
    rate_derivative: FilteredDerivative,
    yaw_hold: Option<f64>,
    saturation: TorqueSaturation,
    /// The hover thrust the position controller uses now.
    hover_thrust: f64,
    hover_thrust_estimator: HoverThrustEstimator,
    land_detector: LandDetector,
    /// PX4's take-off state (`Takeoff.cpp`) from "ready for take-off" on.
    takeoff: TakeoffState,
    /// Time summed over the updates, ns (the estimator's and detector's clock).
    clock_ns: u64,
    /// Upward component of the thrust the last output allocated, normalized.
    thrust_up: f64,
    /// Vertical acceleration setpoint the last thrust was computed from, m/s^2.
    last_acceleration_z: f64,
}

impl Autopilot {
    /// Builds a controller after validating its parameters.
    /// It boots on the ground (landed), as PX4.
    pub fn new(params: AutopilotParams) -> Result<Self, ParamError> {
        params.validate()?;
        Ok(Self {
            velocity_integral: Vector3::zeros(),
            rate_integral: Vector3::zeros(),
            velocity_derivative: FilteredDerivative::default(),
            rate_derivative: FilteredDerivative::default(),
            yaw_hold: None,
            saturation: TorqueSaturation::default(),
            hover_thrust: params.mpc_thr_hover,
            hover_thrust_estimator: HoverThrustEstimator::new(&params),
            land_detector: LandDetector::new(&params),
            takeoff: TakeoffState::Ready,
            clock_ns: 0,
            thrust_up: 0.0,
            last_acceleration_z: 0.0,
            params,
        })
    }

    /// The parameters in use.
    pub fn params(&self) -> &AutopilotParams {
        &self.params
    }

    /// The land detector's latest output: what PX4 publishes as
    /// `vehicle_land_detected`, and what the estimate's `landed` must carry.
    pub fn land_detected(&self) -> &LandDetected {
        self.land_detector.output()
    }

    /// The hover thrust the position controller uses now: MPC_THR_HOVER on the
    /// ground, the valid estimate in flight.
    pub fn hover_thrust(&self) -> f64 {
        self.hover_thrust
    }

    /// The hover thrust estimator, for logs and tests.
    pub fn hover_thrust_estimator(&self) -> &HoverThrustEstimator {
        &self.hover_thrust_estimator
    }

    /// Sets the land detector and the take-off state for a vehicle the simulator
    /// places in the air (`in_air`) or on the ground, as if they had long settled
    /// there: PX4 boots landed, but a vehicle placed in flight must not first drop.
    pub fn place(&mut self, in_air: bool) {
        self.land_detector.force(in_air);
        self.takeoff = if in_air {
            TakeoffState::Flight
        } else {
            TakeoffState::Ready
        };
        if !in_air {
            self.hover_thrust = self.params.mpc_thr_hover;
        }
    }

    /// What PX4 runs while disarmed, for `dt_s`: no control (integrators and filters
    /// cleared), the land detector sees a disarmed vehicle (landed), the hover thrust
    /// estimator restarts from MPC_THR_HOVER.
    pub fn disarmed(&mut self, dt_s: f64, state: &EstimatedState) {
        self.reset();
        self.takeoff = TakeoffState::Ready;
        self.hover_thrust = self.params.mpc_thr_hover;
        self.thrust_up = 0.0;
        if !(dt_s.is_finite() && dt_s > 0.0 && dt_s <= 1.0) {
            return;
        }
        self.clock_ns = self.clock_ns.saturating_add((dt_s * 1e9).round() as u64);
        let landed = self.land_detector.output().landed;
        self.hover_thrust_estimator.update(
            self.clock_ns,
            dt_s,
            &self.params,
            &HoverThrustInput {
                armed: false,
                landed,
                height_m: state.position.z,
                velocity: state.velocity,
                thrust_up: 0.0,
            },
        );
        self.land_detector.update(
            self.clock_ns,
            &self.params,
            &LandDetectorInput {
                armed: false,
                velocity: state.velocity,
                body_rates: state.body_rates,
                acceleration: None,
                throttle: 0.0,
                velocity_setpoint_z: None,
                hover_thrust_estimate: None,
            },
        );
    }

    /// PX4's `PositionControl::updateHoverThrust`: a new hover thrust without a jump
    /// in thrust, the difference moved into the vertical velocity integrator.
    fn update_hover_thrust(&mut self, new: f64) {
        if !(new.is_finite() && new > 0.0) || new == self.hover_thrust {
            return;
        }
        let a = self.last_acceleration_z;
        let a_new = (a + GRAVITY_M_S2) * self.hover_thrust / new - GRAVITY_M_S2;
        self.velocity_integral.z =
            (self.velocity_integral.z + a_new - a).clamp(-GRAVITY_M_S2, GRAVITY_M_S2);
        self.hover_thrust = new;
    }

    /// Clears integrators, derivative filters and the held heading, e.g. on
    /// arming or after a mode switch, so no stale state is carried over.
    pub fn reset(&mut self) {
        self.velocity_integral = Vector3::zeros();
        self.rate_integral = Vector3::zeros();
        self.velocity_derivative.reset();
        self.rate_derivative.reset();
        self.yaw_hold = None;
        self.saturation = TorqueSaturation::default();
    }

    /// Runs the whole cascade once over `dt_s` seconds and returns the motor
    /// commands. Never returns non-finite numbers.
    pub fn update(
        &mut self,
        dt_s: f64,
        state: &EstimatedState,
        setpoint: &Setpoint,
    ) -> ControlOutput {
        let mut status = ControlStatus::default();
        let dt = if dt_s.is_finite() && dt_s > 0.0 && dt_s <= 1.0 {
            dt_s
        } else {
            status.invalid_dt = true;
            0.0
        };
        let q = state.world_from_body.into_inner();
        if !(q.coords.iter().all(|c| c.is_finite()) && q.norm() > 0.5) {
            status.attitude_lost = true;
            status.invalid_state = true;
            return self.level_hover_output(status);
        }
        let attitude = UnitQuaternion::new_normalize(q);
        let position_ok = finite3(&state.position);
        let velocity_ok = finite3(&state.velocity);
        let rates_ok = finite3(&state.body_rates);
        if !(position_ok && velocity_ok && rates_ok) {
            status.invalid_state = true;
        }
        self.clock_ns = self.clock_ns.saturating_add((dt * 1e9).round() as u64);
        let sp = sanitize_setpoint(setpoint, &mut status);

        // --- Take-off state and hover thrust (PX4 MulticopterPositionControl) ---
        let land = *self.land_detector.output();
        self.takeoff = match self.takeoff {
            TakeoffState::Flight if land.landed => TakeoffState::Ready,
            TakeoffState::Ready if position_ok && wants_takeoff(&sp, state) => TakeoffState::Rampup,
            TakeoffState::Rampup if !land.ground_contact => TakeoffState::Flight,
            other => other,
        };
        let flying = self.takeoff == TakeoffState::Flight;
        if !flying {
            self.hover_thrust = self.params.mpc_thr_hover;
        } else if self.params.mpc_use_hte == 1
            && let Some(h) = self.hover_thrust_estimator.valid_estimate()
        {
            self.update_hover_thrust(h);
        }
        // Not taken off, or flying with ground contact: no thrust corrections, only
        // the minimum thrust (zero before take-off), and no integrator windup.
        let idle_thrust = match self.takeoff {
            TakeoffState::Ready => Some(0.0),
            TakeoffState::Flight if land.ground_contact => Some(self.params.mpc_thr_min),
            _ => None,
        };
        // The rate controller stops integrating once maybe landed (PX4 RateControl).
        let integrate = !(state.landed || land.maybe_landed || land.landed) && dt > 0.0;

        // --- Position and velocity control (PX4 PositionControl) ---
        let (velocity_setpoint, acceleration_setpoint, thrust_setpoint) =
            self.position_velocity_control(dt, integrate, idle_thrust, state, &sp, &mut status);

        // --- Attitude setpoint from thrust direction and yaw ---
        let current_yaw = yaw_of(&attitude);
        let yaw_setpoint = match sp.yaw {
            Some(yaw) => {
                self.yaw_hold = None;
                yaw
            }
            None if sp.yaw_rate.is_some() => {
                self.yaw_hold = Some(current_yaw);
                current_yaw
            }
            None => *self.yaw_hold.get_or_insert(current_yaw),
        };
        let attitude_setpoint = attitude_from_thrust(&thrust_setpoint, yaw_setpoint);

        // --- Attitude control (PX4 AttitudeControl) ---
        let rate_setpoint =
            self.attitude_control(&attitude, &attitude_setpoint, sp.yaw_rate.unwrap_or(0.0));

        // --- Rate control (PX4 RateControl) ---
        let rates = if rates_ok {
            state.body_rates
        } else {
            self.rate_derivative.reset();
            Vector3::zeros()
        };
        let torque_setpoint = self.rate_control(dt, integrate, &rates, &rate_setpoint, rates_ok);

        // --- Mixer (PX4 sequential desaturation, airmode disabled) ---
        let collective = thrust_setpoint.norm();
        let mix = mix(collective, &torque_setpoint);
        self.saturation = mix.saturation;

        // --- Hover thrust estimator and land detector, for the next update ---
        if dt > 0.0 && !status.invalid_state {
            let thrust_up = mix.motors.iter().sum::<f64>() / 4.0 * (attitude * Vector3::z()).z;
            self.hover_thrust_estimator.update(
                self.clock_ns,
                dt,
                &self.params,
                &HoverThrustInput {
                    armed: true,
                    landed: land.landed,
                    height_m: state.position.z,
                    velocity: state.velocity,
                    // The thrust that acted over the step just measured.
                    thrust_up: self.thrust_up,
                },
            );
            self.thrust_up = thrust_up;
            let hover_thrust_estimate = self.hover_thrust_estimator.valid_estimate();
            self.land_detector.update(
                self.clock_ns,
                &self.params,
                &LandDetectorInput {
                    armed: true,
                    velocity: state.velocity,
                    body_rates: state.body_rates,
                    acceleration: Some(self.velocity_derivative.value),
                    throttle: collective,
                    velocity_setpoint_z: sp.velocity[2],
                    hover_thrust_estimate,
                },
            );
        }

        let out = ControlOutput {
            motors: mix.motors,
            velocity_setpoint,
            acceleration_setpoint,
            thrust_setpoint,
            attitude_setpoint,
            rate_setpoint,
            torque_setpoint,
            motors_saturated: mix.saturated,
            status,
        };
        if output_is_finite(&out) {
            out
        } else {
            // Defensive: cannot happen with validated parameters and sanitized
            // inputs, but a NaN must never reach the motors.
            self.reset();
            let mut status = status;
            status.invalid_state = true;
            self.level_hover_output(status)
        }
    }

    /// The output used when the attitude is unknown: all motors at hover thrust.
    fn level_hover_output(&mut self, status: ControlStatus) -> ControlOutput {
        self.rate_derivative.reset();
        self.velocity_derivative.reset();
        let hover = self.hover_thrust;
        ControlOutput {
            motors: [hover; 4],
            velocity_setpoint: Vector3::zeros(),
            acceleration_setpoint: Vector3::zeros(),
            thrust_setpoint: Vector3::new(0.0, 0.0, hover),
            attitude_setpoint: UnitQuaternion::identity(),
            rate_setpoint: Vector3::zeros(),
            torque_setpoint: Vector3::zeros(),
            motors_saturated: false,
            status,
        }
    }

    /// Position P, velocity PID, acceleration to thrust, with PX4's limits
    /// and anti-windup. Returns (velocity sp, acceleration sp, thrust vector).
    /// With `idle_thrust` the setpoint is ignored as PX4 ignores it on the ground: a
    /// level thrust of that size, the velocity integrators reset.
    fn position_velocity_control(
        &mut self,
        dt: f64,
        integrate: bool,
        idle_thrust: Option<f64>,
        state: &EstimatedState,
        sp: &Setpoint,
        status: &mut ControlStatus,
    ) -> (Vector3<f64>, Vector3<f64>, Vector3<f64>) {
        let p = &self.params;
        let position_ok = finite3(&state.position);
        let velocity_ok = finite3(&state.velocity);
        if let Some(thrust) = idle_thrust {
            // PX4 commands 100 m/s^2 down: the thrust saturates at its minimum.
            if velocity_ok {
                self.velocity_derivative
                    .update(&state.velocity, dt, p.mpc_veld_lp);
            } else {
                self.velocity_derivative.reset();
            }
            self.velocity_integral = Vector3::zeros();
            self.last_acceleration_z = -p.mpc_acc_down_max;
            return (
                Vector3::zeros(),
                Vector3::new(0.0, 0.0, -p.mpc_acc_down_max),
                Vector3::new(0.0, 0.0, thrust),
            );
        }
        let gains_pos = [p.mpc_xy_p, p.mpc_xy_p, p.mpc_z_p];

        // Velocity setpoint = feed-forward + P on position, per axis.
        let mut vel_from_position = Vector3::zeros();
        let mut vel_ff = Vector3::zeros();
        let mut vel_defined = [false; 3];
        let mut acc_ff = Vector3::zeros();
        for i in 0..3 {
            let mut pos = sp.position[i];
            if pos.is_some() && !position_ok {
                pos = None;
            }
            let mut vel = sp.velocity[i];
            if pos.is_none() && vel.is_none() && sp.acceleration[i].is_none() {
                status.incomplete_setpoint = true;
                vel = Some(0.0);
            }
            if let Some(a) = sp.acceleration[i] {
                acc_ff[i] = a;
            }
            if let Some(target) = pos {
                vel_from_position[i] = gains_pos[i] * (target - state.position[i]);
                vel_defined[i] = true;
            }
            if let Some(v) = vel {
                vel_ff[i] = v;
                vel_defined[i] = true;
            }
        }
        let mut vel_sp = vel_from_position + vel_ff;
        let xy = constrain_xy(&vel_from_position.xy(), &vel_ff.xy(), p.mpc_xy_vel_max);
        vel_sp.x = xy.x;
        vel_sp.y = xy.y;
        vel_sp.z = vel_sp.z.clamp(-p.mpc_z_vel_max_dn, p.mpc_z_vel_max_up);

        // Velocity PID -> acceleration setpoint.
        let vel_dot = if velocity_ok {
            self.velocity_derivative
                .update(&state.velocity, dt, p.mpc_veld_lp)
        } else {
            self.velocity_derivative.reset();
            Vector3::zeros()
        };
        let gains_p = Vector3::new(p.mpc_xy_vel_p_acc, p.mpc_xy_vel_p_acc, p.mpc_z_vel_p_acc);
        let gains_i = Vector3::new(p.mpc_xy_vel_i_acc, p.mpc_xy_vel_i_acc, p.mpc_z_vel_i_acc);
        let gains_d = Vector3::new(p.mpc_xy_vel_d_acc, p.mpc_xy_vel_d_acc, p.mpc_z_vel_d_acc);
        let mut vel_error = Vector3::zeros();
        let mut acc_sp = acc_ff;
        for i in 0..3 {
            if vel_defined[i] && velocity_ok {
                vel_error[i] = vel_sp[i] - state.velocity[i];
                acc_sp[i] +=
                    gains_p[i] * vel_error[i] + self.velocity_integral[i] - gains_d[i] * vel_dot[i];
            }
        }
        for i in 0..3 {
            if !vel_defined[i] {
                vel_sp[i] = 0.0;
            }
        }

        // Acceleration limits.
        let mut acc_limited = acc_sp;
        let hor = acc_limited.xy().norm();
        if hor > p.mpc_acc_hor_max {
            let s = p.mpc_acc_hor_max / hor;
            acc_limited.x *= s;
            acc_limited.y *= s;
        }
        // Vertically the limits bound the commanded motion (feed-forward, P and D),
        // not the integrator's weight compensation: a vehicle heavier than its
        // MPC_THR_HOVER keeps its full climb and descent, and one pressed onto the
        // ground can wind its thrust down to where PX4's land detector sees it (PX4
        // limits nothing here: its limits are in the trajectory generators).
        let integral_z = if vel_defined[2] && velocity_ok {
            self.velocity_integral.z
        } else {
            0.0
        };
        acc_limited.z =
            (acc_sp.z - integral_z).clamp(-p.mpc_acc_down_max, p.mpc_acc_up_max) + integral_z;

        // Acceleration -> thrust vector (PX4 _accelerationControl). Decoupled
        // (MPC_ACC_DECOUPLE 1, PX4's default), the tilt is set against gravity alone: a
        // downward acceleration lowers the collective and the horizontal thrust with it.
        let hover = self.hover_thrust;
        self.last_acceleration_z = acc_limited.z;
        let z_specific_force = if p.mpc_acc_decouple == 1 {
            GRAVITY_M_S2
        } else {
            GRAVITY_M_S2 + acc_limited.z
        };
        let mut body_z = Vector3::new(acc_limited.x, acc_limited.y, z_specific_force);
        body_z = if body_z.norm() > 1e-6 {
            body_z.normalize()
        } else {
            Vector3::z()
        };
        body_z = limit_tilt(&body_z, p.mpc_tiltmax_air.to_radians());
        let thrust_up = hover + acc_limited.z * hover / GRAVITY_M_S2;
        let collective = (thrust_up / body_z.z).max(p.mpc_thr_min);
        let mut thr_sp = body_z * collective;

        // Integrator anti-windup in vertical direction.
        if (thr_sp.z <= p.mpc_thr_min && vel_error.z <= 0.0)
            || (thr_sp.z >= p.mpc_thr_max && vel_error.z >= 0.0)
        {
            vel_error.z = 0.0;
        }
        // Prioritize vertical control while keeping a horizontal margin.
        let thr_xy_norm = thr_sp.xy().norm();
        let thr_max_sq = p.mpc_thr_max * p.mpc_thr_max;
        let allocated_xy = thr_xy_norm.min(p.mpc_thr_xy_marg);
        let thr_z_max = (thr_max_sq - allocated_xy * allocated_xy).max(0.0).sqrt();
        thr_sp.z = thr_sp.z.min(thr_z_max);
        let thr_xy_max = (thr_max_sq - thr_sp.z * thr_sp.z).max(0.0).sqrt();
        if thr_xy_norm > thr_xy_max && thr_xy_norm > 0.0 {
            let s = thr_xy_max / thr_xy_norm;
            thr_sp.x *= s;
            thr_sp.y *= s;
        }
        // Tracking anti-windup in the horizontal direction (Rundqwist 1990, as PX4).
        let acc_produced_xy = thr_sp.xy() * (GRAVITY_M_S2 / hover);
        let acc_sp_xy = acc_sp.xy();
        let acc_effective_xy = if acc_sp_xy.norm_squared() > acc_produced_xy.norm_squared() {
            acc_produced_xy
        } else {
            acc_sp_xy
        };
        let arw_gain = 2.0 / p.mpc_xy_vel_p_acc;
        vel_error.x -= arw_gain * (acc_sp_xy.x - acc_effective_xy.x);
        vel_error.y -= arw_gain * (acc_sp_xy.y - acc_effective_xy.y);

        if integrate && velocity_ok {
            for i in 0..3 {
                if vel_defined[i] && vel_error[i].is_finite() {
                    self.velocity_integral[i] += vel_error[i] * gains_i[i] * dt;
                }
            }
            for i in 0..3 {
                self.velocity_integral[i] =
                    self.velocity_integral[i].clamp(-GRAVITY_M_S2, GRAVITY_M_S2);
            }
        }
        (vel_sp, acc_limited, thr_sp)
    }

    /// Quaternion attitude P with reduced yaw priority, as PX4's AttitudeControl.
    fn attitude_control(
        &self,
        q: &UnitQuaternion<f64>,
        qd: &UnitQuaternion<f64>,
        yaw_rate_ff: f64,
    ) -> Vector3<f64> {
        let p = &self.params;
        let yaw_w = p.mc_yaw_weight.clamp(0.0, 1.0);
        let mut gain = Vector3::new(p.mc_roll_p, p.mc_pitch_p, p.mc_yaw_p);
        if yaw_w > 1e-4 {
            gain.z /= yaw_w;
        }
        let e_z = q * Vector3::z();
        let e_z_d = qd * Vector3::z();
        // Reduced attitude: only tilt to the desired thrust direction, keep yaw.
        let qd_red = match UnitQuaternion::rotation_between(&e_z, &e_z_d) {
            Some(r) => r * q,
            None => *qd,
        };
        // Mix full and reduced desired attitude with the yaw weight.
        let mut q_mix = (qd_red.inverse() * qd).into_inner();
        if q_mix.w < 0.0 {
            q_mix = -q_mix;
        }
        let w = q_mix.w.clamp(-1.0, 1.0);
        let z = q_mix.k.clamp(-1.0, 1.0);
        let yaw_part =
            nalgebra::Quaternion::new((yaw_w * w.acos()).cos(), 0.0, 0.0, (yaw_w * z.asin()).sin());
        let qd_weighted = qd_red * UnitQuaternion::new_normalize(yaw_part);
        let mut qe = (q.inverse() * qd_weighted).into_inner();
        if qe.w < 0.0 {
            qe = -qe;
        }
        let eq = qe.imag() * 2.0;
        let mut rate_sp = eq.component_mul(&gain);
        // Yaw rate feed-forward: world z rate expressed in body.
        rate_sp += q.inverse() * Vector3::z() * yaw_rate_ff;
        let limits = Vector3::new(
            p.mc_rollrate_max.to_radians(),
            p.mc_pitchrate_max.to_radians(),
            p.mc_yawrate_max.to_radians(),
        );
        for i in 0..3 {
            rate_sp[i] = rate_sp[i].clamp(-limits[i], limits[i]);
        }
        rate_sp
    }

    /// Body-rate PID with PX4's saturation-aware integrator.
    fn rate_control(
        &mut self,
        dt: f64,
        integrate: bool,
        rates: &Vector3<f64>,
        rate_sp: &Vector3<f64>,
        rates_ok: bool,
    ) -> Vector3<f64> {
        let p = &self.params;
        let gain_p = Vector3::new(p.mc_rollrate_p, p.mc_pitchrate_p, p.mc_yawrate_p);
        let gain_i = Vector3::new(p.mc_rollrate_i, p.mc_pitchrate_i, p.mc_yawrate_i);
        let gain_d = Vector3::new(p.mc_rollrate_d, p.mc_pitchrate_d, p.mc_yawrate_d);
        let int_lim = Vector3::new(p.mc_rr_int_lim, p.mc_pr_int_lim, p.mc_yr_int_lim);
        let angular_accel = if rates_ok {
            self.rate_derivative.update(rates, dt, p.imu_dgyro_cutoff)
        } else {
            Vector3::zeros()
        };
        let error = rate_sp - rates;
        let torque = error.component_mul(&gain_p) + self.rate_integral
            - angular_accel.component_mul(&gain_d);
        if integrate && rates_ok {
            for i in 0..3 {
                let mut e = error[i];
                if self.saturation.positive[i] {
                    e = e.min(0.0);
                }
                if self.saturation.negative[i] {
                    e = e.max(0.0);
                }
                // Reduce the I gain with increasing rate error (PX4: 400 deg/s).
                let f = e / 400f64.to_radians();
                let i_factor = (1.0 - f * f).max(0.0);
                let next = self.rate_integral[i] + i_factor * gain_i[i] * e * dt;
                if next.is_finite() {
                    self.rate_integral[i] = next.clamp(-int_lim[i], int_lim[i]);
                }
            }
        }
        torque.map(|t| t.clamp(-1.0, 1.0))
    }
}

/// Result of the mixer.
struct Mix {
    motors: [f64; 4],
    saturated: bool,
    saturation: TorqueSaturation,
}

/// Per-motor mixer columns (roll, pitch, yaw, thrust) for the quad X layout.
fn mixer_columns() -> [[f64; 4]; 4] {
    let mut cols = [[0.0; 4]; 4];
    for (i, g) in QUAD_X_MOTORS.iter().enumerate() {
        // Roll torque (+x) comes from thrust on the left (+y) motors.
        cols[0][i] = g.y_sign * MIX_ROLL_PITCH;
        // Pitch torque (+y, nose down) comes from thrust on the rear (-x) motors.
        cols[1][i] = -g.x_sign * MIX_ROLL_PITCH;
        // Yaw torque (+z) is the reaction of the clockwise (spin -1) rotors.
        cols[2][i] = -g.spin * MIX_YAW;
        cols[3][i] = 1.0;
    }
    cols
}

/// PX4's desaturation gain: how far to move along `dir` to bring outputs into `[lo, hi]`.
fn desaturation_gain(u: &[f64; 4], dir: &[f64; 4], lo: f64, hi: f64) -> f64 {
    let (mut k_min, mut k_max) = (0.0_f64, 0.0_f64);
    for i in 0..4 {
        if dir[i].abs() < f64::EPSILON {
            continue;
        }
        if u[i] < lo {
            let k = (lo - u[i]) / dir[i];
            k_min = k_min.min(k);
            k_max = k_max.max(k);
        }
        if u[i] > hi {
            let k = (hi - u[i]) / dir[i];
            k_min = k_min.min(k);
            k_max = k_max.max(k);
        }
    }
    k_min + k_max
}

/// Moves `u` along `dir` to unsaturate it (twice, for a symmetric result).
/// With `decrease_only`, a positive move (e.g. raising thrust) is refused.
fn desaturate(u: &mut [f64; 4], dir: &[f64; 4], lo: f64, hi: f64, decrease_only: bool) {
    let gain = desaturation_gain(u, dir, lo, hi);
    if decrease_only && gain > 0.0 {
        return;
    }
    for i in 0..4 {
        u[i] += gain * dir[i];
    }
    let gain = 0.5 * desaturation_gain(u, dir, lo, hi);
    for i in 0..4 {
        u[i] += gain * dir[i];
    }
}

/// Normalized thrust and torques to motor outputs, as PX4's sequential
/// desaturation with airmode disabled: thrust is never raised to unsaturate,
/// roll and pitch are kept before yaw, yaw gets 15 % headroom.
fn mix(thrust: f64, torque: &Vector3<f64>) -> Mix {
    let cols = mixer_columns();
    let mut u = [0.0; 4];
    for i in 0..4 {
        u[i] = cols[3][i] * thrust + cols[0][i] * torque.x + cols[1][i] * torque.y;
    }
    let raw_rp = u;
    desaturate(&mut u, &cols[3], 0.0, 1.0, true);
    desaturate(&mut u, &cols[0], 0.0, 1.0, false);
    desaturate(&mut u, &cols[1], 0.0, 1.0, false);
    for i in 0..4 {
        u[i] += cols[2][i] * torque.z;
    }
    let before_yaw_desat = u;
    desaturate(&mut u, &cols[2], 0.0, 1.15, false);
    desaturate(&mut u, &cols[3], 0.0, 1.0, true);

    let mut saturated = raw_rp.iter().any(|v| !(0.0..=1.0).contains(v))
        || before_yaw_desat.iter().any(|v| !(0.0..=1.0).contains(v));
    let mut saturation = TorqueSaturation::default();
    for (i, ui) in u.iter().enumerate() {
        let upper = *ui >= 1.0 - 1e-9;
        let lower = *ui <= 1e-9;
        if upper || lower {
            for (axis, col) in cols.iter().enumerate().take(3) {
                let c = col[i];
                if c.abs() < f64::EPSILON {
                    continue;
                }
                // More torque along `axis` would push this motor further out.
                if (upper && c > 0.0) || (lower && c < 0.0) {
                    saturation.positive[axis] = true;
                }
                if (upper && c < 0.0) || (lower && c > 0.0) {
                    saturation.negative[axis] = true;
                }
            }
        }
        if *ui > 1.0 || *ui < 0.0 {
            saturated = true;
        }
    }
    let mut motors = [0.0; 4];
    for i in 0..4 {
        motors[i] = if u[i].is_finite() {
            u[i].clamp(0.0, 1.0)
        } else {
            0.0
        };
    }
    Mix {
        motors,
        saturated,
        saturation,
    }
}

fn finite3(v: &Vector3<f64>) -> bool {
    v.iter().all(|c| c.is_finite())
}

fn output_is_finite(o: &ControlOutput) -> bool {
    o.motors.iter().all(|m| m.is_finite())
        && finite3(&o.velocity_setpoint)
        && finite3(&o.acceleration_setpoint)
        && finite3(&o.thrust_setpoint)
        && o.attitude_setpoint.coords.iter().all(|c| c.is_finite())
        && finite3(&o.rate_setpoint)
        && finite3(&o.torque_setpoint)
}

/// Whether a setpoint asks a landed vehicle to take off (PX4 MulticopterPositionControl,
/// offboard): a position above it, or an upward velocity or acceleration. The
/// commander adds FlightTask's stricter gate in its AUTO modes.
fn wants_takeoff(sp: &Setpoint, state: &EstimatedState) -> bool {
    sp.position[2].is_some_and(|z| z > state.position.z)
        || sp.velocity[2].is_some_and(|vz| vz > 0.0)
        || sp.acceleration[2].is_some_and(|az| az > 0.0)
}

/// Drops non-finite setpoint fields (flagging them).
fn sanitize_setpoint(sp: &Setpoint, status: &mut ControlStatus) -> Setpoint {
    let mut clean = |v: Option<f64>| match v {
        Some(x) if !x.is_finite() => {
            status.invalid_setpoint = true;
            None
        }
        other => other,
    };
    let mut out = *sp;
    for i in 0..3 {
        out.position[i] = clean(sp.position[i]);
        out.velocity[i] = clean(sp.velocity[i]);
        out.acceleration[i] = clean(sp.acceleration[i]);
    }
    out.yaw = clean(sp.yaw);
    out.yaw_rate = clean(sp.yaw_rate);
    out
}

/// Limits a horizontal velocity, keeping the position-correction part `v0`
/// first and as much of the feed-forward `v1` as fits (PX4 constrainXY).
fn constrain_xy(
    v0: &nalgebra::Vector2<f64>,
    v1: &nalgebra::Vector2<f64>,
    max: f64,
) -> nalgebra::Vector2<f64> {
    let sum = v0 + v1;
    if sum.norm() <= max {
        return sum;
    }
    if v0.norm() >= max {
        return v0.normalize() * max;
    }
    if v1.norm() < 1e-9 {
        return *v0;
    }
    // Find s in [0, 1] with |v0 + s v1| = max.
    let a = v1.norm_squared();
    let b = 2.0 * v0.dot(v1);
    let c = v0.norm_squared() - max * max;
    let disc = (b * b - 4.0 * a * c).max(0.0);
    let s = ((-b + disc.sqrt()) / (2.0 * a)).clamp(0.0, 1.0);
    v0 + v1 * s
}

/// Tilts `body_z` back toward up so that it is at most `max_tilt` from vertical.
fn limit_tilt(body_z: &Vector3<f64>, max_tilt: f64) -> Vector3<f64> {
    let tilt = body_z.z.clamp(-1.0, 1.0).acos();
    if tilt <= max_tilt {
        return *body_z;
    }
    let horizontal = Vector3::new(body_z.x, body_z.y, 0.0);
    let n = horizontal.norm();
    if n < 1e-9 {
        return Vector3::z();
    }
    horizontal / n * max_tilt.sin() + Vector3::z() * max_tilt.cos()
}

/// Heading of an attitude (ENU: angle of body x from east, counter-clockwise).
fn yaw_of(q: &UnitQuaternion<f64>) -> f64 {
    let x = q * Vector3::x();
    if x.x.abs() < 1e-9 && x.y.abs() < 1e-9 {
        // Nose straight up or down: fall back to the body y axis.
        let y = q * Vector3::y();
        return (-y.x).atan2(y.y);
    }
    x.y.atan2(x.x)
}

/// Attitude whose body z is along the thrust vector and whose heading is `yaw`
/// (PX4 bodyzToAttitude in ENU/FLU).
pub fn attitude_from_thrust(thrust: &Vector3<f64>, yaw: f64) -> UnitQuaternion<f64> {
    let z = if thrust.norm() > 1e-9 {
        thrust.normalize()
    } else {
        Vector3::z()
    };
    let heading = Vector3::new(yaw.cos(), yaw.sin(), 0.0);
    let mut y = z.cross(&heading);
    if y.norm() < 1e-6 {
        // Thrust horizontal along the heading: pick any perpendicular.
        y = Vector3::new(-yaw.sin(), yaw.cos(), 0.0);
    }
    let y = y.normalize();
    let x = y.cross(&z);
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_basis_unchecked(&[x, y, z]))
}

#[cfg(test)]
#[path = "autopilot_test.rs"]
mod tests;
