//! The landing mission as a state machine: inputs (vehicle state, pad observations,
//! trajectories, autopilot outcomes, safety orders) and time in; setpoints, planner goals,
//! autopilot requests and status out. No clock, no IPC: the `fsm` binary and
//! `landing run` call the same code.

use bspline::BSpline;
use ipc_types::msg::{
    FlightMode, FsmStatus, GoalMode, Header, LandedState, LinkOutcome, LinkOutcomeKind,
    LinkRequest, LinkRequestKind, MissionState, PadObservation, PlannerGoal, SafetyAction,
    SafetyCommand, Setpoint, Stage, Text, Trajectory, VehicleState,
};
use nalgebra::{Rotation3, UnitQuaternion, Vector3};

use crate::config::FsmConfig;
use crate::odometry::Odometry;
use crate::pad_filter::{PadEstimate, PadFilter, Update, turn_pull, wrap};
use crate::relative::RelativeTrack;

/// One transition, kept for the log and the tests.
#[derive(Debug, Clone, PartialEq)]
pub struct Transition {
    /// When, ns.
    pub at_ns: u64,
    /// From.
    pub from: MissionState,
    /// To.
    pub to: MissionState,
    /// Why, for people.
    pub reason: String,
}

/// What one tick asks the caller to publish.
#[derive(Debug, Clone, Default)]
pub struct Outputs {
    /// The setpoint to stream to the autopilot (None: no stream in this state).
    pub setpoint: Option<Setpoint>,
    /// A planner goal (on change and every `goal_period_s`).
    pub goal: Option<PlannerGoal>,
    /// Requests to the autopilot, in order.
    pub requests: Vec<LinkRequest>,
    /// The status (on a transition and every `status_period_s`).
    pub status: Option<FsmStatus>,
}

/// Steps inside Takeoff: a climb in OFFBOARD, which needs no global position (a GPS-less
/// PX4 cannot fly AUTO.TAKEOFF safely; docs/fsm.md, "Take-off").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum TakeoffStep {
    /// Stream a hold at the ground position and ask for OFFBOARD (PX4 accepts it
    /// disarmed).
    EnteringOffboard,
    /// Arm in OFFBOARD.
    Arming,
    /// The setpoint climbs from the ground at `takeoff_climb_m_s`, from `since_ns`.
    Climbing { since_ns: u64 },
}

/// One autopilot request in flight, with its retries.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Pending {
    kind: LinkRequestKind,
    id: u64,
    attempts: u32,
    /// When the current attempt went out (None: waiting to retry).
    sent_ns: Option<u64>,
    retry_at_ns: u64,
    answer: Option<(LinkOutcomeKind, u32)>,
}

/// A mode change the autopilot accepted, waited for until its heartbeat shows it.
#[derive(Debug, Clone, Copy, PartialEq)]
struct ModeWait {
    kind: LinkRequestKind,
    since_ns: u64,
    attempts: u32,
}

/// Where a request stands.
#[derive(Debug, Clone, PartialEq)]
enum Drive {
    Waiting,
    /// Accepted at this attempt.
    Accepted(u32),
    Failed(String),
}

/// Where setpoints come from in Track/GoToPreset.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Guidance {
    Planner,
    Direct,
}

/// How long px4-link may take to answer a request before the fsm counts it as lost.
const NO_ANSWER_NS: u64 = 5_000_000_000;
/// How long the autopilot may show another mode than OFFBOARD before the fsm yields.
const MODE_LOSS_NS: u64 = 1_000_000_000;

/// How long a restarted fsm waits for the watchdog's view (5 Hz) and the pad before it
/// resumes the mission, ns.
const RESUME_WAIT_NS: u64 = 300_000_000;

/// How far a vehicle state is carried forward to now at most, s: as far as the pad's
/// estimate is (`lost_after_s`), so that the offset between them is judged at one
/// instant. At 0.2 s, states 270 ms late at 30 km/h (a simulator behind real time)
/// put the vehicle 0.5 m behind a pad it was over, and it went around. Staler telemetry
/// is lost telemetry (`telemetry_timeout_s`).
const CARRY_MAX_S: f64 = 1.0;

/// Slower than this (m/s, horizontally) a vehicle that gave up may land where it is.
const BRAKED_M_S: f64 = 0.5;

/// The mission state machine.
#[derive(Debug, Clone)]
pub struct Fsm {
    cfg: FsmConfig,
    state: MissionState,
    started: bool,
    filter: PadFilter,
    /// The frame the filter runs in (the integrated velocity).
    odometry: Odometry,
    /// The camera's recent relative measurements: how fast the vehicle still moves over
    /// the pad, for the drop's settle gate and the touchdown's velocity feedback.
    relative: RelativeTrack,
    /// The header of the newest observation the pad filter took: the setpoints that
    /// follow the pad carry its capture time and stage stamps on, so that a recording
    /// shows camera capture -> setpoint on the wire.
    pad_header: Option<Header>,
    /// The newest vehicle state with when it was measured (its stamp).
    vehicle: Option<(u64, VehicleState)>,
    /// When the newest state's telemetry reached px4-link (its `link.last_telemetry_ns`):
    /// telemetry is lost when this stops advancing, whatever its stamp says.
    telemetry_arrived_ns: u64,
    /// When the watchdog's view last came.
    watchdog_seen_ns: Option<u64>,
    /// The mission state the watchdog last saw the fsm in: a restarted fsm's checkpoint.
    watchdog_phase: Option<MissionState>,
    /// Since when a fresh fsm has seen the vehicle flying OFFBOARD (a restart in the air).
    resume_since: Option<u64>,
    trajectory: Option<(u64, BSpline, u64)>,
    takeoff: TakeoffStep,
    pending: Option<Pending>,
    mode_wait: Option<ModeWait>,
    next_request_id: u64,
    streaming: bool,
    hold: Vector3<f64>,
    yaw_sp: f64,
    guidance: Guidance,
    goal_epoch_ns: u64,
    last_goal_ns: Option<u64>,
    goal_seq: u64,
    align_since: Option<u64>,
    track_height: f64,
    h_cmd: f64,
    /// Chasing a fast pad: the velocity, m/s, added to the pad's to hold station over
    /// it against the relative wind's drag (integrated from the pad-relative error), in
    /// the pad's heading frame (along, across): on a curve what it must make up turns
    /// with the pad, and a world-frame integral would forever lag it.
    chase_trim: Vector3<f64>,
    /// Whether `chase_trim` was made chasing (or below the chase speed).
    trim_chasing: bool,
    /// Chasing: the pad's turning pull fed forward, m/s^2, slewed at no more than
    /// [`CHASE_TURN_JERK_MAX_M_S3`]. A road vehicle's lateral acceleration changes that
    /// slowly; the heading rate read from the markers low over the pad swings with the
    /// vehicle's roll, and fed at once it closed a loop (highspeed-50: +-20 deg of roll
    /// at 1.2 Hz over the pad, touching down tilted 15-22 deg).
    chase_turn: Vector3<f64>,
    /// Descending onto a pad below the chase speed: its horizontal velocity, low-passed
    /// over [`DRAG_MEMORY_S`] since the descent began, the velocity whose drag PX4's
    /// integrator holds (`drag_per_s`).
    drag_ref: Option<Vector3<f64>>,
    z_cmd: f64,
    go_arounds: u32,
    /// Given up over a fast pad: hold here, this high (m), until braked, then land.
    brake_at_z: Option<f64>,
    dropping: bool,
    /// Since when the dropping vehicle has stood still at the pad's height.
    touch_since: Option<u64>,
    /// The drop got under way (a vehicle committed at the pad's height has not dropped).
    drop_moving: bool,
    /// Since when the drop has waited at the flare height for the pad to stop manoeuvring.
    manoeuvre_wait_since: Option<u64>,
    /// When the pad was last seen manoeuvring (below the chase speed), ns.
    manoeuvre_seen_ns: Option<u64>,
    /// How long the touchdown has waited at the flare height for alignment alone, s.
    flare_waited_s: f64,
    /// The gear is on the pad: the motors are being switched off.
    touched: bool,
    lost_z0: f64,
    /// The newest tick's time.
    now_ns: u64,
    /// The pad's horizontal velocity when it was lost (zero without an estimate).
    lost_velocity: Vector3<f64>,
    /// The rate the pad's velocity turned at when it was lost, rad/s: Lost follows the
    /// arc it was driving, not the tangent (a 60 m curve at 30 km/h leaves the tangent by
    /// 10 m in 5 s, far outside the camera's view).
    lost_turn_rate: f64,
    lost_since_update: u64,
    mode_lost_since: Option<u64>,
    /// The heartbeat has shown OFFBOARD since the autopilot accepted it (PX4 beats at
    /// 1 Hz: until then another mode is the old heartbeat, given `mode_timeout_s`).
    offboard_shown: bool,
    last_tick_ns: Option<u64>,
    last_status_ns: Option<u64>,
    transitioned: bool,
    transitions: Vec<Transition>,
    safety_ordered: bool,
    /// The mount-calibration survey under way (`[fsm.survey]`), inside Track.
    survey: Option<SurveyStep>,
    /// The survey was flown (once per mission).
    survey_done: bool,
}

/// Where the survey stands.
#[derive(Debug, Clone, Copy, PartialEq)]
struct SurveyStep {
    /// The point flown to (index into `SurveyConfig::points`).
    index: usize,
    /// When the vehicle got there.
    arrived_ns: Option<u64>,
    /// The mission heading, turned back to after the survey, rad.
    yaw0: f64,
}

/// The yaw within which a survey point counts as reached, rad (5 deg).
const SURVEY_YAW_TOLERANCE_RAD: f64 = 0.087;
/// The survey is flown over a pad slower than this only, m/s: a static one.
const SURVEY_PAD_SPEED_MAX_M_S: f64 = 0.2;
/// The speed below which a survey point counts as reached, m/s.
const SURVEY_SPEED_MAX_M_S: f64 = 0.2;

impl Fsm {
    /// A mission with `cfg` (validated), in Idle.
    pub fn new(cfg: FsmConfig) -> Self {
        let filter = PadFilter::new(cfg.pad_filter.clone());
        let started = cfg.autostart;
        let relative = RelativeTrack::new(cfg.relative_window_s);
        Self {
            cfg,
            state: MissionState::Idle,
            started,
            filter,
            odometry: Odometry::default(),
            relative,
            pad_header: None,
            vehicle: None,
            telemetry_arrived_ns: 0,
            trajectory: None,
            takeoff: TakeoffStep::EnteringOffboard,
            pending: None,
            mode_wait: None,
            next_request_id: 1,
            streaming: false,
            hold: Vector3::zeros(),
            yaw_sp: 0.0,
            guidance: Guidance::Planner,
            goal_epoch_ns: 0,
            last_goal_ns: None,
            goal_seq: 0,
            align_since: None,
            track_height: 1.0,
            h_cmd: 1.0,
            chase_trim: Vector3::zeros(),
            trim_chasing: false,
            chase_turn: Vector3::zeros(),
            drag_ref: None,
            z_cmd: 0.0,
            go_arounds: 0,
            brake_at_z: None,
            dropping: false,
            touch_since: None,
            drop_moving: false,
            manoeuvre_wait_since: None,
            manoeuvre_seen_ns: None,
            flare_waited_s: 0.0,
            touched: false,
            lost_z0: 0.0,
            now_ns: 0,
            lost_velocity: Vector3::zeros(),
            lost_turn_rate: 0.0,
            lost_since_update: 0,
            mode_lost_since: None,
            offboard_shown: true,
            last_tick_ns: None,
            last_status_ns: None,
            transitioned: true,
            transitions: Vec::new(),
            safety_ordered: false,
            watchdog_seen_ns: None,
            watchdog_phase: None,
            resume_since: None,
            survey: None,
            survey_done: false,
        }
    }

    /// The state now.
    pub fn state(&self) -> MissionState {
        self.state
    }

    /// Why the last transition happened.
    pub fn reason(&self) -> &str {
        self.transitions
            .last()
            .map_or("initial", |t| t.reason.as_str())
    }

    /// When the state was entered, ns (0 for the initial Idle).
    fn since_ns(&self) -> u64 {
        self.transitions.last().map_or(0, |t| t.at_ns)
    }

    /// Every transition so far.
    pub fn transitions(&self) -> &[Transition] {
        &self.transitions
    }

    /// The pad filter (counters, estimate).
    pub fn pad_filter(&self) -> &PadFilter {
        &self.filter
    }

    /// How often [`Fsm::tick`] is meant to be called (`rate_hz`), ns: the process's timer
    /// and the lockstep runner both use it.
    pub fn tick_period_ns(&self) -> u64 {
        (1e9 / self.cfg.rate_hz) as u64
    }

    /// An operator's start (when `autostart` is off).
    pub fn start(&mut self) {
        self.started = true;
    }

    /// The newest vehicle state, received at `now_ns`. Where it is now is carried
    /// forward from when the autopilot measured it (`msg.capture_ns`, its clock mapped
    /// onto ours); whether telemetry still comes is judged by when it arrived
    /// (`link.last_telemetry_ns`, px4-link's own clock), so neither a state px4-link
    /// repeats while the autopilot is silent nor an autopilot clock that runs slow (a
    /// simulator behind real time) changes the verdict.
    pub fn on_vehicle_state(&mut self, now_ns: u64, v: &VehicleState) {
        if v.world_from_body.is_finite() && v.velocity.iter().all(|x| x.is_finite()) {
            let stamp = |t: u64| match t {
                0 => now_ns,
                t => t.min(now_ns),
            };
            let t = stamp(v.msg.capture_ns);
            // Only a link that has heard the autopilot's heartbeat counts: a restarted
            // px4-link's first states (telemetry, no heartbeat yet) are flown on but do
            // not make the link fresh, nor stale before its budget.
            if v.link.connected != 0 {
                self.telemetry_arrived_ns = stamp(v.link.last_telemetry_ns);
            }
            self.vehicle = Some((t, *v));
            let p = Vector3::from(v.world_from_body.translation);
            self.odometry.on_state(t, p, Vector3::from(v.velocity));
        }
    }

    /// A pad observation, received at `now_ns`.
    pub fn on_observation(&mut self, now_ns: u64, obs: &PadObservation) -> Update {
        // Into the odometry frame (see `odometry`): the estimate's noise at the capture
        // time out, only the camera's error left.
        let mut in_odometry = *obs;
        let d = self.odometry.offset_at(obs.msg.capture_ns);
        let t = Vector3::from(obs.world_from_pad.translation) - d;
        in_odometry.world_from_pad.translation = t.into();
        let u = self.filter.update(now_ns, &in_odometry);
        if matches!(u, Update::Started | Update::Restarted) {
            self.relative.clear();
        }
        if matches!(u, Update::Accepted | Update::Started | Update::Restarted) {
            self.pad_header = Some(obs.msg);
            let capture = obs.msg.capture_ns;
            let r =
                Vector3::from(obs.world_from_pad.translation) - self.odometry.position_at(capture);
            self.relative.push(capture, r);
        }
        match u {
            Update::Restarted => tracing::warn!("pad observations jumped: pad filter restarted"),
            Update::Rejected => tracing::debug!("pad observation outside the gate"),
            _ => {}
        }
        u
    }

    /// A trajectory from the planner.
    pub fn on_trajectory(&mut self, t: &Trajectory) {
        let count = t.points().len();
        if count < 4 || !(t.knot_interval_s.is_finite() && t.knot_interval_s > 0.0) {
            return;
        }
        if let Some((id, _, _)) = &self.trajectory
            && t.id <= *id
        {
            return;
        }
        // Only plans made for the current goal, or an emergency stop.
        if t.start_ns < self.goal_epoch_ns && t.emergency == 0 {
            return;
        }
        let points = t.points().iter().map(|p| Vector3::from(*p)).collect();
        let spline = BSpline {
            points,
            ts: t.knot_interval_s,
        };
        self.trajectory = Some((t.id, spline, t.start_ns));
    }

    /// An answer from px4-link.
    pub fn on_outcome(&mut self, o: &LinkOutcome) {
        if let Some(p) = &mut self.pending
            && p.id == o.id
            && p.sent_ns.is_some()
        {
            let kind = LinkOutcomeKind::from_raw(o.outcome);
            p.answer = Some((kind, o.result));
        }
    }

    /// An order from the watchdog or an operator: executed at once (px4-link executes
    /// the autopilot side itself; the fsm stops the mission).
    pub fn on_safety(&mut self, now_ns: u64, c: &SafetyCommand) {
        let source = c.source.as_str();
        let why = c.reason.as_str();
        match SafetyAction::from_raw(c.action) {
            SafetyAction::None => {}
            SafetyAction::Hold | SafetyAction::Abort => {
                if !matches!(self.state, MissionState::Abort | MissionState::Landed) {
                    self.safety_ordered = true;
                    self.go(now_ns, MissionState::Abort, format!("{source}: {why}"));
                }
            }
            SafetyAction::SafeLand => {
                if !matches!(self.state, MissionState::SafeLand | MissionState::Landed) {
                    self.safety_ordered = true;
                    self.go(now_ns, MissionState::SafeLand, format!("{source}: {why}"));
                }
            }
        }
    }

    /// The watchdog's view arrived at `now_ns`: the stack is supervised, and `phase` is
    /// the mission state it last saw (raw; what a restarted fsm resumes from).
    pub fn on_watchdog_view(&mut self, now_ns: u64, phase: u32) {
        self.watchdog_seen_ns = Some(now_ns);
        // A restarted fsm's own first status (Idle) soon reaches the watchdog: the state
        // before it is the one to resume from.
        match MissionState::from_raw(phase) {
            Some(MissionState::Idle) if self.watchdog_phase.is_some() => {}
            p => self.watchdog_phase = p,
        }
    }

    /// One step at `now_ns` (call at `rate_hz`).
    pub fn tick(&mut self, now_ns: u64) -> Outputs {
        self.now_ns = self.now_ns.max(now_ns);
        let dt = self
            .last_tick_ns
            .map(|t| secs_since(t, now_ns))
            .unwrap_or(0.0)
            .min(0.2);
        self.last_tick_ns = Some(now_ns);
        let mut out = Outputs::default();
        self.check_links(now_ns);
        self.slew_chase_turn(now_ns, dt);
        self.follow_drag(now_ns, dt);
        match self.state {
            MissionState::Idle => self.idle(now_ns, &mut out),
            MissionState::Takeoff => self.takeoff(now_ns, &mut out),
            MissionState::GoToPreset | MissionState::WaitForPad => self.preset(now_ns, &mut out),
            MissionState::Track => self.track(now_ns, dt, &mut out),
            MissionState::Descend => self.descend(now_ns, dt, &mut out),
            MissionState::Land => self.land(now_ns, dt, &mut out),
            MissionState::Lost => self.lost(now_ns, &mut out),
            MissionState::SafeLand => self.safe_land(now_ns, &mut out),
            MissionState::Landed | MissionState::Abort => {}
        }
        if !self.streaming {
            out.setpoint = None;
        }
        if self.transitioned
            || self
                .last_status_ns
                .is_none_or(|t| secs_since(t, now_ns) >= self.cfg.status_period_s)
        {
            self.transitioned = false;
            self.last_status_ns = Some(now_ns);
            out.status = Some(self.status(now_ns));
        }
        out
    }

    /// The status message now.
    pub fn status(&self, now_ns: u64) -> FsmStatus {
        let mut msg = Header::captured_at(now_ns);
        // Bumped by each transition (periodic repeats carry the same number).
        msg.seq = self.transitions.len() as u64;
        msg.push_stage(Stage::Fsm, now_ns, now_ns);
        let est = self.pad_estimate(now_ns);
        FsmStatus {
            msg,
            state: self.state as u32,
            previous: self
                .transitions
                .last()
                .map_or(MissionState::Idle, |t| t.from) as u32,
            since_ns: self.since_ns(),
            reason: Text::new(self.reason()),
            pad_valid: u32::from(est.is_some()),
            reserved: 0,
            pad_position: est.map(|e| e.position.into()).unwrap_or([0.0; 3]),
            pad_velocity: est.map(|e| e.velocity.into()).unwrap_or([0.0; 3]),
            pad_acceleration: est.map(|e| e.acceleration.into()).unwrap_or([0.0; 3]),
        }
    }

    fn go(&mut self, now_ns: u64, to: MissionState, reason: String) {
        if to == self.state {
            return;
        }
        tracing::info!(
            from = self.state.name(),
            to = to.name(),
            reason = reason.as_str(),
            "transition"
        );
        self.transitions.push(Transition {
            at_ns: now_ns,
            from: self.state,
            to,
            reason,
        });
        self.state = to;
        self.transitioned = true;
        self.align_since = None;
        self.mode_wait = None;
        match to {
            MissionState::SafeLand | MissionState::Abort | MissionState::Landed => {
                self.streaming = false;
                self.pending = None;
            }
            MissionState::Takeoff => {
                self.takeoff = TakeoffStep::EnteringOffboard;
                self.pending = None;
                self.streaming = false;
            }
            _ => {}
        }
    }

    fn elapsed_s(&self, now_ns: u64) -> f64 {
        secs_since(self.since_ns(), now_ns)
    }

    fn vehicle(&self) -> Option<&VehicleState> {
        self.vehicle.as_ref().map(|(_, v)| v)
    }

    /// The vehicle's position now: the newest state's, carried forward by its velocity
    /// over its age (at most [`CARRY_MAX_S`]). The pad estimate is predicted to now and
    /// the two are compared: with the state taken as now, every millisecond of telemetry
    /// latency put the pad that much of the vehicle's motion off (8 cm at 0.8 m/s and
    /// 100 ms, on a loaded machine), and the touchdown dropped off the centre.
    fn position(&self) -> Option<Vector3<f64>> {
        self.vehicle.as_ref().map(|(t, v)| {
            let age = secs_since(*t, self.now_ns).min(CARRY_MAX_S);
            Vector3::from(v.world_from_body.translation) + Vector3::from(v.velocity) * age
        })
    }

    fn velocity(&self) -> Vector3<f64> {
        self.vehicle()
            .map(|v| Vector3::from(v.velocity))
            .unwrap_or_else(Vector3::zeros)
    }

    /// Telemetry and flight-mode checks shared by every airborne state.
    fn check_links(&mut self, now_ns: u64) {
        let airborne = matches!(
            self.state,
            MissionState::Takeoff
                | MissionState::GoToPreset
                | MissionState::WaitForPad
                | MissionState::Track
                | MissionState::Descend
                | MissionState::Land
                | MissionState::Lost
        );
        if !airborne {
            return;
        }
        if !self.link_fresh(now_ns) {
            self.go(now_ns, MissionState::SafeLand, "telemetry lost".into());
            return;
        }
        // A silent watchdog is a fault of its own (it may have died, or hung): nothing
        // would land the vehicle on the next fault. Over the pad the descent goes on.
        let unsupervised = self
            .watchdog_seen_ns
            .is_some_and(|t| secs_since(t, now_ns) > self.cfg.watchdog_timeout_s);
        if unsupervised && !matches!(self.state, MissionState::Descend | MissionState::Land) {
            self.go(now_ns, MissionState::SafeLand, "watchdog silent".into());
            return;
        }
        // Once in OFFBOARD, another mode shown for a while means the pilot or a PX4
        // failsafe took over: the mission yields instead of fighting it.
        let in_offboard_phase =
            self.state != MissionState::Takeoff || self.takeoff != TakeoffStep::EnteringOffboard;
        if in_offboard_phase {
            let mode = self
                .vehicle()
                .map(|v| FlightMode::from_raw(v.flight_mode))
                .unwrap_or(FlightMode::Unknown);
            // Just accepted, the heartbeat may show the old mode for up to a second (more
            // on a loaded machine): only `mode_timeout_s` without OFFBOARD is a loss then.
            let limit_ns = if self.offboard_shown {
                MODE_LOSS_NS
            } else {
                ((self.cfg.mode_timeout_s * 1e9) as u64).max(MODE_LOSS_NS)
            };
            if mode == FlightMode::Offboard {
                self.mode_lost_since = None;
                self.offboard_shown = true;
            } else {
                let since = *self.mode_lost_since.get_or_insert(now_ns);
                if now_ns.saturating_sub(since) >= limit_ns {
                    self.go(
                        now_ns,
                        MissionState::Abort,
                        format!("autopilot left OFFBOARD ({mode:?})"),
                    );
                }
            }
        }
    }

    /// Sends `kind` and follows it through retries; one request at a time.
    fn drive(
        &mut self,
        now_ns: u64,
        kind: LinkRequestKind,
        altitude_m: f64,
        out: &mut Outputs,
    ) -> Drive {
        let mut p = match self.pending {
            Some(p) if p.kind == kind => p,
            _ => Pending {
                kind,
                id: 0,
                attempts: 0,
                sent_ns: None,
                retry_at_ns: now_ns,
                answer: None,
            },
        };
        match (p.sent_ns, p.answer) {
            (None, _) if now_ns >= p.retry_at_ns => {
                p.id = self.next_request_id;
                self.next_request_id += 1;
                p.attempts += 1;
                p.sent_ns = Some(now_ns);
                p.answer = None;
                let mut msg = Header::captured_at(now_ns);
                msg.push_stage(Stage::Fsm, now_ns, now_ns);
                out.requests.push(LinkRequest {
                    msg,
                    id: p.id,
                    kind: kind as u32,
                    reserved: 0,
                    altitude_m,
                });
                tracing::info!(?kind, attempt = p.attempts, "autopilot request");
            }
            (Some(_), Some((LinkOutcomeKind::Accepted, _))) => {
                self.pending = None;
                return Drive::Accepted(p.attempts);
            }
            (Some(sent), answer) => {
                let failure = match answer {
                    Some((k, code)) => Some(format!("{k:?} (MAV_RESULT {code})")),
                    None if now_ns.saturating_sub(sent) >= NO_ANSWER_NS => {
                        Some("no answer from px4-link".to_string())
                    }
                    None => None,
                };
                if let Some(f) = failure {
                    tracing::warn!(
                        ?kind,
                        attempt = p.attempts,
                        failure = f.as_str(),
                        "request failed"
                    );
                    if p.attempts >= self.cfg.request_attempts {
                        self.pending = None;
                        return Drive::Failed(format!("{kind:?} failed {} times: {f}", p.attempts));
                    }
                    p.sent_ns = None;
                    p.retry_at_ns = now_ns + (self.cfg.request_retry_s * 1e9) as u64;
                }
            }
            _ => {}
        }
        self.pending = Some(p);
        Drive::Waiting
    }

    /// The newest telemetry of a connected link arrived within `telemetry_timeout_s`.
    pub fn link_fresh(&self, now_ns: u64) -> bool {
        self.telemetry_arrived_ns != 0
            && secs_since(self.telemetry_arrived_ns, now_ns) <= self.cfg.telemetry_timeout_s
    }

    fn idle(&mut self, now_ns: u64, out: &mut Outputs) {
        if self.resume(now_ns, out) {
            return;
        }
        // Armed already: a mission under way (a restart on the pad), not one to start.
        if !self.started || self.vehicle().is_some_and(|v| v.armed != 0) {
            return;
        }
        if self.link_fresh(now_ns) {
            self.go(now_ns, MissionState::Takeoff, "started, link up".into());
        }
    }

    /// A fresh fsm that finds the vehicle armed, in the air and in OFFBOARD was restarted
    /// in flight: it resumes the mission (never a second take-off) once it has waited
    /// [`RESUME_WAIT_NS`] for the watchdog's view, which keeps the state it was in, and for
    /// the pad. True while resuming (nothing else to do in Idle).
    fn resume(&mut self, now_ns: u64, out: &mut Outputs) -> bool {
        let flying = self.link_fresh(now_ns)
            && self.vehicle().is_some_and(|v| {
                v.armed != 0 && FlightMode::from_raw(v.flight_mode) == FlightMode::Offboard
            });
        if !self.transitions.is_empty() || !flying {
            self.resume_since = None;
            return false;
        }
        let (Some(p), Some(v)) = (self.position(), self.vehicle().copied()) else {
            return false;
        };
        let since = *self.resume_since.get_or_insert(now_ns);
        // Hold where it is meanwhile: px4-link repeats a dead fsm's last setpoint for a
        // moment only, and PX4 leaves OFFBOARD a second after the last.
        if !self.streaming {
            self.hold = p;
            self.yaw_sp = yaw_of(&v.world_from_body.rotation_xyzw);
            self.streaming = true;
        }
        out.setpoint = Some(self.hold_setpoint(now_ns, self.hold));
        let pad = self.pad(now_ns);
        let waited = now_ns.saturating_sub(since) >= RESUME_WAIT_NS;
        if !waited && (self.watchdog_phase.is_none() || pad.is_none()) {
            return true;
        }
        let was = self.watchdog_phase.unwrap_or(MissionState::Idle);
        let why = format!("restarted in flight (was {})", was.name());
        let in_air = LandedState::from_raw(v.landed_state) == LandedState::InAir;
        use MissionState as M;
        match (was, pad) {
            (M::SafeLand | M::Abort | M::Landed, _) => self.go(now_ns, M::SafeLand, why),
            // On the pad already, motors still on: finish the touchdown (switch them off).
            (M::Descend | M::Land, _) if !in_air => {
                self.z_cmd = p.z;
                self.dropping = true;
                self.drop_moving = false;
                self.touch_since = None;
                self.touched = false;
                self.go(now_ns, M::Land, why);
            }
            // Armed on the ground with no descent to finish: nothing to resume.
            (_, _) if !in_air => {
                self.streaming = false;
                return false;
            }
            (M::Descend | M::Land, Some(est)) => {
                self.h_cmd = p.z - est.position.z;
                self.track_height = self.h_cmd.max(self.cfg.commit_height_m + 0.3);
                self.guidance = Guidance::Direct;
                self.go(now_ns, M::Descend, why);
            }
            (_, Some(_)) => {
                self.enter_track(now_ns, why);
                self.guidance = Guidance::Direct;
            }
            (M::Track | M::Descend | M::Land | M::Lost, None) => self.enter_lost(now_ns),
            (_, None) => self.enter_preset(now_ns, why),
        }
        true
    }

    fn takeoff_altitude(&self) -> f64 {
        self.preset_point().z.min(self.cfg.takeoff_altitude_m)
    }

    fn takeoff(&mut self, now_ns: u64, out: &mut Outputs) {
        if self.elapsed_s(now_ns) > self.cfg.takeoff_timeout_s {
            self.go(
                now_ns,
                MissionState::SafeLand,
                format!("takeoff timed out ({:?})", self.takeoff),
            );
            return;
        }
        if !self.streaming {
            // The ground position: held while OFFBOARD is asked for and the motors arm.
            let (Some(p), Some(v)) = (self.position(), self.vehicle().copied()) else {
                return;
            };
            self.hold = p;
            self.yaw_sp = yaw_of(&v.world_from_body.rotation_xyzw);
            self.streaming = true;
        }
        let alt = self.takeoff_altitude();
        match self.takeoff {
            TakeoffStep::EnteringOffboard => {
                out.setpoint = Some(self.hold_setpoint(now_ns, self.hold));
                match self.drive(now_ns, LinkRequestKind::Offboard, 0.0, out) {
                    Drive::Accepted(_) => {
                        self.mode_lost_since = None;
                        self.offboard_shown = false;
                        self.takeoff = TakeoffStep::Arming;
                    }
                    Drive::Failed(why) => self.go(now_ns, MissionState::SafeLand, why),
                    Drive::Waiting => {}
                }
            }
            TakeoffStep::Arming => {
                out.setpoint = Some(self.hold_setpoint(now_ns, self.hold));
                match self.drive(now_ns, LinkRequestKind::Arm, 0.0, out) {
                    Drive::Accepted(_) => self.takeoff = TakeoffStep::Climbing { since_ns: now_ns },
                    Drive::Failed(why) => self.go(now_ns, MissionState::SafeLand, why),
                    Drive::Waiting => {}
                }
            }
            TakeoffStep::Climbing { since_ns } => {
                let t = secs_since(since_ns, now_ns);
                let rate = self.cfg.takeoff_climb_m_s;
                let z = (self.hold.z + rate * t).min(alt.max(self.hold.z));
                let vz = if z < alt { rate } else { 0.0 };
                let target = Vector3::new(self.hold.x, self.hold.y, z);
                out.setpoint = Some(self.setpoint(
                    now_ns,
                    target,
                    Vector3::new(0.0, 0.0, vz),
                    Vector3::zeros(),
                ));
                let (Some(p), Some(v)) = (self.position(), self.vehicle().copied()) else {
                    return;
                };
                let up = LandedState::from_raw(v.landed_state) == LandedState::InAir;
                if p.z >= alt - 0.15 && up {
                    self.hold = Vector3::new(self.hold.x, self.hold.y, alt);
                    self.enter_preset(now_ns, "takeoff altitude reached".into());
                }
            }
        }
    }

    fn enter_preset(&mut self, now_ns: u64, reason: String) {
        self.go(now_ns, MissionState::GoToPreset, reason);
        self.new_goal_epoch(now_ns);
        self.guidance = Guidance::Planner;
    }

    fn new_goal_epoch(&mut self, now_ns: u64) {
        self.goal_epoch_ns = now_ns;
        self.last_goal_ns = None;
        self.trajectory = None;
        if let Some(p) = self.position() {
            self.hold = p;
        }
    }

    /// The pad filter's estimate, from the odometry frame into the vehicle's current
    /// estimate: `pad - vehicle` is what the camera measured, whatever the estimate's noise.
    fn pad_estimate(&self, now_ns: u64) -> Option<PadEstimate> {
        let mut est = self.filter.estimate(now_ns)?;
        est.position += self.odometry.offset_now();
        Some(est)
    }

    fn pad(&self, now_ns: u64) -> Option<PadEstimate> {
        let est = self.pad_estimate(now_ns)?;
        (est.age_s <= self.cfg.lost_after_s).then_some(est)
    }

    /// The preset point at a height the camera can see the pad from.
    fn preset_point(&self) -> Vector3<f64> {
        let [x, y, z] = self.cfg.preset_m;
        Vector3::new(x, y, z.min(self.search_ceiling()))
    }

    fn search_ceiling(&self) -> f64 {
        self.cfg.search_height_max_m.unwrap_or(f64::INFINITY)
    }

    fn preset(&mut self, now_ns: u64, out: &mut Outputs) {
        let preset = self.preset_point();
        let limit = if self.state == MissionState::GoToPreset {
            self.cfg.goto_timeout_s
        } else {
            self.cfg.wait_timeout_s
        };
        if self.elapsed_s(now_ns) > limit {
            let why = if self.state == MissionState::GoToPreset {
                "preset point not reached in time"
            } else {
                "pad not seen in time"
            };
            self.go(now_ns, MissionState::SafeLand, why.into());
            return;
        }
        if self.pad(now_ns).is_some() {
            self.enter_track(now_ns, "pad seen".into());
            self.track(now_ns, 0.0, out);
            return;
        }
        let waited = self.elapsed_s(now_ns) - self.cfg.search_after_s;
        if self.state == MissionState::WaitForPad && waited > 0.0 {
            // Not in view from the preset point: climb over it to see more ground, never
            // above the height the pad's markers can be read from.
            let most = self
                .cfg
                .search_climb_m
                .min((self.search_ceiling() - preset.z).max(0.0));
            let climb = (waited * self.cfg.lost_climb_m_s).min(most);
            let vz = if climb < most {
                self.cfg.lost_climb_m_s
            } else {
                0.0
            };
            let mut sp = self.hold_setpoint(now_ns, preset + Vector3::new(0.0, 0.0, climb));
            sp.velocity[2] = vz;
            out.setpoint = Some(sp);
            return;
        }
        self.publish_goal(now_ns, GoalMode::Point, preset, Vector3::zeros(), out);
        out.setpoint = Some(self.trajectory_setpoint(now_ns));
        if self.state == MissionState::GoToPreset
            && self
                .position()
                .is_some_and(|p| (p - preset).norm() <= self.cfg.preset_tolerance_m)
        {
            self.go(
                now_ns,
                MissionState::WaitForPad,
                "at the preset point".into(),
            );
        }
    }

    fn enter_track(&mut self, now_ns: u64, reason: String) {
        let from = self.state;
        self.go(now_ns, MissionState::Track, reason);
        self.new_goal_epoch(now_ns);
        self.guidance = Guidance::Planner;
        if let (Some(p), Some(est)) = (self.position(), self.pad_estimate(now_ns)) {
            let h = p.z - est.position.z;
            let lo = self.cfg.commit_height_m + 0.3;
            let hi = self.cfg.track_height_max_m.max(lo);
            // Coming back up from a descent keeps at least the height it had.
            self.track_height = if matches!(from, MissionState::Descend | MissionState::Land) {
                (h + 0.3).clamp(lo, hi)
            } else {
                h.clamp(lo, hi)
            };
        }
    }

    fn track(&mut self, now_ns: u64, dt: f64, out: &mut Outputs) {
        if self.elapsed_s(now_ns) > self.cfg.track_timeout_s {
            self.go(now_ns, MissionState::SafeLand, "tracking timed out".into());
            return;
        }
        let Some(est) = self.pad(now_ns) else {
            self.enter_lost(now_ns);
            return;
        };
        let Some(p) = self.position() else { return };
        if self.survey.is_some() {
            self.survey(now_ns, &est, &p, out);
            return;
        }
        let e = (est.position - p).xy();
        let dist = e.norm();
        let chase = self.chasing(&est.velocity);
        match self.guidance {
            Guidance::Planner if dist <= self.cfg.direct_range_m || chase => {
                self.guidance = Guidance::Direct
            }
            Guidance::Direct if dist > 1.5 * self.cfg.direct_range_m && !chase => {
                self.guidance = Guidance::Planner;
                self.new_goal_epoch(now_ns);
            }
            _ => {}
        }
        let above = Vector3::new(0.0, 0.0, self.track_height);
        if self.guidance == Guidance::Planner {
            let t_go = (dist / self.cfg.approach_speed_m_s).clamp(0.5, 5.0);
            let v_pad = Vector3::new(est.velocity.x, est.velocity.y, 0.0);
            let meet = est.position + v_pad * t_go + above;
            self.publish_goal(now_ns, GoalMode::Rendezvous, meet, v_pad, out);
            out.setpoint = Some(self.trajectory_setpoint(now_ns));
            return;
        }
        self.integrate_chase_trim(&est, &p, dt);
        out.setpoint =
            Some(self.pad_setpoint(now_ns, &est, est.position.z + self.track_height, 0.0));
        let rel_v = (self.velocity() - est.velocity).xy().norm();
        if dist < self.cfg.align_m && rel_v < self.cfg.align_speed_m_s {
            let since = *self.align_since.get_or_insert(now_ns);
            if secs_since(since, now_ns) >= self.cfg.align_hold_s {
                if self.cfg.survey.enabled()
                    && !self.survey_done
                    && est.velocity.xy().norm() < SURVEY_PAD_SPEED_MAX_M_S
                {
                    tracing::info!(
                        points = self.cfg.survey.points().len(),
                        "aligned over the pad: survey for the mount calibration"
                    );
                    self.survey = Some(SurveyStep {
                        index: 0,
                        arrived_ns: None,
                        yaw0: self.yaw_sp,
                    });
                    self.align_since = None;
                    return;
                }
                self.h_cmd = p.z - est.position.z;
                self.go(now_ns, MissionState::Descend, "aligned over the pad".into());
            }
        } else {
            self.align_since = None;
        }
    }

    /// The survey (`[fsm.survey]`): each point in turn, held once reached (position,
    /// speed and yaw); then the mission heading again and the usual alignment and
    /// descent. The points follow the pad's estimate, so the pad stays under the camera.
    fn survey(&mut self, now_ns: u64, est: &PadEstimate, p: &Vector3<f64>, out: &mut Outputs) {
        let Some(mut step) = self.survey else { return };
        let points = self.cfg.survey.points();
        let Some(&(offset, yaw)) = points.get(step.index) else {
            tracing::info!(points = points.len(), "survey done");
            self.survey = None;
            self.survey_done = true;
            self.yaw_sp = step.yaw0;
            self.align_since = None;
            return;
        };
        let target = est.position + Vector3::from(offset);
        self.yaw_sp = wrap(step.yaw0 + yaw);
        out.setpoint = Some(self.hold_setpoint(now_ns, target));
        let yaw_error = self
            .vehicle()
            .map(|v| wrap(yaw_of(&v.world_from_body.rotation_xyzw) - self.yaw_sp).abs())
            .unwrap_or(f64::INFINITY);
        let there = (target - p).norm() < self.cfg.survey.tolerance_m
            && self.velocity().norm() < SURVEY_SPEED_MAX_M_S
            && yaw_error < SURVEY_YAW_TOLERANCE_RAD;
        if there || step.arrived_ns.is_some() {
            let since = *step.arrived_ns.get_or_insert(now_ns);
            if secs_since(since, now_ns) >= self.cfg.survey.hold_s {
                tracing::info!(
                    point = step.index + 1,
                    of = points.len(),
                    "survey point held"
                );
                step.index += 1;
                step.arrived_ns = None;
            }
        }
        self.survey = Some(step);
    }

    fn go_around(&mut self, now_ns: u64, why: String) {
        self.go_arounds += 1;
        // A drop under way is over: the next descent pulls toward the pad as the first.
        self.dropping = false;
        if self.go_arounds > self.cfg.max_go_arounds {
            // Over a fast pad the vehicle flies at the road's speed: landing in place would
            // meet the road at it (8 m/s at 30 km/h, and it tips over). Brake first, a metre
            // higher, clear of the vehicle it chased.
            let fast = self.moving_to_brake();
            self.brake_at_z = self.position().filter(|_| fast).map(|p| p.z + 1.0);
            self.go(
                now_ns,
                MissionState::SafeLand,
                format!(
                    "{why}; {} go-arounds, landing in place",
                    self.go_arounds - 1
                ),
            );
        } else {
            self.enter_track(now_ns, format!("go-around {}: {why}", self.go_arounds));
            self.guidance = Guidance::Direct;
        }
    }

    fn descend(&mut self, now_ns: u64, dt: f64, out: &mut Outputs) {
        if self.elapsed_s(now_ns) > self.cfg.descend_timeout_s {
            // Over a fast pad, landing in place is landing in the road: try again.
            let fast = self.pad(now_ns).is_some_and(|e| self.chasing(&e.velocity));
            if fast {
                self.go_around(now_ns, "descent timed out over a moving pad".into());
            } else {
                self.go(now_ns, MissionState::SafeLand, "descent timed out".into());
            }
            return;
        }
        let Some(est) = self.pad(now_ns) else {
            self.enter_lost(now_ns);
            return;
        };
        let Some(p) = self.position() else { return };
        self.integrate_chase_trim(&est, &p, dt);
        self.note_manoeuvre(now_ns, &est);
        let e = (est.position - p).xy().norm();
        if e > self.cfg.go_around_m {
            self.go_around(now_ns, format!("{e:.2} m off the pad while descending"));
            return;
        }
        let height = p.z - est.position.z;
        let rel_v = (self.velocity() - est.velocity).xy().norm();
        // Descend only while close to the commit gate; hold the height otherwise (and
        // at the commit height until the commit gates hold), so the vehicle converges
        // over the pad before it is low.
        let aligned = e < 1.5 * self.cfg.land_align_m;
        let floor = self.cfg.commit_height_m - (0.25 * self.cfg.commit_height_m).min(0.1);
        let rate = if aligned && self.h_cmd > floor {
            self.cfg.descend_rate_m_s
        } else {
            0.0
        };
        self.h_cmd = (self.h_cmd - rate * dt).max(floor);
        out.setpoint = Some(self.pad_setpoint(now_ns, &est, est.position.z + self.h_cmd, -rate));
        let gates = height < self.cfg.commit_height_m
            && e < self.cfg.land_align_m
            && rel_v < self.cfg.land_speed_gate_m_s;
        if !gates {
            self.align_since = None;
        }
        // The gates must hold a moment: one lucky frame of a noisy estimate is no commit.
        let held = gates && {
            let since = *self.align_since.get_or_insert(now_ns);
            secs_since(since, now_ns) >= 0.5 * self.cfg.align_hold_s
        };
        if held {
            self.z_cmd = p.z;
            self.dropping = false;
            self.touch_since = None;
            self.drop_moving = false;
            self.manoeuvre_wait_since = None;
            self.flare_waited_s = 0.0;
            self.touched = false;
            self.go(
                now_ns,
                MissionState::Land,
                format!("committed at {height:.2} m, {e:.2} m off, {rel_v:.2} m/s"),
            );
        }
    }

    fn land(&mut self, now_ns: u64, dt: f64, out: &mut Outputs) {
        let Some(v) = self.vehicle().copied() else {
            return;
        };
        let on_ground = LandedState::from_raw(v.landed_state) == LandedState::OnGround;
        if v.armed == 0 && on_ground {
            self.go(
                now_ns,
                MissionState::Landed,
                "touched down, disarmed".into(),
            );
            return;
        }
        if self.elapsed_s(now_ns) > self.cfg.land_timeout_s {
            self.go(now_ns, MissionState::SafeLand, "touchdown timed out".into());
            return;
        }
        // Close to the pad the camera may see too little: the filter carries the pad.
        let Some(est) = self.pad_estimate(now_ns) else {
            self.go(
                now_ns,
                MissionState::SafeLand,
                "pad estimate gone during touchdown".into(),
            );
            return;
        };
        // Carried to now, as everywhere else: at 30 km/h a vehicle state 50 ms old puts
        // the vehicle 0.4 m behind where it is (every --processes touchdown of
        // highspeed-30 went around on it, three times, and landed in the road).
        let Some(p) = self.position() else { return };
        if !self.dropping {
            self.integrate_chase_trim(&est, &p, dt);
        }
        let offset = (est.position - p).xy();
        let e = offset.norm();
        let height = p.z - est.position.z;
        if !on_ground && e > self.cfg.go_around_m && height > 0.15 {
            self.go_around(now_ns, format!("{e:.2} m off the pad at {height:.2} m"));
            return;
        }
        let flare = self.cfg.flare_height_m.min(self.cfg.commit_height_m - 0.05);
        // The pad unseen too long: its estimate is an extrapolation. Low and aligned when
        // it was last seen, drop now (the drop takes a tenth of a second; waiting only
        // lets the extrapolation drift); otherwise climb back and find it again.
        if !on_ground && !self.dropping && est.age_s > self.cfg.land_max_pad_age_s {
            if height <= flare + 0.03 && e < self.cfg.land_align_m {
                self.dropping = true;
            } else {
                self.go_around(
                    now_ns,
                    format!("pad unseen for {:.1} s at {height:.2} m", est.age_s),
                );
                return;
            }
        }
        // The drop stopped at the pad's height: the gear is on it. Motors off now (a forced
        // disarm): PX4's land detector needs a second of low thrust to agree, and until then
        // its controller tilts the vehicle about feet that grip a moving pad.
        let vz = v.velocity[2];
        let vz_rel = vz - est.velocity.z;
        self.drop_moving |= self.dropping && vz_rel < -0.5 * self.cfg.drop_rate_m_s;
        let still = vz_rel > -TOUCH_STILL_M_S;
        // Far above the estimate, stopped in the world as well: an estimate sinking under
        // the drop makes a moving vehicle look still relative to it.
        let near = height < TOUCH_HEIGHT_M;
        let far = height < TOUCH_HEIGHT_FAR_M && vz > -TOUCH_STILL_M_S;
        if self.drop_moving && !on_ground && still && (near || far) {
            let since = *self.touch_since.get_or_insert(now_ns);
            let held = secs_since(since, now_ns);
            let hold = if near { TOUCH_HOLD_S } else { TOUCH_HOLD_FAR_S };
            self.touched |= held >= hold;
        } else {
            self.touch_since = None;
        }
        if self.touched && v.armed != 0 {
            let why = format!("touched down {height:.2} m over the pad estimate, motors off");
            let rate = self.cfg.drop_rate_m_s;
            self.motors_off(now_ns, &est, rate, LinkRequestKind::Touchdown, why, out);
            return;
        }
        if on_ground {
            let rate = self.cfg.land_rate_m_s;
            let why = "touched down, disarmed".to_string();
            self.motors_off(now_ns, &est, rate, LinkRequestKind::Disarm, why, out);
            return;
        }
        // Down to the flare height at the touchdown rate (slowing to a hover when off the
        // commit gate); there, wait until the vehicle is right over the pad and moving
        // with it, then drop: a gust has a fraction of a second to push it off, not the
        // whole descent. Below the chase speed, also wait while the pad brakes or changes
        // lane (a drop begun in one ends 8-16 cm off), for at most MANOEUVRE_WAIT_MAX_S: a
        // slow vehicle circling for good is a steady turn the feed-forward follows.
        let gate = self.cfg.land_align_m;
        let rel_v = (Vector3::from(v.velocity) - est.velocity).xy().norm();
        let at_flare = !self.dropping && height <= flare + 0.03;
        self.note_manoeuvre(now_ns, &est);
        // Quiet for a while, not for a moment: in a lane change's middle the acceleration
        // turns over, under the gate for a few tenths of a second, while the pad moves
        // sideways fastest and is about to slow down.
        let manoeuvring = self
            .manoeuvre_seen_ns
            .is_some_and(|seen| secs_since(seen, now_ns) < self.cfg.flare_quiet_s);
        let waited = if at_flare && manoeuvring {
            let since = *self.manoeuvre_wait_since.get_or_insert(now_ns);
            secs_since(since, now_ns)
        } else {
            0.0
        };
        let held_by_manoeuvre = manoeuvring && waited < MANOEUVRE_WAIT_MAX_S;
        // Tight at first (a drop begun 4 cm off ends 5-8 cm off in wind), wider the
        // longer the vehicle has waited for nothing but alignment: a steady turn or gusts
        // may never let it that close. Time held by a manoeuvre does not count: after a
        // long turn the gate would be wide open the moment the pad straightens.
        if at_flare && !held_by_manoeuvre {
            self.flare_waited_s += dt;
        }
        let chasing = self.chasing(&est.velocity);
        let tight = if chasing {
            self.cfg.chase_flare_align_m
        } else {
            self.cfg.flare_align_m
        };
        let relax = (self.flare_waited_s / self.cfg.flare_relax_s).clamp(0.0, 1.0);
        let align = tight + (gate - tight).max(0.0) * relax * relax;
        // Below the chase speed, also wait until the vehicle has stopped moving over the
        // pad by the camera's own reading (a line through its last quarter second): the
        // drop is open loop, and the pad filter's velocity lags a braking just begun (the
        // worst paper-speed runs began the drop 9-16 cm/s off the pad's speed, reading 4).
        // Widening with the wait as the offset's gate does; without fresh observations
        // (the pad too close to read) the filter's relative speed alone decides.
        let settle = self.cfg.flare_settle_m_s
            + (self.cfg.land_speed_gate_m_s - self.cfg.flare_settle_m_s).max(0.0) * relax * relax;
        let camera_velocity = self.relative.velocity(now_ns);
        let settled = chasing || camera_velocity.is_none_or(|u| u.xy().norm() < settle);
        // Where the vehicle will be over the pad at contact, by the camera: the offset now
        // plus the relative velocity over the fall.
        let landing_within = self.cfg.flare_fall_s <= 0.0
            || chasing
            || camera_velocity
                .is_none_or(|u| (offset + u.xy() * self.cfg.flare_fall_s).norm() < align);
        if at_flare
            && !held_by_manoeuvre
            && e < align
            && rel_v < self.cfg.land_speed_gate_m_s
            && settled
            && landing_within
        {
            self.dropping = true;
        }
        let rate = if self.dropping {
            self.cfg.drop_rate_m_s
        } else {
            self.cfg.land_rate_m_s * ((gate - e) / (0.5 * gate)).clamp(0.0, 1.0)
        };
        // Never back up: a vehicle that committed below the flare height waits there.
        let floor = if self.dropping {
            est.position.z - 0.3
        } else {
            (est.position.z + flare).min(self.z_cmd)
        };
        // Dropping, the descent rate stays commanded below the floor too: PX4's land
        // detector sees ground contact only while a descent of at least 90 % of
        // MPC_LAND_SPEED is asked for and none happens (MulticopterLandDetector).
        let rate = if self.z_cmd <= floor && !self.dropping {
            0.0
        } else {
            rate
        };
        self.z_cmd = (self.z_cmd - rate * dt).max(floor);
        // The setpoint never runs more than TOUCHDOWN_LEAD_M below the vehicle: PX4 adds
        // MPC_Z_P times that lead to the descent asked for, and a drop begun higher than
        // usual (a pad estimate a few cm low) would otherwise reach contact still speeding
        // up towards the drop rate plus the lead.
        self.z_cmd = self.z_cmd.max(p.z - TOUCHDOWN_LEAD_M);
        out.setpoint = Some(self.pad_setpoint(now_ns, &est, self.z_cmd, -rate));
    }

    /// On the pad: stay pressed onto it at `rate`, moving with it, while `kind` (a disarm,
    /// forced or not) switches the motors off; Landed with `why` once it is accepted.
    fn motors_off(
        &mut self,
        now_ns: u64,
        est: &PadEstimate,
        rate: f64,
        kind: LinkRequestKind,
        why: String,
        out: &mut Outputs,
    ) {
        out.setpoint = Some(self.pad_setpoint(now_ns, est, est.position.z - 0.3, -rate));
        match self.drive(now_ns, kind, 0.0, out) {
            Drive::Accepted(_) => self.go(now_ns, MissionState::Landed, why),
            Drive::Failed(why) => self.go(now_ns, MissionState::SafeLand, why),
            Drive::Waiting => {}
        }
    }

    fn enter_lost(&mut self, now_ns: u64) {
        let z0 = self.position().map(|p| p.z).unwrap_or(self.hold.z);
        let estimate = self.pad_estimate(now_ns);
        // The pad as last seen, and as the filter carries it on to now (straight, its
        // speed changing as it was).
        let seen = self
            .filter
            .last_update_ns()
            .and_then(|t| Some((t, self.pad_estimate(t)?)));
        let flat = |v: &Vector3<f64>| Vector3::new(v.x, v.y, 0.0);
        let (origin, velocity, unseen_s, speed) = match (&seen, &estimate) {
            (Some((t, s)), Some(e)) => (
                s.position,
                flat(&s.velocity),
                secs_since(*t, now_ns).min(2.0),
                e.velocity.xy().norm(),
            ),
            _ => (Vector3::zeros(), Vector3::zeros(), 0.0, 0.0),
        };
        self.lost_turn_rate = seen
            .as_ref()
            .map_or(0.0, |(_, s)| self.turn_rate(s, &velocity));
        // On a curve the pad drove the arc since it was last seen, not the tangent the
        // filter carries it along: the arc, with the filter's change of speed along it.
        let (drift, turned) = arc(&velocity, self.lost_turn_rate, unseen_s);
        let along = turned.try_normalize(1e-9).unwrap_or_else(Vector3::zeros);
        let speed_change = estimate.as_ref().map_or(Vector3::zeros(), |e| {
            flat(&(e.position - origin)) - velocity * unseen_s
        });
        let speed_change = along * speed_change.dot(&along);
        let lost_velocity = along * speed;
        self.lost_velocity = if lost_velocity.iter().all(|c| c.is_finite()) {
            lost_velocity
        } else {
            Vector3::zeros()
        };
        // Follow where the pad should be, not the vehicle's own offset from it: a pad
        // that outran the camera (a chase at speed) is caught up with, not trailed.
        let predicted = estimate
            .as_ref()
            .map(|_| origin + drift + speed_change)
            .map(|p| Vector3::new(p.x, p.y, z0))
            .filter(|p| p.iter().all(|c| c.is_finite()));
        let why = match estimate {
            Some(e) => format!("no pad for {:.1} s", e.age_s),
            None => "pad estimate restarted (observations jumped)".to_string(),
        };
        self.go(now_ns, MissionState::Lost, why);
        self.lost_z0 = z0;
        self.lost_since_update = self.filter.last_update_ns().unwrap_or(0);
        if let Some(p) = predicted.or_else(|| self.position()) {
            self.hold = p;
        }
    }

    fn lost(&mut self, now_ns: u64, out: &mut Outputs) {
        let t = self.elapsed_s(now_ns);
        if t > self.cfg.lost_timeout_s {
            self.go(
                now_ns,
                MissionState::SafeLand,
                format!("pad lost for {:.0} s", self.cfg.lost_timeout_s),
            );
            return;
        }
        let regained = self
            .filter
            .last_update_ns()
            .is_some_and(|t| t > self.lost_since_update);
        if regained && self.pad(now_ns).is_some() {
            self.enter_track(now_ns, "pad regained".into());
            return;
        }
        // Chasing a fast pad, the height that saw it is kept while following.
        let hold_s = if self.chasing(&self.lost_velocity) {
            self.cfg.lost_hold_s.max(self.cfg.lost_follow_s)
        } else {
            self.cfg.lost_hold_s
        };
        let climb =
            ((t - hold_s).max(0.0) * self.cfg.lost_climb_m_s).min(self.cfg.lost_climb_max_m);
        let climbing = t > hold_s && climb < self.cfg.lost_climb_max_m;
        // Where the pad would be had it driven on as it was (for `lost_follow_s`: its
        // speed, and its turn), above it.
        let follow = t.min(self.cfg.lost_follow_s);
        let (drift, velocity) = arc(&self.lost_velocity, self.lost_turn_rate, follow);
        let target = Vector3::new(
            self.hold.x + drift.x,
            self.hold.y + drift.y,
            self.lost_z0 + climb,
        );
        let mut sp = self.hold_setpoint(now_ns, target);
        if t < self.cfg.lost_follow_s {
            let pull = turn_pull(&velocity, self.lost_turn_rate);
            sp.velocity[0] = velocity.x;
            sp.velocity[1] = velocity.y;
            sp.acceleration[0] = pull.x;
            sp.acceleration[1] = pull.y;
        }
        if climbing {
            sp.velocity[2] = self.cfg.lost_climb_m_s;
        }
        out.setpoint = Some(sp);
    }

    fn safe_land(&mut self, now_ns: u64, out: &mut Outputs) {
        let Some(v) = self.vehicle().copied() else {
            return;
        };
        let down = v.armed == 0 && LandedState::from_raw(v.landed_state) == LandedState::OnGround;
        if down || self.safety_ordered {
            // On the ground already, or px4-link executed the order itself.
            return;
        }
        let mode = FlightMode::from_raw(v.flight_mode);
        if mode == FlightMode::Land {
            self.mode_wait = None;
            return;
        }
        if let Some(z) = self.brake_at_z {
            match self.position() {
                Some(p) if self.moving_to_brake() && mode == FlightMode::Offboard => {
                    out.setpoint = Some(self.hold_setpoint(now_ns, Vector3::new(p.x, p.y, z)));
                    return;
                }
                _ => self.brake_at_z = None,
            }
        }
        if let Drive::Failed(why) = self.drive_mode(now_ns, LinkRequestKind::Land, out) {
            // A vehicle that must land keeps asking; each failure is logged.
            tracing::error!(why = why.as_str(), "land request failed, asking again");
        }
    }

    /// Asks for a mode change and waits for the autopilot's heartbeat to show it: an
    /// accepted request is not asked again until `mode_timeout_s` passes without the
    /// mode, then it is, as its next attempt. (Asked again at every cycle until the
    /// 1 Hz heartbeat caught up, PX4 restarted AUTO.LAND at each NAV_LAND: issue 34.)
    /// The caller stops calling once the mode shows.
    fn drive_mode(&mut self, now_ns: u64, kind: LinkRequestKind, out: &mut Outputs) -> Drive {
        if let Some(w) = self.mode_wait.filter(|w| w.kind == kind) {
            let waited_s = secs_since(w.since_ns, now_ns);
            if waited_s < self.cfg.mode_timeout_s {
                return Drive::Waiting;
            }
            tracing::warn!(
                ?kind,
                waited_s,
                "the autopilot accepted the request but does not show its mode: asking again"
            );
            self.mode_wait = None;
            self.pending = Some(Pending {
                kind,
                id: 0,
                attempts: w.attempts,
                sent_ns: None,
                retry_at_ns: now_ns,
                answer: None,
            });
        }
        match self.drive(now_ns, kind, 0.0, out) {
            Drive::Accepted(attempts) => {
                self.mode_wait = Some(ModeWait {
                    kind,
                    since_ns: now_ns,
                    attempts,
                });
                Drive::Waiting
            }
            d => d,
        }
    }

    /// A planner goal when it changed or is due again.
    fn publish_goal(
        &mut self,
        now_ns: u64,
        mode: GoalMode,
        position: Vector3<f64>,
        velocity: Vector3<f64>,
        out: &mut Outputs,
    ) {
        let due = self
            .last_goal_ns
            .is_none_or(|t| secs_since(t, now_ns) >= self.cfg.goal_period_s);
        if !due
            || !position
                .iter()
                .chain(velocity.iter())
                .all(|x| x.is_finite())
        {
            return;
        }
        self.last_goal_ns = Some(now_ns);
        self.goal_seq += 1;
        let mut msg = Header::captured_at(now_ns);
        msg.seq = self.goal_seq;
        msg.push_stage(Stage::Fsm, now_ns, now_ns);
        out.goal = Some(PlannerGoal {
            msg,
            position: position.into(),
            velocity: velocity.into(),
            acceleration: [0.0; 3],
            yaw: self.yaw_sp,
            mode: mode as u32,
            reserved: 0,
        });
    }

    fn setpoint(&self, now_ns: u64, p: Vector3<f64>, v: Vector3<f64>, a: Vector3<f64>) -> Setpoint {
        let follows_pad = matches!(
            self.state,
            MissionState::Track | MissionState::Descend | MissionState::Land
        );
        let mut msg = match (&self.pad_header, follows_pad) {
            (Some(h), true) => Header::derived_from(h),
            _ => Header::captured_at(now_ns),
        };
        msg.push_stage(Stage::Fsm, now_ns, now_ns);
        Setpoint {
            msg,
            position: p.into(),
            velocity: v.into(),
            acceleration: a.into(),
            yaw: self.yaw_sp,
            valid: Setpoint::POSITION | Setpoint::VELOCITY | Setpoint::ACCELERATION | Setpoint::YAW,
            reserved: 0,
        }
    }

    fn hold_setpoint(&self, now_ns: u64, p: Vector3<f64>) -> Setpoint {
        self.setpoint(now_ns, p, Vector3::zeros(), Vector3::zeros())
    }

    /// The current trajectory sampled now; the hold point before the first one.
    fn trajectory_setpoint(&self, now_ns: u64) -> Setpoint {
        if let Some((_, s, t0)) = &self.trajectory {
            let t = secs_since(*t0, now_ns);
            let d = s.duration();
            let st = s.eval(t.min(d));
            if st.is_finite() {
                if t >= d {
                    return self.hold_setpoint(now_ns, st.p);
                }
                return self.setpoint(now_ns, st.p, st.v, st.a);
            }
        }
        self.hold_setpoint(now_ns, self.hold)
    }

    /// A pad moving this fast (horizontal `velocity`) is chased: faster than the planner
    /// flies (`chase_speed_m_s`). The one test every chase behaviour is gated on.
    /// Too fast to land where it is (a vehicle that gave up over a fast pad brakes first).
    fn moving_to_brake(&self) -> bool {
        self.velocity().xy().norm() > BRAKED_M_S
    }

    fn chasing(&self, velocity: &Vector3<f64>) -> bool {
        velocity.xy().norm() > self.cfg.chase_speed_m_s
    }

    /// The rate the pad's `velocity` turns at, rad/s. Chasing, it is read off the turning
    /// pull the chase flies (slewed: the heading rate read low over the pad swings with
    /// the vehicle's roll, +-0.26 rad/s at 1.2 Hz in highspeed-50, and taken as it is would
    /// send Lost off on a circle that is not there). Below the chase speed the heading
    /// rate itself, at most [`LOST_TURN_RATE_MAX_RAD_S`].
    fn turn_rate(&self, est: &PadEstimate, velocity: &Vector3<f64>) -> f64 {
        let speed2 = velocity.xy().norm_squared();
        let w = if self.chasing(velocity) {
            (velocity.x * self.chase_turn.y - velocity.y * self.chase_turn.x) / speed2
        } else if speed2 >= HEADING_SPEED_MIN_M_S * HEADING_SPEED_MIN_M_S {
            est.yaw_rate
        } else {
            0.0
        };
        if w.is_finite() {
            w.clamp(-LOST_TURN_RATE_MAX_RAD_S, LOST_TURN_RATE_MAX_RAD_S)
        } else {
            0.0
        }
    }

    /// Below the chase speed, remembers when the pad last accelerated past the drop's
    /// gate (Descend and Land watch it, so a manoeuvre ending at the commit still counts).
    fn note_manoeuvre(&mut self, now_ns: u64, est: &PadEstimate) {
        if !self.chasing(&est.velocity)
            && est.manoeuvre_acceleration.xy().norm() >= self.cfg.flare_accel_max_m_s2
        {
            self.manoeuvre_seen_ns = Some(now_ns);
        }
    }

    /// Moves the chase's turning feed-forward towards the pad's turning pull now (none
    /// before its heading was measured for [`CHASE_TURN_EVIDENCE_S`]), at most `dt` times
    /// [`CHASE_TURN_JERK_MAX_M_S3`]; zero when not chasing.
    fn slew_chase_turn(&mut self, now_ns: u64, dt: f64) {
        let target = match self.pad_estimate(now_ns) {
            Some(est) if self.chasing(&est.velocity) => {
                if est.heading_seen_s >= CHASE_TURN_EVIDENCE_S {
                    turn_acceleration(&est).cap_magnitude(CHASE_TURN_ACCEL_MAX_M_S2)
                } else {
                    Vector3::zeros()
                }
            }
            _ => {
                self.chase_turn = Vector3::zeros();
                return;
            }
        };
        let step = (target - self.chase_turn).cap_magnitude(CHASE_TURN_JERK_MAX_M_S3 * dt);
        if step.iter().all(|c| c.is_finite()) {
            self.chase_turn += step;
        }
    }

    /// Descending onto a pad below the chase speed (`drag_per_s` set), low-passes its
    /// velocity into `drag_ref`, from the velocity it had when the descent began (the
    /// vehicle aligned over it for `align_hold_s`: PX4's integrator holds that velocity's
    /// drag); otherwise forgets it.
    fn follow_drag(&mut self, now_ns: u64, dt: f64) {
        let following = self.cfg.drag_per_s > 0.0
            && matches!(self.state, MissionState::Descend | MissionState::Land);
        if !following {
            self.drag_ref = None;
            return;
        }
        let v = match self.pad(now_ns) {
            Some(est) if !self.chasing(&est.velocity) => {
                Vector3::new(est.velocity.x, est.velocity.y, 0.0)
            }
            _ => {
                self.drag_ref = None;
                return;
            }
        };
        let r = self.drag_ref.get_or_insert(v);
        let next = *r + (v - *r) * (dt / DRAG_MEMORY_S).min(1.0);
        if next.iter().all(|c| c.is_finite()) {
            *r = next;
        }
    }

    /// Chasing, integrates the pad-relative horizontal error into `chase_trim` (tracking,
    /// descending, touching down until the drop): at 30 km/h the relative wind's drag
    /// held the racer 5-10 cm behind the pad, outside the flare gate, for the whole
    /// touchdown (highspeed-30). Below the chase speed it stays zero, so the paper's
    /// flights are flown as before.
    fn integrate_chase_trim(&mut self, est: &PadEstimate, p: &Vector3<f64>, dt: f64) {
        let chasing = self.chasing(&est.velocity);
        // Below the chase speed the same integral holds station over the pad against the
        // wind, from the descent to the drop (`flare_trim_gain`); a trim made chasing is
        // not a paper-speed one, nor the other way round.
        let flare = !chasing
            && self.cfg.flare_trim_gain > 0.0
            && matches!(self.state, MissionState::Descend | MissionState::Land);
        if chasing != self.trim_chasing || !(chasing || flare) {
            self.chase_trim = Vector3::zeros();
            self.trim_chasing = chasing;
        }
        if !(chasing || flare) {
            return;
        }
        let e = est.position - p;
        // Only once caught up: a catch-up from metres behind would wind it up and
        // overshoot the pad.
        if e.xy().norm() > self.cfg.direct_range_m {
            return;
        }
        let (gain, max) = if chasing {
            (self.cfg.chase_trim_gain, CHASE_TRIM_MAX_M_S)
        } else {
            (self.cfg.flare_trim_gain, FLARE_TRIM_MAX_M_S)
        };
        let pad_from_world = Rotation3::from_axis_angle(&Vector3::z_axis(), -est.yaw);
        let e = pad_from_world * Vector3::new(e.x, e.y, 0.0);
        let step = e * (gain * dt);
        let trim = (self.chase_trim + step).cap_magnitude(max);
        if trim.iter().all(|c| c.is_finite()) {
            self.chase_trim = trim;
        }
    }

    /// Over the pad at height `z`, moving with it (velocity feed-forward), `vz` down.
    /// Descending, the horizontal error also feeds the velocity (`relative_gain`, chasing
    /// `chase_relative_gain`, dropping below the chase speed `drop_relative_gain`): the
    /// autopilot's own position gain alone lets a gust carry the vehicle off while it
    /// descends, and trails a pad that speeds up.
    fn pad_setpoint(&self, now_ns: u64, est: &PadEstimate, z: f64, vz: f64) -> Setpoint {
        let chasing = self.chasing(&est.velocity);
        let p = Vector3::new(est.position.x, est.position.y, z);
        let mut v = Vector3::new(est.velocity.x, est.velocity.y, est.velocity.z + vz);
        v += Rotation3::from_axis_angle(&Vector3::z_axis(), est.yaw) * self.chase_trim;
        // Touching down, never ask to descend faster than the touchdown's own rate: a pad
        // seen sinking is more often an estimate dragged down by late telemetry (a
        // --processes flight on a loaded machine: -0.28 m/s at contact, the pad's truth 0)
        // than a road going downhill, and on such a road the cap only softens the contact.
        if self.state == MissionState::Land {
            v.z = v.z.max(vz.min(0.0));
        }
        // A fast pad on a curve turns its velocity at its heading rate: that acceleration
        // fed forward, or the vehicle trails outside the curve by the distance the
        // autopilot's position and velocity gains need to make it (0.7 m at 30 km/h on a
        // 60 m radius).
        let mut a = if chasing {
            self.chase_turn
        } else if matches!(self.state, MissionState::Descend | MissionState::Land) {
            // A braking, a lane change or a turn fed forward: PX4's velocity loop trails a
            // ramp by its acceleration over MPC_XY_VEL_P_ACC (0.25 m/s in a 0.45 m/s^2
            // braking).
            (pad_acceleration(est) * self.cfg.pad_accel_gain).cap_magnitude(PAD_ACCEL_MAX_M_S2)
        } else {
            Vector3::zeros()
        };
        // The drag's change since the descent began: PX4's integrator holds the old. Only
        // the swing of its direction, at the speed now (a turn): the speed's wander comes
        // and goes faster than the integrator's memory, and fed forward as well it cost the
        // straight roads what it gained the turn (docs/fsm.md).
        if let Some(r) = self.drag_ref {
            let pad_v = Vector3::new(est.velocity.x, est.velocity.y, 0.0);
            let held = r.try_normalize(1e-3).map_or(pad_v, |u| u * pad_v.norm());
            a += (pad_v - held) * self.cfg.drag_per_s;
        }
        // Dropping, the pull keeps working below the chase speed (`drop_relative_gain`):
        // as the drop takes thrust away the lean against the wind lags, and the fall
        // drifted 1-2 cm downwind. Chasing, the vehicle only matches the pad's velocity:
        // at 30 km/h the last centimetres chased only add sideways speed at contact.
        if matches!(self.state, MissionState::Descend | MissionState::Land)
            && let Some(u) = self.position()
        {
            let gain = match (chasing, self.dropping) {
                (true, false) => self.cfg.chase_relative_gain,
                (true, true) => 0.0,
                (false, false) => self.cfg.relative_gain,
                (false, true) => self.cfg.drop_relative_gain,
            };
            v.x += gain * (est.position.x - u.x);
            v.y += gain * (est.position.y - u.y);
        }
        // The touchdown only: higher up, the pad estimate's noise through this feedback
        // set the descent oscillating (paper-sim seed 3 at 3 m, +-0.8 m/s).
        if self.state == MissionState::Land {
            // The pad's velocity relative to the vehicle, plus what the setpoint adds to
            // the pad's own (the pull toward its centre, the trim).
            let camera = self.cfg.relative_velocity_from_camera && !chasing;
            let relative = match self.relative.velocity(now_ns) {
                Some(u) if camera => u + (v - est.velocity),
                _ => v - self.velocity(),
            };
            // Chasing, only its part along the road. Across it, in a curve, the setpoint's
            // velocity turns now while the vehicle's measured velocity lags the turn (its
            // stamp, PX4's velocity loop): the difference read 10-50 cm/s toward the inside
            // and pulled the touchdown 4.6 cm inside the curve (highspeed-30-curve); the
            // position pull and the trim hold the across error.
            let relative = match along(&relative, &est.velocity) {
                Some(part) if chasing => part,
                _ => relative,
            };
            let dv = relative.xy() * self.cfg.relative_velocity_gain;
            let dv = dv.cap_magnitude(self.cfg.relative_accel_max_m_s2);
            a += Vector3::new(dv.x, dv.y, 0.0);
        }
        self.setpoint(now_ns, p, v, a)
    }
}

/// The pad's horizontal acceleration, fed forward below the chase speed: along its velocity
/// the models' weighted mean (a braking), across it the heading rate times the speed (a
/// vehicle points along its velocity, so its heading turns as its velocity does, in a curve
/// and in a lane change). The weighted mean across as well fed 0.4-0.6 of a steady turn's
/// pull: the constant-velocity model keeps weight while the pad cruises round at a
/// constant speed, and the vehicle trailed the pad 6-9 cm at the flare height (paper-turn).
fn pad_acceleration(est: &PadEstimate) -> Vector3<f64> {
    let v = est.velocity.xy();
    let a = est.acceleration.xy();
    let speed = v.norm();
    // At a crawl the heading says little about the velocity's direction.
    if speed < HEADING_SPEED_MIN_M_S {
        return Vector3::new(a.x, a.y, 0.0);
    }
    along(&est.acceleration, &est.velocity).unwrap_or_else(Vector3::zeros) + turn_acceleration(est)
}

/// The horizontal part of `x` along the horizontal `direction` (no vertical part): a
/// pad's acceleration or a relative velocity split along the road; `None` when
/// `direction` has no horizontal length to speak of.
fn along(x: &Vector3<f64>, direction: &Vector3<f64>) -> Option<Vector3<f64>> {
    let u = direction.xy().try_normalize(1e-3)?;
    let part = u * x.xy().dot(&u);
    Some(Vector3::new(part.x, part.y, 0.0))
}

/// The pad's velocity turned at its heading rate: the pull of the curve it drives, for
/// the chase and below it alike.
fn turn_acceleration(est: &PadEstimate) -> Vector3<f64> {
    turn_pull(&est.velocity, est.yaw_rate)
}

/// Where a pad at velocity `v` turning at `w` rad/s is after `t` s, relative to where it
/// was, and its velocity then: the constant-turn arc (the tangent when `w` is zero).
fn arc(v: &Vector3<f64>, w: f64, t: f64) -> (Vector3<f64>, Vector3<f64>) {
    let turned = w * t;
    let (s, c) = turned.sin_cos();
    // Along the first velocity, and across it toward the turn.
    let (along, across) = if turned.abs() < 1e-6 {
        (t, 0.5 * w * t * t)
    } else {
        (s / w, (1.0 - c) / w)
    };
    (
        Vector3::new(v.x * along - v.y * across, v.y * along + v.x * across, 0.0),
        Vector3::new(v.x * c - v.y * s, v.y * c + v.x * s, 0.0),
    )
}

/// Seconds from `since_ns` to `now_ns`: zero, never a wrapped time, if `now_ns` is the
/// earlier (the one way every wait and age in the mission is measured).
fn secs_since(since_ns: u64, now_ns: u64) -> f64 {
    now_ns.saturating_sub(since_ns) as f64 * 1e-9
}

/// The slowest pad whose heading rate is taken for its velocity's, m/s.
const HEADING_SPEED_MIN_M_S: f64 = 0.2;

/// How far the touchdown's position setpoint may lead the vehicle down, m: with PX4's
/// MPC_Z_P of 1, the descent asked for stays within 0.1 m/s of the touchdown's rate however
/// long the drop (paper-sim: 0.86 m/s at contact from the flare height, 0.96 from 20 cm
/// higher, and 1.05 once in CI with the pad estimate 11 cm low).
const TOUCHDOWN_LEAD_M: f64 = 0.1;

/// The most turning acceleration fed forward, m/s^2 (a car at 50 km/h on a 30 m radius
/// pulls 6.4; a misread heading rate must not tilt the vehicle further).
const CHASE_TURN_ACCEL_MAX_M_S2: f64 = 6.0;

/// How fast the chase's turning feed-forward may change, m/s^3: a car's lateral jerk stays
/// under about 2 even driven hard (comfort is under 1), and a 60 m curve at 30 km/h
/// (1.16 m/s^2) is fed in 0.6 s.
const CHASE_TURN_JERK_MAX_M_S3: f64 = 2.0;

/// How long the pad's heading must have been measured before the chase turns with it, s.
/// A pad at 50 km/h crosses the waiting vehicle's view in 0.25-0.4 s, and the heading
/// rate read off that glimpse (0.1-0.15 rad/s, on a straight road) turned the chase and
/// then Lost off the road: 4 of 16 runs of highspeed-50 on seed 21 lost the pad for good.
/// A curve held in view for a second is turned with (the 60 m curve at 30 km/h was
/// lost, and followed round, 1.3 s into Track).
const CHASE_TURN_EVIDENCE_S: f64 = 1.0;

/// How long the drag PX4's velocity integrator holds takes to follow a change of
/// velocity, s: its slow pole (MPC_XY_VEL_P_ACC 1.8, MPC_XY_VEL_I_ACC 0.4) is at 0.26 /s,
/// and the reference forgets more slowly still, so that a steady turn's drag is fed
/// forward nearly whole (a linear model of paper-turn: 9.4 cm behind without, 2.4 with).
pub const DRAG_MEMORY_S: f64 = 10.0;

/// The fastest turn Lost follows, rad/s: a car's tightest (5 m radius) at the 2 m/s of
/// the chase speed, 0.4 rad/s; a faster read is noise.
const LOST_TURN_RATE_MAX_RAD_S: f64 = 0.4;

/// The longest the drop waits for a manoeuvring pad, s: a braking or a lane change lasts
/// 2-3 s.
const MANOEUVRE_WAIT_MAX_S: f64 = 4.0;

/// The most of the pad's acceleration fed forward, m/s^2 (a hard braking; a misread
/// must not tilt the vehicle further).
const PAD_ACCEL_MAX_M_S2: f64 = 3.0;

/// The most velocity the chase trim may add, m/s: drag at 14 m/s needs a few tenths.
const CHASE_TRIM_MAX_M_S: f64 = 1.0;

/// The most velocity the trim below the chase speed may add, m/s: what PX4's velocity
/// integrator has not yet made of a gust is a few centimetres per second.
const FLARE_TRIM_MAX_M_S: f64 = 0.3;

/// Touchdown: the drop has stopped (vertical speed relative to the pad above minus
/// this, m/s) ...
const TOUCH_STILL_M_S: f64 = 0.2;
/// ... this close to the pad estimate's height (the pad's height is known to a few cm), m ...
const TOUCH_HEIGHT_M: f64 = 0.12;
/// ... for this long (three fsm cycles at 50 Hz), s.
const TOUCH_HOLD_S: f64 = 0.05;
/// Or the drop has stopped up to this far above the pad estimate, m ...
///
/// The pad's height is known to a few cm while the camera sees it; in the last 20 cm it
/// comes from PnP at a few cm range and from velocity integrated through the contact: a
/// CI flight found its contact with the estimate 12 cm low, at the edge of the gate above.
/// A little lower and the vehicle sits on the moving pad, motors on, until PX4's land
/// detector agrees (seconds, drifting off; tests/transitions.rs). A drop that was under
/// way does not stop in the air while the setpoint leads it down, so a longer stop this
/// far up is the contact too.
const TOUCH_HEIGHT_FAR_M: f64 = 0.3;
/// ... for this long, s (ten fsm cycles: a stall, not one slow telemetry sample).
const TOUCH_HOLD_FAR_S: f64 = 0.2;

/// Heading of the body x axis from a quaternion (x, y, z, w), rad; 0 when degenerate.
fn yaw_of(q: &[f64; 4]) -> f64 {
    let [x, y, z, w] = *q;
    let uq = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
    let ax = uq * Vector3::x();
    let yaw = ax.y.atan2(ax.x);
    if yaw.is_finite() { yaw } else { 0.0 }
}
