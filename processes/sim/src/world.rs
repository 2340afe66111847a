//! The simulated world: quadrotor, autopilot, estimator noise, wind, the
//! ground vehicle with its pad, and box obstacles, stepped together.
//!
//! [`World::step`] runs one fixed step the way PX4 on a real vehicle would
//! experience it: the estimator reports truth plus noise, the autopilot turns
//! the current setpoint into motor commands, the physics integrates under the
//! wind and against the surface under the vehicle (the pad if the vehicle is
//! over its footprint, otherwise the ground). The world records ground-truth
//! events (touchdown, lift-off, crash, collision) that only the evaluator may
//! see; the pipeline never does.

use nalgebra::{Vector2, Vector3};
use serde::Deserialize;
use thiserror::Error;

use crate::autopilot::{Autopilot, ControlOutput, EstimatedState, Setpoint};
use crate::autopilot_params::AutopilotParams;
use crate::estimator_noise::{EstimatorNoise, EstimatorNoiseParams};
pub use crate::geometry::{Aabb, Obb};
use crate::ground_vehicle::{GroundVehicle, GroundVehicleParams, PAD_SURFACE_ID, PadState};
use crate::params::{self, ParamError};
use crate::quadrotor::{
    AirframeParams, ContactState, Environment, MotorCommands, Quadrotor, QuadrotorError, Surface,
    VehicleState,
};
use crate::wind::{Wind, WindParams};

/// Longest accepted step: 2 ms, i.e. the physics runs at 500 Hz or faster.
pub const MAX_STEP_NS: u64 = 2_000_000;

/// How long the vehicle must be out of contact before it counts as airborne
/// (and a later contact as a new touchdown), so a skip on landing is one event.
pub const AIRBORNE_DEBOUNCE_NS: u64 = 200_000_000;

/// How far the gear may sink below the roof before touching the vehicle's body
/// counts as hitting its side, m: more than the gear's deflection on a 3 m/s touch (4 cm).
pub const BODY_CONTACT_TOLERANCE_M: f64 = 0.06;

/// Propeller radius as a fraction of the arm length (10" props on 0.225 m arms).
pub(crate) const ROTOR_RADIUS_FRACTION: f64 = 0.55;

/// When a contact or attitude counts as a crash.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CrashThresholds {
    /// Impact speed along the surface normal above which a contact is a crash, m/s.
    pub max_impact_speed_m_s: f64,
    /// Tilt from the surface normal above which a contact is a crash, deg.
    pub max_contact_tilt_deg: f64,
    /// Tilt from vertical above which the vehicle has crashed anywhere, deg.
    pub max_tilt_deg: f64,
}

impl Default for CrashThresholds {
    /// 3 m/s impact, 60 deg in contact, 90 deg anywhere.
    fn default() -> Self {
        Self {
            max_impact_speed_m_s: 3.0,
            max_contact_tilt_deg: 60.0,
            max_tilt_deg: 90.0,
        }
    }
}

impl CrashThresholds {
    /// Checks every field.
    pub fn validate(&self) -> Result<(), ParamError> {
        params::positive("max_impact_speed_m_s", self.max_impact_speed_m_s)?;
        params::in_range(
            "max_contact_tilt_deg",
            self.max_contact_tilt_deg,
            0.0,
            180.0,
        )?;
        params::in_range("max_tilt_deg", self.max_tilt_deg, 0.0, 180.0)?;
        Ok(())
    }
}

/// Everything that defines a world, loadable from the `[world]` part of a scenario.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WorldParams {
    /// The quadrotor's physical parameters.
    pub airframe: AirframeParams,
    /// Controller parameters; absent means PX4 defaults tuned for the airframe.
    pub autopilot: Option<AutopilotParams>,
    /// Noise of the state estimate the autopilot (and px4-link) sees.
    pub estimator_noise: EstimatorNoiseParams,
    /// Wind.
    pub wind: WindParams,
    /// The ground vehicle carrying the pad; absent means no pad.
    pub ground_vehicle: Option<GroundVehicleParams>,
    /// Box obstacles that raise collision events.
    pub obstacles: Vec<Aabb>,
    /// Crash criteria.
    pub crash: CrashThresholds,
    /// Where the vehicle starts, world ENU, m (on the ground at the origin by default).
    pub initial_position_m: [f64; 3],
    /// Initial heading, rad (ENU: 0 = east, counter-clockwise).
    pub initial_yaw_rad: f64,
}

impl Default for WorldParams {
    /// A P450 on the ground at the origin, VIO-like estimator noise, calm air,
    /// no ground vehicle, no obstacles.
    fn default() -> Self {
        Self {
            airframe: AirframeParams::default(),
            autopilot: None,
            estimator_noise: EstimatorNoiseParams::default(),
            wind: WindParams::default(),
            ground_vehicle: None,
            obstacles: Vec::new(),
            crash: CrashThresholds::default(),
            initial_position_m: [0.0; 3],
            initial_yaw_rad: 0.0,
        }
    }
}

impl WorldParams {
    /// Parses world parameters from TOML text (unknown fields are errors).
    pub fn from_toml(text: &str) -> Result<Self, WorldError> {
        Ok(toml::from_str(text)?)
    }
}

/// Why a crash was declared.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CrashReason {
    /// Hit a surface faster than the limit along its normal.
    HardImpact {
        /// Whether the surface was the pad.
        on_pad: bool,
        /// Impact speed along the surface normal, m/s.
        normal_speed_m_s: f64,
    },
    /// Touched a surface tilted beyond the contact limit.
    TiltedContact {
        /// Whether the surface was the pad.
        on_pad: bool,
        /// Tilt relative to the surface normal, deg.
        tilt_deg: f64,
    },
    /// Tilted beyond the in-flight limit (e.g. flipped over).
    Excessive {
        /// Tilt from vertical, deg.
        tilt_deg: f64,
    },
    /// Touched the ground vehicle's body below its roof (its side, or the roof's edge
    /// from below).
    HitGroundVehicle,
}

/// A ground-truth event.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Event {
    /// The vehicle came to rest on a surface after being airborne.
    Touchdown {
        /// True if it landed on the pad, false if on the ground.
        on_pad: bool,
        /// Where, in the pad frame (x, y), m; None without a ground vehicle.
        rel_position_pad: Option<Vector2<f64>>,
        /// Vehicle velocity relative to the surface point it hit, in the
        /// surface's frame (pad frame on the pad, world on the ground), m/s.
        rel_velocity: Vector3<f64>,
        /// Angle between body up and the surface normal at contact, rad.
        tilt_rad: f64,
        /// Each foot of the landing gear in the pad frame (x, y), m; None without a
        /// ground vehicle.
        gear_pad: Option<[[f64; 2]; 4]>,
    },
    /// The vehicle left a surface and has been airborne for the debounce time.
    Liftoff {
        /// True if it left the pad.
        from_pad: bool,
    },
    /// The vehicle crashed; the motors are stopped from then on.
    Crash {
        /// Why.
        reason: CrashReason,
    },
    /// The vehicle's collision sphere entered an obstacle box.
    Collision {
        /// Index into the world's obstacle list.
        obstacle_index: usize,
    },
}

/// An event with the simulated time it happened at.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimedEvent {
    /// Simulated time at the end of the step that produced it, ns.
    pub time_ns: u64,
    /// The event.
    pub event: Event,
}

/// Why a world could not be built or stepped.
#[derive(Debug, Error)]
pub enum WorldError {
    /// A parameter is invalid; `section` names the part of the world it belongs to.
    #[error("{section}.{source}")]
    Params {
        /// Which part (airframe, autopilot, ...).
        section: &'static str,
        /// The parameter error.
        source: ParamError,
    },
    /// The scenario text is not valid TOML for these parameters.
    #[error("invalid world parameters: {0}")]
    Parse(#[from] toml::de::Error),
    /// The step length is not in (0, MAX_STEP_NS].
    #[error("dt_ns = {0}: must be in (0, {MAX_STEP_NS}] (physics at >= 500 Hz)")]
    InvalidStep(u64),
    /// The physics rejected an input or diverged.
    #[error("physics: {0}")]
    Physics(#[from] QuadrotorError),
}

fn section(name: &'static str) -> impl Fn(ParamError) -> WorldError {
    move |source| WorldError::Params {
        section: name,
        source,
    }
}

/// The whole simulated world.
#[derive(Debug, Clone)]
pub struct World {
    quad: Quadrotor,
    autopilot: Autopilot,
    noise: EstimatorNoise,
    wind: Wind,
    ground_vehicle: Option<GroundVehicle>,
    obstacles: Vec<Aabb>,
    crash: CrashThresholds,
    time_ns: u64,
    armed: bool,
    setpoint: Setpoint,
    estimate: EstimatedState,
    last_control: Option<ControlOutput>,
    crashed: bool,
    airborne: bool,
    left_contact_ns: Option<u64>,
    last_surface_id: u32,
    touching: Vec<bool>,
    events: Vec<TimedEvent>,
    step_events_from: usize,
}

impl World {
    /// Builds the world at time zero, disarmed, with the vehicle at its
    /// initial position (resting on whatever surface is at or above it).
    pub fn new(params: WorldParams) -> Result<Self, WorldError> {
        let WorldParams {
            airframe,
            autopilot,
            estimator_noise,
            wind,
            ground_vehicle,
            obstacles,
            crash,
            initial_position_m,
            initial_yaw_rad,
        } = params;
        airframe.validate().map_err(section("airframe"))?;
        let autopilot = autopilot.unwrap_or_else(|| AutopilotParams::tuned_for(&airframe));
        let autopilot = Autopilot::new(autopilot).map_err(section("autopilot"))?;
        let noise = EstimatorNoise::new(estimator_noise).map_err(section("estimator_noise"))?;
        let wind = Wind::new(&wind).map_err(section("wind"))?;
        let ground_vehicle = ground_vehicle
            .map(GroundVehicle::new)
            .transpose()
            .map_err(section("ground_vehicle"))?;
        for (i, o) in obstacles.iter().enumerate() {
            o.validate(i).map_err(section("world"))?;
        }
        crash.validate().map_err(section("crash"))?;
        params::finite_all("initial_position_m", &initial_position_m).map_err(section("world"))?;
        params::finite("initial_yaw_rad", initial_yaw_rad).map_err(section("world"))?;

        let initial = VehicleState::at_rest(Vector3::from(initial_position_m), initial_yaw_rad);
        let quad = Quadrotor::new(airframe, initial, &Surface::ground())?;
        let touching = vec![false; obstacles.len()];
        let mut world = Self {
            quad,
            autopilot,
            noise,
            wind,
            ground_vehicle,
            obstacles,
            crash,
            time_ns: 0,
            armed: false,
            setpoint: Setpoint::default(),
            estimate: EstimatedState::from_truth(&initial, false),
            last_control: None,
            crashed: false,
            airborne: false,
            left_contact_ns: None,
            last_surface_id: 0,
            touching,
            events: Vec::new(),
            step_events_from: 0,
        };
        world.set_vehicle_state(initial)?;
        Ok(world)
    }

    /// Places the vehicle in `state` (e.g. a scenario starting in the air),
    /// resting on the surface under it if it is at or below it.
    pub fn set_vehicle_state(&mut self, state: VehicleState) -> Result<(), WorldError> {
        let surface = self.surface_under(&state.position, self.time_s());
        self.quad.set_state(state, &surface)?;
        let resting = self.quad.contact() != ContactState::Airborne;
        self.airborne = !resting;
        self.left_contact_ns = if resting { None } else { Some(self.time_ns) };
        self.last_surface_id = surface.id;
        self.estimate = EstimatedState::from_truth(self.quad.state(), resting);
        // A placement, not a flight: the land detector starts settled where the vehicle is.
        self.autopilot.place(!resting);
        Ok(())
    }

    /// Simulated time since the start, ns.
    pub fn time_ns(&self) -> u64 {
        self.time_ns
    }

    /// Simulated time since the start, s.
    pub fn time_s(&self) -> f64 {
        self.time_ns as f64 * 1e-9
    }

    /// Arms or disarms the motors; arming resets the controller's integrators.
    pub fn set_armed(&mut self, armed: bool) {
        if armed && !self.armed {
            self.autopilot.reset();
        }
        self.armed = armed;
    }

    /// Whether the motors are armed (a crash disarms them).
    pub fn armed(&self) -> bool {
        self.armed
    }

    /// Sets what the autopilot should fly from the next step on.
    pub fn set_setpoint(&mut self, setpoint: Setpoint) {
        self.setpoint = setpoint;
    }

    /// The setpoint in use.
    pub fn setpoint(&self) -> &Setpoint {
        &self.setpoint
    }

    /// Ground-truth state of the quadrotor (for the simulator and the evaluator only).
    pub fn truth(&self) -> &VehicleState {
        self.quad.state()
    }

    /// The noisy estimate the autopilot used in the last step (what PX4 would report).
    pub fn estimate(&self) -> &EstimatedState {
        &self.estimate
    }

    /// The controller's output of the last step, if it ran (None while disarmed).
    pub fn last_control(&self) -> Option<&ControlOutput> {
        self.last_control.as_ref()
    }

    /// Whether the vehicle flies or rests, and on what.
    pub fn contact(&self) -> ContactState {
        self.quad.contact()
    }

    /// True once a crash has been declared.
    pub fn crashed(&self) -> bool {
        self.crashed
    }

    /// The pad now, if there is a ground vehicle.
    pub fn pad(&self) -> Option<PadState> {
        self.ground_vehicle
            .as_ref()
            .map(|g| g.state_at(self.time_s()))
    }

    /// Each foot of the landing gear in the pad frame (x, y) now, m; None without a
    /// ground vehicle. Truth, for the evaluator's "every foot on the board".
    pub fn gear_in_pad(&self) -> Option<[[f64; 2]; 4]> {
        let pad = self.pad()?;
        let s = self.quad.state();
        let feet = self.quad.params().landing_gear_m;
        Some(feet.map(|f| {
            let world = s.position + s.world_from_body * Vector3::from(f);
            let local = pad.world_from_pad.inverse_transform_point(&world.into());
            [local.x, local.y]
        }))
    }

    /// The surface the vehicle rests on: `None` while airborne, else whether it is the
    /// pad.
    pub fn resting_on_pad(&self) -> Option<bool> {
        match self.quad.contact() {
            ContactState::Resting { surface_id } => Some(surface_id == PAD_SURFACE_ID),
            ContactState::Airborne => None,
        }
    }

    /// The ground vehicle, if any.
    pub fn ground_vehicle(&self) -> Option<&GroundVehicle> {
        self.ground_vehicle.as_ref()
    }

    /// Wind at the current time, world ENU, m/s.
    pub fn wind_now(&self) -> Vector3<f64> {
        self.wind.velocity_at(self.time_s())
    }

    /// The box obstacles.
    pub fn obstacles(&self) -> &[Aabb] {
        &self.obstacles
    }

    /// Every box a camera sees now: the obstacles and the ground vehicle's body.
    pub fn boxes_in_view(&self) -> Vec<Obb> {
        let mut boxes = Vec::new();
        self.boxes_in_view_into(&mut boxes);
        boxes
    }

    /// [`World::boxes_in_view`] into the caller's buffer (cleared first), so a renderer
    /// allocates once, not per frame.
    pub fn boxes_in_view_into(&self, boxes: &mut Vec<Obb>) {
        boxes.clear();
        boxes.extend(self.obstacles.iter().map(Obb::from));
        if let Some(g) = &self.ground_vehicle {
            boxes.push(g.body(&g.state_at(self.time_s())));
        }
    }

    /// Every event so far, oldest first.
    pub fn events(&self) -> &[TimedEvent] {
        &self.events
    }

    /// The quadrotor's airframe parameters.
    pub fn airframe(&self) -> &AirframeParams {
        self.quad.params()
    }

    /// The autopilot's parameters.
    pub fn autopilot_params(&self) -> &AutopilotParams {
        self.autopilot.params()
    }

    /// The autopilot, for its hover thrust estimate and land detector (logs, tests).
    pub fn autopilot(&self) -> &Autopilot {
        &self.autopilot
    }

    /// Advances the world by `dt_ns` with the autopilot flying the current
    /// setpoint (motors stopped and controller idle while disarmed). Returns
    /// the events of this step.
    pub fn step(&mut self, dt_ns: u64) -> Result<&[TimedEvent], WorldError> {
        check_step(dt_ns)?;
        let dt_s = dt_ns as f64 * 1e-9;
        // Landed is the autopilot's own land detector's word (PX4's), not the contact.
        let landed = self.autopilot.land_detected().landed;
        self.estimate = self.noise.apply(dt_s, self.quad.state(), landed);
        let commands = if self.armed && !self.crashed {
            let control = self.autopilot.update(dt_s, &self.estimate, &self.setpoint);
            self.last_control = Some(control);
            MotorCommands {
                armed: true,
                thrust: control.motors,
            }
        } else {
            // Like PX4, the controllers do not run while disarmed.
            self.autopilot.disarmed(dt_s, &self.estimate);
            self.last_control = None;
            MotorCommands::off()
        };
        self.step_physics(dt_ns, &commands)
    }

    /// Advances the world by `dt_ns` with explicit motor commands, bypassing
    /// the autopilot (for tests and for an external controller). A crashed
    /// vehicle's motors stay stopped. The autopilot, land detector included, does
    /// not run: the estimate's `landed` keeps its last value.
    pub fn step_with_motors(
        &mut self,
        dt_ns: u64,
        commands: &MotorCommands,
    ) -> Result<&[TimedEvent], WorldError> {
        check_step(dt_ns)?;
        let dt_s = dt_ns as f64 * 1e-9;
        let landed = self.autopilot.land_detected().landed;
        self.estimate = self.noise.apply(dt_s, self.quad.state(), landed);
        let mut commands = *commands;
        if self.crashed {
            commands.armed = false;
        }
        self.step_physics(dt_ns, &commands)
    }

    /// The surface under world point `p` at time `t_s`: the pad if `p` is over
    /// its footprint, else the ground.
    fn surface_under(&self, p: &Vector3<f64>, t_s: f64) -> Surface {
        if let Some(g) = &self.ground_vehicle {
            let pad = g.state_at(t_s);
            if g.is_over_pad(&pad, p) {
                return g.roof(&pad);
            }
        }
        Surface::ground()
    }

    fn step_physics(
        &mut self,
        dt_ns: u64,
        commands: &MotorCommands,
    ) -> Result<&[TimedEvent], WorldError> {
        self.step_events_from = self.events.len();
        let wind = self.wind.velocity_at(self.time_s());
        let end_ns = self.time_ns.saturating_add(dt_ns);
        let end_s = end_ns as f64 * 1e-9;
        let pad_end = self.ground_vehicle.as_ref().map(|g| g.state_at(end_s));
        let env = Environment {
            wind_world: wind,
            surface: Surface::ground(),
            platform: self
                .ground_vehicle
                .as_ref()
                .zip(pad_end.as_ref())
                .map(|(g, pad)| g.roof(pad)),
        };
        let dt_s = dt_ns as f64 * 1e-9;
        let report = self.quad.step(dt_s, commands, &env)?;
        self.time_ns = end_ns;

        if report.lifted_off {
            self.left_contact_ns = Some(self.time_ns);
        }
        if let Some(impact) = report.impact {
            self.left_contact_ns = None;
            let on_pad = impact.surface_id == PAD_SURFACE_ID;
            let surface = env.surface_with_id(impact.surface_id);
            let normal_speed = -impact.relative_velocity.dot(&surface.normal());
            let crash = if normal_speed > self.crash.max_impact_speed_m_s {
                Some(CrashReason::HardImpact {
                    on_pad,
                    normal_speed_m_s: normal_speed,
                })
            } else {
                None
            };
            if let Some(reason) = crash {
                self.declare_crash(reason);
            } else if self.airborne && !self.crashed {
                let rel_position_pad = self.pad().map(|pad| {
                    let local = pad
                        .world_from_pad
                        .inverse_transform_point(&impact.position.into());
                    Vector2::new(local.x, local.y)
                });
                let rel_velocity = surface
                    .world_from_surface
                    .rotation
                    .inverse_transform_vector(&impact.relative_velocity);
                let gear_pad = self.gear_in_pad();
                self.push(Event::Touchdown {
                    on_pad,
                    rel_position_pad,
                    rel_velocity,
                    tilt_rad: impact.tilt_rad,
                    gear_pad,
                });
            }
            self.airborne = false;
        }
        if let ContactState::Resting { surface_id } = report.contact {
            self.last_surface_id = surface_id;
            // Tipped over onto its arms: on the ground, the tilt is the contact's.
            let tilt_deg = env
                .surface_with_id(surface_id)
                .tilt_rad(&self.quad.state().world_from_body)
                .to_degrees();
            if tilt_deg > self.crash.max_contact_tilt_deg {
                self.declare_crash(CrashReason::TiltedContact {
                    on_pad: surface_id == PAD_SURFACE_ID,
                    tilt_deg,
                });
            }
        }
        if !self.airborne
            && self.quad.contact() == ContactState::Airborne
            && self
                .left_contact_ns
                .is_some_and(|t| self.time_ns.saturating_sub(t) >= AIRBORNE_DEBOUNCE_NS)
        {
            self.airborne = true;
            self.push(Event::Liftoff {
                from_pad: self.last_surface_id == PAD_SURFACE_ID,
            });
        }

        let tilt_deg = self.quad.state().tilt_rad().to_degrees();
        if tilt_deg > self.crash.max_tilt_deg {
            self.declare_crash(CrashReason::Excessive { tilt_deg });
        }

        let position = self.quad.state().position;
        let radius = self.quad.params().collision_radius_m;
        if let (Some(g), Some(pad)) = (&self.ground_vehicle, &pad_end)
            && self.touches_vehicle_body(&g.body(pad), pad)
        {
            self.declare_crash(CrashReason::HitGroundVehicle);
        }
        for i in 0..self.obstacles.len() {
            let hit = self.obstacles[i].intersects_sphere(&position, radius);
            if hit && !self.touching[i] {
                self.push(Event::Collision { obstacle_index: i });
            }
            self.touching[i] = hit;
        }
        Ok(&self.events[self.step_events_from..])
    }

    /// True if the gear or a rotor is in the ground vehicle's body below its roof: a
    /// foot standing on the roof touches only its top face; one below the roof (beside
    /// it) or a rotor disc there touches its side.
    fn touches_vehicle_body(&self, body: &Obb, pad: &PadState) -> bool {
        let s = self.quad.state();
        let air = self.quad.params();
        let feet = air.landing_gear_m.map(|f| (Vector3::from(f), 0.0));
        let rotors: [(Vector3<f64>, f64); 4] = std::array::from_fn(|i| {
            (
                air.motor_position_body(i) + air.com_body(),
                ROTOR_RADIUS_FRACTION * air.arm_length_m,
            )
        });
        feet.iter().chain(rotors.iter()).any(|(p_body, radius)| {
            let p = s.position + s.world_from_body * p_body;
            let below_roof =
                pad.world_from_pad.inverse_transform_point(&p.into()).z < -BODY_CONTACT_TOLERANCE_M;
            below_roof && body.intersects_sphere(&p, *radius)
        })
    }

    fn declare_crash(&mut self, reason: CrashReason) {
        if !self.crashed {
            self.crashed = true;
            self.armed = false;
            self.push(Event::Crash { reason });
        }
    }

    fn push(&mut self, event: Event) {
        self.events.push(TimedEvent {
            time_ns: self.time_ns,
            event,
        });
    }
}

fn check_step(dt_ns: u64) -> Result<(), WorldError> {
    if dt_ns == 0 || dt_ns > MAX_STEP_NS {
        return Err(WorldError::InvalidStep(dt_ns));
    }
    Ok(())
}

#[cfg(test)]
#[path = "world_test.rs"]
mod tests;
