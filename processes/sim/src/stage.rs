//! The simulator as a stage, for both drivers: the world and the PX4-like autopilot
//! advance to the driver's time on each tick (physics steps of [`PHYSICS_STEP_NS`]),
//! MAVLink leaves and arrives as wire bytes (a command number the dialect lacks is
//! answered UNSUPPORTED, as PX4's commander does), camera and depth frames are rendered
//! at capture and handed over after the sensor's latency, and the ground truth goes out
//! on the evaluator-only topics (no pipeline stage may read them; the graph check
//! refuses a node that does).
//!
//! [`Pace`] says how simulated time follows the driver's: equal to it in lockstep, the
//! wall clock times a speed in the `sim` process, whose messages then carry the driver's
//! (monotonic) times like every other process's.

use std::collections::VecDeque;

use ipc_types::msg::{
    CameraFrameHeader, DepthFrameHeader, Header, Intrinsics, PixelEncoding, Stage as StageId,
};
use ipc_types::topics;
use mavlink::MavHeader;
use mavlink::dialects::common::MavMessage;
use mavlink::dialects::common::MavResult;
use px4_protocol::codec::{Guard, StreamDecoder};
use px4_protocol::raw::{COMMAND_ACK_CRC_EXTRA, command_ack_frame, unknown_commands};
use px4_protocol::signing::{Signer, SigningKey};
use stage::{Counter, Input, Message, Outbox, SliceHeader, SliceMut, Stage, StageError};

use crate::camera::PixelFormat;
use crate::depth::DEPTH_SCALE_M;
use crate::lockstep::{PHYSICS_STEP_NS, Simulator, TRUTH_STATE_PERIOD_NS, truth_state};
use crate::px4::commander::BootClock;

/// What the `sim` process flies, as its flags say.
#[derive(Debug, Clone, clap::Args)]
pub struct SimFlags {
    /// Scenario name (from deploy/scenarios/) or TOML file.
    #[arg(long, default_value = "paper-sim")]
    pub scenario: String,
    /// Seed of every random process (default: the scenario's).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Simulated seconds per wall-clock second.
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// Stop after this many simulated seconds (default: the scenario's duration).
    #[arg(long)]
    pub duration_s: Option<f64>,
    /// The autopilot's clock rate against true time, boot seconds per second (default:
    /// the scenario's `[autopilot_clock] rate`, 1): 0.98 stamps telemetry as a PX4 SITL
    /// running 2 % behind real time does.
    #[arg(long, value_name = "RATE")]
    pub autopilot_clock_rate: Option<f64>,
    /// The autopilot's MAVLink signing key file (as PX4 keeps one on its SD card):
    /// signing on from the start. Empty or absent: off until SETUP_SIGNING installs one.
    #[arg(long, default_value = "")]
    pub signing_key: String,
    /// Real PX4 flies instead of the built-in autopilot: serve PX4 SITL's simulator API
    /// on this TCP address (PX4 connects to 4560 + instance), lockstep at 250 Hz. PX4
    /// then talks MAVLink to px4-link itself.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = "127.0.0.1:4560")]
    pub px4_sitl: Option<std::net::SocketAddr>,
    /// Fly this airframe profile (deploy/config/airframes/) instead of the scenario's:
    /// `iris` is PX4 SITL's vehicle.
    #[arg(long, value_name = "NAME")]
    pub airframe: Option<String>,
}

/// Why the flags make no simulator.
#[derive(Debug, thiserror::Error)]
pub enum SimFlagsError {
    /// `--speed` out of range.
    #[error("--speed {0} is not allowed (allowed: above 0, at most 100)")]
    Speed(f64),
    /// `--duration-s` out of range.
    #[error("--duration-s {0} is not allowed (allowed: above 0, at most 86400)")]
    Duration(f64),
    /// `--autopilot-clock-rate` out of range.
    #[error("--autopilot-clock-rate: {0}")]
    ClockRate(crate::params::ParamError),
    /// `--signing-key`.
    #[error("--signing-key: {0}")]
    Key(#[from] px4_protocol::signing::KeyError),
    /// The scenario.
    #[error(transparent)]
    Scenario(#[from] crate::scenario::ScenarioError),
    /// The simulator.
    #[error(transparent)]
    Sim(#[from] crate::lockstep::SimError),
}

impl SimFlags {
    /// The stage: the scenario's world (shipped scenarios from `deploy`), paced by the
    /// wall clock at `--speed`, ending at `--duration-s` or the scenario's duration,
    /// signing with `--signing-key` (`unix_ns_at_zero`: the Unix time at the driver
    /// clock's zero).
    pub fn stage(
        &self,
        deploy: &std::path::Path,
        unix_ns_at_zero: u64,
    ) -> Result<SimStage, SimFlagsError> {
        let key_file = Some(&self.signing_key).filter(|k| !k.is_empty());
        let key = key_file
            .map(|k| SigningKey::load(std::path::Path::new(k)))
            .transpose()?;
        if !(self.speed.is_finite() && self.speed > 0.0 && self.speed <= 100.0) {
            return Err(SimFlagsError::Speed(self.speed));
        }
        let mut scenario = crate::scenario::load(&self.scenario, deploy)?;
        if let Some(name) = &self.airframe {
            scenario = scenario.with_airframe(name)?;
        }
        if let Some(rate) = self.autopilot_clock_rate {
            let clock = &mut scenario.scenario.autopilot_clock;
            clock.rate = rate;
            clock.validate().map_err(SimFlagsError::ClockRate)?;
        }
        let end_s = self.duration_s.unwrap_or(scenario.scenario.duration_s);
        if !(end_s.is_finite() && end_s > 0.0 && end_s <= 86_400.0) {
            return Err(SimFlagsError::Duration(end_s));
        }
        let seed = self.seed.unwrap_or(scenario.scenario.seed);
        tracing::info!(scenario = %scenario.scenario.name, seed, end_s, "sim");
        let stage = SimStage::from_config(
            &scenario,
            seed,
            Pace::realtime(self.speed),
            Some((end_s * 1e9) as u64),
        )?;
        let stage = stage.with_signing(key, unix_ns_at_zero);
        Ok(match self.px4_sitl {
            Some(_) => stage.with_px4_sitl(&scenario),
            None => stage,
        })
    }
}

/// A rendered frame waiting for its sensor latency.
struct Held<T> {
    pixels: Vec<T>,
    capture_ns: u64,
    publish_ns: u64,
}

/// The autopilot's MAVLink system and component ids (PX4: 1, 1).
const SYSTEM_ID: u8 = 1;
const COMPONENT_ID: u8 = 1;

/// How far the wall clock may run ahead of simulated time before the simulator skips
/// ahead instead of racing to catch up (a loaded machine).
pub const MAX_LAG_NS: u64 = 100_000_000;

/// How simulated time follows the driver's clock.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pace {
    /// The driver's time is simulated time (the lockstep driver).
    Lockstep,
    /// The driver's time is the wall clock: simulated time runs `speed` times as fast
    /// from the first tick, and skips ahead when it falls more than [`MAX_LAG_NS`]
    /// behind.
    Realtime {
        /// Simulated seconds per wall-clock second.
        speed: f64,
        /// The driver time at which simulated time was 0 (set on the first tick).
        start_ns: Option<u64>,
        /// Simulated time skipped so far.
        skipped_ns: u64,
    },
}

impl Pace {
    /// Wall-clock pacing at `speed` (a speed that is not a positive number is 1).
    pub fn realtime(speed: f64) -> Self {
        Self::Realtime {
            speed: if speed.is_finite() && speed > 0.0 {
                speed
            } else {
                1.0
            },
            start_ns: None,
            skipped_ns: 0,
        }
    }

    /// The simulated time to step to at driver time `now_ns`, the world being at
    /// `sim_ns`.
    fn target(&mut self, now_ns: u64, sim_ns: u64) -> u64 {
        match self {
            Self::Lockstep => now_ns,
            Self::Realtime {
                speed,
                start_ns,
                skipped_ns,
            } => {
                let start = *start_ns.get_or_insert(now_ns);
                let elapsed = (now_ns.saturating_sub(start) as f64 * *speed) as u64;
                let target = elapsed.saturating_sub(*skipped_ns);
                if target > sim_ns + MAX_LAG_NS {
                    *skipped_ns += target - sim_ns - PHYSICS_STEP_NS;
                    tracing::debug!(
                        behind_ms = (target - sim_ns) / 1_000_000,
                        "the simulator fell behind the wall clock; skipping ahead"
                    );
                    return sim_ns + PHYSICS_STEP_NS;
                }
                target
            }
        }
    }

    /// Simulated time `sim_ns` is now, on the driver's clock at `now_ns`: a simulator held
    /// back by real PX4's lockstep re-anchors at every step, so that what it stamps (the
    /// cameras, the VIO) keeps to the wall clock PX4's own telemetry arrives by, rather
    /// than jumping [`MAX_LAG_NS`] at a time.
    fn follow(&mut self, now_ns: u64, sim_ns: u64) {
        if let Self::Realtime {
            speed,
            start_ns,
            skipped_ns,
        } = self
        {
            let start = *start_ns.get_or_insert(now_ns);
            let elapsed = (now_ns.saturating_sub(start) as f64 * *speed) as u64;
            *skipped_ns = (*skipped_ns).max(elapsed.saturating_sub(sim_ns));
        }
    }

    /// The autopilot's boot clock: on the driver's clock, as the camera's stamps are.
    fn boot_clock(&self) -> BootClock {
        match self {
            Self::Lockstep => BootClock::default(),
            Self::Realtime {
                speed, skipped_ns, ..
            } => BootClock {
                ahead_ns: *skipped_ns,
                rate: *speed,
            },
        }
    }

    /// The driver time of simulated time `sim_ns` (what the messages carry).
    fn driver_time_of(&self, sim_ns: u64) -> u64 {
        match self {
            Self::Lockstep => sim_ns,
            Self::Realtime {
                speed,
                start_ns,
                skipped_ns,
            } => start_ns.unwrap_or(0) + ((sim_ns + skipped_ns) as f64 / speed) as u64,
        }
    }

    /// The tick period on the driver's clock: one physics step.
    fn tick_ns(&self) -> u64 {
        match self {
            Self::Lockstep => PHYSICS_STEP_NS,
            Self::Realtime { speed, .. } => ((PHYSICS_STEP_NS as f64 / speed) as u64).max(1),
        }
    }
}

/// The `sim` node.
pub struct SimStage {
    sim: Simulator,
    pace: Pace,
    /// Simulated time at which the scenario ends (the process stops there).
    end_ns: Option<u64>,
    /// The autopilot's own MAVLink sequence.
    sequence: u8,
    wire: Vec<u8>,
    decoder: StreamDecoder,
    /// MAVLink 2 signing as PX4's `MavlinkSignControl`: off until a key is installed
    /// (at start, or by SETUP_SIGNING); then what goes out is signed and what comes in
    /// must be, but for the messages PX4 lets through unsigned.
    guard: Guard,
    /// The Unix time at the driver's time 0, ns (signing timestamps).
    unix_ns_at_zero: u64,
    decoded: Vec<(MavHeader, MavMessage)>,
    camera: VecDeque<Held<u8>>,
    depth: VecDeque<Held<u16>>,
    spare_u8: Vec<Vec<u8>>,
    spare_u16: Vec<Vec<u16>>,
    next_truth_state_ns: u64,
    counts: Counts,
    /// With `--px4-sitl`: real PX4 flies the vehicle through its simulator API.
    px4_sitl: Option<Box<SitlBridge>>,
}

/// The longest PX4 may boot on the ground before the world's clock starts anyway.
const MAX_PX4_BOOT_NS: u64 = 60_000_000_000;

/// How often HIL_STATE_QUATERNION (ground truth for PX4's logs) goes out: 50 Hz.
const HIL_STATE_PERIOD_NS: u64 = 20_000_000;

/// PX4 SITL's side of the simulator: its sensors, the lockstep, its byte stream.
struct SitlBridge {
    /// PX4's clock at the world's time 0: how long it booted on the ground first.
    boot_ns: u64,
    /// The world's clock runs (PX4 armed, or booted for [`MAX_PX4_BOOT_NS`]).
    world_started: bool,
    /// The driver time of the next boot step (boot steps keep to the wall clock).
    next_boot_step_ns: Option<u64>,
    gps: crate::hil::GpsParams,
    gps_rng: crate::rng::Pcg32,
    next_gps_ns: u64,
    sensors: crate::hil::HilSensors,
    lockstep: crate::hil::Lockstep,
    home_amsl_m: f64,
    decoder: StreamDecoder,
    guard: Guard,
    decoded: Vec<(MavHeader, MavMessage)>,
    /// One encoded message, reused (250 a second).
    wire: Vec<u8>,
    sequence: u8,
    /// PX4 has spoken (its first HEARTBEAT): time starts.
    connected: bool,
    next_state_ns: u64,
    /// Velocity at the last HIL_STATE_QUATERNION, for its acceleration.
    last_velocity: nalgebra::Vector3<f64>,
    sensors_out: u64,
    other_in: u64,
}

impl SitlBridge {
    /// Bytes of PX4's stream: its motor outputs answer the lockstep; its first message
    /// (a HEARTBEAT, sent on connecting) starts simulated time.
    fn receive(&mut self, bytes: &[u8], now_ns: u64) {
        self.decoded.clear();
        self.decoder
            .push(bytes, now_ns, &mut self.guard, &mut self.decoded);
        for (_, m) in &self.decoded {
            self.connected = true;
            match m {
                MavMessage::HIL_ACTUATOR_CONTROLS(c) => self.lockstep.answered(c),
                // HEARTBEAT, PX4's request for HIL_STATE_QUATERNION at 200 Hz (this
                // simulator sends it at 50 Hz; PX4 only logs it).
                _ => self.other_in += 1,
            }
        }
    }

    /// One message to PX4, MAVLink 2 from this simulator (system 1, component 51: a
    /// simulator's id, not the autopilot's).
    fn send(&mut self, msg: &MavMessage, out: &mut dyn Outbox) -> Result<(), StageError> {
        let header = MavHeader {
            system_id: 1,
            component_id: 51,
            sequence: self.sequence,
        };
        self.sequence = self.sequence.wrapping_add(1);
        self.wire.clear();
        px4_protocol::codec::encode(&mut self.wire, header, msg)
            .map_err(|e| StageError::Transport(e.to_string()))?;
        out.publish(topics::HIL_TO_PX4, Message::Mavlink(&self.wire))
    }
}

#[derive(Debug, Default, Clone, Copy)]
struct Counts {
    steps: u64,
    camera_frames: u64,
    depth_frames: u64,
    truth_events: u64,
    mavlink_in: u64,
    mavlink_out: u64,
    parse_errors: u64,
    unsupported: u64,
    /// Datagrams from an address other than the companion's (never read).
    wrong_address: u64,
    /// Keys installed by SETUP_SIGNING.
    keys_installed: u64,
    dropped: u64,
    /// Camera and depth renders (at capture; a frame goes out after its latency).
    renders: u64,
    depth_renders: u64,
    vio: u64,
}

impl SimStage {
    /// The one way the stage is built, wherever it runs (its process on the wall clock,
    /// the lockstep registry): from its scenario (the simulator's configuration: the
    /// world) and a seed, paced by `pace`, finished at simulated time `end_ns`.
    pub fn from_config(
        scenario: &crate::scenario::LoadedScenario,
        seed: u64,
        pace: Pace,
        end_ns: Option<u64>,
    ) -> Result<Self, crate::lockstep::SimError> {
        Ok(Self::paced(Simulator::new(scenario, seed)?, pace, end_ns))
    }

    /// The stage of `sim`, in lockstep (built by [`Self::from_config`]; tests build it
    /// here around simulators of their own).
    pub fn new(sim: Simulator) -> Self {
        Self {
            sim,
            pace: Pace::Lockstep,
            end_ns: None,
            sequence: 0,
            wire: Vec::with_capacity(280),
            decoder: StreamDecoder::new(),
            guard: Guard::open(),
            unix_ns_at_zero: 0,
            decoded: Vec::with_capacity(8),
            camera: VecDeque::new(),
            depth: VecDeque::new(),
            spare_u8: Vec::new(),
            spare_u16: Vec::new(),
            next_truth_state_ns: 0,
            counts: Counts::default(),
            px4_sitl: None,
        }
    }

    /// Real PX4 flies instead of this simulator's autopilot: the vehicle's sensors (the
    /// airframe's `[sensors]`, the barometer reading `[px4] SIH_LOC_H0` at the ground) go
    /// to it as HIL_SENSOR on `hil/to-px4` at 250 Hz in lockstep, a GPS fix when the
    /// scenario has a `[gps]`, and its HIL_ACTUATOR_CONTROLS from `hil/from-px4` drive the
    /// motors. Simulated time starts when PX4 first speaks.
    pub fn with_px4_sitl(mut self, scenario: &crate::scenario::LoadedScenario) -> Self {
        let seed = self.sim.seed().wrapping_add(7);
        let home_amsl_m = scenario.px4.sih_loc_h0;
        let sensors = scenario.sensors.clone();
        self.px4_sitl = Some(Box::new(SitlBridge {
            boot_ns: 0,
            world_started: false,
            next_boot_step_ns: None,
            gps: scenario.scenario.gps.clone(),
            gps_rng: crate::rng::Pcg32::with_stream(seed, 67),
            next_gps_ns: 0,
            sensors: crate::hil::HilSensors::new(sensors, home_amsl_m, seed),
            lockstep: crate::hil::Lockstep::default(),
            home_amsl_m,
            decoder: StreamDecoder::new(),
            guard: Guard::open(),
            decoded: Vec::with_capacity(8),
            wire: Vec::with_capacity(96),
            sequence: 0,
            connected: false,
            next_state_ns: 0,
            last_velocity: nalgebra::Vector3::zeros(),
            sensors_out: 0,
            other_in: 0,
        }));
        self
    }

    /// The same, paced by `pace` and finished at simulated time `end_ns`.
    pub fn paced(sim: Simulator, pace: Pace, end_ns: Option<u64>) -> Self {
        Self {
            pace,
            end_ns,
            ..Self::new(sim)
        }
    }

    /// Signing on with `key` from the start (a key PX4 already holds on its SD card);
    /// `unix_ns_at_zero` is the Unix time at the driver's time 0, ns.
    pub fn with_signing(mut self, key: Option<SigningKey>, unix_ns_at_zero: u64) -> Self {
        self.unix_ns_at_zero = unix_ns_at_zero;
        if let Some(key) = key {
            self.guard.set_signer(Signer::new(key, 0, unix_ns_at_zero));
        }
        self
    }

    /// Whether the autopilot signs (a key installed).
    pub fn signing(&self) -> bool {
        self.guard.signer().is_some()
    }

    /// Frames refused so far, by reason.
    pub fn rejected(&self) -> px4_protocol::codec::Rejections {
        self.guard.rejected()
    }

    /// SETUP_SIGNING (addressed to this system) installs its key and initial timestamp,
    /// as PX4's `MavlinkSignControl::check_for_signing` does; a blank key turns signing
    /// off. On a signed link it arrives here only signed with the current key.
    fn setup_signing(&mut self, msg: &MavMessage) -> bool {
        let MavMessage::SETUP_SIGNING(s) = msg else {
            return false;
        };
        if s.target_system != SYSTEM_ID {
            return true;
        }
        if s.secret_key == [0; 32] && s.initial_timestamp == 0 {
            self.guard.clear_signer();
            tracing::info!("MAVLink signing turned off by SETUP_SIGNING");
        } else {
            let mut signer = Signer::new(
                SigningKey::from_bytes(s.secret_key),
                0,
                self.unix_ns_at_zero,
            );
            signer.advance_to(s.initial_timestamp);
            self.guard.set_signer(signer);
            self.counts.keys_installed += 1;
            tracing::info!("MAVLink signing key installed by SETUP_SIGNING");
        }
        true
    }

    /// Answers each COMMAND_LONG of `datagram` whose number the dialect lacks and
    /// that is addressed to this autopilot (its system, component its own or 0)
    /// MAV_RESULT_UNSUPPORTED, as PX4's commander does; others are ignored, as PX4's
    /// receiver does.
    fn answer_unknown(
        &mut self,
        datagram: &[u8],
        now_ns: u64,
        out: &mut dyn Outbox,
    ) -> Result<(), StageError> {
        if self.sim.autopilot_silent() {
            return Ok(());
        }
        for cmd in unknown_commands(datagram) {
            let ours = cmd.target_system == SYSTEM_ID
                && (cmd.target_component == 0 || cmd.target_component == COMPONENT_ID);
            if !ours {
                continue;
            }
            let mut frame = command_ack_frame(
                self.sequence,
                SYSTEM_ID,
                COMPONENT_ID,
                &cmd,
                MavResult::MAV_RESULT_UNSUPPORTED as u8,
            );
            self.guard
                .sign_raw(&mut frame, COMMAND_ACK_CRC_EXTRA, now_ns);
            self.sequence = self.sequence.wrapping_add(1);
            self.counts.unsupported += 1;
            out.publish(topics::MAVLINK_FROM_PX4, Message::Mavlink(&frame))?;
        }
        Ok(())
    }

    /// The simulator (the evaluator and the tests read the world through it).
    pub fn simulator(&self) -> &Simulator {
        &self.sim
    }

    /// The simulator, mutably (fault injection in tests).
    pub fn simulator_mut(&mut self) -> &mut Simulator {
        &mut self.sim
    }

    fn render(&mut self) -> Result<(), StageError> {
        if let Some(len) = self.sim.down_camera().map(|c| c.frame_len()) {
            let mut buf = self.spare_u8.pop().unwrap_or_else(|| vec![0; len]);
            buf.resize(len, 0);
            self.counts.renders += 1;
            match self.sim.render_camera_into(&mut buf) {
                Ok(Some(shot)) => self.camera.push_back(Held {
                    pixels: buf,
                    capture_ns: shot.capture_ns,
                    publish_ns: shot.publish_ns,
                }),
                Ok(None) => self.spare_u8.push(buf),
                Err(e) => return Err(StageError::Failed(e.to_string())),
            }
        }
        Ok(())
    }

    fn render_depth(&mut self) {
        if let Some(len) = self.sim.depth_camera().map(|c| c.frame_len()) {
            let mut buf = self.spare_u16.pop().unwrap_or_else(|| vec![0; len]);
            buf.resize(len, 0);
            self.counts.depth_renders += 1;
            match self.sim.render_depth_into(&mut buf) {
                Some(shot) => self.depth.push_back(Held {
                    pixels: buf,
                    capture_ns: shot.capture_ns,
                    publish_ns: shot.publish_ns,
                }),
                None => self.spare_u16.push(buf),
            }
        }
    }

    /// What a physics step produced: its truth events out, its sensors rendered.
    fn absorb(
        &mut self,
        report: crate::lockstep::StepReport,
        out: &mut dyn Outbox,
    ) -> Result<(), StageError> {
        self.counts.steps += 1;
        for t in &report.truth {
            out.publish(topics::SIM_TRUTH, Message::TruthEvent(t))?;
            self.counts.truth_events += 1;
        }
        if report.camera_due {
            self.render()?;
        }
        if report.depth_due {
            self.render_depth();
        }
        Ok(())
    }

    /// The autopilot's MAVLink that has reached the companion by now, on the wire.
    fn send_telemetry(&mut self, now_ns: u64, out: &mut dyn Outbox) -> Result<(), StageError> {
        for m in self.sim.take_mavlink() {
            let header = MavHeader {
                system_id: 1,
                component_id: 1,
                sequence: self.sequence,
            };
            self.sequence = self.sequence.wrapping_add(1);
            self.wire.clear();
            self.guard
                .encode(&mut self.wire, header, &m, now_ns)
                .map_err(|e| StageError::Transport(e.to_string()))?;
            out.publish(topics::MAVLINK_FROM_PX4, Message::Mavlink(&self.wire))?;
            self.counts.mavlink_out += 1;
        }
        Ok(())
    }

    /// Lockstep with PX4: while it owes no answer and simulated time is behind `target`,
    /// one HIL step (two physics steps on PX4's motors), then the sensors at the new
    /// time on `hil/to-px4`.
    fn step_px4_sitl(
        &mut self,
        now_ns: u64,
        target: u64,
        out: &mut dyn Outbox,
    ) -> Result<(), StageError> {
        let Some(mut b) = self.px4_sitl.take() else {
            return Ok(());
        };
        let result = self.lockstep_px4(&mut b, now_ns, target, out);
        self.px4_sitl = Some(b);
        result
    }

    /// PX4 boots first, on the ground, before the world's clock starts: a crew powers the
    /// vehicle and waits for its estimator before the pad vehicle drives off, and PX4
    /// v1.16 refuses to arm for its first seconds ("heading estimate not stable"), where
    /// this simulator's own autopilot is ready at once. Boot steps keep to the wall clock
    /// (the VIO reaches PX4 by the wall clock); the world starts when PX4 arms.
    fn lockstep_px4(
        &mut self,
        b: &mut SitlBridge,
        now_ns: u64,
        target: u64,
        out: &mut dyn Outbox,
    ) -> Result<(), StageError> {
        use crate::hil::HIL_STEP_NS;
        while b.connected && b.lockstep.may_step() {
            if !b.world_started {
                let next = *b.next_boot_step_ns.get_or_insert(now_ns);
                if now_ns < next {
                    break;
                }
                // Not more than 0.1 s of catching up on a loaded machine.
                let tick = 2 * self.pace.tick_ns();
                b.next_boot_step_ns = Some(next.max(now_ns.saturating_sub(100_000_000)) + tick);
                b.boot_ns += HIL_STEP_NS;
                self.sim.step_vio_before_start(b.boot_ns);
                self.pace.follow(now_ns, 0);
                self.send_px4(b, b.boot_ns, out)?;
                if b.lockstep.motors().armed || b.boot_ns >= MAX_PX4_BOOT_NS {
                    b.world_started = true;
                    tracing::info!(
                        boot_s = b.boot_ns as f64 * 1e-9,
                        armed = b.lockstep.motors().armed,
                        "PX4 booted: the world's clock starts"
                    );
                }
                continue;
            }
            if self.sim.time_ns() >= target {
                break;
            }
            for _ in 0..HIL_STEP_NS / PHYSICS_STEP_NS {
                let motors = *b.lockstep.motors();
                let report = self
                    .sim
                    .step_with_motors(&motors)
                    .map_err(|e| StageError::Failed(e.to_string()))?;
                self.absorb(report, out)?;
            }
            self.send_px4(b, b.boot_ns + self.sim.time_ns(), out)?;
            self.pace.follow(now_ns, self.sim.time_ns());
        }
        Ok(())
    }

    /// PX4's sensors at its clock `px4_ns` (the world's time plus its boot): HIL_SENSOR,
    /// a GPS fix when due, HIL_STATE_QUATERNION when due.
    fn send_px4(
        &mut self,
        b: &mut SitlBridge,
        px4_ns: u64,
        out: &mut dyn Outbox,
    ) -> Result<(), StageError> {
        use crate::hil::{gps_fix, state_quaternion};
        let truth = *self.sim.world().truth();
        let sensor = MavMessage::HIL_SENSOR(b.sensors.sample(&truth, px4_ns));
        b.send(&sensor, out)?;
        b.sensors_out += 1;
        if b.gps.rate_hz > 0.0 && px4_ns >= b.next_gps_ns {
            b.next_gps_ns = px4_ns + (1e9 / b.gps.rate_hz) as u64;
            let rng = &mut b.gps_rng;
            let fix = gps_fix(&truth, &b.gps, b.home_amsl_m, px4_ns, &mut || rng.normal());
            b.send(&MavMessage::HIL_GPS(fix), out)?;
        }
        b.lockstep.sent();
        if px4_ns >= b.next_state_ns {
            let dt = (px4_ns + HIL_STATE_PERIOD_NS - b.next_state_ns) as f64 * 1e-9;
            let accel = (truth.velocity - b.last_velocity) / dt.max(1e-3);
            b.last_velocity = truth.velocity;
            b.next_state_ns = px4_ns + HIL_STATE_PERIOD_NS;
            let state = state_quaternion(&truth, &accel, b.home_amsl_m, px4_ns);
            b.send(&MavMessage::HIL_STATE_QUATERNION(state), out)?;
        }
        Ok(())
    }

    /// Frames whose latency has passed, in order.
    fn release(&mut self, now_ns: u64, out: &mut dyn Outbox) -> Result<(), StageError> {
        while self.camera.front().is_some_and(|f| f.publish_ns <= now_ns) {
            let Some(f) = self.camera.pop_front() else {
                break;
            };
            let Some(cam) = self.sim.down_camera() else {
                break;
            };
            let (width, height) = (cam.calibration().width, cam.calibration().height);
            let (encoding, bpp) = match cam.params().format {
                PixelFormat::Mono8 => (PixelEncoding::Mono8, 1),
                PixelFormat::Bgr8 => (PixelEncoding::Bgr8, 3),
            };
            let capture = self.pace.driver_time_of(f.capture_ns);
            let mut msg = Header::captured_at(capture);
            // Left open: the driver closes it when the frame really leaves (a simulator
            // behind the wall clock delivers late, as a slow camera driver would).
            msg.push_stage(StageId::Sensor, capture, capture);
            let header = CameraFrameHeader {
                msg,
                width,
                height,
                stride: width * bpp,
                encoding: encoding as u32,
                camera_id: 0,
                undistorted: 0,
                exposure_ns: (cam.params().exposure_time_s * 1e9) as u64,
            };
            let pixels = &f.pixels;
            if out.publish_slice(topics::SIM_CAMERA, pixels.len(), &mut |buf| match buf {
                SliceMut::U8(b) => {
                    b.copy_from_slice(pixels);
                    Some(SliceHeader::CameraFrame(header))
                }
                SliceMut::U16(_) => None,
            })? {
                self.counts.camera_frames += 1;
            } else {
                // Every sample held by consumers: dropped rather than queued.
                self.counts.dropped += 1;
            }
            self.spare_u8.push(f.pixels);
        }
        while self.depth.front().is_some_and(|f| f.publish_ns <= now_ns) {
            let Some(f) = self.depth.pop_front() else {
                break;
            };
            let Some(cam) = self.sim.depth_camera() else {
                break;
            };
            let p = cam.params();
            let (fx, fy) = p.focal_px();
            let (cx, cy) = p.principal_point_px();
            let capture = self.pace.driver_time_of(f.capture_ns);
            let mut msg = Header::captured_at(capture);
            // Left open: the driver closes it when the frame really leaves (a simulator
            // behind the wall clock delivers late, as a slow camera driver would).
            msg.push_stage(StageId::Sensor, capture, capture);
            let header = DepthFrameHeader {
                msg,
                width: p.width,
                height: p.height,
                depth_scale_m: DEPTH_SCALE_M,
                intrinsics: Intrinsics { fx, fy, cx, cy },
                camera_id: 0,
                reserved: 0,
            };
            let pixels = &f.pixels;
            if out.publish_slice(topics::SIM_DEPTH, pixels.len(), &mut |buf| match buf {
                SliceMut::U16(b) => {
                    b.copy_from_slice(pixels);
                    Some(SliceHeader::DepthFrame(header))
                }
                SliceMut::U8(_) => None,
            })? {
                self.counts.depth_frames += 1;
            } else {
                self.counts.dropped += 1;
            }
            self.spare_u16.push(f.pixels);
        }
        Ok(())
    }
}

impl Stage for SimStage {
    fn name(&self) -> &'static str {
        "sim"
    }

    fn tick_period_ns(&self) -> Option<u64> {
        Some(self.pace.tick_ns())
    }

    fn on_input(
        &mut self,
        now_ns: u64,
        input: Input<'_>,
        out: &mut dyn Outbox,
    ) -> Result<(), StageError> {
        if let (Message::Mavlink(bytes), Some(b)) = (&input.msg, self.px4_sitl.as_deref_mut()) {
            if input.topic == topics::HIL_FROM_PX4 {
                b.receive(bytes, now_ns);
            }
            return Ok(());
        }
        if let Message::Mavlink(bytes) = input.msg {
            if input.topic == topics::MAVLINK_FOREIGN {
                self.counts.wrong_address += 1;
                return Ok(());
            }
            let mut decoded = std::mem::take(&mut self.decoded);
            decoded.clear();
            let errors = self
                .decoder
                .push_datagram(bytes, now_ns, &mut self.guard, &mut decoded);
            for (h, m) in &decoded {
                if !self.setup_signing(m) {
                    self.sim.handle_mavlink(h, m);
                }
                self.counts.mavlink_in += 1;
            }
            self.decoded = decoded;
            self.counts.parse_errors += errors;
            for frame in self.decoder.take_undecoded() {
                self.answer_unknown(&frame, now_ns, out)?;
            }
        }
        Ok(())
    }

    fn on_inputs_done(&mut self, now_ns: u64, out: &mut dyn Outbox) -> Result<(), StageError> {
        // PX4's answer lets the next lockstep step run at once, not at the next tick.
        if self.px4_sitl.is_some() && !self.finished() {
            let target = self.pace.target(now_ns, self.sim.time_ns());
            self.step_px4_sitl(now_ns, target, out)?;
        }
        Ok(())
    }

    fn on_tick(&mut self, now_ns: u64, out: &mut dyn Outbox) -> Result<(), StageError> {
        let target = self.pace.target(now_ns, self.sim.time_ns());
        if self.finished() {
            return Ok(());
        }
        if self.px4_sitl.is_some() {
            self.step_px4_sitl(now_ns, target, out)?;
        } else {
            self.sim
                .commander_mut()
                .set_boot_clock(self.pace.boot_clock());
            while self.sim.time_ns() < target {
                let report = self
                    .sim
                    .step()
                    .map_err(|e| StageError::Failed(e.to_string()))?;
                self.absorb(report, out)?;
            }
            self.send_telemetry(now_ns, out)?;
        }
        while let Some(mut v) = self.sim.take_vio() {
            v.msg = Header::captured_at(self.pace.driver_time_of(v.msg.capture_ns));
            out.publish(topics::VIO_ODOMETRY, Message::VioOdometry(&v))?;
            self.counts.vio += 1;
        }
        // Behind the target only while PX4 owes a lockstep answer.
        let reached = target.min(self.sim.time_ns());
        self.release(reached, out)?;
        if reached >= self.next_truth_state_ns {
            self.next_truth_state_ns = reached + TRUTH_STATE_PERIOD_NS;
            let s = truth_state(&self.sim, self.pace.driver_time_of(reached));
            out.publish(topics::SIM_TRUTH_STATE, Message::TruthState(&s))?;
        }
        Ok(())
    }

    fn finished(&self) -> bool {
        self.end_ns.is_some_and(|end| self.sim.time_ns() >= end)
    }

    fn max_slice_len(&self, topic: &str) -> usize {
        match topic {
            topics::SIM_CAMERA => self.sim.down_camera().map_or(0, |c| c.frame_len()),
            topics::SIM_DEPTH => self.sim.depth_camera().map_or(0, |c| c.frame_len()),
            _ => 0,
        }
    }

    fn counters(&self) -> Vec<Counter> {
        let c = self.counts;
        let mut counters = vec![
            ("steps", c.steps),
            ("camera_frames", c.camera_frames),
            ("depth_frames", c.depth_frames),
            ("truth_events", c.truth_events),
            ("mavlink_in", c.mavlink_in),
            ("mavlink_out", c.mavlink_out),
            ("parse_errors", c.parse_errors),
            ("unsupported", c.unsupported),
            ("wrong_address", c.wrong_address),
            ("wrong_source", self.guard.rejected().wrong_source),
            ("unknown_id", self.guard.rejected().unknown_id),
            ("unsigned", self.guard.rejected().unsigned),
            ("bad_signature", self.guard.rejected().bad_signature),
            ("replayed", self.guard.rejected().replayed),
            ("keys_installed", c.keys_installed),
            ("dropped", c.dropped),
            ("renders", c.renders),
            ("depth_renders", c.depth_renders),
            ("vio", c.vio),
        ];
        if let Some(b) = &self.px4_sitl {
            counters.extend([
                ("hil_sensors_out", b.sensors_out),
                ("hil_answers", b.lockstep.answers()),
                ("hil_other_in", b.other_in),
                ("hil_parse_errors", b.decoder.parse_errors()),
            ]);
        }
        counters
    }
}
