//! The companion side of the link, as a pure state machine: messages and time in,
//! messages to send and the vehicle state out. The binary owns the socket or serial port
//! and the clock; tests drive it against the simulator's autopilot in simulated time.

use std::collections::VecDeque;

use ipc_types::msg::{FlightMode, Header, LandedState, LinkHealth, Pose, Setpoint, VehicleState};
use mavlink::MavHeader;
use mavlink::dialects::common::{
    HEARTBEAT_DATA, MavAutopilot, MavCmd, MavFrame, MavLandedState, MavMessage, MavModeFlag,
    MavResult, MavState, MavType, PositionTargetTypemask, SET_POSITION_TARGET_LOCAL_NED_DATA,
};
use nalgebra::{UnitQuaternion, Vector3};

use crate::clock::AutopilotClock;
use px4_protocol::frames::{
    enu_from_ned, flu_from_frd, ned_from_enu, world_from_body_enu, yaw_enu_to_ned,
};
use px4_protocol::mode::{OFFBOARD, flight_mode};

/// What the stack asks of the autopilot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Request {
    /// Arm the motors.
    Arm,
    /// Disarm (refused by PX4 in flight).
    Disarm,
    /// Disarm even in flight (PX4's ARM_DISARM with param2 21196): motors off at
    /// touchdown, before PX4's land detector agrees.
    ForceDisarm,
    /// AUTO.TAKEOFF to this world height (local frame, z up), m; sent as an altitude
    /// above mean sea level (PX4's reading of NAV_TAKEOFF param7).
    Takeoff {
        /// Height, m.
        altitude_m: f32,
    },
    /// Switch to OFFBOARD: sent only after the setpoint stream has run long enough.
    Offboard,
    /// AUTO.LAND where the vehicle is.
    Land,
    /// AUTO.LOITER where the vehicle is.
    Hold,
}

impl Request {
    /// The mode this request puts the autopilot in, for a mode change.
    pub fn mode(&self) -> Option<FlightMode> {
        match self {
            Self::Takeoff { .. } => Some(FlightMode::Takeoff),
            Self::Offboard => Some(FlightMode::Offboard),
            Self::Land => Some(FlightMode::Land),
            Self::Hold => Some(FlightMode::Hold),
            Self::Arm | Self::Disarm | Self::ForceDisarm => None,
        }
    }
}

/// How a request ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Outcome {
    /// COMMAND_ACK accepted.
    Accepted,
    /// COMMAND_ACK with another result: PX4 refused. TEMPORARILY_REJECTED counts only
    /// once every send was refused so.
    Rejected(MavResult),
    /// No answer after every retry.
    TimedOut,
    /// OFFBOARD asked but the setpoint stream stopped before it could be sent.
    NoSetpointStream,
    /// A take-off without an altitude reference (no global position): not sent.
    NoAltitudeReference,
}

/// How often a link that hears the autopilot but no heartbeat asks for one, ns.
const HEARTBEAT_ASK_NS: u64 = 200_000_000;

/// How long a mode change the autopilot accepted is taken as under way while its
/// heartbeat does not show it yet, ns: PX4 beats at 1 Hz, so the mode shows within a
/// second; two lost beats are allowed for. Asked again inside it, the request is
/// answered accepted without going on the wire again (PX4 restarts AUTO.LAND's landing
/// point at every NAV_LAND, and a mission or watchdog asking every cycle made a storm
/// of them). The fsm re-asks after its own `mode_timeout_s`, which is longer.
pub const MODE_CONFIRM_NS: u64 = 2_500_000_000;

/// Timing and identity of the link.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkSettings {
    /// Our MAVLink system id (the autopilot's, as companions use).
    pub system_id: u8,
    /// Our component id (MAV_COMP_ID_ONBOARD_COMPUTER = 191).
    pub component_id: u8,
    /// The autopilot's system and component ids.
    pub target: (u8, u8),
    /// Our heartbeat period, ns (MAVLink: 1 Hz).
    pub heartbeat_period_ns: u64,
    /// Setpoint stream period, ns (PX4 needs > 2 Hz; we send 20 Hz or more).
    pub setpoint_period_ns: u64,
    /// A new setpoint goes out at once instead of at the stream's next period (the
    /// newest is still repeated every period): `[px4_link] new_setpoints_at_once`.
    pub new_setpoints_at_once: bool,
    /// A setpoint older than this is not streamed (the mission stopped): PX4's
    /// offboard-loss failsafe must then act, not a stale setpoint, ns.
    pub setpoint_max_age_ns: u64,
    /// OFFBOARD is asked only after the stream has run this long, ns. PX4 needs one
    /// setpoint younger than COM_OF_LOSS_T (offboardCheck.cpp); a few in a row make
    /// sure one arrived on a lossy link.
    pub offboard_stream_ns: u64,
    /// Wait for a COMMAND_ACK this long before resending, ns.
    pub command_timeout_ns: u64,
    /// Sends of one command before it counts as timed out (or, answered
    /// TEMPORARILY_REJECTED each time, as rejected).
    pub command_attempts: u32,
    /// The autopilot counts as disconnected without a heartbeat this long, ns.
    pub heartbeat_timeout_ns: u64,
    /// Telemetry rates asked of the autopilot: LOCAL_POSITION_NED, ATTITUDE_QUATERNION,
    /// EXTENDED_SYS_STATE, Hz.
    pub telemetry_hz: [f32; 3],
    /// What a setpoint may ask; beyond it the setpoint is refused and counted.
    pub bounds: SetpointBounds,
    /// VIO samples go to the autopilot as ODOMETRY.
    pub forward_vio: bool,
}

/// The envelope px4-link lets a setpoint ask for, whatever the planner or fsm says:
/// checked on the values as they go on the wire (f32), against the take-off point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SetpointBounds {
    /// Horizontal speed, m/s.
    pub max_horizontal_speed_m_s: f64,
    /// Vertical speed, m/s.
    pub max_vertical_speed_m_s: f64,
    /// Acceleration, m/s^2.
    pub max_acceleration_m_s2: f64,
    /// Horizontal distance of a position from the take-off point, m.
    pub geofence_radius_m: f64,
    /// Height of a position above the take-off point, m (and at most 2 m below it).
    pub geofence_height_m: f64,
}

impl Default for SetpointBounds {
    /// 20 m/s across (72 km/h: above the 50 km/h the stack aims at), 5 m/s up or down,
    /// 20 m/s^2, 200 m around the take-off point, 50 m above it.
    fn default() -> Self {
        Self {
            max_horizontal_speed_m_s: 20.0,
            max_vertical_speed_m_s: 5.0,
            max_acceleration_m_s2: 20.0,
            geofence_radius_m: 200.0,
            geofence_height_m: 50.0,
        }
    }
}

/// Why a setpoint was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refusal {
    /// A field is not finite once converted to the wire's f32.
    NotFinite,
    /// Beyond a speed or acceleration limit.
    TooFast,
    /// A position outside the geofence around the take-off point.
    OutsideGeofence,
}

impl SetpointBounds {
    /// Whether `sp` (ENU) stays inside, with `home` the take-off point when known.
    pub fn check(&self, sp: &Setpoint, home: Option<Vector3<f64>>) -> Result<(), Refusal> {
        let wire = |v: &[f64; 3]| v.map(|x| f64::from(x as f32));
        let used = |bit: u32| sp.valid & bit != 0;
        let (p, v, a) = (
            wire(&sp.position),
            wire(&sp.velocity),
            wire(&sp.acceleration),
        );
        let finite = |x: &[f64]| x.iter().all(|c| c.is_finite());
        if (used(Setpoint::POSITION) && !finite(&p))
            || (used(Setpoint::VELOCITY) && !finite(&v))
            || (used(Setpoint::ACCELERATION) && !finite(&a))
            || (used(Setpoint::YAW) && !(sp.yaw as f32).is_finite())
        {
            return Err(Refusal::NotFinite);
        }
        let inside = |x: f64, max: f64| x <= max;
        if used(Setpoint::VELOCITY)
            && !(inside(v[0].hypot(v[1]), self.max_horizontal_speed_m_s)
                && inside(v[2].abs(), self.max_vertical_speed_m_s))
        {
            return Err(Refusal::TooFast);
        }
        if used(Setpoint::ACCELERATION)
            && !inside(Vector3::from(a).norm(), self.max_acceleration_m_s2)
        {
            return Err(Refusal::TooFast);
        }
        if let (true, Some(h)) = (used(Setpoint::POSITION), home) {
            let d = Vector3::from(p) - h;
            if !(inside(d.xy().norm(), self.geofence_radius_m)
                && inside(d.z, self.geofence_height_m)
                && inside(-d.z, 2.0))
            {
                return Err(Refusal::OutsideGeofence);
            }
        }
        Ok(())
    }
}

impl Default for LinkSettings {
    fn default() -> Self {
        Self {
            system_id: 1,
            component_id: 191,
            target: (1, 1),
            heartbeat_period_ns: 1_000_000_000,
            setpoint_period_ns: 40_000_000,
            new_setpoints_at_once: true,
            setpoint_max_age_ns: 300_000_000,
            offboard_stream_ns: 300_000_000,
            command_timeout_ns: 500_000_000,
            command_attempts: 4,
            heartbeat_timeout_ns: 3_500_000_000,
            telemetry_hz: [30.0, 50.0, 5.0],
            bounds: SetpointBounds::default(),
            forward_vio: false,
        }
    }
}

#[derive(Debug, Clone, Copy)]
struct Pending {
    request: Request,
    command: MavCmd,
    params: [f32; 7],
    sent_ns: u64,
    attempts: u32,
}

/// The autopilot's last word on each subject.
#[derive(Debug, Clone, Copy, Default)]
struct Telemetry {
    position: Option<(Vector3<f64>, Vector3<f64>)>,
    attitude: Option<(UnitQuaternion<f64>, Vector3<f64>)>,
    custom_mode: u32,
    armed: bool,
    landed: Option<MavLandedState>,
    last_heartbeat_ns: Option<u64>,
    /// When the newest telemetry arrived, on our clock: what staleness is judged by.
    last_telemetry_ns: u64,
    /// When the newest telemetry was measured, the autopilot's stamp on our clock: what
    /// the vehicle state is stamped with.
    last_measured_ns: u64,
    last_seq: Option<u8>,
    lost: u64,
    /// The autopilot's boot clock on ours: telemetry is stamped when it was measured.
    clock: AutopilotClock,
    /// AMSL altitude of the local frame's origin from HOME_POSITION (home altitude
    /// plus its NED z), m.
    origin_amsl_from_home: Option<f64>,
    /// The latest GLOBAL_POSITION_INT altitude above mean sea level, m.
    global_alt_amsl: Option<f64>,
}

impl Telemetry {
    /// Telemetry measured at the autopilot's `time_boot_ms`, arrived at `now_ns`: the
    /// newest measurement time on our clock and the newest arrival, neither going back
    /// (but for a jump of the autopilot's clock, which starts the mapping over).
    fn measured(&mut self, time_boot_ms: u32, now_ns: u64) {
        let jumps = self.clock.jumps();
        let t = self
            .clock
            .local_time(u64::from(time_boot_ms) * 1_000_000, now_ns);
        self.last_measured_ns = if self.clock.jumps() == jumps {
            self.last_measured_ns.max(t)
        } else {
            t
        };
        self.last_telemetry_ns = self.last_telemetry_ns.max(now_ns);
    }
}

/// What the link knows of the autopilot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Status {
    /// Heartbeats arrive.
    pub connected: bool,
    /// Armed, per the heartbeat.
    pub armed: bool,
    /// Flight mode, per the heartbeat (OFFBOARD counts only when this says so).
    pub mode: FlightMode,
    /// Landed state, per EXTENDED_SYS_STATE.
    pub landed: LandedState,
    /// A request is waiting for its answer.
    pub busy: bool,
}

/// The link.
#[derive(Debug, Clone)]
pub struct Px4Link {
    settings: LinkSettings,
    telemetry: Telemetry,
    pending: Option<Pending>,
    queue: VecDeque<Request>,
    outcomes: Vec<(Request, Outcome)>,
    setpoint: Option<(u64, Setpoint)>,
    /// The setpoint held has not gone out yet (with `new_setpoints_at_once` it goes at
    /// once, not at the stream's next period: the mission's latency ends on the wire).
    setpoint_new: bool,
    /// The last new setpoint sent, with when it was taken in, until taken.
    sent: Option<(u64, Setpoint)>,
    home: Option<Vector3<f64>>,
    refused: u64,
    last_refusal: Option<Refusal>,
    stream_since_ns: Option<u64>,
    /// A mode change the autopilot accepted, with when, until its heartbeat shows it
    /// or [`MODE_CONFIRM_NS`] passes.
    mode_accepted: Option<(Request, u64)>,
    last_setpoint_sent_ns: Option<u64>,
    last_heartbeat_sent_ns: Option<u64>,
    /// When a HEARTBEAT was last asked for (telemetry heard, no heartbeat yet).
    heartbeat_asked_ns: Option<u64>,
    intervals_requested: bool,
    parse_errors: u32,
    state_seq: u64,
    out: Vec<MavMessage>,
    /// VIO samples waiting for the next poll, and how many were not sendable.
    vio: Vec<MavMessage>,
    vio_refused: u64,
}

impl Px4Link {
    /// A link that has heard nothing yet.
    pub fn new(settings: LinkSettings) -> Self {
        Self {
            settings,
            telemetry: Telemetry::default(),
            pending: None,
            queue: VecDeque::new(),
            outcomes: Vec::new(),
            setpoint: None,
            setpoint_new: false,
            sent: None,
            home: None,
            refused: 0,
            last_refusal: None,
            stream_since_ns: None,
            mode_accepted: None,
            last_setpoint_sent_ns: None,
            last_heartbeat_sent_ns: None,
            heartbeat_asked_ns: None,
            intervals_requested: false,
            parse_errors: 0,
            state_seq: 0,
            out: Vec::new(),
            vio: Vec::new(),
            vio_refused: 0,
        }
    }

    /// A VIO sample for the autopilot: sent as ODOMETRY on the next poll when
    /// forwarding is on; one with a value that is not finite is counted and dropped.
    pub fn set_vio(&mut self, vio: &ipc_types::msg::VioOdometry) {
        if !self.settings.forward_vio {
            return;
        }
        match crate::odometry::odometry_from_vio(vio) {
            Some(o) => self.vio.push(MavMessage::ODOMETRY(o)),
            None => self.vio_refused += 1,
        }
    }

    /// VIO samples dropped because a value was not finite.
    pub fn vio_refused(&self) -> u64 {
        self.vio_refused
    }

    /// The MAVLink header our messages carry (the sequence is the transport's business).
    pub fn header(&self, sequence: u8) -> MavHeader {
        MavHeader {
            system_id: u32::from(self.settings.system_id),
            component_id: self.settings.component_id,
            sequence,
        }
    }

    /// Counts `count` datagrams or frames that did not parse (reported in link health).
    pub fn add_parse_errors(&mut self, count: u64) {
        let count = u32::try_from(count).unwrap_or(u32::MAX);
        self.parse_errors = self.parse_errors.saturating_add(count);
    }

    /// Queues a request; requests go out one at a time, in order.
    pub fn request(&mut self, request: Request) {
        self.queue.push_back(request);
    }

    /// Drops every queued and pending request (an abort must not wait behind them).
    pub fn clear_requests(&mut self) {
        self.queue.clear();
        self.pending = None;
    }

    /// Requests that ended since the last call, with how.
    pub fn take_outcomes(&mut self) -> Vec<(Request, Outcome)> {
        std::mem::take(&mut self.outcomes)
    }

    /// The setpoint to stream (ENU), received at `now_ns`. A non-finite field is
    /// dropped from the setpoint (its valid bit cleared), never sent.
    pub fn set_setpoint(&mut self, now_ns: u64, setpoint: &Setpoint) {
        let mut sp = *setpoint;
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        if !finite(&sp.position) {
            sp.valid &= !Setpoint::POSITION;
        }
        if !finite(&sp.velocity) {
            sp.valid &= !Setpoint::VELOCITY;
        }
        if !finite(&sp.acceleration) {
            sp.valid &= !Setpoint::ACCELERATION;
        }
        if !sp.yaw.is_finite() {
            sp.valid &= !Setpoint::YAW;
        }
        if sp.valid & (Setpoint::POSITION | Setpoint::VELOCITY) == 0 {
            return;
        }
        if let Err(why) = self.settings.bounds.check(&sp, self.home) {
            self.refused += 1;
            self.last_refusal = Some(why);
            return;
        }
        self.setpoint = Some((now_ns, sp));
        self.setpoint_new = true;
    }

    /// The last new setpoint that went out since the last call, and when it was taken
    /// in (ns): what the latency profile ends on.
    pub fn take_sent_setpoint(&mut self) -> Option<(u64, Setpoint)> {
        self.sent.take()
    }

    /// Setpoints refused by the bounds so far, and why the last one was.
    pub fn refused_setpoints(&self) -> (u64, Option<Refusal>) {
        (self.refused, self.last_refusal)
    }

    /// The autopilot's clock as mapped onto ours: its estimated rate and its jumps.
    pub fn autopilot_clock(&self) -> &AutopilotClock {
        &self.telemetry.clock
    }

    /// The take-off point the geofence is centred on (ENU): where the vehicle was when
    /// it armed, else its first reported position.
    pub fn home(&self) -> Option<Vector3<f64>> {
        self.home
    }

    /// Takes in one message from the autopilot, received at `now_ns`.
    pub fn on_message(&mut self, now_ns: u64, header: &MavHeader, msg: &MavMessage) {
        let (sys, comp) = self.settings.target;
        if (header.system_id, header.component_id) != (u32::from(sys), comp) {
            return;
        }
        if let Some(last) = self.telemetry.last_seq {
            let gap = header.sequence.wrapping_sub(last).wrapping_sub(1);
            // A big jump is a restart of the autopilot rather than 200 lost messages.
            if gap < 128 {
                self.telemetry.lost += u64::from(gap);
            }
        }
        self.telemetry.last_seq = Some(header.sequence);
        match msg {
            MavMessage::HEARTBEAT(h) => {
                if h.autopilot == MavAutopilot::MAV_AUTOPILOT_INVALID {
                    return;
                }
                self.telemetry.custom_mode = h.custom_mode;
                // The accepted mode change showed: done (a later mode change away from
                // it is then asked for afresh).
                if self
                    .mode_accepted
                    .is_some_and(|(r, _)| r.mode() == Some(flight_mode(h.custom_mode)))
                {
                    self.mode_accepted = None;
                }
                let armed = h
                    .base_mode
                    .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED);
                if armed && !self.telemetry.armed {
                    // The geofence is centred where the vehicle armed.
                    if let Some((p, _)) = self.telemetry.position {
                        self.home = Some(p);
                    }
                }
                self.telemetry.armed = armed;
                self.telemetry.last_heartbeat_ns = Some(now_ns);
            }
            MavMessage::LOCAL_POSITION_NED(p) => {
                let pos = enu_from_ned([f64::from(p.x), f64::from(p.y), f64::from(p.z)]);
                let vel = enu_from_ned([f64::from(p.vx), f64::from(p.vy), f64::from(p.vz)]);
                if pos.iter().chain(vel.iter()).all(|v| v.is_finite()) {
                    self.home.get_or_insert(pos);
                    self.telemetry.position = Some((pos, vel));
                    self.telemetry.measured(p.time_boot_ms, now_ns);
                }
            }
            MavMessage::ATTITUDE_QUATERNION(a) => {
                if let Some(q) = world_from_body_enu([a.q1, a.q2, a.q3, a.q4]) {
                    let rates = flu_from_frd([a.rollspeed, a.pitchspeed, a.yawspeed]);
                    if rates.iter().all(|v| v.is_finite()) {
                        self.telemetry.attitude = Some((q, rates));
                        self.telemetry.measured(a.time_boot_ms, now_ns);
                    }
                }
            }
            MavMessage::EXTENDED_SYS_STATE(s) => self.telemetry.landed = Some(s.landed_state),
            MavMessage::HOME_POSITION(h) => {
                let origin = f64::from(h.altitude) * 1e-3 + f64::from(h.z);
                if origin.is_finite() {
                    self.telemetry.origin_amsl_from_home = Some(origin);
                }
                // The autopilot's own home (PX4 sets it where it armed, and repeats it
                // every 2 s): a px4-link restarted in the air centres its geofence there
                // rather than where it first heard the vehicle.
                let home = enu_from_ned([f64::from(h.x), f64::from(h.y), f64::from(h.z)]);
                if home.iter().all(|v| v.is_finite()) {
                    self.home = Some(home);
                }
            }
            MavMessage::GLOBAL_POSITION_INT(g) => {
                self.telemetry.global_alt_amsl = Some(f64::from(g.alt) * 1e-3);
            }
            // Behind a router the autopilot's answers to a ground station's commands
            // reach us too: only ours (or an ACK addressed to nobody, as older
            // autopilots send) settle our request.
            MavMessage::COMMAND_ACK(ack)
                if (ack.target_system == 0 || ack.target_system == self.settings.system_id)
                    && (ack.target_component == 0
                        || ack.target_component == self.settings.component_id) =>
            {
                self.on_ack(now_ns, ack.command, ack.result);
            }
            _ => {}
        }
    }

    fn on_ack(&mut self, now_ns: u64, command: MavCmd, result: MavResult) {
        let Some(p) = self.pending else { return };
        if p.command != command || result == MavResult::MAV_RESULT_IN_PROGRESS {
            return;
        }
        // "Not now" (PX4: preflight checks not yet passing, OFFBOARD not yet available):
        // asked again after the command timeout while sends remain. Every other refusal
        // (DENIED, UNSUPPORTED, FAILED) is final at once: resending cannot change it.
        if result == MavResult::MAV_RESULT_TEMPORARILY_REJECTED
            && p.attempts < self.settings.command_attempts
        {
            return;
        }
        let outcome = if result == MavResult::MAV_RESULT_ACCEPTED {
            if p.request.mode().is_some() {
                self.mode_accepted = Some((p.request, now_ns));
            }
            Outcome::Accepted
        } else {
            Outcome::Rejected(result)
        };
        self.outcomes.push((p.request, outcome));
        self.pending = None;
    }

    /// The altitude above mean sea level of the local frame's origin (world z = 0), m:
    /// from HOME_POSITION (exact: altitude and local z of one point), else from the
    /// latest GLOBAL_POSITION_INT and local position; None without a global position.
    pub fn origin_amsl(&self) -> Option<f64> {
        self.telemetry.origin_amsl_from_home.or_else(|| {
            let alt = self.telemetry.global_alt_amsl?;
            let (p, _) = self.telemetry.position?;
            Some(alt - p.z)
        })
    }

    /// What the link knows now.
    pub fn status(&self, now_ns: u64) -> Status {
        Status {
            connected: self.connected(now_ns),
            armed: self.telemetry.armed,
            mode: flight_mode(self.telemetry.custom_mode),
            landed: match self.telemetry.landed {
                Some(MavLandedState::MAV_LANDED_STATE_ON_GROUND) => LandedState::OnGround,
                Some(MavLandedState::MAV_LANDED_STATE_IN_AIR) => LandedState::InAir,
                Some(MavLandedState::MAV_LANDED_STATE_TAKEOFF) => LandedState::Takeoff,
                Some(MavLandedState::MAV_LANDED_STATE_LANDING) => LandedState::Landing,
                _ => LandedState::Unknown,
            },
            busy: self.pending.is_some() || !self.queue.is_empty(),
        }
    }

    /// Whether `request` was accepted and its mode is still on its way: asked again, it
    /// is answered accepted without being sent (see [`MODE_CONFIRM_NS`]).
    pub fn mode_under_way(&self, now_ns: u64, request: Request) -> bool {
        self.mode_accepted.is_some_and(|(r, at)| {
            r == request
                && now_ns.saturating_sub(at) < MODE_CONFIRM_NS
                && r.mode() != Some(flight_mode(self.telemetry.custom_mode))
        })
    }

    fn connected(&self, now_ns: u64) -> bool {
        self.telemetry
            .last_heartbeat_ns
            .is_some_and(|t| now_ns.saturating_sub(t) <= self.settings.heartbeat_timeout_ns)
    }

    /// The vehicle state in ENU/FLU, once both position and attitude have arrived.
    pub fn vehicle_state(&self, now_ns: u64) -> Option<VehicleState> {
        let (pos, vel) = self.telemetry.position?;
        let (q, rates) = self.telemetry.attitude?;
        let status = self.status(now_ns);
        Some(VehicleState {
            msg: Header {
                seq: self.state_seq,
                ..Header::captured_at(self.telemetry.last_measured_ns)
            },
            world_from_body: Pose {
                translation: [pos.x, pos.y, pos.z],
                rotation_xyzw: [q.i, q.j, q.k, q.w],
            },
            velocity: [vel.x, vel.y, vel.z],
            body_rates: [rates.x, rates.y, rates.z],
            armed: u32::from(status.armed),
            flight_mode: status.mode as u32,
            landed_state: status.landed as u32,
            reserved: 0,
            link: LinkHealth {
                connected: u32::from(status.connected),
                parse_errors: self.parse_errors,
                last_heartbeat_ns: self.telemetry.last_heartbeat_ns.unwrap_or(0),
                last_telemetry_ns: self.telemetry.last_telemetry_ns,
                messages_lost: self.telemetry.lost,
                // The guard's counts are the stage's, added where it publishes.
                ..LinkHealth::default()
            },
        })
    }

    /// Advances time: returns what to send now (heartbeat, telemetry rate requests,
    /// setpoints, commands and their retries).
    pub fn poll(&mut self, now_ns: u64) -> &[MavMessage] {
        self.out.clear();
        let s = self.settings;
        if self
            .last_heartbeat_sent_ns
            .is_none_or(|t| now_ns.saturating_sub(t) >= s.heartbeat_period_ns)
        {
            self.last_heartbeat_sent_ns = Some(now_ns);
            self.out.push(MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                custom_mode: 0,
                mavtype: MavType::MAV_TYPE_ONBOARD_CONTROLLER,
                autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
                base_mode: MavModeFlag::empty(),
                system_status: MavState::MAV_STATE_ACTIVE,
                mavlink_version: 3,
            }));
        }
        // The autopilot is heard but its heartbeat (1 Hz) not yet: a restarted px4-link
        // asks for one at once rather than fly up to a second without the vehicle's
        // mode and arming (REQUEST_MESSAGE, answered by PX4 and the simulator alike).
        if !self.connected(now_ns)
            && self.telemetry.last_seq.is_some()
            && self
                .heartbeat_asked_ns
                .is_none_or(|t| now_ns.saturating_sub(t) >= HEARTBEAT_ASK_NS)
        {
            self.heartbeat_asked_ns = Some(now_ns);
            self.out.push(self.command_long(
                MavCmd::MAV_CMD_REQUEST_MESSAGE,
                [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            ));
        }
        if !self.intervals_requested && self.connected(now_ns) {
            self.intervals_requested = true;
            for (id, hz) in [32u32, 31, 245].iter().zip(s.telemetry_hz) {
                let interval_us = if hz > 0.0 { 1e6 / hz } else { -1.0 };
                self.out.push(self.command_long(
                    MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
                    [*id as f32, interval_us, 0.0, 0.0, 0.0, 0.0, 0.0],
                ));
            }
        }
        self.out.append(&mut self.vio);
        self.stream(now_ns);
        self.commands(now_ns);
        &self.out
    }

    fn stream(&mut self, now_ns: u64) {
        let s = self.settings;
        let fresh = self
            .setpoint
            .filter(|(t, _)| now_ns.saturating_sub(*t) <= s.setpoint_max_age_ns);
        let Some((taken_ns, sp)) = fresh else {
            self.stream_since_ns = None;
            return;
        };
        // A new setpoint goes at once when so configured; the newest every period.
        if !(self.setpoint_new && s.new_setpoints_at_once)
            && self
                .last_setpoint_sent_ns
                .is_some_and(|t| now_ns.saturating_sub(t) < s.setpoint_period_ns)
        {
            return;
        }
        if std::mem::take(&mut self.setpoint_new) {
            self.sent = Some((taken_ns, sp));
        }
        self.stream_since_ns.get_or_insert(now_ns);
        self.last_setpoint_sent_ns = Some(now_ns);
        let mut mask = PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE;
        if sp.valid & Setpoint::POSITION == 0 {
            mask |= PositionTargetTypemask::POSITION_TARGET_TYPEMASK_X_IGNORE
                | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_Y_IGNORE
                | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_Z_IGNORE;
        }
        if sp.valid & Setpoint::VELOCITY == 0 {
            mask |= PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VX_IGNORE
                | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VY_IGNORE
                | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VZ_IGNORE;
        }
        if sp.valid & Setpoint::ACCELERATION == 0 {
            mask |= PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AX_IGNORE
                | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AY_IGNORE
                | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AZ_IGNORE;
        }
        if sp.valid & Setpoint::YAW == 0 {
            mask |= PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_IGNORE;
        }
        // Ignored fields go out as 0, never NaN.
        let pick = |bit: u32, v: &[f64; 3]| {
            if sp.valid & bit != 0 {
                ned_from_enu(&Vector3::from(*v)).map(|x| x as f32)
            } else {
                [0.0; 3]
            }
        };
        let (p, v, a) = (
            pick(Setpoint::POSITION, &sp.position),
            pick(Setpoint::VELOCITY, &sp.velocity),
            pick(Setpoint::ACCELERATION, &sp.acceleration),
        );
        let yaw = if sp.valid & Setpoint::YAW != 0 {
            yaw_enu_to_ned(sp.yaw) as f32
        } else {
            0.0
        };
        self.out.push(MavMessage::SET_POSITION_TARGET_LOCAL_NED(
            SET_POSITION_TARGET_LOCAL_NED_DATA {
                time_boot_ms: (now_ns / 1_000_000) as u32,
                x: p[0],
                y: p[1],
                z: p[2],
                vx: v[0],
                vy: v[1],
                vz: v[2],
                afx: a[0],
                afy: a[1],
                afz: a[2],
                yaw,
                yaw_rate: 0.0,
                type_mask: mask,
                target_system: s.target.0,
                target_component: s.target.1,
                coordinate_frame: MavFrame::MAV_FRAME_LOCAL_NED,
            },
        ));
    }

    fn commands(&mut self, now_ns: u64) {
        let s = self.settings;
        if let Some(mut p) = self.pending {
            if now_ns.saturating_sub(p.sent_ns) < s.command_timeout_ns {
                return;
            }
            if p.attempts >= s.command_attempts {
                self.outcomes.push((p.request, Outcome::TimedOut));
                self.pending = None;
            } else {
                p.attempts += 1;
                p.sent_ns = now_ns;
                self.pending = Some(p);
                self.out
                    .push(self.command_long_confirm(p.command, p.params, p.attempts - 1));
                return;
            }
        }
        let Some(&next) = self.queue.front() else {
            return;
        };
        let origin = self.origin_amsl();
        if matches!(next, Request::Takeoff { .. }) && origin.is_none() {
            // PX4 reads param7 as AMSL; without a global position a GPS-less PX4 flies
            // NAV_TAKEOFF towards its local origin, so nothing is sent.
            self.queue.pop_front();
            self.outcomes.push((next, Outcome::NoAltitudeReference));
            return;
        }
        if next == Request::Offboard {
            match self.stream_since_ns {
                Some(t) if now_ns.saturating_sub(t) >= s.offboard_stream_ns => {}
                Some(_) => return, // wait for the stream to have run long enough
                // No fresh setpoint (none yet, or its sender stopped): PX4 would refuse
                // OFFBOARD; say so now rather than hold every later request behind it.
                None => {
                    self.queue.pop_front();
                    self.outcomes.push((next, Outcome::NoSetpointStream));
                    return;
                }
            }
        }
        self.queue.pop_front();
        if self.mode_under_way(now_ns, next) {
            tracing::debug!(
                ?next,
                "accepted a moment ago and the mode is on its way: not sent again"
            );
            self.outcomes.push((next, Outcome::Accepted));
            return;
        }
        let (command, params) = match next {
            Request::Arm => (
                MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            ),
            Request::Disarm => (MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, [0.0; 7]),
            Request::ForceDisarm => (
                MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                [
                    0.0,
                    px4_protocol::command::FORCE_DISARM_MAGIC,
                    0.0,
                    0.0,
                    0.0,
                    0.0,
                    0.0,
                ],
            ),
            // param7 is the target altitude above mean sea level (takeoff.cpp); the
            // request's altitude is a world (local) height.
            Request::Takeoff { altitude_m } => (
                MavCmd::MAV_CMD_NAV_TAKEOFF,
                [
                    f32::NAN,
                    0.0,
                    0.0,
                    f32::NAN,
                    f32::NAN,
                    f32::NAN,
                    (origin.unwrap_or(f64::NAN) + f64::from(altitude_m)) as f32,
                ],
            ),
            Request::Offboard => (
                MavCmd::MAV_CMD_DO_SET_MODE,
                [OFFBOARD.0, OFFBOARD.1, OFFBOARD.2, 0.0, 0.0, 0.0, 0.0],
            ),
            Request::Land => (
                MavCmd::MAV_CMD_NAV_LAND,
                [0.0, 0.0, 0.0, f32::NAN, f32::NAN, f32::NAN, f32::NAN],
            ),
            Request::Hold => (
                MavCmd::MAV_CMD_DO_SET_MODE,
                [1.0, 4.0, 3.0, 0.0, 0.0, 0.0, 0.0],
            ),
        };
        self.pending = Some(Pending {
            request: next,
            command,
            params,
            sent_ns: now_ns,
            attempts: 1,
        });
        self.out.push(self.command_long(command, params));
    }

    fn command_long(&self, command: MavCmd, p: [f32; 7]) -> MavMessage {
        px4_protocol::command_long(command, p, self.settings.target)
    }

    fn command_long_confirm(&self, command: MavCmd, p: [f32; 7], confirmation: u32) -> MavMessage {
        px4_protocol::command_long_confirmation(
            command,
            p,
            self.settings.target,
            confirmation.min(255) as u8,
        )
    }
}
