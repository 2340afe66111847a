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

/// Faults the simulated autopilot injects, from a scenario's `[faults]` table, so the
/// stack's handling of a refusing or silent autopilot can be tested. None by default.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Faults {
    /// Every arm command is answered DENIED (PX4: arming refused for good).
    pub reject_arming: bool,
    /// The first N arm commands are answered TEMPORARILY_REJECTED (PX4: preflight
    /// checks not passing yet), later ones as usual.
    pub reject_arming_times: u32,
    /// Every switch to OFFBOARD (DO_SET_MODE or SET_MODE) is answered DENIED.
    pub reject_offboard: bool,
    /// From this simulated time, s, the autopilot sends nothing at all (no heartbeat,
    /// telemetry or ACK: a cut TX wire) while it keeps obeying what it receives and
    /// flying its own failsafes.
    pub telemetry_stop_s: Option<f64>,
}

impl Faults {
    /// Checks the values, so a bad scenario fails before it flies.
    pub fn validate(&self) -> Result<(), ParamError> {
        if self.reject_arming && self.reject_arming_times > 0 {
            return Err(ParamError::new(
                "reject_arming_times",
                self.reject_arming_times,
                "must be 0 when reject_arming = true (set one or the other)",
            ));
        }
        if let Some(t) = self.telemetry_stop_s {
            params::in_range("telemetry_stop_s", t, 0.0, 3600.0)?;
        }
        Ok(())
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
    faults: Faults,
    arm_rejections: u32,
    silent: bool,
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
            faults: Faults::default(),
            arm_rejections: 0,
            silent: false,
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

    /// Injects `faults` from now on (they are checked first).
    pub fn set_faults(&mut self, faults: Faults) -> Result<(), ParamError> {
        faults.validate()?;
        self.faults = faults;
        Ok(())
    }

    /// The faults in effect.
    pub fn faults(&self) -> &Faults {
        &self.faults
    }

    fn update_silence(&mut self, now_ns: u64) {
        if let Some(t) = self.faults.telemetry_stop_s
            && !self.silent
            && now_ns >= secs_to_ns(t)
        {
            tracing::warn!(t_s = t, "fault: autopilot telemetry stops");
            self.silent = true;
        }
    }

    /// Takes the MAVLink messages produced since the last call, oldest first (none once
    /// the `telemetry_stop_s` fault has silenced the autopilot).
    pub fn take_outgoing(&mut self) -> Vec<MavMessage> {
        if self.silent {
            // Silenced: what was built is dropped, the buffer kept.
            self.outgoing.clear();
            return Vec::new();
        }
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
        self.update_silence(now_ns);
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
            if self.crashed || self.faults.reject_arming {
                return MavResult::MAV_RESULT_DENIED;
            }
            if self.arm_rejections < self.faults.reject_arming_times {
                self.arm_rejections += 1;
                return MavResult::MAV_RESULT_TEMPORARILY_REJECTED;
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
            ModeRequest::Simulated(FlightMode::Offboard) if self.faults.reject_offboard => {
                MavResult::MAV_RESULT_DENIED
            }
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
        self.update_silence(now_ns);
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
#[path = "commander_test.rs"]
mod tests;
