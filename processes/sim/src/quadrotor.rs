//! Rigid-body quadrotor dynamics.
//!
//! The model follows the paper's quadrotor model: four rotors with thrust
//! `T_i = c_T w_i^2` and drag torque `c_M w_i^2`, an X frame, linear drag on the
//! air-relative velocity (so wind acts through drag), a full inertia matrix with
//! the rigid-body and rotor gyroscopic terms, and a first-order lag between the
//! commanded and the actual motor speed. Contact with the surface under the
//! vehicle (ground, or the landing pad) is a perfectly inelastic, sticking
//! contact: the vehicle cannot go below it, and once resting it moves rigidly
//! with it until the thrust lifts it off.
//!
//! Frames: world ENU, body FLU, `world_from_body` maps body vectors to world.
//! Motor order is PX4's quad X order (see [`QUAD_X_MOTORS`]).

use nalgebra::{Isometry3, Matrix3, Quaternion, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde::Deserialize;
use thiserror::Error;

use crate::params::{self, ParamError};

/// Standard gravity, the value PX4 uses (`CONSTANTS_ONE_G`), so hover thrust
/// computed here matches what a PX4 parameter would hold.
pub const GRAVITY_M_S2: f64 = 9.80665;

/// Where a motor sits on the X frame and which way its rotor spins.
///
/// Shared by the physics and the autopilot's mixer so both agree on the layout.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotorGeometry {
    /// +1 for a motor ahead of the centre (body +x), -1 behind.
    pub x_sign: f64,
    /// +1 for a motor left of the centre (body +y), -1 right.
    pub y_sign: f64,
    /// +1 if the rotor spins counter-clockwise seen from above (angular
    /// velocity along body +z), -1 if clockwise.
    pub spin: f64,
}

/// PX4's quad X motor order: 1 front-right CCW, 2 rear-left CCW, 3 front-left
/// CW, 4 rear-right CW (index 0..3 here), so motor outputs can be compared with
/// a real PX4 log one to one.
pub const QUAD_X_MOTORS: [MotorGeometry; 4] = [
    MotorGeometry {
        x_sign: 1.0,
        y_sign: -1.0,
        spin: 1.0,
    },
    MotorGeometry {
        x_sign: -1.0,
        y_sign: 1.0,
        spin: 1.0,
    },
    MotorGeometry {
        x_sign: 1.0,
        y_sign: 1.0,
        spin: -1.0,
    },
    MotorGeometry {
        x_sign: -1.0,
        y_sign: -1.0,
        spin: -1.0,
    },
];

/// Physical parameters of the airframe, loadable from a scenario file.
///
/// Missing fields take the P450-class default, unknown fields are rejected so
/// a typo in a scenario file is an error instead of a silently ignored value.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AirframeParams {
    /// Take-off mass in kg.
    pub mass_kg: f64,
    /// Distance from the centre to each motor axis in m (X frame, motors on the diagonals).
    pub arm_length_m: f64,
    /// Principal moments of inertia about body x, y, z in kg m^2.
    pub inertia_diag_kg_m2: [f64; 3],
    /// Products of inertia (Jxy, Jxz, Jyz) in kg m^2, zero for a symmetric frame.
    pub inertia_products_kg_m2: [f64; 3],
    /// Rotor thrust coefficient c_T in N / (rad/s)^2: `T = c_T w^2`.
    pub thrust_coefficient: f64,
    /// Rotor drag-torque coefficient c_M in N m / (rad/s)^2: `Q = c_M w^2`.
    pub torque_coefficient: f64,
    /// Time constant of the first-order motor-speed lag in s.
    pub motor_time_constant_s: f64,
    /// Idle speed of an armed motor in rad/s (the lowest commandable speed).
    pub motor_speed_min_rad_s: f64,
    /// Highest motor speed in rad/s.
    pub motor_speed_max_rad_s: f64,
    /// Inertia of one rotor (propeller + motor bell) about its axis in kg m^2,
    /// for the rotor gyroscopic torque.
    pub rotor_inertia_kg_m2: f64,
    /// Linear drag coefficients along body x, y, z in N per (m/s) of air-relative velocity.
    pub drag_coefficients_n_s_m: [f64; 3],
    /// Aerodynamic damping of the body rates about x, y, z in N m per (rad/s).
    pub angular_drag_coefficients_n_m_s: [f64; 3],
    /// Radius of the sphere around the body origin used for obstacle collisions, in m.
    pub collision_radius_m: f64,
    /// Where the landing gear touches the ground: the feet, in body FLU, m (z = 0: the
    /// body origin is the gear's lowest point). The referee wants every foot on the
    /// printed board.
    pub landing_gear_m: [[f64; 3]; 4],
}

impl Default for AirframeParams {
    /// A P450-class quadrotor (F450 frame, 10" propellers, 4S): 1.5 kg,
    /// 0.225 m arms, thrust-to-weight about 2.6.
    fn default() -> Self {
        Self {
            mass_kg: 1.5,
            arm_length_m: 0.225,
            inertia_diag_kg_m2: [0.0175, 0.0175, 0.030],
            inertia_products_kg_m2: [0.0; 3],
            thrust_coefficient: 9.5e-6,
            torque_coefficient: 1.52e-7,
            motor_time_constant_s: 0.025,
            motor_speed_min_rad_s: 120.0,
            motor_speed_max_rad_s: 1000.0,
            rotor_inertia_kg_m2: 5.0e-5,
            drag_coefficients_n_s_m: [0.35, 0.35, 0.5],
            angular_drag_coefficients_n_m_s: [0.003, 0.003, 0.005],
            collision_radius_m: 0.25,
            // F450 landing gear: skids 20 cm long, 24 cm apart.
            landing_gear_m: [
                [0.10, 0.12, 0.0],
                [0.10, -0.12, 0.0],
                [-0.10, -0.12, 0.0],
                [-0.10, 0.12, 0.0],
            ],
        }
    }
}

impl AirframeParams {
    /// A light, fast airframe (thrust-to-weight about 4.5, lower drag) for the
    /// high-speed chase scenarios where the ground vehicle drives up to 60 km/h.
    pub fn racer() -> Self {
        Self {
            mass_kg: 0.9,
            arm_length_m: 0.125,
            inertia_diag_kg_m2: [0.0045, 0.0045, 0.008],
            inertia_products_kg_m2: [0.0; 3],
            thrust_coefficient: 1.59e-6,
            torque_coefficient: 1.59e-8,
            motor_time_constant_s: 0.015,
            motor_speed_min_rad_s: 250.0,
            motor_speed_max_rad_s: 2500.0,
            rotor_inertia_kg_m2: 6.0e-6,
            drag_coefficients_n_s_m: [0.12, 0.12, 0.25],
            angular_drag_coefficients_n_m_s: [0.001, 0.001, 0.002],
            collision_radius_m: 0.18,
            landing_gear_m: [
                [0.07, 0.07, 0.0],
                [0.07, -0.07, 0.0],
                [-0.07, -0.07, 0.0],
                [-0.07, 0.07, 0.0],
            ],
        }
    }

    /// Checks every field, so a bad scenario is rejected before it is flown.
    pub fn validate(&self) -> Result<(), ParamError> {
        params::positive("mass_kg", self.mass_kg)?;
        params::positive("arm_length_m", self.arm_length_m)?;
        for (i, j) in self.inertia_diag_kg_m2.iter().enumerate() {
            params::positive(&format!("inertia_diag_kg_m2[{i}]"), *j)?;
        }
        params::finite_all("inertia_products_kg_m2", &self.inertia_products_kg_m2)?;
        if self.inertia_matrix().cholesky().is_none() {
            return Err(ParamError::new(
                "inertia_products_kg_m2",
                format!("{:?}", self.inertia_products_kg_m2),
                "the inertia matrix must be positive definite",
            ));
        }
        params::positive("thrust_coefficient", self.thrust_coefficient)?;
        params::non_negative("torque_coefficient", self.torque_coefficient)?;
        params::positive("motor_time_constant_s", self.motor_time_constant_s)?;
        params::non_negative("motor_speed_min_rad_s", self.motor_speed_min_rad_s)?;
        params::positive("motor_speed_max_rad_s", self.motor_speed_max_rad_s)?;
        if self.motor_speed_max_rad_s <= self.motor_speed_min_rad_s {
            return Err(ParamError::new(
                "motor_speed_max_rad_s",
                self.motor_speed_max_rad_s,
                format!(
                    "must be > motor_speed_min_rad_s ({})",
                    self.motor_speed_min_rad_s
                ),
            ));
        }
        params::non_negative("rotor_inertia_kg_m2", self.rotor_inertia_kg_m2)?;
        for (i, d) in self.drag_coefficients_n_s_m.iter().enumerate() {
            params::non_negative(&format!("drag_coefficients_n_s_m[{i}]"), *d)?;
        }
        for (i, d) in self.angular_drag_coefficients_n_m_s.iter().enumerate() {
            params::non_negative(&format!("angular_drag_coefficients_n_m_s[{i}]"), *d)?;
        }
        params::positive("collision_radius_m", self.collision_radius_m)?;
        for (i, foot) in self.landing_gear_m.iter().enumerate() {
            params::finite_all(&format!("landing_gear_m[{i}]"), foot)?;
            if foot.iter().any(|c| c.abs() > 2.0) {
                return Err(ParamError::new(
                    format!("landing_gear_m[{i}]"),
                    format!("{foot:?}"),
                    "each coordinate must be within 2 m of the body origin",
                ));
            }
        }
        let ratio = self.thrust_to_weight();
        if ratio <= 1.2 {
            return Err(ParamError::new(
                "thrust_coefficient",
                self.thrust_coefficient,
                format!(
                    "thrust-to-weight is {ratio:.2}: 4 * thrust_coefficient * motor_speed_max_rad_s^2 must exceed 1.2 * mass_kg * g"
                ),
            ));
        }
        Ok(())
    }

    /// The full inertia matrix in body FLU, built from the diagonal and the products.
    pub fn inertia_matrix(&self) -> Matrix3<f64> {
        let [jxx, jyy, jzz] = self.inertia_diag_kg_m2;
        let [jxy, jxz, jyz] = self.inertia_products_kg_m2;
        Matrix3::new(jxx, jxy, jxz, jxy, jyy, jyz, jxz, jyz, jzz)
    }

    /// Thrust of one motor at full speed in N.
    pub fn max_thrust_per_motor_n(&self) -> f64 {
        self.thrust_coefficient * self.motor_speed_max_rad_s * self.motor_speed_max_rad_s
    }

    /// Ratio of the total full-speed thrust to the weight.
    pub fn thrust_to_weight(&self) -> f64 {
        4.0 * self.max_thrust_per_motor_n() / (self.mass_kg * GRAVITY_M_S2)
    }

    /// Normalized per-motor thrust needed to hover (what PX4 calls MPC_THR_HOVER).
    pub fn hover_thrust_normalized(&self) -> f64 {
        1.0 / self.thrust_to_weight()
    }

    /// Distance of each motor from the body x and y axes in m (arm projected on a diagonal).
    fn motor_offset_m(&self) -> f64 {
        self.arm_length_m * std::f64::consts::FRAC_1_SQRT_2
    }

    /// Body position of motor `i` (in [`QUAD_X_MOTORS`] order) in m.
    pub fn motor_position_body(&self, i: usize) -> Vector3<f64> {
        let g = QUAD_X_MOTORS[i % 4];
        let d = self.motor_offset_m();
        Vector3::new(g.x_sign * d, g.y_sign * d, 0.0)
    }
}

/// Normalized motor commands as PX4 outputs them, with the arming state.
///
/// `thrust[i]` is the normalized thrust of motor `i` in `[0, 1]` (PX4's
/// convention with THR_MDL_FAC = 1: the ESC turns it into the speed
/// `sqrt(thrust) * max_speed`, never below idle while armed). Disarmed motors stop.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MotorCommands {
    /// Whether the ESCs run: when false every motor is commanded to stop.
    pub armed: bool,
    /// Normalized thrust per motor in [`QUAD_X_MOTORS`] order; clamped to `[0, 1]`.
    pub thrust: [f64; 4],
}

impl MotorCommands {
    /// All motors stopped.
    pub fn off() -> Self {
        Self::default()
    }

    /// Armed, with the same normalized thrust on every motor.
    pub fn uniform(thrust: f64) -> Self {
        Self {
            armed: true,
            thrust: [thrust; 4],
        }
    }
}

/// Complete physical state of the quadrotor (ground truth).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleState {
    /// Position of the body origin in world ENU, m. The origin is taken as the
    /// lowest point of the landing gear, so a landed vehicle has the surface height.
    pub position: Vector3<f64>,
    /// Velocity in world ENU, m/s.
    pub velocity: Vector3<f64>,
    /// Attitude: maps body FLU vectors to world ENU.
    pub world_from_body: UnitQuaternion<f64>,
    /// Angular velocity of the body relative to the world, in body FLU, rad/s.
    pub body_rates: Vector3<f64>,
    /// Actual rotor speeds in rad/s, [`QUAD_X_MOTORS`] order.
    pub motor_speeds: [f64; 4],
}

impl VehicleState {
    /// A vehicle at rest at `position` with heading `yaw_rad` (ENU: 0 = east,
    /// counter-clockwise positive), motors stopped.
    pub fn at_rest(position: Vector3<f64>, yaw_rad: f64) -> Self {
        Self {
            position,
            velocity: Vector3::zeros(),
            world_from_body: UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw_rad),
            body_rates: Vector3::zeros(),
            motor_speeds: [0.0; 4],
        }
    }

    /// Angle between body up and world up in rad (0 = level, pi = inverted).
    pub fn tilt_rad(&self) -> f64 {
        let z = self.world_from_body * Vector3::z();
        z.z.clamp(-1.0, 1.0).acos()
    }

    /// Heading in rad (ENU: 0 = east, counter-clockwise positive).
    pub fn yaw_rad(&self) -> f64 {
        self.world_from_body.euler_angles().2
    }

    /// True if every number in the state is finite.
    pub fn is_finite(&self) -> bool {
        self.position.iter().all(|v| v.is_finite())
            && self.velocity.iter().all(|v| v.is_finite())
            && self.world_from_body.coords.iter().all(|v| v.is_finite())
            && self.body_rates.iter().all(|v| v.is_finite())
            && self.motor_speeds.iter().all(|v| v.is_finite())
    }
}

/// A rigid, moving plane the vehicle can stand on (the ground or the pad).
///
/// The plane is the `z = 0` plane of its frame; the caller gives its pose at
/// the END of the step being simulated, and its velocity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Surface {
    /// Stable identifier, so a resting vehicle keeps following the same
    /// surface across steps (by convention 0 is the ground).
    pub id: u32,
    /// Pose of the surface frame (z up, out of the surface).
    pub world_from_surface: Isometry3<f64>,
    /// Velocity of the surface frame origin in world, m/s.
    pub linear_velocity: Vector3<f64>,
    /// Angular velocity of the surface in world, rad/s.
    pub angular_velocity: Vector3<f64>,
}

/// Identifier of the ground surface.
pub const GROUND_SURFACE_ID: u32 = 0;

impl Surface {
    /// The static ground, the plane z = 0.
    pub fn ground() -> Self {
        Self {
            id: GROUND_SURFACE_ID,
            world_from_surface: Isometry3::identity(),
            linear_velocity: Vector3::zeros(),
            angular_velocity: Vector3::zeros(),
        }
    }

    /// Unit normal (surface +z) in world.
    pub fn normal(&self) -> Vector3<f64> {
        self.world_from_surface.rotation * Vector3::z()
    }

    /// Height of the plane at world (x, y), m. A plane tilted more than 84 deg
    /// is treated as level at its origin to stay finite.
    pub fn height_at(&self, x: f64, y: f64) -> f64 {
        let n = self.normal();
        let o = self.world_from_surface.translation.vector;
        if n.z < 0.1 {
            return o.z;
        }
        o.z - (n.x * (x - o.x) + n.y * (y - o.y)) / n.z
    }

    /// Velocity of the surface material point at world position `p`, m/s.
    pub fn velocity_at(&self, p: &Vector3<f64>) -> Vector3<f64> {
        let o = self.world_from_surface.translation.vector;
        self.linear_velocity + self.angular_velocity.cross(&(p - o))
    }

    fn is_finite(&self) -> bool {
        self.world_from_surface
            .translation
            .vector
            .iter()
            .chain(self.world_from_surface.rotation.coords.iter())
            .chain(self.linear_velocity.iter())
            .chain(self.angular_velocity.iter())
            .all(|v| v.is_finite())
    }
}

/// Conditions around the vehicle during one step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Environment {
    /// Wind (air velocity) in world, m/s; acts through drag.
    pub wind_world: Vector3<f64>,
    /// The surface under the vehicle at the end of the step.
    pub surface: Surface,
}

impl Default for Environment {
    /// Still air over the ground.
    fn default() -> Self {
        Self {
            wind_world: Vector3::zeros(),
            surface: Surface::ground(),
        }
    }
}

/// Whether the vehicle is flying or standing on a surface.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ContactState {
    /// Free flight.
    Airborne,
    /// Standing on the surface with this id, moving rigidly with it.
    Resting {
        /// Id of the supporting surface.
        surface_id: u32,
    },
}

/// What happened when the vehicle hit a surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Impact {
    /// Id of the surface that was hit.
    pub surface_id: u32,
    /// Velocity of the vehicle relative to the surface point it hit, world frame, m/s.
    pub relative_velocity: Vector3<f64>,
    /// Angle between body up and the surface normal at the moment of impact, rad.
    pub tilt_rad: f64,
    /// How far below the surface the free motion ended before it was put back
    /// on top, m. Much more than one step of travel means the vehicle entered
    /// the surface from the side (e.g. hit the ground vehicle's flank).
    pub penetration_m: f64,
    /// Where the vehicle came to rest (on the surface), world, m.
    pub position: Vector3<f64>,
}

/// Result of one physics step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepReport {
    /// Contact state at the end of the step.
    pub contact: ContactState,
    /// Set when the vehicle hit the surface during this step.
    pub impact: Option<Impact>,
    /// True when the vehicle left a surface during this step.
    pub lifted_off: bool,
}

/// Why a quadrotor could not be built or stepped.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum QuadrotorError {
    /// The airframe parameters are invalid.
    #[error("invalid airframe parameter: {0}")]
    Params(#[from] ParamError),
    /// A step input (time step, command, wind, surface, state) is not usable.
    #[error("invalid input {what} = {value}: {allowed}")]
    Input {
        /// Which input.
        what: &'static str,
        /// Its value, formatted.
        value: String,
        /// What is accepted.
        allowed: &'static str,
    },
    /// The integration produced non-finite numbers; the state was left unchanged.
    #[error("integration diverged (non-finite state)")]
    Diverged,
}

/// The state while resting: the pose relative to the supporting surface is frozen.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Attachment {
    surface_id: u32,
    surface_from_body: Isometry3<f64>,
}

/// Integration state (quaternion not necessarily unit inside RK4 stages).
#[derive(Debug, Clone, Copy)]
struct Rigid {
    p: Vector3<f64>,
    v: Vector3<f64>,
    q: Quaternion<f64>,
    w: Vector3<f64>,
    m: [f64; 4],
}

impl Rigid {
    fn add_scaled(&self, d: &Rigid, h: f64) -> Rigid {
        let mut m = self.m;
        for (mi, di) in m.iter_mut().zip(d.m.iter()) {
            *mi += di * h;
        }
        Rigid {
            p: self.p + d.p * h,
            v: self.v + d.v * h,
            q: self.q + d.q * h,
            w: self.w + d.w * h,
            m,
        }
    }
}

/// The simulated quadrotor: parameters, state and contact.
#[derive(Debug, Clone)]
pub struct Quadrotor {
    params: AirframeParams,
    inertia: Matrix3<f64>,
    inertia_inv: Matrix3<f64>,
    state: VehicleState,
    attachment: Option<Attachment>,
}

impl Quadrotor {
    /// Builds a quadrotor in `state`; if it is at or below `surface`, it is
    /// placed on it, resting.
    pub fn new(
        params: AirframeParams,
        state: VehicleState,
        surface: &Surface,
    ) -> Result<Self, QuadrotorError> {
        params.validate()?;
        let inertia = params.inertia_matrix();
        let inertia_inv = inertia.try_inverse().ok_or_else(|| {
            ParamError::new(
                "inertia_diag_kg_m2",
                format!("{:?}", params.inertia_diag_kg_m2),
                "the inertia matrix must be invertible",
            )
        })?;
        let mut quad = Self {
            params,
            inertia,
            inertia_inv,
            state,
            attachment: None,
        };
        quad.set_state(state, surface)?;
        Ok(quad)
    }

    /// Replaces the state (e.g. to start a scenario); if the vehicle is at or
    /// below `surface` it is placed on it, resting.
    pub fn set_state(
        &mut self,
        state: VehicleState,
        surface: &Surface,
    ) -> Result<(), QuadrotorError> {
        if !state.is_finite() {
            return Err(input_error("state", "non-finite", "must be finite"));
        }
        if !surface.is_finite() {
            return Err(input_error("surface", "non-finite", "must be finite"));
        }
        self.state = state;
        self.state.world_from_body =
            UnitQuaternion::new_normalize(state.world_from_body.into_inner());
        self.attachment = None;
        if self.state.position.z <= surface.height_at(state.position.x, state.position.y) {
            self.attach(surface);
        }
        Ok(())
    }

    /// The airframe parameters.
    pub fn params(&self) -> &AirframeParams {
        &self.params
    }

    /// The current ground-truth state.
    pub fn state(&self) -> &VehicleState {
        &self.state
    }

    /// Whether the vehicle is flying or resting on a surface.
    pub fn contact(&self) -> ContactState {
        match self.attachment {
            Some(a) => ContactState::Resting {
                surface_id: a.surface_id,
            },
            None => ContactState::Airborne,
        }
    }

    /// Advances the vehicle by `dt_s` seconds under `commands` (held constant
    /// over the step) in `env`. Use dt <= 2 ms (>= 500 Hz).
    pub fn step(
        &mut self,
        dt_s: f64,
        commands: &MotorCommands,
        env: &Environment,
    ) -> Result<StepReport, QuadrotorError> {
        if !(dt_s.is_finite() && dt_s > 0.0 && dt_s <= 0.1) {
            return Err(input_error("dt_s", dt_s, "must be in (0, 0.1]"));
        }
        if commands.thrust.iter().any(|u| !u.is_finite()) {
            return Err(input_error(
                "motor thrust",
                format!("{:?}", commands.thrust),
                "must be finite",
            ));
        }
        if env.wind_world.iter().any(|w| !w.is_finite()) {
            return Err(input_error(
                "wind_world",
                format!("{:?}", env.wind_world),
                "must be finite",
            ));
        }
        if !env.surface.is_finite() {
            return Err(input_error("surface", "non-finite", "must be finite"));
        }
        let speed_cmd = self.speed_commands(commands);

        let mut lifted_off = false;
        if let Some(att) = self.attachment {
            if att.surface_id == env.surface.id && !self.thrust_lifts_off(&env.surface, env) {
                self.follow_surface(dt_s, &speed_cmd, att, &env.surface);
                return Ok(StepReport {
                    contact: self.contact(),
                    impact: None,
                    lifted_off: false,
                });
            }
            self.attachment = None;
            lifted_off = true;
        }

        let next = self.integrate(dt_s, &speed_cmd, &env.wind_world);
        if !next.is_finite() {
            return Err(QuadrotorError::Diverged);
        }
        self.state = next;

        let surface = &env.surface;
        let height = surface.height_at(self.state.position.x, self.state.position.y);
        let mut impact = None;
        if self.state.position.z < height {
            let penetration_m = height - self.state.position.z;
            self.state.position.z = height;
            let relative_velocity = self.state.velocity - surface.velocity_at(&self.state.position);
            let body_up = self.state.world_from_body * Vector3::z();
            let tilt_rad = body_up.dot(&surface.normal()).clamp(-1.0, 1.0).acos();
            self.attach(surface);
            impact = Some(Impact {
                surface_id: surface.id,
                relative_velocity,
                tilt_rad,
                penetration_m,
                position: self.state.position,
            });
        }
        Ok(StepReport {
            contact: self.contact(),
            impact,
            lifted_off,
        })
    }

    /// Converts normalized commands into motor speed commands (the ESC).
    fn speed_commands(&self, commands: &MotorCommands) -> [f64; 4] {
        let p = &self.params;
        let mut out = [0.0; 4];
        if commands.armed {
            for (o, u) in out.iter_mut().zip(commands.thrust.iter()) {
                let u = u.clamp(0.0, 1.0);
                *o = (u.sqrt() * p.motor_speed_max_rad_s)
                    .clamp(p.motor_speed_min_rad_s, p.motor_speed_max_rad_s);
            }
        }
        out
    }

    /// Sum of thrust and drag in world, N.
    fn aero_force_world(
        &self,
        rot: &UnitQuaternion<f64>,
        v: &Vector3<f64>,
        motor_speeds: &[f64; 4],
        wind: &Vector3<f64>,
    ) -> Vector3<f64> {
        let p = &self.params;
        let thrust: f64 = motor_speeds
            .iter()
            .map(|w| p.thrust_coefficient * w.max(0.0) * w.max(0.0))
            .sum();
        let air_body = rot.inverse() * (v - wind);
        let drag_body = -Vector3::from(p.drag_coefficients_n_s_m).component_mul(&air_body);
        rot * (Vector3::new(0.0, 0.0, thrust) + drag_body)
    }

    /// True when thrust and drag would accelerate the vehicle away from the surface.
    fn thrust_lifts_off(&self, surface: &Surface, env: &Environment) -> bool {
        let s = &self.state;
        let f = self.aero_force_world(
            &s.world_from_body,
            &s.velocity,
            &s.motor_speeds,
            &env.wind_world,
        );
        let n = surface.normal();
        f.dot(&n) / self.params.mass_kg > GRAVITY_M_S2 * n.z
    }

    /// One resting step: motors spin up or down, the pose rides on the surface.
    fn follow_surface(
        &mut self,
        dt_s: f64,
        speed_cmd: &[f64; 4],
        att: Attachment,
        surface: &Surface,
    ) {
        let decay = (-dt_s / self.params.motor_time_constant_s).exp();
        for (w, c) in self.state.motor_speeds.iter_mut().zip(speed_cmd.iter()) {
            *w = c + (*w - c) * decay;
        }
        let pose = surface.world_from_surface * att.surface_from_body;
        self.state.position = pose.translation.vector;
        self.state.world_from_body = pose.rotation;
        self.state.velocity = surface.velocity_at(&self.state.position);
        self.state.body_rates = pose.rotation.inverse() * surface.angular_velocity;
    }

    /// Puts the vehicle on `surface` (already at its height), level with it,
    /// keeping its heading, moving with it.
    fn attach(&mut self, surface: &Surface) {
        let n = surface.normal();
        let s = &mut self.state;
        s.position.z = surface.height_at(s.position.x, s.position.y);
        let forward = s.world_from_body * Vector3::x();
        let mut x = forward - n * forward.dot(&n);
        if x.norm() < 1e-6 {
            let side = s.world_from_body * Vector3::y();
            x = side.cross(&n);
        }
        if x.norm() < 1e-6 {
            x = surface.world_from_surface.rotation * Vector3::x();
        }
        let x = x.normalize();
        let y = n.cross(&x);
        let rot =
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_basis_unchecked(&[x, y, n]));
        s.world_from_body = rot;
        s.velocity = surface.velocity_at(&s.position);
        s.body_rates = rot.inverse() * surface.angular_velocity;
        let pose = Isometry3::from_parts(Translation3::from(s.position), rot);
        self.attachment = Some(Attachment {
            surface_id: surface.id,
            surface_from_body: surface.world_from_surface.inverse() * pose,
        });
    }

    /// Classic RK4 over position, velocity, attitude, body rates and motor speeds.
    fn integrate(&self, dt: f64, speed_cmd: &[f64; 4], wind: &Vector3<f64>) -> VehicleState {
        let s0 = Rigid {
            p: self.state.position,
            v: self.state.velocity,
            q: self.state.world_from_body.into_inner(),
            w: self.state.body_rates,
            m: self.state.motor_speeds,
        };
        let k1 = self.derivative(&s0, speed_cmd, wind);
        let k2 = self.derivative(&s0.add_scaled(&k1, dt / 2.0), speed_cmd, wind);
        let k3 = self.derivative(&s0.add_scaled(&k2, dt / 2.0), speed_cmd, wind);
        let k4 = self.derivative(&s0.add_scaled(&k3, dt), speed_cmd, wind);
        let s = s0
            .add_scaled(&k1, dt / 6.0)
            .add_scaled(&k2, dt / 3.0)
            .add_scaled(&k3, dt / 3.0)
            .add_scaled(&k4, dt / 6.0);
        let mut motor_speeds = s.m;
        for w in motor_speeds.iter_mut() {
            *w = w.max(0.0);
        }
        VehicleState {
            position: s.p,
            velocity: s.v,
            world_from_body: UnitQuaternion::new_normalize(s.q),
            body_rates: s.w,
            motor_speeds,
        }
    }

    /// Time derivative of the integration state.
    fn derivative(&self, s: &Rigid, speed_cmd: &[f64; 4], wind: &Vector3<f64>) -> Rigid {
        let p = &self.params;
        let rot = UnitQuaternion::new_normalize(s.q);
        let mut motor_speeds = s.m;
        for w in motor_speeds.iter_mut() {
            *w = w.max(0.0);
        }
        let force = self.aero_force_world(&rot, &s.v, &motor_speeds, wind);
        let accel = force / p.mass_kg - Vector3::new(0.0, 0.0, GRAVITY_M_S2);

        let mut motor_accel = [0.0; 4];
        let mut torque = Vector3::zeros();
        let mut rotor_momentum = 0.0;
        let mut rotor_momentum_rate = 0.0;
        for i in 0..4 {
            let g = QUAD_X_MOTORS[i];
            let w = motor_speeds[i];
            motor_accel[i] = (speed_cmd[i] - s.m[i]) / p.motor_time_constant_s;
            let thrust = p.thrust_coefficient * w * w;
            let r = p.motor_position_body(i);
            torque += r.cross(&Vector3::new(0.0, 0.0, thrust));
            torque.z -= g.spin * p.torque_coefficient * w * w;
            rotor_momentum += g.spin * w;
            rotor_momentum_rate += g.spin * motor_accel[i];
        }
        let omega = s.w;
        let rotor_h = Vector3::new(0.0, 0.0, p.rotor_inertia_kg_m2 * rotor_momentum);
        torque -= omega.cross(&(self.inertia * omega));
        torque -= omega.cross(&rotor_h);
        torque.z -= p.rotor_inertia_kg_m2 * rotor_momentum_rate;
        torque -= Vector3::from(p.angular_drag_coefficients_n_m_s).component_mul(&omega);
        let omega_dot = self.inertia_inv * torque;
        let q_dot = s.q * Quaternion::from_imag(omega) * 0.5;
        Rigid {
            p: s.v,
            v: accel,
            q: q_dot,
            w: omega_dot,
            m: motor_accel,
        }
    }
}

fn input_error(what: &'static str, value: impl ToString, allowed: &'static str) -> QuadrotorError {
    QuadrotorError::Input {
        what,
        value: value.to_string(),
        allowed,
    }
}

#[cfg(test)]
#[path = "quadrotor_test.rs"]
mod tests;
