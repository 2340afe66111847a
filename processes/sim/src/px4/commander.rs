//! A PX4-like commander: what PX4 does with the MAVLink messages a companion
//! computer sends, and what it sends back.
//!
//! Pure: decoded messages and `now_ns` in, MAVLink messages, the armed flag
//! and the autopilot [`Setpoint`] out. No sockets, clocks or sleeps, so the
//! same logic runs on the wall clock (behind the UDP endpoint) and in lockstep.
//! All MAVLink quantities are NED / FRD; the world is ENU / FLU; conversions
//! happen here and nowhere else (see [`super::frames`]).

use mavlink::MavHeader;
// SET_MODE is deprecated in MAVLink, but PX4 still honours it and older
// tools send it, so the simulator does too.
#[allow(deprecated)]
use mavlink::dialects::common::{
    ATTITUDE_QUATERNION_DATA, COMMAND_ACK_DATA, COMMAND_LONG_DATA, EXTENDED_SYS_STATE_DATA,
    HEARTBEAT_DATA, LOCAL_POSITION_NED_DATA, MavAutopilot, MavCmd, MavEstimatorType, MavFrame,
    MavLandedState, MavMessage, MavModeFlag, MavResult, MavState, MavType, MavVtolState,
    ODOMETRY_DATA, PositionTargetTypemask, SET_MODE_DATA, SET_POSITION_TARGET_LOCAL_NED_DATA,
};
use nalgebra::Vector3;
use serde::Deserialize;

use super::frames::{
    enu_to_ned, flu_to_frd, ned_from_frd, ned_to_enu, quaternion_wxyz, yaw_ned_to_enu,
};
use crate::autopilot::{EstimatedState, Setpoint};
use crate::params::{self, ParamError};

/// PX4's magic `param2` of ARM_DISARM that forces a disarm in the air.
pub const FORCE_DISARM_MAGIC: f32 = 21196.0;

/// How long a setpoint stream must have been arriving before OFFBOARD is
/// accepted (the rule companions follow: stream for > 1 s, then switch).
pub const OFFBOARD_STREAM_MIN_NS: u64 = 1_000_000_000;

/// How long the estimator must report ground contact before the vehicle
/// counts as landed (PX4's land detector needs a moment too).
pub const LAND_DETECT_NS: u64 = 500_000_000;

/// How close (m) below the takeoff altitude AUTO.TAKEOFF counts as done.
pub const TAKEOFF_ACCEPTANCE_M: f64 = 0.2;

/// Message ids of the telemetry streams the commander can send.
pub mod msg_id {
    /// HEARTBEAT.
    pub const HEARTBEAT: u32 = 0;
    /// ATTITUDE_QUATERNION.
    pub const ATTITUDE_QUATERNION: u32 = 31;
    /// LOCAL_POSITION_NED.
    pub const LOCAL_POSITION_NED: u32 = 32;
    /// EXTENDED_SYS_STATE.
    pub const EXTENDED_SYS_STATE: u32 = 245;
    /// ODOMETRY.
    pub const ODOMETRY: u32 = 331;
}

/// PX4 parameters the commander uses, under their PX4 names (TOML accepts
/// `COM_OF_LOSS_T = 1.0`), so a scenario reads like a PX4 parameter file.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default, rename_all = "SCREAMING_SNAKE_CASE")]
pub struct Px4Params {
    /// Offboard setpoint timeout before the failsafe, s (PX4 default 1).
    pub com_of_loss_t: f64,
    /// Offboard-loss action: 4 = Land (PX4 default), 5 = Hold (AUTO.LOITER).
    pub com_obl_rc_act: u8,
    /// Takeoff altitude above home when NAV_TAKEOFF gives none, m (PX4 default 2.5).
    pub mis_takeoff_alt: f64,
    /// Takeoff climb speed, m/s (PX4 default 1.5).
    pub mpc_tko_speed: f64,
    /// Landing descent speed, m/s (PX4 default 0.7).
    pub mpc_land_speed: f64,
    /// Disarm this long after landing is detected, s (PX4 default 2; negative disables).
    pub com_disarm_land: f64,
    /// Disarm this long after arming if the vehicle never took off, s
    /// (PX4 default 10; negative disables).
    pub com_disarm_prflt: f64,
}

impl Default for Px4Params {
    /// PX4 v1.14 defaults.
    fn default() -> Self {
        Self {
            com_of_loss_t: 1.0,
            com_obl_rc_act: 4,
            mis_takeoff_alt: 2.5,
            mpc_tko_speed: 1.5,
            mpc_land_speed: 0.7,
            com_disarm_land: 2.0,
            com_disarm_prflt: 10.0,
        }
    }
}

impl Px4Params {
    /// Checks every parameter, so a bad scenario fails before it flies.
    pub fn validate(&self) -> Result<(), ParamError> {
        params::in_range("COM_OF_LOSS_T", self.com_of_loss_t, 1e-3, 60.0)?;
        if !matches!(self.com_obl_rc_act, 4 | 5) {
            return Err(ParamError::new(
                "COM_OBL_RC_ACT",
                self.com_obl_rc_act,
                "must be 4 (Land) or 5 (Hold); other PX4 actions are not simulated",
            ));
        }
        params::in_range("MIS_TAKEOFF_ALT", self.mis_takeoff_alt, 0.1, 1000.0)?;
        params::positive("MPC_TKO_SPEED", self.mpc_tko_speed)?;
        params::positive("MPC_LAND_SPEED", self.mpc_land_speed)?;
        params::finite("COM_DISARM_LAND", self.com_disarm_land)?;
        params::finite("COM_DISARM_PRFLT", self.com_disarm_prflt)?;
        Ok(())
    }

    fn loss_ns(&self) -> u64 {
        secs_to_ns(self.com_of_loss_t)
    }
}

fn secs_to_ns(s: f64) -> u64 {
    (s.max(0.0) * 1e9) as u64
}

/// The PX4 flight modes the simulator flies (PX4's navigation states).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FlightMode {
    /// POSCTL: without RC sticks, holds position (the mode PX4 boots into here).
    Posctl,
    /// AUTO.TAKEOFF: climbs to the takeoff altitude, then AUTO.LOITER.
    AutoTakeoff,
    /// AUTO.LOITER (Hold): holds position.
    AutoLoiter,
    /// AUTO.LAND: descends at MPC_LAND_SPEED and disarms after landing.
    AutoLand,
    /// OFFBOARD: flies the companion's setpoints.
    Offboard,
}

/// PX4 main mode AUTO.
const MAIN_AUTO: u8 = 4;

impl FlightMode {
    /// PX4's (main mode, sub mode), as packed in HEARTBEAT and DO_SET_MODE.
    pub const fn main_sub(self) -> (u8, u8) {
        match self {
            Self::Posctl => (3, 0),
            Self::AutoTakeoff => (MAIN_AUTO, 2),
            Self::AutoLoiter => (MAIN_AUTO, 3),
            Self::AutoLand => (MAIN_AUTO, 6),
            Self::Offboard => (6, 0),
        }
    }

    /// HEARTBEAT custom_mode: `(sub << 24) | (main << 16)`.
    pub const fn custom_mode(self) -> u32 {
        let (main, sub) = self.main_sub();
        ((sub as u32) << 24) | ((main as u32) << 16)
    }
}

/// What a requested (main, sub) mode means to the simulator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModeRequest {
    /// A mode the simulator flies.
    Simulated(FlightMode),
    /// A real PX4 mode the simulator does not fly (MANUAL, MISSION, RTL, ...).
    NotSimulated,
    /// Not a PX4 mode: PX4 ACKs it and does nothing.
    Unknown,
}

impl ModeRequest {
    /// Decodes PX4's main/sub mode numbers.
    pub fn from_main_sub(main: u8, sub: u8) -> Self {
        match (main, sub) {
            (3, _) => Self::Simulated(FlightMode::Posctl),
            (6, _) => Self::Simulated(FlightMode::Offboard),
            (MAIN_AUTO, 2) => Self::Simulated(FlightMode::AutoTakeoff),
            (MAIN_AUTO, 3) => Self::Simulated(FlightMode::AutoLoiter),
            (MAIN_AUTO, 6) => Self::Simulated(FlightMode::AutoLand),
            (MAIN_AUTO, 1 | 4 | 5 | 7 | 8 | 9 | 10) | (1 | 2 | 5 | 7 | 8, _) => Self::NotSimulated,
            _ => Self::Unknown,
        }
    }
}

/// PX4's landed state as in EXTENDED_SYS_STATE.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LandedState {
    /// On the ground (or disarmed).
    OnGround,
    /// Flying.
    InAir,
    /// Climbing in AUTO.TAKEOFF.
    Takeoff,
    /// Descending in AUTO.LAND.
    Landing,
}

impl LandedState {
    fn to_mav(self) -> MavLandedState {
        match self {
            Self::OnGround => MavLandedState::MAV_LANDED_STATE_ON_GROUND,
            Self::InAir => MavLandedState::MAV_LANDED_STATE_IN_AIR,
            Self::Takeoff => MavLandedState::MAV_LANDED_STATE_TAKEOFF,
            Self::Landing => MavLandedState::MAV_LANDED_STATE_LANDING,
        }
    }
}

/// What the commander knows about the vehicle each step: the estimate PX4
/// would have (never ground truth) and whether it has crashed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleStatus {
    /// The noisy state estimate, world ENU / body FLU.
    pub estimate: EstimatedState,
    /// True once the world declared a crash (arming is then refused).
    pub crashed: bool,
}

/// Why the commander left OFFBOARD or disarmed on its own, for logs and tests.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CommanderEvent {
    /// The offboard setpoint stream stopped for COM_OF_LOSS_T; the mode is
    /// now the COM_OBL_RC_ACT one.
    OffboardLost(FlightMode),
    /// Disarmed COM_DISARM_LAND after landing.
    AutoDisarmLanded,
    /// Disarmed COM_DISARM_PRFLT after arming without taking off.
    AutoDisarmPreflight,
    /// Disarmed because the vehicle crashed.
    DisarmCrash,
}

#[derive(Debug, Clone, Copy)]
struct Stream {
    id: u32,
    default_interval_ns: Option<u64>,
    interval_ns: Option<u64>,
    next_due_ns: u64,
}

impl Stream {
    const fn new(id: u32, default_hz: Option<u64>) -> Self {
        let default_interval_ns = match default_hz {
            Some(hz) => Some(1_000_000_000 / hz),
            None => None,
        };
        Self {
            id,
            default_interval_ns,
            interval_ns: default_interval_ns,
            next_due_ns: 0,
        }
    }
}

#[derive(Debug, Clone, Copy)]
struct Takeoff {
    start_ns: u64,
    start_z: f64,
    target_z: f64,
    xy: [f64; 2],
    yaw: f64,
}

/// The PX4-like commander (see the module docs).
#[derive(Debug, Clone)]
pub struct Commander {
    params: Px4Params,
    mode: FlightMode,
    armed: bool,
    crashed: bool,
    armed_at_ns: u64,
    has_flown: bool,
    landed: bool,
    contact_since_ns: Option<u64>,
    stream_start_ns: Option<u64>,
    last_setpoint_ns: Option<u64>,
    offboard_setpoint: Setpoint,
    hold_position: Vector3<f64>,
    hold_yaw: f64,
    takeoff_alt_m: f64,
    takeoff: Option<Takeoff>,
    setpoint: Setpoint,
    streams: [Stream; 5],
    outgoing: Vec<MavMessage>,
    events: Vec<CommanderEvent>,
}

impl Commander {
    /// A disarmed commander in POSCTL, on the ground, with PX4's stream rates
    /// (HEARTBEAT 1 Hz, ATTITUDE_QUATERNION 50 Hz, LOCAL_POSITION_NED 30 Hz,
    /// EXTENDED_SYS_STATE 5 Hz, ODOMETRY off until requested).
    pub fn new(params: Px4Params) -> Result<Self, ParamError> {
        params.validate()?;
        let takeoff_alt_m = params.mis_takeoff_alt;
        Ok(Self {
            params,
            mode: FlightMode::Posctl,
            armed: false,
            crashed: false,
            armed_at_ns: 0,
            has_flown: false,
            landed: true,
            contact_since_ns: Some(0),
            stream_start_ns: None,
            last_setpoint_ns: None,
            offboard_setpoint: Setpoint::default(),
            hold_position: Vector3::zeros(),
            hold_yaw: 0.0,
            takeoff_alt_m,
            takeoff: None,
            setpoint: Setpoint::default(),
            streams: [
                Stream::new(msg_id::HEARTBEAT, Some(1)),
                Stream::new(msg_id::ATTITUDE_QUATERNION, Some(50)),
                Stream::new(msg_id::LOCAL_POSITION_NED, Some(30)),
                Stream::new(msg_id::EXTENDED_SYS_STATE, Some(5)),
                Stream::new(msg_id::ODOMETRY, None),
            ],
            outgoing: Vec::new(),
            events: Vec::new(),
        })
    }

    /// The parameters in use.
    pub fn params(&self) -> &Px4Params {
        &self.params
    }

    /// The current flight mode, as HEARTBEAT reports it.
    pub fn mode(&self) -> FlightMode {
        self.mode
    }

    /// Whether the motors should be armed (apply to the world every step).
    pub fn armed(&self) -> bool {
        self.armed
    }

    /// What the autopilot should fly now, world ENU (apply every step).
    pub fn setpoint(&self) -> Setpoint {
        self.setpoint
    }

    /// PX4's landed state now.
    pub fn landed_state(&self) -> LandedState {
        if !self.armed || self.landed {
            LandedState::OnGround
        } else if self.mode == FlightMode::AutoTakeoff {
            LandedState::Takeoff
        } else if self.mode == FlightMode::AutoLand {
            LandedState::Landing
        } else {
            LandedState::InAir
        }
    }

    /// Whether an OFFBOARD switch would be accepted now: a setpoint stream
    /// has been arriving, without a gap of COM_OF_LOSS_T, for at least
    /// [`OFFBOARD_STREAM_MIN_NS`].
    pub fn offboard_available(&self, now_ns: u64) -> bool {
        match (self.stream_start_ns, self.last_setpoint_ns) {
            (Some(start), Some(last)) => {
                self.stream_alive(now_ns, last)
                    && now_ns.saturating_sub(start) >= OFFBOARD_STREAM_MIN_NS
            }
            _ => false,
        }
    }

    fn stream_alive(&self, now_ns: u64, last_ns: u64) -> bool {
        now_ns.saturating_sub(last_ns) <= self.params.loss_ns()
    }

    /// Takes the MAVLink messages produced since the last call, oldest first.
    pub fn take_outgoing(&mut self) -> Vec<MavMessage> {
        std::mem::take(&mut self.outgoing)
    }

    /// Takes the failsafe / auto-disarm events since the last call.
    pub fn take_events(&mut self) -> Vec<CommanderEvent> {
        std::mem::take(&mut self.events)
    }

    /// Handles one message from the companion (anything not addressed to
    /// system 1 / component 1 or broadcast is ignored, like PX4 does).
    #[allow(deprecated)] // SET_MODE, see the import.
    pub fn handle_message(
        &mut self,
        now_ns: u64,
        sender: &MavHeader,
        msg: &MavMessage,
        vehicle: &VehicleStatus,
    ) {
        self.crashed |= vehicle.crashed;
        match msg {
            MavMessage::COMMAND_LONG(cmd)
                if addressed_to_us(cmd.target_system, cmd.target_component) =>
            {
                let result = self.handle_command(now_ns, cmd, vehicle);
                self.outgoing.push(ack(
                    cmd.command,
                    result,
                    sender.system_id,
                    sender.component_id,
                ));
                if cmd.command == MavCmd::MAV_CMD_REQUEST_MESSAGE
                    && result == MavResult::MAV_RESULT_ACCEPTED
                {
                    let id = cmd.param1 as u32;
                    if let Some(m) = self.telemetry(id, now_ns, vehicle) {
                        self.outgoing.push(m);
                    }
                }
            }
            MavMessage::SET_MODE(m) if m.target_system == 0 || m.target_system == 1 => {
                let result = self.handle_set_mode_message(now_ns, m, vehicle);
                self.outgoing.push(ack(
                    MavCmd::MAV_CMD_DO_SET_MODE,
                    result,
                    sender.system_id,
                    sender.component_id,
                ));
            }
            MavMessage::SET_POSITION_TARGET_LOCAL_NED(sp) => {
                if addressed_to_us(sp.target_system, sp.target_component)
                    && let Some(setpoint) = setpoint_from_local_ned(sp)
                {
                    let continuous = self
                        .last_setpoint_ns
                        .is_some_and(|last| self.stream_alive(now_ns, last));
                    if !continuous {
                        self.stream_start_ns = Some(now_ns);
                    }
                    self.last_setpoint_ns = Some(now_ns);
                    self.offboard_setpoint = setpoint;
                    if self.mode == FlightMode::Offboard {
                        self.setpoint = setpoint;
                    }
                }
            }
            _ => {}
        }
    }

    fn handle_command(
        &mut self,
        now_ns: u64,
        cmd: &COMMAND_LONG_DATA,
        vehicle: &VehicleStatus,
    ) -> MavResult {
        match cmd.command {
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM => self.arm_disarm(now_ns, cmd, vehicle),
            MavCmd::MAV_CMD_NAV_TAKEOFF => {
                if self.crashed {
                    return MavResult::MAV_RESULT_DENIED;
                }
                // PX4 reads param7 as AMSL; here home is at 0 m, so it is the
                // altitude above home. NaN (or <= 0) means MIS_TAKEOFF_ALT.
                self.takeoff_alt_m = if cmd.param7.is_finite() && cmd.param7 > 0.0 {
                    f64::from(cmd.param7)
                } else {
                    self.params.mis_takeoff_alt
                };
                self.enter_mode(FlightMode::AutoTakeoff, now_ns, vehicle);
                MavResult::MAV_RESULT_ACCEPTED
            }
            MavCmd::MAV_CMD_NAV_LAND => {
                self.enter_mode(FlightMode::AutoLand, now_ns, vehicle);
                MavResult::MAV_RESULT_ACCEPTED
            }
            MavCmd::MAV_CMD_DO_SET_MODE => {
                if !cmd.param1.is_finite() || !cmd.param2.is_finite() || !cmd.param3.is_finite() {
                    return MavResult::MAV_RESULT_DENIED;
                }
                let base = cmd.param1 as u32;
                let custom = base & MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED.bits() as u32;
                if custom == 0 {
                    // PX4 only honours custom modes; the rest is ACKed and ignored.
                    return MavResult::MAV_RESULT_ACCEPTED;
                }
                self.set_mode(now_ns, cmd.param2 as u8, cmd.param3 as u8, vehicle)
            }
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL => {
                self.set_message_interval(now_ns, cmd.param1, cmd.param2)
            }
            MavCmd::MAV_CMD_REQUEST_MESSAGE => {
                if cmd.param1.is_finite() && self.stream_index(cmd.param1 as u32).is_some() {
                    MavResult::MAV_RESULT_ACCEPTED
                } else {
                    MavResult::MAV_RESULT_FAILED
                }
            }
            _ => MavResult::MAV_RESULT_UNSUPPORTED,
        }
    }

    fn arm_disarm(
        &mut self,
        now_ns: u64,
        cmd: &COMMAND_LONG_DATA,
        vehicle: &VehicleStatus,
    ) -> MavResult {
        let arm = if cmd.param1 == 1.0 {
            true
        } else if cmd.param1 == 0.0 {
            false
        } else {
            return MavResult::MAV_RESULT_DENIED;
        };
        if arm == self.armed {
            return MavResult::MAV_RESULT_ACCEPTED;
        }
        if arm {
            if self.crashed {
                return MavResult::MAV_RESULT_DENIED;
            }
            if self.mode == FlightMode::Offboard && !self.offboard_available(now_ns) {
                // PX4's mode requirements: OFFBOARD without a stream cannot arm.
                return MavResult::MAV_RESULT_TEMPORARILY_REJECTED;
            }
            self.armed = true;
            self.armed_at_ns = now_ns;
            self.has_flown = false;
            // Re-enter the mode so holds and takeoffs start from here.
            self.enter_mode(self.mode, now_ns, vehicle);
            MavResult::MAV_RESULT_ACCEPTED
        } else {
            let on_ground = self.landed || vehicle.estimate.landed;
            if !on_ground && cmd.param2 != FORCE_DISARM_MAGIC {
                return MavResult::MAV_RESULT_TEMPORARILY_REJECTED;
            }
            self.armed = false;
            MavResult::MAV_RESULT_ACCEPTED
        }
    }

    #[allow(deprecated)] // SET_MODE, see the import.
    fn handle_set_mode_message(
        &mut self,
        now_ns: u64,
        m: &SET_MODE_DATA,
        vehicle: &VehicleStatus,
    ) -> MavResult {
        if !m
            .base_mode
            .contains(MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)
        {
            return MavResult::MAV_RESULT_ACCEPTED;
        }
        let main = ((m.custom_mode >> 16) & 0xff) as u8;
        let sub = ((m.custom_mode >> 24) & 0xff) as u8;
        self.set_mode(now_ns, main, sub, vehicle)
    }

    fn set_mode(&mut self, now_ns: u64, main: u8, sub: u8, vehicle: &VehicleStatus) -> MavResult {
        match ModeRequest::from_main_sub(main, sub) {
            ModeRequest::Unknown => MavResult::MAV_RESULT_ACCEPTED,
            ModeRequest::NotSimulated => MavResult::MAV_RESULT_UNSUPPORTED,
            ModeRequest::Simulated(FlightMode::Offboard) if !self.offboard_available(now_ns) => {
                MavResult::MAV_RESULT_TEMPORARILY_REJECTED
            }
            ModeRequest::Simulated(mode) => {
                if mode != self.mode {
                    if mode == FlightMode::AutoTakeoff {
                        self.takeoff_alt_m = self.params.mis_takeoff_alt;
                    }
                    self.enter_mode(mode, now_ns, vehicle);
                }
                MavResult::MAV_RESULT_ACCEPTED
            }
        }
    }

    fn set_message_interval(&mut self, now_ns: u64, id: f32, interval_us: f32) -> MavResult {
        if !id.is_finite() || !interval_us.is_finite() {
            return MavResult::MAV_RESULT_DENIED;
        }
        let Some(i) = self.stream_index(id as u32) else {
            return MavResult::MAV_RESULT_FAILED;
        };
        let stream = &mut self.streams[i];
        stream.interval_ns = if interval_us == -1.0 {
            None
        } else if interval_us == 0.0 {
            stream.default_interval_ns
        } else if interval_us > 0.0 {
            Some((f64::from(interval_us) * 1e3).max(1.0) as u64)
        } else {
            return MavResult::MAV_RESULT_DENIED;
        };
        stream.next_due_ns = now_ns;
        MavResult::MAV_RESULT_ACCEPTED
    }

    fn stream_index(&self, id: u32) -> Option<usize> {
        self.streams.iter().position(|s| s.id == id)
    }

    fn enter_mode(&mut self, mode: FlightMode, _now_ns: u64, vehicle: &VehicleStatus) {
        let est = &vehicle.estimate;
        let yaw = yaw_of(est);
        match mode {
            FlightMode::Posctl | FlightMode::AutoLoiter | FlightMode::AutoLand => {
                self.hold_position = est.position;
                self.hold_yaw = yaw;
            }
            FlightMode::AutoTakeoff => self.takeoff = None,
            FlightMode::Offboard => self.setpoint = self.offboard_setpoint,
        }
        if mode != self.mode {
            tracing::debug!(from = ?self.mode, to = ?mode, "mode change");
        }
        self.mode = mode;
    }

    /// Runs the commander for this step: failsafes, mode logic, auto-disarm,
    /// telemetry. Call once per physics step, before applying [`Self::armed`]
    /// and [`Self::setpoint`] to the world.
    pub fn update(&mut self, now_ns: u64, vehicle: &VehicleStatus) {
        self.crashed |= vehicle.crashed;
        if self.crashed && self.armed {
            self.armed = false;
            self.events.push(CommanderEvent::DisarmCrash);
        }
        self.detect_landing(now_ns, vehicle);
        self.offboard_failsafe(now_ns, vehicle);
        self.fly_mode(now_ns, vehicle);
        self.auto_disarm(now_ns);
        self.send_telemetry(now_ns, vehicle);
    }

    fn detect_landing(&mut self, now_ns: u64, vehicle: &VehicleStatus) {
        if vehicle.estimate.landed {
            let since = *self.contact_since_ns.get_or_insert(now_ns);
            self.landed = now_ns.saturating_sub(since) >= LAND_DETECT_NS;
        } else {
            self.contact_since_ns = None;
            self.landed = false;
            if self.armed {
                self.has_flown = true;
            }
        }
    }

    fn offboard_failsafe(&mut self, now_ns: u64, vehicle: &VehicleStatus) {
        if self.mode != FlightMode::Offboard || !self.armed {
            return;
        }
        let alive = self
            .last_setpoint_ns
            .is_some_and(|last| self.stream_alive(now_ns, last));
        if !alive {
            let mode = if self.params.com_obl_rc_act == 5 {
                FlightMode::AutoLoiter
            } else {
                FlightMode::AutoLand
            };
            tracing::warn!(?mode, "offboard setpoints lost");
            self.enter_mode(mode, now_ns, vehicle);
            self.events.push(CommanderEvent::OffboardLost(mode));
        }
    }

    fn fly_mode(&mut self, now_ns: u64, vehicle: &VehicleStatus) {
        let est = &vehicle.estimate;
        if !self.armed {
            self.setpoint = Setpoint::position(est.position, yaw_of(est));
            return;
        }
        self.setpoint = match self.mode {
            FlightMode::Posctl | FlightMode::AutoLoiter => {
                Setpoint::position(self.hold_position, self.hold_yaw)
            }
            FlightMode::Offboard => self.offboard_setpoint,
            FlightMode::AutoLand => Setpoint {
                position: [Some(self.hold_position.x), Some(self.hold_position.y), None],
                velocity: [None, None, Some(-self.params.mpc_land_speed)],
                yaw: Some(self.hold_yaw),
                ..Setpoint::default()
            },
            FlightMode::AutoTakeoff => {
                let alt = self.takeoff_alt_m;
                let t = *self.takeoff.get_or_insert(Takeoff {
                    start_ns: now_ns,
                    start_z: est.position.z,
                    target_z: alt,
                    xy: [est.position.x, est.position.y],
                    yaw: yaw_of(est),
                });
                if est.position.z >= t.target_z - TAKEOFF_ACCEPTANCE_M {
                    self.mode = FlightMode::AutoLoiter;
                    self.takeoff = None;
                    self.hold_position =
                        Vector3::new(t.xy[0], t.xy[1], t.target_z.max(est.position.z));
                    self.hold_yaw = t.yaw;
                    Setpoint::position(self.hold_position, self.hold_yaw)
                } else {
                    let elapsed = now_ns.saturating_sub(t.start_ns) as f64 * 1e-9;
                    let z = (t.start_z + self.params.mpc_tko_speed * elapsed).min(t.target_z);
                    let vz = if z < t.target_z {
                        self.params.mpc_tko_speed
                    } else {
                        0.0
                    };
                    Setpoint {
                        position: [Some(t.xy[0]), Some(t.xy[1]), Some(z)],
                        velocity: [None, None, Some(vz)],
                        yaw: Some(t.yaw),
                        ..Setpoint::default()
                    }
                }
            }
        };
    }

    fn auto_disarm(&mut self, now_ns: u64) {
        if !self.armed || !self.landed {
            return;
        }
        if self.has_flown {
            if self.params.com_disarm_land >= 0.0
                && let Some(since) = self.contact_since_ns
            {
                let after = LAND_DETECT_NS + secs_to_ns(self.params.com_disarm_land);
                if now_ns.saturating_sub(since) >= after {
                    self.armed = false;
                    self.events.push(CommanderEvent::AutoDisarmLanded);
                }
            }
        } else if self.params.com_disarm_prflt >= 0.0
            && now_ns.saturating_sub(self.armed_at_ns) >= secs_to_ns(self.params.com_disarm_prflt)
        {
            self.armed = false;
            self.events.push(CommanderEvent::AutoDisarmPreflight);
        }
    }

    fn send_telemetry(&mut self, now_ns: u64, vehicle: &VehicleStatus) {
        for i in 0..self.streams.len() {
            let s = self.streams[i];
            let Some(interval) = s.interval_ns else {
                continue;
            };
            if now_ns < s.next_due_ns {
                continue;
            }
            let mut next = s.next_due_ns.saturating_add(interval);
            if next <= now_ns {
                next = now_ns.saturating_add(interval);
            }
            self.streams[i].next_due_ns = next;
            if let Some(m) = self.telemetry(s.id, now_ns, vehicle) {
                self.outgoing.push(m);
            }
        }
    }

    /// Builds telemetry message `id` for now, as PX4 would report it.
    fn telemetry(&self, id: u32, now_ns: u64, vehicle: &VehicleStatus) -> Option<MavMessage> {
        let est = &vehicle.estimate;
        let time_boot_ms = (now_ns / 1_000_000) as u32;
        Some(match id {
            msg_id::HEARTBEAT => MavMessage::HEARTBEAT(self.heartbeat()),
            msg_id::LOCAL_POSITION_NED => {
                let p = enu_to_ned(&est.position);
                let v = enu_to_ned(&est.velocity);
                MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
                    time_boot_ms,
                    x: p.x as f32,
                    y: p.y as f32,
                    z: p.z as f32,
                    vx: v.x as f32,
                    vy: v.y as f32,
                    vz: v.z as f32,
                })
            }
            msg_id::ATTITUDE_QUATERNION => {
                let q = quaternion_wxyz(&ned_from_frd(&est.world_from_body));
                let w = flu_to_frd(&est.body_rates);
                MavMessage::ATTITUDE_QUATERNION(ATTITUDE_QUATERNION_DATA {
                    time_boot_ms,
                    q1: q[0],
                    q2: q[1],
                    q3: q[2],
                    q4: q[3],
                    rollspeed: w.x as f32,
                    pitchspeed: w.y as f32,
                    yawspeed: w.z as f32,
                    repr_offset_q: [0.0; 4],
                })
            }
            msg_id::EXTENDED_SYS_STATE => MavMessage::EXTENDED_SYS_STATE(EXTENDED_SYS_STATE_DATA {
                vtol_state: MavVtolState::MAV_VTOL_STATE_UNDEFINED,
                landed_state: self.landed_state().to_mav(),
            }),
            msg_id::ODOMETRY => {
                let q_ned = ned_from_frd(&est.world_from_body);
                let p = enu_to_ned(&est.position);
                // PX4 reports the velocity in the body frame (FRD) here.
                let v = q_ned.inverse_transform_vector(&enu_to_ned(&est.velocity));
                let w = flu_to_frd(&est.body_rates);
                let mut unknown = [0.0f32; 21];
                unknown[0] = f32::NAN;
                MavMessage::ODOMETRY(ODOMETRY_DATA {
                    time_usec: now_ns / 1000,
                    x: p.x as f32,
                    y: p.y as f32,
                    z: p.z as f32,
                    q: quaternion_wxyz(&q_ned),
                    vx: v.x as f32,
                    vy: v.y as f32,
                    vz: v.z as f32,
                    rollspeed: w.x as f32,
                    pitchspeed: w.y as f32,
                    yawspeed: w.z as f32,
                    pose_covariance: unknown,
                    velocity_covariance: unknown,
                    frame_id: MavFrame::MAV_FRAME_LOCAL_NED,
                    child_frame_id: MavFrame::MAV_FRAME_BODY_FRD,
                    reset_counter: 0,
                    estimator_type: MavEstimatorType::MAV_ESTIMATOR_TYPE_VIO,
                    quality: 0,
                })
            }
            _ => return None,
        })
    }

    /// The HEARTBEAT PX4 would send now (type, autopilot, mode flags, custom
    /// mode, status).
    pub fn heartbeat(&self) -> HEARTBEAT_DATA {
        let mut base_mode = MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            | MavModeFlag::MAV_MODE_FLAG_STABILIZE_ENABLED
            | MavModeFlag::MAV_MODE_FLAG_GUIDED_ENABLED;
        base_mode |= match self.mode {
            FlightMode::Posctl => MavModeFlag::MAV_MODE_FLAG_MANUAL_INPUT_ENABLED,
            _ => MavModeFlag::MAV_MODE_FLAG_AUTO_ENABLED,
        };
        if self.armed {
            base_mode |= MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
        }
        let system_status = if self.crashed {
            MavState::MAV_STATE_EMERGENCY
        } else if self.armed {
            MavState::MAV_STATE_ACTIVE
        } else {
            MavState::MAV_STATE_STANDBY
        };
        HEARTBEAT_DATA {
            custom_mode: self.mode.custom_mode(),
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
            base_mode,
            system_status,
            mavlink_version: 3,
        }
    }
}

fn addressed_to_us(system: u8, component: u8) -> bool {
    (system == 0 || system == 1) && (component == 0 || component == 1)
}

fn ack(command: MavCmd, result: MavResult, system: u32, component: u8) -> MavMessage {
    MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
        command,
        result,
        progress: 0,
        result_param2: 0,
        target_system: u8::try_from(system).unwrap_or(0),
        target_component: component,
    })
}

fn yaw_of(est: &EstimatedState) -> f64 {
    let x = est.world_from_body * Vector3::x();
    x.y.atan2(x.x)
}

/// Converts SET_POSITION_TARGET_LOCAL_NED to an ENU [`Setpoint`], as PX4's
/// MAVLink receiver does: type_mask bits set mean "ignore", non-finite
/// values count as ignored. Returns None for what PX4 would not use as an
/// offboard setpoint here: a frame other than LOCAL_NED, the FORCE bit, or
/// nothing at all in position, velocity and acceleration.
pub fn setpoint_from_local_ned(sp: &SET_POSITION_TARGET_LOCAL_NED_DATA) -> Option<Setpoint> {
    if sp.coordinate_frame != MavFrame::MAV_FRAME_LOCAL_NED {
        return None;
    }
    let mask = sp.type_mask;
    if mask.contains(PositionTargetTypemask::POSITION_TARGET_TYPEMASK_FORCE_SET) {
        return None;
    }
    let field = |value: f32, bit: PositionTargetTypemask| -> Option<f64> {
        (!mask.contains(bit) && value.is_finite()).then_some(f64::from(value))
    };
    use PositionTargetTypemask as M;
    let ned3 = |v: [f32; 3], bits: [M; 3]| -> [Option<f64>; 3] {
        let n = [
            field(v[0], bits[0]),
            field(v[1], bits[1]),
            field(v[2], bits[2]),
        ];
        // ENU x = NED y, ENU y = NED x, ENU z = -NED z, per axis.
        [n[1], n[0], n[2].map(|z| -z)]
    };
    let position = ned3(
        [sp.x, sp.y, sp.z],
        [
            M::POSITION_TARGET_TYPEMASK_X_IGNORE,
            M::POSITION_TARGET_TYPEMASK_Y_IGNORE,
            M::POSITION_TARGET_TYPEMASK_Z_IGNORE,
        ],
    );
    let velocity = ned3(
        [sp.vx, sp.vy, sp.vz],
        [
            M::POSITION_TARGET_TYPEMASK_VX_IGNORE,
            M::POSITION_TARGET_TYPEMASK_VY_IGNORE,
            M::POSITION_TARGET_TYPEMASK_VZ_IGNORE,
        ],
    );
    let acceleration = ned3(
        [sp.afx, sp.afy, sp.afz],
        [
            M::POSITION_TARGET_TYPEMASK_AX_IGNORE,
            M::POSITION_TARGET_TYPEMASK_AY_IGNORE,
            M::POSITION_TARGET_TYPEMASK_AZ_IGNORE,
        ],
    );
    if position
        .iter()
        .chain(&velocity)
        .chain(&acceleration)
        .all(Option::is_none)
    {
        return None;
    }
    Some(Setpoint {
        position,
        velocity,
        acceleration,
        yaw: field(sp.yaw, M::POSITION_TARGET_TYPEMASK_YAW_IGNORE).map(yaw_ned_to_enu),
        yaw_rate: field(sp.yaw_rate, M::POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE).map(|r| -r),
    })
}

/// The ENU position a NED LOCAL_POSITION_NED reading stands for (for tests
/// and tools that read the endpoint back).
pub fn enu_from_local_ned(x: f32, y: f32, z: f32) -> Vector3<f64> {
    ned_to_enu(&Vector3::new(f64::from(x), f64::from(y), f64::from(z)))
}

#[cfg(test)]
mod tests {
    use std::f64::consts::FRAC_PI_2;

    use mavlink::dialects::common::MavCmd;
    use nalgebra::UnitQuaternion;

    use super::*;

    const MS: u64 = 1_000_000;
    const S: u64 = 1_000_000_000;
    const COMPANION: MavHeader = MavHeader {
        system_id: 1,
        component_id: 191,
        sequence: 0,
    };

    fn status(z: f64, landed: bool) -> VehicleStatus {
        VehicleStatus {
            estimate: EstimatedState {
                position: Vector3::new(1.0, 2.0, z),
                velocity: Vector3::zeros(),
                world_from_body: UnitQuaternion::identity(),
                body_rates: Vector3::zeros(),
                landed,
            },
            crashed: false,
        }
    }

    fn ground() -> VehicleStatus {
        status(0.0, true)
    }

    fn cmd(command: MavCmd, p: [f32; 7]) -> MavMessage {
        MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            param1: p[0],
            param2: p[1],
            param3: p[2],
            param4: p[3],
            param5: p[4],
            param6: p[5],
            param7: p[6],
            command,
            target_system: 1,
            target_component: 1,
            confirmation: 0,
        })
    }

    /// Sends a command and returns its ACK result (and drops other output).
    fn command(c: &mut Commander, now: u64, msg: &MavMessage, v: &VehicleStatus) -> MavResult {
        c.take_outgoing();
        c.handle_message(now, &COMPANION, msg, v);
        let acks: Vec<_> = c
            .take_outgoing()
            .into_iter()
            .filter_map(|m| match m {
                MavMessage::COMMAND_ACK(a) => Some(a),
                _ => None,
            })
            .collect();
        assert_eq!(acks.len(), 1, "one ACK per command");
        assert_eq!((acks[0].target_system, acks[0].target_component), (1, 191));
        acks[0].result
    }

    fn arm_msg(arm: bool) -> MavMessage {
        cmd(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [f32::from(u8::from(arm)), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        )
    }

    fn set_mode_msg(main: f32, sub: f32) -> MavMessage {
        cmd(
            MavCmd::MAV_CMD_DO_SET_MODE,
            [1.0, main, sub, 0.0, 0.0, 0.0, 0.0],
        )
    }

    fn sp_msg(type_mask: u16, frame: MavFrame, v: [f32; 11]) -> MavMessage {
        MavMessage::SET_POSITION_TARGET_LOCAL_NED(SET_POSITION_TARGET_LOCAL_NED_DATA {
            time_boot_ms: 0,
            x: v[0],
            y: v[1],
            z: v[2],
            vx: v[3],
            vy: v[4],
            vz: v[5],
            afx: v[6],
            afy: v[7],
            afz: v[8],
            yaw: v[9],
            yaw_rate: v[10],
            type_mask: PositionTargetTypemask::from_bits_retain(type_mask),
            target_system: 1,
            target_component: 1,
            coordinate_frame: frame,
        })
    }

    /// Position-only setpoint at NED (x, y, z).
    fn pos_sp(x: f32, y: f32, z: f32) -> MavMessage {
        sp_msg(
            0x0DF8,
            MavFrame::MAV_FRAME_LOCAL_NED,
            [x, y, z, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        )
    }

    fn new() -> Commander {
        Commander::new(Px4Params::default()).unwrap()
    }

    /// Streams setpoints at 20 Hz from `from` for `dur`, updating at 500 Hz.
    fn stream(c: &mut Commander, from: u64, dur: u64, v: &VehicleStatus) -> u64 {
        let mut t = from;
        while t < from + dur {
            if (t - from).is_multiple_of(50 * MS) {
                c.handle_message(t, &COMPANION, &pos_sp(0.0, 0.0, -2.0), v);
            }
            c.update(t, v);
            t += 2 * MS;
        }
        t
    }

    #[test]
    fn params_parse_with_px4_names_and_validate() {
        let p: Px4Params = toml::from_str("COM_OF_LOSS_T = 0.5\nCOM_OBL_RC_ACT = 5").unwrap();
        assert_eq!(p.com_of_loss_t, 0.5);
        assert_eq!(p.com_obl_rc_act, 5);
        assert_eq!(p.mis_takeoff_alt, 2.5);
        assert!(toml::from_str::<Px4Params>("COM_FOO = 1").is_err());
        let bad = Px4Params {
            com_obl_rc_act: 3,
            ..Px4Params::default()
        };
        assert!(bad.validate().is_err());
        let bad = Px4Params {
            mpc_land_speed: f64::NAN,
            ..Px4Params::default()
        };
        assert!(Commander::new(bad).is_err());
        assert!(Px4Params::default().validate().is_ok());
    }

    #[test]
    fn custom_mode_packing() {
        assert_eq!(FlightMode::Offboard.custom_mode(), 6 << 16);
        assert_eq!(FlightMode::AutoLand.custom_mode(), (6 << 24) | (4 << 16));
        assert_eq!(FlightMode::AutoLoiter.custom_mode(), (3 << 24) | (4 << 16));
        assert_eq!(FlightMode::AutoTakeoff.custom_mode(), (2 << 24) | (4 << 16));
        assert_eq!(FlightMode::Posctl.custom_mode(), 3 << 16);
        for m in [
            FlightMode::Posctl,
            FlightMode::AutoTakeoff,
            FlightMode::AutoLoiter,
            FlightMode::AutoLand,
            FlightMode::Offboard,
        ] {
            let (main, sub) = m.main_sub();
            assert_eq!(
                ModeRequest::from_main_sub(main, sub),
                ModeRequest::Simulated(m)
            );
        }
        assert_eq!(ModeRequest::from_main_sub(4, 5), ModeRequest::NotSimulated);
        assert_eq!(ModeRequest::from_main_sub(1, 0), ModeRequest::NotSimulated);
        assert_eq!(ModeRequest::from_main_sub(0, 6), ModeRequest::Unknown);
        assert_eq!(ModeRequest::from_main_sub(42, 0), ModeRequest::Unknown);
    }

    #[test]
    fn heartbeat_at_1_hz_with_px4_identity() {
        let mut c = new();
        let v = ground();
        let mut beats = Vec::new();
        for i in 0..1500 {
            c.update(i * 2 * MS, &v);
            beats.extend(c.take_outgoing().into_iter().filter_map(|m| match m {
                MavMessage::HEARTBEAT(h) => Some(h),
                _ => None,
            }));
        }
        assert_eq!(beats.len(), 3, "t = 0, 1, 2 s");
        let h = &beats[0];
        assert_eq!(h.mavtype, MavType::MAV_TYPE_QUADROTOR);
        assert_eq!(h.autopilot, MavAutopilot::MAV_AUTOPILOT_PX4);
        assert!(
            h.base_mode
                .contains(MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)
        );
        assert!(
            !h.base_mode
                .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED)
        );
        assert_eq!(h.system_status, MavState::MAV_STATE_STANDBY);
        assert_eq!(h.custom_mode, FlightMode::Posctl.custom_mode());
        assert_eq!(
            command(&mut c, 3 * S, &arm_msg(true), &v),
            MavResult::MAV_RESULT_ACCEPTED
        );
        let h = c.heartbeat();
        assert!(
            h.base_mode
                .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED)
        );
        assert_eq!(h.system_status, MavState::MAV_STATE_ACTIVE);
    }

    #[test]
    fn telemetry_default_rates_and_frames() {
        let mut c = new();
        let mut v = status(3.0, false);
        v.estimate.velocity = Vector3::new(1.0, 0.0, 0.5);
        v.estimate.body_rates = Vector3::new(0.1, 0.2, 0.3);
        let mut out = Vec::new();
        for i in 0..500 {
            c.update(i * 2 * MS, &v);
            out.extend(c.take_outgoing());
        }
        let n = |id| {
            out.iter()
                .filter(|m| mavlink::Message::message_id(*m) == id)
                .count()
        };
        assert_eq!(n(msg_id::ATTITUDE_QUATERNION), 50);
        assert!((29..=31).contains(&n(msg_id::LOCAL_POSITION_NED)));
        assert_eq!(n(msg_id::EXTENDED_SYS_STATE), 5);
        assert_eq!(n(msg_id::ODOMETRY), 0);
        for m in &out {
            match m {
                MavMessage::LOCAL_POSITION_NED(p) => {
                    assert_eq!([p.x, p.y, p.z], [2.0, 1.0, -3.0]);
                    assert_eq!([p.vx, p.vy, p.vz], [0.0, 1.0, -0.5]);
                }
                MavMessage::ATTITUDE_QUATERNION(q) => {
                    assert_eq!([q.rollspeed, q.pitchspeed, q.yawspeed], [0.1, -0.2, -0.3]);
                    let h = 0.5f32.sqrt();
                    assert!((q.q1 - h).abs() < 1e-6 && (q.q4 - h).abs() < 1e-6);
                }
                MavMessage::EXTENDED_SYS_STATE(s) => {
                    // Disarmed counts as on the ground.
                    assert_eq!(s.landed_state, MavLandedState::MAV_LANDED_STATE_ON_GROUND);
                }
                _ => {}
            }
        }
    }

    #[test]
    fn set_message_interval_and_request_message() {
        let mut c = new();
        let v = ground();
        let req = |id: f32, us: f32| {
            cmd(
                MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
                [id, us, 0.0, 0.0, 0.0, 0.0, 0.0],
            )
        };
        assert_eq!(
            command(&mut c, 0, &req(32.0, 100_000.0), &v),
            MavResult::MAV_RESULT_ACCEPTED
        );
        assert_eq!(
            command(&mut c, 0, &req(331.0, 20_000.0), &v),
            MavResult::MAV_RESULT_ACCEPTED
        );
        assert_eq!(
            command(&mut c, 0, &req(31.0, -1.0), &v),
            MavResult::MAV_RESULT_ACCEPTED
        );
        assert_eq!(
            command(&mut c, 0, &req(9999.0, 1000.0), &v),
            MavResult::MAV_RESULT_FAILED
        );
        assert_eq!(
            command(&mut c, 0, &req(32.0, -5.0), &v),
            MavResult::MAV_RESULT_DENIED
        );
        assert_eq!(
            command(&mut c, 0, &req(f32::NAN, 5.0), &v),
            MavResult::MAV_RESULT_DENIED
        );
        let mut out = Vec::new();
        for i in 0..500 {
            c.update(i * 2 * MS, &v);
            out.extend(c.take_outgoing());
        }
        let n = |id| {
            out.iter()
                .filter(|m| mavlink::Message::message_id(*m) == id)
                .count()
        };
        assert_eq!(n(msg_id::LOCAL_POSITION_NED), 10);
        assert_eq!(n(msg_id::ODOMETRY), 50);
        assert_eq!(n(msg_id::ATTITUDE_QUATERNION), 0);
        let odom = out.iter().find_map(|m| match m {
            MavMessage::ODOMETRY(o) => Some(o.clone()),
            _ => None,
        });
        let odom = odom.unwrap();
        assert_eq!(odom.frame_id, MavFrame::MAV_FRAME_LOCAL_NED);
        assert_eq!(odom.child_frame_id, MavFrame::MAV_FRAME_BODY_FRD);
        assert_eq!([odom.x, odom.y, odom.z], [2.0, 1.0, -0.0]);
        // Interval 0 restores the default.
        assert_eq!(
            command(&mut c, S, &req(31.0, 0.0), &v),
            MavResult::MAV_RESULT_ACCEPTED
        );
        // REQUEST_MESSAGE: ACK, then the message once.
        c.take_outgoing();
        c.handle_message(
            S,
            &COMPANION,
            &cmd(
                MavCmd::MAV_CMD_REQUEST_MESSAGE,
                [245.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            ),
            &v,
        );
        let out = c.take_outgoing();
        assert!(
            matches!(&out[0], MavMessage::COMMAND_ACK(a) if a.result == MavResult::MAV_RESULT_ACCEPTED)
        );
        assert!(matches!(&out[1], MavMessage::EXTENDED_SYS_STATE(_)));
        let r = command(
            &mut c,
            S,
            &cmd(
                MavCmd::MAV_CMD_REQUEST_MESSAGE,
                [77.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            ),
            &v,
        );
        assert_eq!(r, MavResult::MAV_RESULT_FAILED);
    }

    #[test]
    fn arm_disarm_results() {
        let mut c = new();
        let g = ground();
        assert_eq!(
            command(&mut c, 0, &arm_msg(true), &g),
            MavResult::MAV_RESULT_ACCEPTED
        );
        assert!(c.armed());
        // Already armed: accepted.
        assert_eq!(
            command(&mut c, 0, &arm_msg(true), &g),
            MavResult::MAV_RESULT_ACCEPTED
        );
        // Bad param1.
        let bad = cmd(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        assert_eq!(command(&mut c, 0, &bad, &g), MavResult::MAV_RESULT_DENIED);
        // Disarm in the air refused unless forced.
        let air = status(3.0, false);
        c.update(10 * MS, &air);
        assert_eq!(
            command(&mut c, 20 * MS, &arm_msg(false), &air),
            MavResult::MAV_RESULT_TEMPORARILY_REJECTED
        );
        assert!(c.armed());
        let force = cmd(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [0.0, FORCE_DISARM_MAGIC, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        assert_eq!(
            command(&mut c, 30 * MS, &force, &air),
            MavResult::MAV_RESULT_ACCEPTED
        );
        assert!(!c.armed());
        // Crashed: arming denied.
        let mut crashed = ground();
        crashed.crashed = true;
        c.update(40 * MS, &crashed);
        assert_eq!(
            command(&mut c, 50 * MS, &arm_msg(true), &crashed),
            MavResult::MAV_RESULT_DENIED
        );
        assert!(!c.armed());
        assert_eq!(c.heartbeat().system_status, MavState::MAV_STATE_EMERGENCY);
    }

    #[test]
    fn crash_disarms() {
        let mut c = new();
        let air = status(3.0, false);
        command(&mut c, 0, &arm_msg(true), &air);
        let mut crashed = air;
        crashed.crashed = true;
        c.update(2 * MS, &crashed);
        assert!(!c.armed());
        assert_eq!(c.take_events(), vec![CommanderEvent::DisarmCrash]);
    }

    #[test]
    fn commands_for_other_systems_are_ignored_and_unknown_ones_unsupported() {
        let mut c = new();
        let g = ground();
        let mut m = arm_msg(true);
        if let MavMessage::COMMAND_LONG(d) = &mut m {
            d.target_system = 2;
        }
        c.handle_message(0, &COMPANION, &m, &g);
        assert!(c.take_outgoing().is_empty());
        assert!(!c.armed());
        let r = command(&mut c, 0, &cmd(MavCmd::MAV_CMD_DO_REPOSITION, [0.0; 7]), &g);
        assert_eq!(r, MavResult::MAV_RESULT_UNSUPPORTED);
    }

    #[test]
    fn takeoff_climbs_at_tko_speed_then_loiters() {
        let mut c = new();
        let g = ground();
        command(&mut c, 0, &arm_msg(true), &g);
        let r = command(
            &mut c,
            0,
            &cmd(
                MavCmd::MAV_CMD_NAV_TAKEOFF,
                [0.0, 0.0, 0.0, f32::NAN, f32::NAN, f32::NAN, f32::NAN],
            ),
            &g,
        );
        assert_eq!(r, MavResult::MAV_RESULT_ACCEPTED);
        assert_eq!(c.mode(), FlightMode::AutoTakeoff);
        c.update(0, &g);
        c.update(S, &status(1.0, false));
        assert_eq!(c.landed_state(), LandedState::Takeoff);
        let sp = c.setpoint();
        assert_eq!(sp.position[0], Some(1.0));
        assert_eq!(sp.position[1], Some(2.0));
        assert!(
            (sp.position[2].unwrap() - 1.5).abs() < 1e-9,
            "ramp at 1.5 m/s"
        );
        assert_eq!(sp.velocity[2], Some(1.5));
        // Reaching MIS_TAKEOFF_ALT (2.5 m) switches to AUTO.LOITER there.
        c.update(2 * S, &status(2.4, false));
        assert_eq!(c.mode(), FlightMode::AutoLoiter);
        assert_eq!(c.landed_state(), LandedState::InAir);
        let sp = c.setpoint();
        assert_eq!(sp.position, [Some(1.0), Some(2.0), Some(2.5)]);
        // param7 gives the altitude.
        let r = command(
            &mut c,
            3 * S,
            &cmd(
                MavCmd::MAV_CMD_NAV_TAKEOFF,
                [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 6.0],
            ),
            &status(2.5, false),
        );
        assert_eq!(r, MavResult::MAV_RESULT_ACCEPTED);
        c.update(3 * S, &status(2.5, false));
        c.update(4 * S, &status(3.0, false));
        assert_eq!(c.mode(), FlightMode::AutoTakeoff);
        c.update(5 * S, &status(5.9, false));
        assert_eq!(c.mode(), FlightMode::AutoLoiter);
        assert_eq!(c.setpoint().position[2], Some(6.0));
    }

    #[test]
    fn takeoff_while_disarmed_waits_for_arming() {
        let mut c = new();
        let g = ground();
        let to = cmd(MavCmd::MAV_CMD_NAV_TAKEOFF, [0.0; 7]);
        assert_eq!(command(&mut c, 0, &to, &g), MavResult::MAV_RESULT_ACCEPTED);
        c.update(S, &g);
        assert_eq!(c.mode(), FlightMode::AutoTakeoff);
        assert_eq!(c.landed_state(), LandedState::OnGround);
        command(&mut c, 2 * S, &arm_msg(true), &g);
        c.update(2 * S, &g);
        c.update(2 * S + 500 * MS, &g);
        let z = c.setpoint().position[2].unwrap();
        assert!((z - 0.75).abs() < 1e-9, "ramp starts at arming: {z}");
    }

    #[test]
    fn land_descends_then_disarms_after_com_disarm_land() {
        let mut c = new();
        let air = status(3.0, false);
        command(&mut c, 0, &arm_msg(true), &ground());
        c.update(0, &air);
        let r = command(&mut c, 0, &cmd(MavCmd::MAV_CMD_NAV_LAND, [0.0; 7]), &air);
        assert_eq!(r, MavResult::MAV_RESULT_ACCEPTED);
        c.update(2 * MS, &air);
        assert_eq!(c.mode(), FlightMode::AutoLand);
        assert_eq!(c.landed_state(), LandedState::Landing);
        let sp = c.setpoint();
        assert_eq!(sp.position, [Some(1.0), Some(2.0), None]);
        assert_eq!(sp.velocity, [None, None, Some(-0.7)]);
        // Touchdown at t = 1 s: landed after the land detector (0.5 s),
        // disarmed COM_DISARM_LAND (2 s) after that.
        let mut t = S;
        while t < S + LAND_DETECT_NS + 2 * S - 10 * MS {
            c.update(t, &ground());
            t += 2 * MS;
        }
        assert_eq!(c.landed_state(), LandedState::OnGround);
        assert!(c.armed());
        c.update(S + LAND_DETECT_NS + 2 * S + 2 * MS, &ground());
        assert!(!c.armed());
        assert_eq!(c.mode(), FlightMode::AutoLand);
        assert_eq!(c.take_events(), vec![CommanderEvent::AutoDisarmLanded]);
    }

    #[test]
    fn preflight_auto_disarm() {
        let mut c = new();
        let g = ground();
        command(&mut c, 0, &arm_msg(true), &g);
        let mut t = 0;
        while t < 10 * S - 10 * MS {
            c.update(t, &g);
            t += 10 * MS;
        }
        assert!(c.armed());
        c.update(10 * S, &g);
        assert!(!c.armed());
        assert_eq!(c.take_events(), vec![CommanderEvent::AutoDisarmPreflight]);
    }

    #[test]
    fn offboard_needs_a_one_second_stream() {
        let mut c = new();
        let g = ground();
        // No stream at all.
        assert_eq!(
            command(&mut c, 0, &set_mode_msg(6.0, 0.0), &g),
            MavResult::MAV_RESULT_TEMPORARILY_REJECTED
        );
        assert_eq!(c.mode(), FlightMode::Posctl);
        // 0.5 s of stream: still refused.
        let t = stream(&mut c, 0, 500 * MS, &g);
        assert_eq!(
            command(&mut c, t, &set_mode_msg(6.0, 0.0), &g),
            MavResult::MAV_RESULT_TEMPORARILY_REJECTED
        );
        assert_eq!(c.mode(), FlightMode::Posctl);
        // Setpoints do not drive the vehicle outside OFFBOARD.
        command(&mut c, t, &arm_msg(true), &g);
        c.update(t, &g);
        assert_eq!(c.setpoint().position[2], Some(0.0));
        // >= 1 s: accepted, and the setpoint (NED z -2 = ENU z 2) applies.
        let t = stream(&mut c, t, 600 * MS, &g);
        assert!(c.offboard_available(t));
        assert_eq!(
            command(&mut c, t, &set_mode_msg(6.0, 0.0), &g),
            MavResult::MAV_RESULT_ACCEPTED
        );
        assert_eq!(c.mode(), FlightMode::Offboard);
        assert_eq!(c.heartbeat().custom_mode, 6 << 16);
        c.update(t, &g);
        assert_eq!(c.setpoint().position, [Some(0.0), Some(0.0), Some(2.0)]);
    }

    #[test]
    fn a_gap_restarts_the_stream_clock() {
        let mut c = new();
        let g = ground();
        let t = stream(&mut c, 0, 800 * MS, &g);
        // A 1.5 s gap (> COM_OF_LOSS_T), then 0.5 s more: not 1 s continuous.
        let t = stream(&mut c, t + 1500 * MS, 500 * MS, &g);
        assert!(!c.offboard_available(t));
        assert_eq!(
            command(&mut c, t, &set_mode_msg(6.0, 0.0), &g),
            MavResult::MAV_RESULT_TEMPORARILY_REJECTED
        );
    }

    #[test]
    fn arming_in_offboard_without_stream_is_rejected() {
        let mut c = new();
        let g = ground();
        let t = stream(&mut c, 0, 1200 * MS, &g);
        command(&mut c, t, &set_mode_msg(6.0, 0.0), &g);
        assert_eq!(c.mode(), FlightMode::Offboard);
        // Stream stops; disarmed, so no failsafe, but arming is refused.
        c.update(t + 3 * S, &g);
        assert_eq!(c.mode(), FlightMode::Offboard);
        assert_eq!(
            command(&mut c, t + 3 * S, &arm_msg(true), &g),
            MavResult::MAV_RESULT_TEMPORARILY_REJECTED
        );
    }

    fn offboard_loss(action: u8) -> (FlightMode, u64, Vec<CommanderEvent>) {
        let mut c = Commander::new(Px4Params {
            com_obl_rc_act: action,
            ..Px4Params::default()
        })
        .unwrap();
        let air = status(2.0, false);
        let t = stream(&mut c, 0, 1200 * MS, &air);
        command(&mut c, t, &arm_msg(true), &air);
        command(&mut c, t, &set_mode_msg(6.0, 0.0), &air);
        assert_eq!(c.mode(), FlightMode::Offboard);
        let last = t - 50 * MS;
        let mut now = t;
        while c.mode() == FlightMode::Offboard && now < t + 5 * S {
            c.update(now, &air);
            now += 2 * MS;
        }
        (c.mode(), now - 2 * MS - last, c.take_events())
    }

    #[test]
    fn offboard_loss_lands_after_com_of_loss_t() {
        let (mode, after, events) = offboard_loss(4);
        assert_eq!(mode, FlightMode::AutoLand);
        assert!((1000 * MS..=1010 * MS).contains(&after), "after {after} ns");
        assert_eq!(
            events,
            vec![CommanderEvent::OffboardLost(FlightMode::AutoLand)]
        );
    }

    #[test]
    fn offboard_loss_holds_with_com_obl_rc_act_5() {
        let (mode, _, events) = offboard_loss(5);
        assert_eq!(mode, FlightMode::AutoLoiter);
        assert_eq!(
            events,
            vec![CommanderEvent::OffboardLost(FlightMode::AutoLoiter)]
        );
    }

    #[test]
    fn do_set_mode_results() {
        let mut c = new();
        let air = status(2.0, false);
        command(&mut c, 0, &arm_msg(true), &ground());
        assert_eq!(
            command(&mut c, 0, &set_mode_msg(4.0, 3.0), &air),
            MavResult::MAV_RESULT_ACCEPTED
        );
        assert_eq!(c.mode(), FlightMode::AutoLoiter);
        assert_eq!(c.heartbeat().custom_mode, (3 << 24) | (4 << 16));
        c.update(0, &air);
        assert_eq!(c.setpoint().position, [Some(1.0), Some(2.0), Some(2.0)]);
        assert_eq!(
            command(&mut c, 0, &set_mode_msg(4.0, 6.0), &air),
            MavResult::MAV_RESULT_ACCEPTED
        );
        assert_eq!(c.mode(), FlightMode::AutoLand);
        assert_eq!(
            command(&mut c, 0, &set_mode_msg(3.0, 0.0), &air),
            MavResult::MAV_RESULT_ACCEPTED
        );
        assert_eq!(c.mode(), FlightMode::Posctl);
        // Real PX4 modes the simulator does not fly.
        assert_eq!(
            command(&mut c, 0, &set_mode_msg(4.0, 5.0), &air),
            MavResult::MAV_RESULT_UNSUPPORTED
        );
        assert_eq!(
            command(&mut c, 0, &set_mode_msg(1.0, 0.0), &air),
            MavResult::MAV_RESULT_UNSUPPORTED
        );
        assert_eq!(c.mode(), FlightMode::Posctl);
        // Wrongly packed: ACKed, nothing happens (as PX4).
        assert_eq!(
            command(&mut c, 0, &set_mode_msg(0.0, 6.0), &air),
            MavResult::MAV_RESULT_ACCEPTED
        );
        let no_flag = cmd(
            MavCmd::MAV_CMD_DO_SET_MODE,
            [0.0, 4.0, 6.0, 0.0, 0.0, 0.0, 0.0],
        );
        assert_eq!(
            command(&mut c, 0, &no_flag, &air),
            MavResult::MAV_RESULT_ACCEPTED
        );
        assert_eq!(c.mode(), FlightMode::Posctl);
        assert_eq!(
            command(&mut c, 0, &set_mode_msg(f32::NAN, 0.0), &air),
            MavResult::MAV_RESULT_DENIED
        );
        // DO_SET_MODE to AUTO.TAKEOFF uses MIS_TAKEOFF_ALT.
        assert_eq!(
            command(&mut c, 0, &set_mode_msg(4.0, 2.0), &air),
            MavResult::MAV_RESULT_ACCEPTED
        );
        assert_eq!(c.mode(), FlightMode::AutoTakeoff);
    }

    #[test]
    #[allow(deprecated)]
    fn set_mode_message_is_acked_as_do_set_mode() {
        let mut c = new();
        let g = ground();
        let m = MavMessage::SET_MODE(SET_MODE_DATA {
            custom_mode: (3 << 24) | (4 << 16),
            target_system: 1,
            base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
        });
        c.handle_message(0, &COMPANION, &m, &g);
        let out = c.take_outgoing();
        assert!(matches!(&out[0], MavMessage::COMMAND_ACK(a)
            if a.command == MavCmd::MAV_CMD_DO_SET_MODE && a.result == MavResult::MAV_RESULT_ACCEPTED));
        assert_eq!(c.mode(), FlightMode::AutoLoiter);
    }

    #[test]
    fn setpoint_conversion_ned_to_enu() {
        let all = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 0.0, 0.5];
        let sp = setpoint_from_local_ned(&match sp_msg(0, MavFrame::MAV_FRAME_LOCAL_NED, all) {
            MavMessage::SET_POSITION_TARGET_LOCAL_NED(d) => d,
            _ => unreachable!(),
        })
        .unwrap();
        assert_eq!(sp.position, [Some(2.0), Some(1.0), Some(-3.0)]);
        assert_eq!(sp.velocity, [Some(5.0), Some(4.0), Some(-6.0)]);
        assert_eq!(sp.acceleration, [Some(8.0), Some(7.0), Some(-9.0)]);
        assert!(
            (sp.yaw.unwrap() - FRAC_PI_2).abs() < 1e-9,
            "NED yaw 0 = north = ENU pi/2"
        );
        assert_eq!(sp.yaw_rate, Some(-0.5));
    }

    fn convert(mask: u16, frame: MavFrame, v: [f32; 11]) -> Option<Setpoint> {
        match sp_msg(mask, frame, v) {
            MavMessage::SET_POSITION_TARGET_LOCAL_NED(d) => setpoint_from_local_ned(&d),
            _ => None,
        }
    }

    #[test]
    fn setpoint_type_mask_frames_and_non_finite() {
        let v = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 0.0, 0.5];
        // Ignore NED x position (bit 1): ENU y is absent.
        let sp = convert(1, MavFrame::MAV_FRAME_LOCAL_NED, v).unwrap();
        assert_eq!(sp.position, [Some(2.0), None, Some(-3.0)]);
        // Velocity only (the usual 0x0DC7) with yaw rate.
        let sp = convert(0x05C7, MavFrame::MAV_FRAME_LOCAL_NED, v).unwrap();
        assert_eq!(sp.position, [None; 3]);
        assert_eq!(sp.velocity, [Some(5.0), Some(4.0), Some(-6.0)]);
        assert_eq!(sp.acceleration, [None; 3]);
        assert_eq!(sp.yaw, None);
        assert_eq!(sp.yaw_rate, Some(-0.5));
        // NaN counts as ignored.
        let mut nan = v;
        nan[2] = f32::NAN;
        nan[9] = f32::INFINITY;
        let sp = convert(0, MavFrame::MAV_FRAME_LOCAL_NED, nan).unwrap();
        assert_eq!(sp.position[2], None);
        assert_eq!(sp.yaw, None);
        // Everything ignored, body frames and force: not a setpoint.
        assert!(convert(0x01FF, MavFrame::MAV_FRAME_LOCAL_NED, v).is_none());
        assert!(convert(0, MavFrame::MAV_FRAME_BODY_FRD, v).is_none());
        assert!(convert(0, MavFrame::MAV_FRAME_LOCAL_OFFSET_NED, v).is_none());
        assert!(convert(0x0200, MavFrame::MAV_FRAME_LOCAL_NED, v).is_none());
    }

    #[test]
    fn rejected_setpoints_do_not_count_as_a_stream() {
        let mut c = new();
        let g = ground();
        let body = sp_msg(0x0DF8, MavFrame::MAV_FRAME_BODY_FRD, [0.0; 11]);
        let mut t = 0;
        while t < 1500 * MS {
            c.handle_message(t, &COMPANION, &body, &g);
            c.update(t, &g);
            t += 50 * MS;
        }
        assert!(!c.offboard_available(t));
    }

    #[test]
    fn enu_from_local_ned_inverts_the_report() {
        let p = enu_from_local_ned(2.0, 1.0, -3.0);
        assert_eq!(p, Vector3::new(1.0, 2.0, 3.0));
    }
}
