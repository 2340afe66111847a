//! The simulator as a steppable object: the same code the `sim` binary runs on the wall
//! clock, driven here on simulated time so that `landing run` can compose it with the
//! pipeline libraries in one process, deterministically and faster than real time.
//!
//! A step advances physics by one fixed step and tells the caller which sensors are due;
//! the caller renders into a buffer of its choosing (a loaned shared-memory sample in the
//! `sim` binary, a reused vector in lockstep), so rendering never copies.

use ipc_types::msg::{Contact, Header, Point2, Text, TruthEvent, TruthKind, TruthState};

use mavlink::MavHeader;
use mavlink::dialects::common::MavMessage;

use nalgebra::{Isometry3, Translation3};
use optics::{CameraCalibration, PadModel};

use crate::camera::{BodyMotion, CameraError, DownCamera};
use crate::depth::DepthCamera;
use crate::ground_vehicle::PadState;
use crate::params::ParamError;
use crate::px4::commander::{Commander, VehicleStatus};
use crate::quadrotor::MotorCommands;
use crate::scenario::LoadedScenario;
use crate::world::{Event, TimedEvent, World, WorldError};

/// How far the camera's timestamps are from the true capture time.
#[derive(Debug, Clone)]
struct CameraClock {
    /// Fixed per run, ns.
    offset_ns: i64,
    /// Standard deviation per frame, ns.
    jitter_ns: f64,
    /// The jitter's draw.
    rng: crate::rng::Pcg32,
}

/// The autopilot's MAVLink on its way to the companion: each message is held for the
/// link's delay (per run) plus jitter (per message), in order.
#[derive(Debug, Clone)]
struct TelemetryDelay {
    offset_ns: f64,
    jitter_ns: f64,
    rng: crate::rng::Pcg32,
    held: std::collections::VecDeque<(u64, MavMessage)>,
}

impl TelemetryDelay {
    fn hold(&mut self, now_ns: u64, msgs: Vec<MavMessage>) {
        for m in msgs {
            let delay = (self.offset_ns + self.jitter_ns * self.rng.normal()).max(0.0);
            let due = (now_ns + delay as u64).max(self.held.back().map_or(0, |(t, _)| *t));
            self.held.push_back((due, m));
        }
    }

    fn release(&mut self, now_ns: u64) -> Vec<MavMessage> {
        let n = self.held.iter().take_while(|(t, _)| *t <= now_ns).count();
        self.held.drain(..n).map(|(_, m)| m).collect()
    }
}

/// Physics step: 2 ms (500 Hz).
pub const PHYSICS_STEP_NS: u64 = 2_000_000;

/// How often the `sim` process publishes the evaluator's truth state (20 Hz: enough for
/// the plots and the speed figures).
pub const TRUTH_STATE_PERIOD_NS: u64 = 50_000_000;

/// What one step produced.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct StepReport {
    /// A downward-camera frame is due: its exposure is centred on `camera_time_ns`.
    pub camera_due: bool,
    /// A depth frame is due.
    pub depth_due: bool,
    /// Ground-truth events that happened in this step (evaluator only).
    pub truth: Vec<TruthEvent>,
}

/// A periodic sensor trigger on simulated time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Schedule {
    period_ns: u64,
    next_ns: u64,
}

impl Schedule {
    /// Fires every `1 / rate_hz` seconds, first at `start_ns`.
    pub fn new(rate_hz: f64, start_ns: u64) -> Self {
        let period_ns = if rate_hz.is_finite() && rate_hz > 0.0 {
            (1e9 / rate_hz).round() as u64
        } else {
            u64::MAX
        };
        Self {
            period_ns,
            next_ns: start_ns,
        }
    }

    /// True once per period when `now_ns` has reached the next trigger; the next trigger
    /// keeps the grid (no drift), skipping triggers that fell entirely behind.
    pub fn due(&mut self, now_ns: u64) -> bool {
        if now_ns < self.next_ns {
            return false;
        }
        let behind = (now_ns - self.next_ns) / self.period_ns.max(1);
        self.next_ns = self
            .next_ns
            .saturating_add(self.period_ns.saturating_mul(behind + 1));
        true
    }

    /// Trigger period, ns.
    pub fn period_ns(&self) -> u64 {
        self.period_ns
    }
}

/// Why a simulator could not be built or stepped.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The world.
    #[error(transparent)]
    World(#[from] WorldError),
    /// A PX4 parameter.
    #[error("PX4 parameter {0}")]
    Px4(#[from] ParamError),
    /// The camera calibration file.
    #[error(transparent)]
    Calibration(#[from] optics::CalibrationError),
    /// The pad model.
    #[error(transparent)]
    Pad(#[from] optics::PadError),
    /// The downward camera.
    #[error(transparent)]
    Camera(#[from] CameraError),
}

/// When a rendered frame was captured and when it may be published.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shot {
    /// Middle of the exposure, simulated ns.
    pub capture_ns: u64,
    /// Capture plus the sensor's latency: when a real driver would hand it over.
    pub publish_ns: u64,
    /// Sub-exposures blended (motion blur).
    pub blur_samples: u32,
}

/// The world, the PX4 commander that flies it, and the sensor schedule.
#[derive(Debug, Clone)]
pub struct Simulator {
    world: World,
    commander: Commander,
    down_camera: Option<Box<DownCamera>>,
    depth_camera: Option<Box<DepthCamera>>,
    camera: Schedule,
    depth: Schedule,
    events_seen: usize,
    seed: u64,
    /// The camera clock's error.
    camera_clock: CameraClock,
    /// The telemetry link's delay.
    telemetry: TelemetryDelay,
    /// The boxes the depth camera renders, refilled per frame.
    boxes: Vec<crate::geometry::Obb>,
    /// The visual-inertial odometry (for an autopilot that fuses it).
    vio: crate::vio::Vio,
    /// The VIO's clock ahead of the world's: PX4's boot before the world started.
    vio_ahead_ns: u64,
}

impl Simulator {
    /// A simulator for `scenario` with every random process seeded from `seed`.
    pub fn new(scenario: &LoadedScenario, seed: u64) -> Result<Self, SimError> {
        let world = World::new(scenario.world_params(seed))?;
        let mut commander = Commander::new(scenario.px4.clone())?;
        commander.set_faults(scenario.scenario.faults.clone())?;
        commander.set_clock(scenario.scenario.autopilot_clock)?;
        let calibration = CameraCalibration::load(scenario.calibration_path())?;
        let pad = PadModel::load(scenario.pad_path())?;
        let mut down = scenario.scenario.camera.sensor.clone();
        down.seed = seed.wrapping_add(2);
        let mut depth = scenario.scenario.depth.sensor.clone();
        depth.seed = seed.wrapping_add(3);
        let mut sim = Self::from_world(
            world,
            commander,
            scenario.scenario.camera.rate_hz,
            scenario.scenario.depth.rate_hz,
            seed,
        );
        // The camera as built differs from its calibration file and drawing (the
        // pipeline reads those): per seed, within the scenario's camera errors.
        let (truth, mount_error) = scenario
            .scenario
            .camera
            .errors
            .draw(&calibration, seed.wrapping_add(4))?;
        let mut camera = DownCamera::new(down, truth, &pad)?;
        camera.set_mount_error(mount_error);
        sim.down_camera = Some(Box::new(camera));
        sim.vio = crate::vio::Vio::new(scenario.scenario.vio.clone(), seed.wrapping_add(8));
        let errors = &scenario.scenario.camera.errors;
        sim.camera_clock.offset_ns = errors.draw_clock_offset_ns(seed.wrapping_add(4));
        sim.camera_clock.jitter_ns = errors.clock_jitter_ms * 1e6;
        // So is the depth camera's mount.
        let mut depth = DepthCamera::new(depth)?;
        let mount_errors = &scenario.scenario.depth.mount_errors;
        depth.set_mount_error(mount_errors.draw(seed.wrapping_add(6)));
        sim.depth_camera = Some(Box::new(depth));
        let link = &scenario.scenario.telemetry_link;
        let mut draw = crate::rng::Pcg32::with_stream(seed.wrapping_add(5), 41);
        sim.telemetry.offset_ns =
            (link.latency_ms + link.latency_spread_ms * draw.normal()).max(0.0) * 1e6;
        sim.telemetry.jitter_ns = link.jitter_ms * 1e6;
        Ok(sim)
    }

    /// A simulator around an existing world and commander (tests, custom set-ups).
    pub fn from_world(
        world: World,
        commander: Commander,
        camera_hz: f64,
        depth_hz: f64,
        seed: u64,
    ) -> Self {
        Self {
            world,
            commander,
            down_camera: None,
            depth_camera: None,
            camera: Schedule::new(camera_hz, (1e9 / camera_hz.max(1.0)) as u64),
            // Offset by half a period so camera and depth work do not land on one step.
            depth: Schedule::new(depth_hz, (1.5e9 / depth_hz.max(1.0)) as u64),
            events_seen: 0,
            seed,
            camera_clock: CameraClock {
                offset_ns: 0,
                jitter_ns: 0.0,
                rng: crate::rng::Pcg32::with_stream(seed, 23),
            },
            telemetry: TelemetryDelay {
                offset_ns: 0.0,
                jitter_ns: 0.0,
                rng: crate::rng::Pcg32::with_stream(seed, 29),
                held: std::collections::VecDeque::new(),
            },
            boxes: Vec::new(),
            vio: crate::vio::Vio::new(
                crate::vio::VioParams {
                    rate_hz: 0.0,
                    ..Default::default()
                },
                seed,
            ),
            vio_ahead_ns: 0,
        }
    }

    /// What the commander sees of the world: the estimate, never truth.
    pub fn status(&self) -> VehicleStatus {
        VehicleStatus {
            estimate: *self.world.estimate(),
            crashed: self.world.crashed(),
        }
    }

    /// A MAVLink message from the companion (px4-link), at the current simulated time.
    pub fn handle_mavlink(&mut self, header: &MavHeader, msg: &MavMessage) {
        let status = self.status();
        self.commander
            .handle_message(self.world.time_ns(), header, msg, &status);
    }

    /// True once the autopilot's `telemetry_stop_s` fault has silenced it.
    pub fn autopilot_silent(&self) -> bool {
        self.commander.is_silent()
    }

    /// MAVLink messages of the autopilot that reach the companion by now: those produced
    /// since the last call, held for the telemetry link's delay (none without one).
    pub fn take_mavlink(&mut self) -> Vec<MavMessage> {
        let now = self.world.time_ns();
        let fresh = self.commander.take_outgoing();
        self.telemetry.hold(now, fresh);
        self.telemetry.release(now)
    }

    /// The next VIO sample that has arrived by now (its capture in simulated time; one
    /// taken before the world started says 0).
    pub fn take_vio(&mut self) -> Option<ipc_types::msg::VioOdometry> {
        let mut v = self
            .vio
            .take_due(self.world.time_ns() + self.vio_ahead_ns)?;
        v.msg.capture_ns = v.msg.capture_ns.saturating_sub(self.vio_ahead_ns);
        Some(v)
    }

    /// Before the world's clock starts (an autopilot booting on the ground, [`Self::time_ns`]
    /// still 0): the VIO runs on the autopilot's clock `boot_ns` and sees the vehicle at
    /// rest; from then on it stays that far ahead of the world's clock.
    pub fn step_vio_before_start(&mut self, boot_ns: u64) {
        self.vio_ahead_ns = boot_ns;
        self.vio.step(self.world.truth(), boot_ns);
    }

    /// The downward camera, if this simulator has one.
    pub fn down_camera(&self) -> Option<&DownCamera> {
        self.down_camera.as_deref()
    }

    /// The depth camera, if this simulator has one.
    pub fn depth_camera(&self) -> Option<&DepthCamera> {
        self.depth_camera.as_deref()
    }

    /// What the downward camera sees now: the body's true motion and the pad.
    pub fn camera_view(&self) -> (BodyMotion, Option<PadState>) {
        let truth = self.world.truth();
        let body = BodyMotion {
            world_from_body: Isometry3::from_parts(
                Translation3::from(truth.position),
                truth.world_from_body,
            ),
            linear_velocity: truth.velocity,
            angular_velocity_body: truth.body_rates,
        };
        (body, self.world.pad())
    }

    /// Renders the downward camera at the current true pose into `out` (exactly
    /// `down_camera().frame_len()` bytes); `None` without a camera.
    pub fn render_camera_into(&mut self, out: &mut [u8]) -> Result<Option<Shot>, SimError> {
        let (body, pad) = self.camera_view();
        let now = self.world.time_ns();
        let Some(cam) = self.down_camera.as_deref_mut() else {
            return Ok(None);
        };
        let blur_samples = cam.render_into(&body, pad.as_ref(), out)?;
        let publish_ns = now + (cam.params().latency_s.max(0.0) * 1e9) as u64;
        // The frame's timestamp is the camera's clock: off by the drawn offset and
        // jitter, never after the frame is published.
        let c = &mut self.camera_clock;
        let error = c.offset_ns + (c.jitter_ns * c.rng.normal()) as i64;
        let capture_ns = now.saturating_add_signed(error).min(publish_ns);
        Ok(Some(Shot {
            capture_ns,
            publish_ns,
            blur_samples,
        }))
    }

    /// Renders the depth camera at the current true pose into `out`; `None` without one.
    pub fn render_depth_into(&mut self, out: &mut [u16]) -> Option<Shot> {
        let cam = self.depth_camera.as_deref_mut()?;
        let truth = self.world.truth();
        let world_from_body =
            Isometry3::from_parts(Translation3::from(truth.position), truth.world_from_body);
        self.world.boxes_in_view_into(&mut self.boxes);
        cam.render_into(&world_from_body, &self.boxes, out);
        let now = self.world.time_ns();
        Some(Shot {
            capture_ns: now,
            publish_ns: now + (cam.params().latency_s.max(0.0) * 1e9) as u64,
            blur_samples: 1,
        })
    }

    /// The PX4 commander (mode, arming).
    pub fn commander(&self) -> &Commander {
        &self.commander
    }

    /// The PX4 commander, mutably (events, fault injection).
    pub fn commander_mut(&mut self) -> &mut Commander {
        &mut self.commander
    }

    /// Runs the commander, applies its arming and setpoint, advances physics by one step,
    /// and reports what is due.
    pub fn step(&mut self) -> Result<StepReport, SimError> {
        let status = self.status();
        self.commander.update(self.world.time_ns(), &status);
        self.world.set_armed(self.commander.armed());
        self.world.set_setpoint(self.commander.setpoint());
        self.world.step(PHYSICS_STEP_NS)?;
        Ok(self.report())
    }

    /// Advances physics by one step with the motors another autopilot commands (real PX4
    /// through `sim --px4-sitl`): this simulator's commander and autopilot stay idle.
    pub fn step_with_motors(&mut self, motors: &MotorCommands) -> Result<StepReport, SimError> {
        self.world.set_armed(motors.armed);
        self.world.step_with_motors(PHYSICS_STEP_NS, motors)?;
        Ok(self.report())
    }

    /// What the step just taken produced: new truth events, sensors due.
    fn report(&mut self) -> StepReport {
        let now = self.world.time_ns();
        self.vio.step(self.world.truth(), now + self.vio_ahead_ns);
        let events = self.world.events();
        let truth = events[self.events_seen.min(events.len())..]
            .iter()
            .map(truth_event)
            .collect();
        self.events_seen = events.len();
        StepReport {
            camera_due: self.camera.due(now),
            depth_due: self.depth.due(now),
            truth,
        }
    }

    /// The world (ground truth: for the simulator's own sensors and the evaluator).
    pub fn world(&self) -> &World {
        &self.world
    }

    /// The world, mutable (the autopilot side sets setpoints and arming).
    pub fn world_mut(&mut self) -> &mut World {
        &mut self.world
    }

    /// Simulated time, ns.
    pub fn time_ns(&self) -> u64 {
        self.world.time_ns()
    }

    /// The seed this run uses.
    pub fn seed(&self) -> u64 {
        self.seed
    }
}

/// Converts a world event to the evaluator-only message.
pub fn truth_event(e: &TimedEvent) -> TruthEvent {
    let mut m = TruthEvent {
        msg: Header::captured_at(e.time_ns),
        ..Default::default()
    };
    match e.event {
        Event::Touchdown {
            on_pad,
            rel_position_pad,
            rel_velocity,
            tilt_rad,
            gear_pad,
        } => {
            m.kind = TruthKind::Touchdown as u32;
            m.on_pad = u32::from(on_pad);
            if let Some(p) = rel_position_pad {
                m.rel_position_pad = [p.x, p.y];
            }
            m.rel_velocity = [rel_velocity.x, rel_velocity.y, rel_velocity.z];
            m.tilt_deg = tilt_rad.to_degrees();
            m.gear_pad = gear_pad.unwrap_or_default().map(Point2::from);
        }
        Event::Liftoff { from_pad } => {
            m.kind = TruthKind::Liftoff as u32;
            m.on_pad = u32::from(from_pad);
        }
        Event::Crash { reason } => {
            m.kind = TruthKind::Crash as u32;
            m.reason = Text::new(&format!("{reason:?}"));
        }
        Event::Collision { obstacle_index } => {
            m.kind = TruthKind::Collision as u32;
            m.obstacle_index = obstacle_index as u32;
        }
    }
    m
}

#[cfg(test)]
#[path = "lockstep_test.rs"]
mod tests;

/// Where the vehicle and the pad really are now, stamped `now_ns` (the publisher's clock),
/// for the evaluator-only truth-state topic.
pub fn truth_state(sim: &Simulator, now_ns: u64) -> TruthState {
    world_truth_state(sim.world(), now_ns)
}

/// [`truth_state`] of a bare world (the referee's scripted tests step one directly).
pub fn world_truth_state(world: &World, now_ns: u64) -> TruthState {
    let truth = world.truth();
    let pad = world.pad();
    TruthState {
        msg: Header::captured_at(now_ns),
        sim_time_ns: world.time_ns(),
        vehicle_position: truth.position.into(),
        vehicle_velocity: truth.velocity.into(),
        pad_valid: u32::from(pad.is_some()),
        armed: u32::from(world.armed()),
        pad_position: pad
            .as_ref()
            .map_or([0.0; 3], |p| p.world_from_pad.translation.vector.into()),
        pad_velocity: pad.as_ref().map_or([0.0; 3], |p| p.linear_velocity.into()),
        vehicle_velocity_rel_pad: pad.as_ref().map_or([0.0; 3], |p| {
            (truth.velocity - p.velocity_at(&truth.position)).into()
        }),
        gear_pad: world.gear_in_pad().unwrap_or_default().map(Point2::from),
        contact: match world.resting_on_pad() {
            None => Contact::Airborne,
            Some(false) => Contact::Ground,
            Some(true) => Contact::Pad,
        } as u32,
        reserved: 0,
    }
}
