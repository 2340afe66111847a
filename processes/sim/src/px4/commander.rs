//! A PX4-like commander: what PX4 v1.16 does with the MAVLink messages a companion
//! computer sends, and what it sends back. Each rule is read from PX4's source; the
//! table in docs/px4-conformance.md names the file, the behaviour here and the test.
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
    GLOBAL_POSITION_INT_DATA, HEARTBEAT_DATA, HOME_POSITION_DATA, LOCAL_POSITION_NED_DATA,
    MavAutopilot, MavCmd, MavEstimatorType, MavFrame, MavLandedState, MavMessage, MavModeFlag,
    MavParamType, MavResult, MavState, MavType, MavVtolState, ODOMETRY_DATA, PARAM_VALUE_DATA,
    PositionTargetTypemask, SET_MODE_DATA, SET_POSITION_TARGET_LOCAL_NED_DATA, TIMESYNC_DATA,
};
use nalgebra::{UnitQuaternion, Vector3};
use serde::Deserialize;

use super::frames::{
    enu_to_ned, flu_to_frd, ned_from_frd, ned_to_enu, quaternion_wxyz, yaw_enu_to_ned,
    yaw_ned_to_enu,
};
use crate::autopilot::{EstimatedState, Setpoint};
use crate::params::{self, ParamError};

pub use px4_protocol::command::FORCE_DISARM_MAGIC;

/// Mean Earth radius PX4's map projection uses, m.
const EARTH_RADIUS_M: f64 = 6_371_000.0;

/// Commands PX4 answers even when sent to every system (target_system 0):
/// REQUEST_PROTOCOL_VERSION and REQUEST_AUTOPILOT_CAPABILITIES
/// (mavlink_receiver.cpp, `evaluate_target_ok`); both deprecated in MAVLink,
/// still honoured by PX4.
#[allow(deprecated)]
const BROADCAST_COMMANDS: [MavCmd; 2] = [
    MavCmd::MAV_CMD_REQUEST_PROTOCOL_VERSION,
    MavCmd::MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
];

/// Message ids of the telemetry streams the commander can send.
pub mod msg_id {
    /// HEARTBEAT.
    pub const HEARTBEAT: u32 = 0;
    /// ATTITUDE_QUATERNION.
    pub const ATTITUDE_QUATERNION: u32 = 31;
    /// LOCAL_POSITION_NED.
    pub const LOCAL_POSITION_NED: u32 = 32;
    /// GLOBAL_POSITION_INT.
    pub const GLOBAL_POSITION_INT: u32 = 33;
    /// HOME_POSITION.
    pub const HOME_POSITION: u32 = 242;
    /// EXTENDED_SYS_STATE.
    pub const EXTENDED_SYS_STATE: u32 = 245;
    /// ODOMETRY.
    pub const ODOMETRY: u32 = 331;
}

/// PX4 parameters the commander uses, under their PX4 names (TOML accepts
/// `COM_OF_LOSS_T = 1.0`), so an airframe's `[px4]` table reads like a PX4
/// parameter file. Defaults are PX4 v1.16's.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default, rename_all = "SCREAMING_SNAKE_CASE")]
pub struct Px4Params {
    /// Offboard setpoint timeout before the failsafe, s (PX4 default 1).
    pub com_of_loss_t: f64,
    /// Offboard-loss action: 0 = Position (PX4 default), 4 = Land, 5 = Hold.
    pub com_obl_rc_act: u8,
    /// Takeoff height above the current altitude when NAV_TAKEOFF gives no
    /// altitude (NaN), m (PX4 default 2.5).
    pub mis_takeoff_alt: f64,
    /// Takeoff climb speed, m/s (PX4 default 1.5).
    pub mpc_tko_speed: f64,
    /// Landing descent speed, m/s (PX4 default 0.7).
    pub mpc_land_speed: f64,
    /// Altitude acceptance radius of a multicopter takeoff, m (PX4 default 0.8).
    pub nav_mc_alt_rad: f64,
    /// Disarm this long after landing is detected, s (PX4 default 2; <= 0 disables).
    pub com_disarm_land: f64,
    /// Disarm this long (plus COM_SPOOLUP_TIME) after arming if the vehicle never
    /// took off, s (PX4 default 10; <= 0 disables).
    pub com_disarm_prflt: f64,
    /// Motor spool-up time after arming, s (PX4 default 1).
    pub com_spoolup_time: f64,
    /// Altitude of the local origin (the take-off point's ground) above mean sea
    /// level, m (PX4 SIH default 489.4; `PX4_HOME_ALT` in SITL).
    pub sih_loc_h0: f64,
    /// Latitude of the local origin, deg (PX4 SIH default 47.397742).
    pub sih_loc_lat0: f64,
    /// Longitude of the local origin, deg (PX4 SIH default 8.545594).
    pub sih_loc_lon0: f64,
}

impl Default for Px4Params {
    /// PX4 v1.16 defaults (commander_params.c, mission_params.c, sih_params.c).
    fn default() -> Self {
        Self {
            com_of_loss_t: 1.0,
            com_obl_rc_act: 0,
            mis_takeoff_alt: 2.5,
            mpc_tko_speed: 1.5,
            mpc_land_speed: 0.7,
            nav_mc_alt_rad: 0.8,
            com_disarm_land: 2.0,
            com_disarm_prflt: 10.0,
            com_spoolup_time: 1.0,
            sih_loc_h0: 489.4,
            sih_loc_lat0: 47.397742,
            sih_loc_lon0: 8.545594,
        }
    }
}

impl Px4Params {
    /// Checks every parameter, so a bad airframe fails before it flies.
    pub fn validate(&self) -> Result<(), ParamError> {
        params::in_range("COM_OF_LOSS_T", self.com_of_loss_t, 1e-3, 60.0)?;
        if OffboardLossAction::from_param(self.com_obl_rc_act).is_none() {
            return Err(ParamError::new(
                "COM_OBL_RC_ACT",
                self.com_obl_rc_act,
                "must be 0 (Position), 4 (Land) or 5 (Hold); PX4's other actions are not simulated",
            ));
        }
        params::in_range("MIS_TAKEOFF_ALT", self.mis_takeoff_alt, 0.1, 1000.0)?;
        params::positive("MPC_TKO_SPEED", self.mpc_tko_speed)?;
        params::positive("MPC_LAND_SPEED", self.mpc_land_speed)?;
        params::in_range("NAV_MC_ALT_RAD", self.nav_mc_alt_rad, 0.05, 10.0)?;
        params::finite("COM_DISARM_LAND", self.com_disarm_land)?;
        params::finite("COM_DISARM_PRFLT", self.com_disarm_prflt)?;
        params::in_range("COM_SPOOLUP_TIME", self.com_spoolup_time, 0.0, 30.0)?;
        params::in_range("SIH_LOC_H0", self.sih_loc_h0, -420.0, 8848.0)?;
        params::in_range("SIH_LOC_LAT0", self.sih_loc_lat0, -85.0, 85.0)?;
        params::in_range("SIH_LOC_LON0", self.sih_loc_lon0, -180.0, 180.0)?;
        Ok(())
    }

    fn loss_ns(&self) -> u64 {
        secs_to_ns(self.com_of_loss_t)
    }

    /// The parameters as PX4 lists them over MAVLink (PARAM_VALUE): name, value, type.
    /// EKF2_EV_CTRL and EKF2_HGT_REF say what the simulated estimator always does
    /// (fuse the external vision's position, velocity and yaw, height from vision), so
    /// that a preflight check reads what a real PX4 must be set to.
    pub fn table(&self) -> Vec<(&'static str, f64, MavParamType)> {
        use MavParamType::{MAV_PARAM_TYPE_INT32 as INT, MAV_PARAM_TYPE_REAL32 as REAL};
        vec![
            ("COM_DISARM_LAND", self.com_disarm_land, REAL),
            ("COM_DISARM_PRFLT", self.com_disarm_prflt, REAL),
            ("COM_OBL_RC_ACT", f64::from(self.com_obl_rc_act), INT),
            ("COM_OF_LOSS_T", self.com_of_loss_t, REAL),
            ("COM_SPOOLUP_TIME", self.com_spoolup_time, REAL),
            ("EKF2_EV_CTRL", 15.0, INT),
            ("EKF2_HGT_REF", 3.0, INT),
            ("MIS_TAKEOFF_ALT", self.mis_takeoff_alt, REAL),
            ("MPC_LAND_SPEED", self.mpc_land_speed, REAL),
            ("MPC_TKO_SPEED", self.mpc_tko_speed, REAL),
            ("NAV_MC_ALT_RAD", self.nav_mc_alt_rad, REAL),
        ]
    }
}

/// A PARAM_VALUE as PX4 sends it: INT32 values bytewise in the float field
/// (MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE).
fn param_value(
    index: usize,
    count: usize,
    name: &str,
    value: f64,
    typ: MavParamType,
) -> MavMessage {
    let param_value = match typ {
        MavParamType::MAV_PARAM_TYPE_INT32 => f32::from_ne_bytes((value as i32).to_ne_bytes()),
        _ => value as f32,
    };
    MavMessage::PARAM_VALUE(PARAM_VALUE_DATA {
        param_value,
        param_count: u16::try_from(count).unwrap_or(u16::MAX),
        param_index: u16::try_from(index).unwrap_or(u16::MAX),
        param_id: name.into(),
        param_type: typ,
    })
}

/// What PX4 does when the offboard setpoints stop (COM_OBL_RC_ACT).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum OffboardLossAction {
    Position,
    Land,
    Hold,
}

impl OffboardLossAction {
    fn from_param(value: u8) -> Option<Self> {
        match value {
            0 => Some(Self::Position),
            4 => Some(Self::Land),
            5 => Some(Self::Hold),
            _ => None,
        }
    }

    fn mode(self) -> FlightMode {
        match self {
            Self::Position => FlightMode::Posctl,
            Self::Land => FlightMode::AutoLand,
            Self::Hold => FlightMode::AutoLoiter,
        }
    }
}

/// Faults the simulated autopilot injects, from a scenario's `[faults]` table, so the
/// stack's handling of a refusing or silent autopilot can be tested. None by default.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Faults {
    /// Every arm command is refused, answered TEMPORARILY_REJECTED as PX4 answers
    /// every arming refusal (a health check that never passes).
    pub reject_arming: bool,
    /// The first N arm commands are answered TEMPORARILY_REJECTED (PX4: preflight
    /// checks not passing yet), later ones as usual.
    pub reject_arming_times: u32,
    /// Every switch to OFFBOARD (DO_SET_MODE or SET_MODE) is refused,
    /// TEMPORARILY_REJECTED (PX4: the offboard signal is not accepted).
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
    /// POSCTL: without RC sticks, holds position. There is no RC here, so PX4
    /// refuses to arm in it.
    Posctl,
    /// AUTO.TAKEOFF: climbs to the takeoff altitude, then AUTO.LOITER.
    AutoTakeoff,
    /// AUTO.LOITER (Hold): holds position; the mode PX4 v1.16 boots into.
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

    /// Modes PX4 will not arm in and does not return to after a disarm
    /// (mode_requirements.cpp: LAND, RTL, DESCEND, ...).
    const fn prevents_arming(self) -> bool {
        matches!(self, Self::AutoLand)
    }
}

/// What a requested (main, sub) mode means to the simulator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModeRequest {
    /// A mode the simulator flies.
    Simulated(FlightMode),
    /// A real PX4 mode the simulator does not fly (MANUAL, MISSION, RTL, ...).
    NotSimulated,
    /// An AUTO sub mode PX4 does not have: "Unsupported auto mode",
    /// TEMPORARILY_REJECTED.
    UnsupportedAuto,
    /// Not a PX4 main mode: PX4 ACKs it and changes nothing.
    Unknown,
}

impl ModeRequest {
    /// Decodes PX4's main/sub mode numbers as Commander::handle_command does.
    pub fn from_main_sub(main: u8, sub: u8) -> Self {
        match (main, sub) {
            (3, 2) => Self::NotSimulated, // POSCTL slow
            (3, _) => Self::Simulated(FlightMode::Posctl),
            (6, _) => Self::Simulated(FlightMode::Offboard),
            (MAIN_AUTO, 2) => Self::Simulated(FlightMode::AutoTakeoff),
            (MAIN_AUTO, 3) => Self::Simulated(FlightMode::AutoLoiter),
            (MAIN_AUTO, 6) => Self::Simulated(FlightMode::AutoLand),
            (MAIN_AUTO, 0 | 4 | 5 | 8 | 9 | 11..=18) | (1 | 2 | 5 | 7, _) => Self::NotSimulated,
            (MAIN_AUTO, _) => Self::UnsupportedAuto,
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

/// Why the commander changed mode or disarmed on its own, for logs and tests.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CommanderEvent {
    /// The offboard setpoint stream stopped for COM_OF_LOSS_T; the mode is
    /// now the COM_OBL_RC_ACT one.
    OffboardLost(FlightMode),
    /// Setpoints came back while the offboard-loss action ran: OFFBOARD again
    /// (PX4 clears the failsafe when its condition clears).
    OffboardRegained,
    /// NAV_TAKEOFF asked for an altitude below the current one: PX4's navigator
    /// clamps it ("Already higher than takeoff altitude") and does not climb.
    AlreadyHigher,
    /// Disarmed COM_DISARM_LAND after landing.
    AutoDisarmLanded,
    /// Disarmed COM_SPOOLUP_TIME + COM_DISARM_PRFLT after arming without taking off.
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
    const fn new(id: u32, default_interval_ns: Option<u64>) -> Self {
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

/// PX4's home: where and at which altitude the vehicle was armed (or booted).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Home {
    /// Position in the local frame, ENU, m.
    pub position: Vector3<f64>,
    /// Heading, ENU, rad.
    pub yaw: f64,
    /// Altitude above mean sea level, m.
    pub alt_amsl: f64,
}

/// The autopilot's boot clock against simulated time. A real autopilot's clock runs
/// with the world's; the simulator's time pauses when the machine falls behind (it then
/// skips ahead) and runs `speed` times as fast as the wall clock, so the clock the
/// telemetry carries is kept on the wall clock that stamps the camera's frames:
/// `(sim + ahead) / rate`. px4-link maps that clock onto its own, as on a vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BootClock {
    /// Simulated time skipped so far, ns.
    pub ahead_ns: u64,
    /// Simulated seconds per boot-clock second.
    pub rate: f64,
}

impl Default for BootClock {
    fn default() -> Self {
        Self {
            ahead_ns: 0,
            rate: 1.0,
        }
    }
}

impl BootClock {
    /// The boot clock at simulated time `sim_ns`.
    pub fn at(&self, sim_ns: u64) -> u64 {
        let rate = if self.rate.is_finite() && self.rate > 0.0 {
            self.rate
        } else {
            1.0
        };
        (sim_ns.saturating_add(self.ahead_ns) as f64 / rate) as u64
    }
}

/// The autopilot's own clock against true time (scenario `[autopilot_clock]`): a
/// crystal that drifts, or a PX4 SITL whose simulator runs behind or ahead of real time
/// (SIH's loop sleeps its interval minus its compute time and runs about 1 % slow on a
/// loaded machine), and jumps (a reboot, a simulator reset). What the telemetry's
/// `time_boot_ms` says; the vehicle flies in true time either way.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AutopilotClock {
    /// Autopilot seconds per true second (1: keeps time; 0.98: 2 % slow).
    pub rate: f64,
    /// The autopilot's boot clock when the simulation starts, s (it booted before).
    pub boot_offset_s: f64,
    /// From this true time, s, the clock reads `jump_s` more (negative: back, as a
    /// restarted autopilot's clock does).
    pub jump_at_s: Option<f64>,
    /// The jump, s.
    pub jump_s: f64,
}

impl Default for AutopilotClock {
    /// A clock that keeps time, booted with the simulation, never jumping.
    fn default() -> Self {
        Self {
            rate: 1.0,
            boot_offset_s: 0.0,
            jump_at_s: None,
            jump_s: 0.0,
        }
    }
}

impl AutopilotClock {
    /// Checks the values, so a bad scenario fails before it flies.
    pub fn validate(&self) -> Result<(), ParamError> {
        params::in_range("autopilot_clock.rate", self.rate, 0.1, 10.0)?;
        params::in_range(
            "autopilot_clock.boot_offset_s",
            self.boot_offset_s,
            0.0,
            1e6,
        )?;
        if let Some(t) = self.jump_at_s {
            params::in_range("autopilot_clock.jump_at_s", t, 0.0, 86_400.0)?;
        }
        params::in_range("autopilot_clock.jump_s", self.jump_s, -1e6, 1e6)?;
        Ok(())
    }

    /// The boot clock, ns, at `true_ns` of true time (0 is the simulation's start).
    pub fn at(&self, true_ns: u64) -> u64 {
        // Exact for a clock that keeps time: lockstep flights stamp as they always did.
        let scaled = if self.rate == 1.0 {
            true_ns
        } else {
            (true_ns as f64 * self.rate) as u64
        };
        let jump = match self.jump_at_s {
            Some(at) if true_ns as f64 >= at * 1e9 => (self.jump_s * 1e9) as i64,
            _ => 0,
        };
        let offset = (self.boot_offset_s * 1e9) as i64;
        scaled.saturating_add_signed(offset.saturating_add(jump))
    }
}

/// The PX4-like commander (see the module docs).
#[derive(Debug, Clone)]
pub struct Commander {
    params: Px4Params,
    /// The mode the user (companion) asked for last: PX4's user intention.
    intended: FlightMode,
    /// The mode restored on disarm: the last one asked for that does not prevent
    /// arming (UserModeIntention::onDisarm).
    after_disarm: FlightMode,
    /// The offboard-loss action while it runs (it overrides `intended`).
    failsafe: Option<FlightMode>,
    armed: bool,
    crashed: bool,
    armed_at_ns: u64,
    has_flown: bool,
    /// PX4's `vehicle_land_detected.landed` as last seen.
    landed: bool,
    /// Since when landed has held, for COM_DISARM_LAND.
    landed_since_ns: Option<u64>,
    last_setpoint_ns: Option<u64>,
    offboard_setpoint: Setpoint,
    hold_position: Vector3<f64>,
    hold_yaw: f64,
    /// param7 of the last NAV_TAKEOFF (an AMSL altitude, or NaN), used when the
    /// takeoff starts; None when AUTO.TAKEOFF was entered without the command.
    takeoff_param7: Option<f32>,
    takeoff: Option<Takeoff>,
    home: Option<Home>,
    setpoint: Setpoint,
    streams: [Stream; 7],
    outgoing: Vec<MavMessage>,
    events: Vec<CommanderEvent>,
    faults: Faults,
    arm_rejections: u32,
    silent: bool,
    boot_clock: BootClock,
    clock: AutopilotClock,
}

/// PX4's default rates on an onboard link: HEARTBEAT 1 Hz, ATTITUDE_QUATERNION
/// 50 Hz, LOCAL_POSITION_NED 30 Hz, EXTENDED_SYS_STATE 5 Hz, HOME_POSITION
/// 0.5 Hz; GLOBAL_POSITION_INT 5 Hz (PX4's normal-link rate: the stack reads it
/// only for the take-off altitude); ODOMETRY off until requested.
fn default_streams() -> [Stream; 7] {
    const fn every(hz_milli: u64) -> Option<u64> {
        Some(1_000_000_000_000 / hz_milli)
    }
    [
        Stream::new(msg_id::HEARTBEAT, every(1_000)),
        Stream::new(msg_id::ATTITUDE_QUATERNION, every(50_000)),
        Stream::new(msg_id::LOCAL_POSITION_NED, every(30_000)),
        Stream::new(msg_id::GLOBAL_POSITION_INT, every(5_000)),
        Stream::new(msg_id::HOME_POSITION, every(500)),
        Stream::new(msg_id::EXTENDED_SYS_STATE, every(5_000)),
        Stream::new(msg_id::ODOMETRY, None),
    ]
}

impl Commander {
    /// A disarmed commander in AUTO.LOITER (PX4 v1.16's boot mode), on the ground,
    /// with PX4's stream rates (see [`default_streams`]).
    pub fn new(params: Px4Params) -> Result<Self, ParamError> {
        params.validate()?;
        Ok(Self {
            params,
            intended: FlightMode::AutoLoiter,
            after_disarm: FlightMode::AutoLoiter,
            failsafe: None,
            armed: false,
            crashed: false,
            armed_at_ns: 0,
            has_flown: false,
            landed: true,
            landed_since_ns: Some(0),
            last_setpoint_ns: None,
            offboard_setpoint: Setpoint::default(),
            hold_position: Vector3::zeros(),
            hold_yaw: 0.0,
            takeoff_param7: None,
            takeoff: None,
            home: None,
            setpoint: Setpoint::default(),
            streams: default_streams(),
            outgoing: Vec::new(),
            events: Vec::new(),
            faults: Faults::default(),
            arm_rejections: 0,
            silent: false,
            boot_clock: BootClock::default(),
            clock: AutopilotClock::default(),
        })
    }

    /// How the boot clock the telemetry carries follows simulated time (see [`BootClock`]).
    pub fn set_boot_clock(&mut self, clock: BootClock) {
        self.boot_clock = clock;
    }

    /// How the autopilot's own clock runs against true time (see [`AutopilotClock`]).
    pub fn set_clock(&mut self, clock: AutopilotClock) -> Result<(), ParamError> {
        clock.validate()?;
        self.clock = clock;
        Ok(())
    }

    /// The boot clock the telemetry carries at simulated time `now_ns`, ns.
    pub fn boot_ns(&self, now_ns: u64) -> u64 {
        self.clock.at(self.boot_clock.at(now_ns))
    }

    /// The parameters in use.
    pub fn params(&self) -> &Px4Params {
        &self.params
    }

    /// The current flight mode (PX4's nav_state), as HEARTBEAT reports it: the
    /// offboard-loss action while it runs, else the mode asked for.
    pub fn mode(&self) -> FlightMode {
        self.failsafe.unwrap_or(self.intended)
    }

    /// Whether the motors should be armed (apply to the world every step).
    pub fn armed(&self) -> bool {
        self.armed
    }

    /// What the autopilot should fly now, world ENU (apply every step).
    pub fn setpoint(&self) -> Setpoint {
        self.setpoint
    }

    /// Home, once set (at the first update, then at each arming).
    pub fn home(&self) -> Option<Home> {
        self.home
    }

    /// The altitude above mean sea level of a local (ENU) height, m.
    pub fn amsl_of(&self, z: f64) -> f64 {
        self.params.sih_loc_h0 + z
    }

    /// PX4's landed state now: TAKEOFF and LANDING only in the AUTO modes, as
    /// EXTENDED_SYS_STATE reports them.
    pub fn landed_state(&self) -> LandedState {
        if !self.armed || self.landed {
            LandedState::OnGround
        } else if self.mode() == FlightMode::AutoTakeoff {
            LandedState::Takeoff
        } else if self.mode() == FlightMode::AutoLand {
            LandedState::Landing
        } else {
            LandedState::InAir
        }
    }

    /// Whether OFFBOARD can run now (offboardCheck.cpp): a setpoint younger than
    /// COM_OF_LOSS_T has arrived. No minimum stream length.
    pub fn offboard_available(&self, now_ns: u64) -> bool {
        self.last_setpoint_ns
            .is_some_and(|last| now_ns.saturating_sub(last) < self.params.loss_ns())
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

    /// True once the `telemetry_stop_s` fault has silenced the autopilot.
    pub fn is_silent(&self) -> bool {
        self.silent
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

    /// Handles one message from the companion. Commands reach the commander only
    /// when sent to system 1 and component 1 or 0 (target_system 0 only for the
    /// two broadcast requests), as PX4's receiver filters them; setpoints and
    /// SET_MODE also for system 0.
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
            MavMessage::COMMAND_LONG(cmd) if command_addressed_to_us(cmd) => {
                let Some(result) = self.handle_command(now_ns, cmd, vehicle) else {
                    return;
                };
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
            MavMessage::PARAM_REQUEST_READ(r)
                if addressed_to_us(r.target_system, r.target_component) =>
            {
                let table = self.params.table();
                let wanted = r.param_id.to_str().unwrap_or_default();
                let found = match usize::try_from(r.param_index) {
                    Ok(k) => table.get(k).map(|e| (k, e)),
                    Err(_) => table.iter().enumerate().find(|(_, e)| e.0 == wanted),
                };
                // PX4 answers an unknown name with nothing (a PARAM_ERROR in newer
                // versions): the asker times out.
                if let Some((k, (name, value, typ))) = found {
                    self.outgoing
                        .push(param_value(k, table.len(), name, *value, *typ));
                }
            }
            MavMessage::PARAM_REQUEST_LIST(r)
                if addressed_to_us(r.target_system, r.target_component) =>
            {
                let table = self.params.table();
                for (k, (name, value, typ)) in table.iter().enumerate() {
                    self.outgoing
                        .push(param_value(k, table.len(), name, *value, *typ));
                }
            }
            // A TIMESYNC request (tc1 0): answered with the autopilot's boot clock, ns.
            MavMessage::TIMESYNC(t) if t.tc1 == 0 => {
                self.outgoing.push(MavMessage::TIMESYNC(TIMESYNC_DATA {
                    tc1: i64::try_from(self.boot_ns(now_ns)).unwrap_or(i64::MAX),
                    ts1: t.ts1,
                    target_system: u8::try_from(sender.system_id).unwrap_or(0),
                    target_component: sender.component_id,
                }));
            }
            MavMessage::SET_POSITION_TARGET_LOCAL_NED(sp) => {
                if addressed_to_us(sp.target_system, sp.target_component)
                    && let Some(setpoint) = setpoint_from_local_ned(sp)
                {
                    self.last_setpoint_ns = Some(now_ns);
                    self.offboard_setpoint = setpoint;
                    if self.mode() == FlightMode::Offboard {
                        self.setpoint = setpoint;
                    }
                }
            }
            _ => {}
        }
    }

    /// The result to ACK, or None where PX4 sends no ACK at all.
    fn handle_command(
        &mut self,
        now_ns: u64,
        cmd: &COMMAND_LONG_DATA,
        vehicle: &VehicleStatus,
    ) -> Option<MavResult> {
        Some(match cmd.command {
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM => return self.arm_disarm(now_ns, cmd, vehicle),
            MavCmd::MAV_CMD_NAV_TAKEOFF => {
                // Commander ACKs the mode change; the navigator reads param7 (AMSL)
                // when the takeoff starts, and never ACKs.
                let result = self.change_mode(now_ns, FlightMode::AutoTakeoff, false, vehicle);
                if result == MavResult::MAV_RESULT_ACCEPTED {
                    self.takeoff_param7 = Some(cmd.param7);
                    self.takeoff = None;
                }
                result
            }
            // Forced: accepted in every state, even disarmed (arming is then blocked).
            MavCmd::MAV_CMD_NAV_LAND => {
                self.change_mode(now_ns, FlightMode::AutoLand, true, vehicle)
            }
            MavCmd::MAV_CMD_DO_SET_MODE => {
                let base = cmd.param1.round() as i64 as u32;
                if base & MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED.bits() as u32 == 0 {
                    // Only custom modes are simulated; the rest changes nothing here.
                    return Some(MavResult::MAV_RESULT_ACCEPTED);
                }
                let (main, sub) = (cmd.param2.round(), cmd.param3.round());
                if !(0.0..=255.0).contains(&main) || !(0.0..=255.0).contains(&sub) {
                    return Some(MavResult::MAV_RESULT_ACCEPTED);
                }
                self.set_mode(now_ns, main as u8, sub as u8, vehicle)
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
            // Commander's `default:` branch: every command it does not handle.
            _ => MavResult::MAV_RESULT_UNSUPPORTED,
        })
    }

    /// Commander::handle_command's ARM_DISARM case: param1 rounded (1 arm, 0
    /// disarm, anything else: no ACK at all); every refusal TEMPORARILY_REJECTED.
    fn arm_disarm(
        &mut self,
        now_ns: u64,
        cmd: &COMMAND_LONG_DATA,
        vehicle: &VehicleStatus,
    ) -> Option<MavResult> {
        let arm = match cmd.param1.round() {
            1.0 => true,
            0.0 => false,
            _ => return None,
        };
        let rejected = Some(MavResult::MAV_RESULT_TEMPORARILY_REJECTED);
        if arm == self.armed {
            return Some(MavResult::MAV_RESULT_ACCEPTED);
        }
        if !arm {
            let on_ground = self.landed || vehicle.estimate.landed;
            if !on_ground && cmd.param2 != FORCE_DISARM_MAGIC {
                return rejected; // "Disarming denied: not landed"
            }
            self.disarm();
            return Some(MavResult::MAV_RESULT_ACCEPTED);
        }
        if self.crashed || self.faults.reject_arming {
            return rejected;
        }
        if self.arm_rejections < self.faults.reject_arming_times {
            self.arm_rejections += 1;
            return rejected;
        }
        // "Arming denied: Resolve system health failures first": the mode's
        // requirements (modeCheck.cpp) - not in LAND, no RC for POSCTL here, a
        // fresh offboard signal for OFFBOARD.
        let mode = self.mode();
        if mode.prevents_arming()
            || mode == FlightMode::Posctl
            || (mode == FlightMode::Offboard && !self.offboard_available(now_ns))
        {
            return rejected;
        }
        self.armed = true;
        self.armed_at_ns = now_ns;
        self.has_flown = false;
        self.set_home(vehicle);
        // Re-enter the mode so holds and takeoffs start from here.
        self.enter_mode(mode, vehicle);
        Some(MavResult::MAV_RESULT_ACCEPTED)
    }

    fn disarm(&mut self) {
        self.armed = false;
        self.failsafe = None;
        self.takeoff = None;
        // UserModeIntention::onDisarm.
        self.intended = self.after_disarm;
    }

    fn set_home(&mut self, vehicle: &VehicleStatus) {
        let est = &vehicle.estimate;
        self.home = Some(Home {
            position: est.position,
            yaw: yaw_of(est),
            alt_amsl: self.amsl_of(est.position.z),
        });
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
            ModeRequest::UnsupportedAuto => MavResult::MAV_RESULT_TEMPORARILY_REJECTED,
            ModeRequest::Simulated(FlightMode::Offboard) if self.faults.reject_offboard => {
                MavResult::MAV_RESULT_TEMPORARILY_REJECTED
            }
            ModeRequest::Simulated(mode) => {
                let result = self.change_mode(now_ns, mode, mode == FlightMode::AutoLand, vehicle);
                if result == MavResult::MAV_RESULT_ACCEPTED && mode == FlightMode::AutoTakeoff {
                    // No NAV_TAKEOFF: MIS_TAKEOFF_ALT above the current altitude.
                    self.takeoff_param7 = None;
                }
                result
            }
        }
    }

    /// UserModeIntention::change: while armed a mode whose requirements are not
    /// met is TEMPORARILY_REJECTED (unless `forced`); disarmed, every change is
    /// accepted. An accepted change ends a failsafe (the user took over).
    fn change_mode(
        &mut self,
        now_ns: u64,
        mode: FlightMode,
        forced: bool,
        vehicle: &VehicleStatus,
    ) -> MavResult {
        if self.armed && !forced && !self.can_run(mode, now_ns) {
            return MavResult::MAV_RESULT_TEMPORARILY_REJECTED;
        }
        if mode != self.mode() {
            self.enter_mode(mode, vehicle);
        }
        self.intended = mode;
        self.failsafe = None;
        if !mode.prevents_arming() {
            self.after_disarm = mode;
        }
        MavResult::MAV_RESULT_ACCEPTED
    }

    /// Mode requirements (mode_requirements.cpp) the simulator can miss: the
    /// offboard signal. Position and attitude are always valid here.
    fn can_run(&self, mode: FlightMode, now_ns: u64) -> bool {
        mode != FlightMode::Offboard || self.offboard_available(now_ns)
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

    fn enter_mode(&mut self, mode: FlightMode, vehicle: &VehicleStatus) {
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
        if mode != self.mode() {
            tracing::debug!(from = ?self.mode(), to = ?mode, "mode change");
        }
    }

    /// Runs the commander for this step: failsafes, mode logic, auto-disarm,
    /// telemetry. Call once per physics step, before applying [`Self::armed`]
    /// and [`Self::setpoint`] to the world.
    pub fn update(&mut self, now_ns: u64, vehicle: &VehicleStatus) {
        self.crashed |= vehicle.crashed;
        self.update_silence(now_ns);
        if self.home.is_none() {
            // Home is set as soon as the position is valid (HomePosition.cpp).
            self.set_home(vehicle);
        }
        if self.crashed && self.armed {
            self.disarm();
            self.events.push(CommanderEvent::DisarmCrash);
        }
        self.detect_landing(now_ns, vehicle);
        self.offboard_failsafe(now_ns, vehicle);
        self.fly_mode(now_ns, vehicle);
        self.auto_disarm(now_ns);
        self.send_telemetry(now_ns, vehicle);
    }

    /// The landed state is the land detector's (the autopilot's, in the estimate),
    /// taken as it comes: its hysteresis is the detector's own.
    fn detect_landing(&mut self, now_ns: u64, vehicle: &VehicleStatus) {
        if vehicle.estimate.landed {
            self.landed_since_ns.get_or_insert(now_ns);
            self.landed = true;
        } else {
            self.landed_since_ns = None;
            if self.landed && self.armed {
                // Takeoff detected: PX4 sets home again (landDetectorUpdate).
                self.has_flown = true;
                self.set_home(vehicle);
            }
            self.landed = false;
            if self.armed {
                self.has_flown = true;
            }
        }
    }

    /// Failsafe::checkModeFallback: with OFFBOARD asked for and armed, a setpoint
    /// older than COM_OF_LOSS_T switches to the COM_OBL_RC_ACT mode at once (no
    /// COM_FAIL_ACT_T hold for this failsafe); fresh setpoints switch back.
    fn offboard_failsafe(&mut self, now_ns: u64, vehicle: &VehicleStatus) {
        if self.intended != FlightMode::Offboard || !self.armed {
            self.failsafe = None;
            return;
        }
        let lost = !self.offboard_available(now_ns);
        match (lost, self.failsafe) {
            (true, None) => {
                let action = OffboardLossAction::from_param(self.params.com_obl_rc_act)
                    .unwrap_or(OffboardLossAction::Position);
                let mode = action.mode();
                tracing::warn!(?mode, "offboard setpoints lost");
                self.enter_mode(mode, vehicle);
                self.failsafe = Some(mode);
                self.events.push(CommanderEvent::OffboardLost(mode));
            }
            (false, Some(_)) => {
                self.failsafe = None;
                self.enter_mode(FlightMode::Offboard, vehicle);
                self.events.push(CommanderEvent::OffboardRegained);
            }
            _ => {}
        }
    }

    fn fly_mode(&mut self, now_ns: u64, vehicle: &VehicleStatus) {
        let est = &vehicle.estimate;
        if !self.armed {
            self.setpoint = Setpoint::position(est.position, yaw_of(est));
            return;
        }
        let spooling = self.landed
            && now_ns.saturating_sub(self.armed_at_ns) < secs_to_ns(self.params.com_spoolup_time);
        if spooling {
            // The motors spool up for COM_SPOOLUP_TIME after arming: no take-off yet,
            // in any mode.
            self.setpoint = self.ground_idle(est);
            return;
        }
        self.setpoint = match self.mode() {
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
            FlightMode::AutoTakeoff => self.fly_takeoff(now_ns, est),
        };
        if self.landed && !wants_takeoff(&self.setpoint, est) {
            // Landed, PX4's take-off state machine keeps the motors at idle until a
            // setpoint asks to climb (Takeoff.cpp, FlightTask::_checkTakeoff).
            self.setpoint = self.ground_idle(est);
        }
    }

    /// Motors at idle on the ground: hold xy, press down as AUTO.LAND does (no
    /// setpoint asking to climb, so the autopilot keeps its thrust at zero and its
    /// land detector at "landed").
    fn ground_idle(&self, est: &EstimatedState) -> Setpoint {
        Setpoint {
            position: [Some(est.position.x), Some(est.position.y), None],
            velocity: [None, None, Some(-self.params.mpc_land_speed)],
            yaw: Some(yaw_of(est)),
            ..Setpoint::default()
        }
    }

    /// AUTO.TAKEOFF (takeoff.cpp): the target is NAV_TAKEOFF's param7 read as
    /// AMSL, or the current altitude plus MIS_TAKEOFF_ALT when it is NaN or was
    /// not given; a target below the current altitude is clamped to it ("Already
    /// higher than takeoff altitude"), so a vehicle on the ground stays there.
    /// Reached within NAV_MC_ALT_RAD (halved for a low takeoff), then AUTO.LOITER.
    fn fly_takeoff(&mut self, now_ns: u64, est: &EstimatedState) -> Setpoint {
        let t = match self.takeoff {
            Some(t) => t,
            None => {
                let current = self.amsl_of(est.position.z);
                let mut target = match self.takeoff_param7 {
                    Some(p) if p.is_finite() => f64::from(p),
                    _ => current + self.params.mis_takeoff_alt,
                };
                if target < current {
                    tracing::warn!(
                        target_amsl_m = target,
                        current_amsl_m = current,
                        "Already higher than takeoff altitude"
                    );
                    self.events.push(CommanderEvent::AlreadyHigher);
                    target = current;
                }
                let t = Takeoff {
                    start_ns: now_ns,
                    start_z: est.position.z,
                    target_z: target - self.params.sih_loc_h0,
                    xy: [est.position.x, est.position.y],
                    yaw: yaw_of(est),
                };
                self.takeoff = Some(t);
                t
            }
        };
        let home_z = self.home.map_or(0.0, |h| h.position.z);
        let mut radius = self.params.nav_mc_alt_rad;
        let above_home = t.target_z - home_z;
        if above_home > 0.0 && above_home < radius {
            radius = above_home / 2.0;
        }
        if !self.landed && est.position.z > t.target_z - radius {
            // Checked in Commander::checkForMissionUpdate: on to Hold.
            self.intended = FlightMode::AutoLoiter;
            self.after_disarm = FlightMode::AutoLoiter;
            self.takeoff = None;
            self.hold_position = Vector3::new(t.xy[0], t.xy[1], t.target_z.max(est.position.z));
            self.hold_yaw = t.yaw;
            return Setpoint::position(self.hold_position, self.hold_yaw);
        }
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

    /// Commander::handleAutoDisarm: COM_DISARM_LAND after landing if the vehicle
    /// took off since arming, else COM_SPOOLUP_TIME + COM_DISARM_PRFLT after
    /// arming; a value <= 0 disables each.
    fn auto_disarm(&mut self, now_ns: u64) {
        if !self.armed || !self.landed {
            return;
        }
        if self.has_flown {
            if self.params.com_disarm_land > 0.0
                && let Some(since) = self.landed_since_ns
            {
                let after = secs_to_ns(self.params.com_disarm_land);
                if now_ns.saturating_sub(since) >= after {
                    self.disarm();
                    self.events.push(CommanderEvent::AutoDisarmLanded);
                }
            }
        } else if self.params.com_disarm_prflt > 0.0 {
            let after = secs_to_ns(self.params.com_spoolup_time + self.params.com_disarm_prflt);
            if now_ns.saturating_sub(self.armed_at_ns) >= after {
                self.disarm();
                self.events.push(CommanderEvent::AutoDisarmPreflight);
            }
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

    /// Latitude and longitude (deg) of a local ENU position: PX4's map
    /// projection around the SIH origin (azimuthal equidistant; flat at these
    /// distances).
    fn lat_lon_of(&self, p: &Vector3<f64>) -> (f64, f64) {
        let lat0 = self.params.sih_loc_lat0;
        let lat = lat0 + (p.y / EARTH_RADIUS_M).to_degrees();
        let lon = self.params.sih_loc_lon0
            + (p.x / (EARTH_RADIUS_M * lat0.to_radians().cos())).to_degrees();
        (lat, lon)
    }

    /// Builds telemetry message `id` for now, as PX4 would report it.
    fn telemetry(&self, id: u32, now_ns: u64, vehicle: &VehicleStatus) -> Option<MavMessage> {
        let est = &vehicle.estimate;
        let boot_ns = self.boot_ns(now_ns);
        let time_boot_ms = (boot_ns / 1_000_000) as u32;
        let deg_e7 = |deg: f64| (deg * 1e7).round() as i32;
        let mm = |m: f64| (m * 1e3).round() as i32;
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
            msg_id::GLOBAL_POSITION_INT => {
                let (lat, lon) = self.lat_lon_of(&est.position);
                let alt = self.amsl_of(est.position.z);
                // PX4's quirk: without a home altitude, relative_alt is the AMSL one.
                let relative = self.home.map_or(alt, |h| alt - h.alt_amsl);
                let v = enu_to_ned(&est.velocity);
                let cm_s = |x: f64| (x * 100.0).round().clamp(-32768.0, 32767.0) as i16;
                let hdg = yaw_enu_to_ned(yaw_of(est)).to_degrees().rem_euclid(360.0);
                MavMessage::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
                    time_boot_ms,
                    lat: deg_e7(lat),
                    lon: deg_e7(lon),
                    alt: mm(alt),
                    relative_alt: mm(relative),
                    vx: cm_s(v.x),
                    vy: cm_s(v.y),
                    vz: cm_s(v.z),
                    hdg: ((hdg * 100.0).round() as u16) % 36000,
                })
            }
            msg_id::HOME_POSITION => {
                let h = self.home?;
                let (lat, lon) = self.lat_lon_of(&h.position);
                let p = enu_to_ned(&h.position);
                let q = UnitQuaternion::from_euler_angles(0.0, 0.0, yaw_enu_to_ned(h.yaw));
                MavMessage::HOME_POSITION(HOME_POSITION_DATA {
                    latitude: deg_e7(lat),
                    longitude: deg_e7(lon),
                    altitude: mm(h.alt_amsl),
                    x: p.x as f32,
                    y: p.y as f32,
                    z: p.z as f32,
                    q: [q.w as f32, q.i as f32, q.j as f32, q.k as f32],
                    approach_x: 0.0,
                    approach_y: 0.0,
                    approach_z: 0.0,
                    time_usec: boot_ns / 1000,
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
                    time_usec: boot_ns / 1000,
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

    /// The HEARTBEAT PX4 would send now (HEARTBEAT.hpp): base_mode CUSTOM plus
    /// the control flags of the mode (AUTO modes 29, POSCTL 81, OFFBOARD 17;
    /// +128 armed), system_status STANDBY / ACTIVE / CRITICAL (armed in a
    /// failsafe) / EMERGENCY (crashed).
    pub fn heartbeat(&self) -> HEARTBEAT_DATA {
        let mut base_mode = MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            | MavModeFlag::MAV_MODE_FLAG_STABILIZE_ENABLED;
        base_mode |= match self.mode() {
            FlightMode::Posctl => MavModeFlag::MAV_MODE_FLAG_MANUAL_INPUT_ENABLED,
            FlightMode::Offboard => MavModeFlag::empty(),
            FlightMode::AutoTakeoff | FlightMode::AutoLoiter | FlightMode::AutoLand => {
                MavModeFlag::MAV_MODE_FLAG_AUTO_ENABLED | MavModeFlag::MAV_MODE_FLAG_GUIDED_ENABLED
            }
        };
        if self.armed {
            base_mode |= MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
        }
        let system_status = if self.crashed {
            MavState::MAV_STATE_EMERGENCY
        } else if self.armed && self.failsafe.is_some() {
            MavState::MAV_STATE_CRITICAL
        } else if self.armed {
            MavState::MAV_STATE_ACTIVE
        } else {
            MavState::MAV_STATE_STANDBY
        };
        HEARTBEAT_DATA {
            custom_mode: self.mode().custom_mode(),
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
            base_mode,
            system_status,
            mavlink_version: 3,
        }
    }
}

/// Whether a setpoint asks a landed multicopter to take off (FlightTask::_checkTakeoff):
/// a position more than 0.2 m above it, or a climb faster than 0.3 m/s.
fn wants_takeoff(sp: &Setpoint, est: &EstimatedState) -> bool {
    sp.position[2].is_some_and(|z| z > est.position.z + 0.2)
        || sp.velocity[2].is_some_and(|vz| vz > 0.3)
}

/// Whether PX4's receiver passes a COMMAND_LONG to its commander: our system
/// (1), or 0 for the broadcast requests only; component 1 or 0.
fn command_addressed_to_us(cmd: &COMMAND_LONG_DATA) -> bool {
    let system_ok = cmd.target_system == 1
        || (cmd.target_system == 0 && BROADCAST_COMMANDS.contains(&cmd.command));
    system_ok && (cmd.target_component == 0 || cmd.target_component == 1)
}

/// Whether a setpoint or SET_MODE is for us (system 1 or 0, component 1 or 0).
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
