//! The evaluator of `landing run`: the only part that reads the simulator's ground
//! truth (where the vehicle and the pad really are, touchdowns, collisions, crashes).

use ipc_types::msg::{
    Contact, FsmStatus, MissionState, PlannerStats, Point2, TruthEvent, TruthKind, TruthState,
};
pub use sim::scenario::TouchdownLimits;

use crate::flight_log::{self, FlightLog, FlightSample, Outcome, TouchdownContact};

/// The world at one instant, for the flight log and the plots.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Simulated time, s.
    pub t_s: f64,
    /// True vehicle position, world ENU, m.
    pub uav: [f64; 3],
    /// True vehicle velocity, m/s.
    pub uav_velocity: [f64; 3],
    /// True pad centre, m (None without a ground vehicle).
    pub pad: Option<[f64; 3]>,
    /// True pad velocity, m/s.
    pub pad_velocity: Option<[f64; 3]>,
    /// The fsm's state.
    pub phase: MissionState,
}

impl Sample {
    /// The truth the `sim` process published (`landing/sim/truth_state`).
    pub fn from_truth(s: &TruthState, phase: MissionState) -> Self {
        let pad = s.pad_valid != 0;
        Self {
            t_s: s.sim_time_ns as f64 * 1e-9,
            uav: s.vehicle_position,
            uav_velocity: s.vehicle_velocity,
            pad: pad.then_some(s.pad_position),
            pad_velocity: pad.then_some(s.pad_velocity),
            phase,
        }
    }
}

/// Horizontal distance from the vehicle to the pad, m (`None` without a pad).
pub fn distance_to_pad(s: &TruthState) -> Option<f64> {
    (s.pad_valid != 0).then(|| {
        let (u, p) = (s.vehicle_position, s.pad_position);
        (u[0] - p[0]).hypot(u[1] - p[1])
    })
}

/// True for the simulator's crash event.
pub fn is_crash(t: &TruthEvent) -> bool {
    t.kind == TruthKind::Crash as u32
}

/// A touchdown as the simulator saw it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Touchdown {
    /// When, s.
    pub t_s: f64,
    /// On the pad (not the ground).
    pub on_pad: bool,
    /// Horizontal distance from the pad centre, m.
    pub error_m: f64,
    /// Speed relative to the surface, m/s.
    pub rel_speed_mps: f64,
    /// Speed along the surface normal, m/s.
    pub vertical_mps: f64,
    /// Speed along the surface, m/s.
    pub horizontal_mps: f64,
    /// Angle between body up and the surface normal, deg.
    pub tilt_deg: f64,
    /// Each foot of the landing gear in the pad frame, m.
    pub gear_pad: [Point2; 4],
    /// How long the vehicle had been in the air before (since its last lift-off), s;
    /// infinite for the first touchdown.
    pub airborne_s: f64,
    /// The fsm's state at that moment.
    pub phase: MissionState,
}

/// A lift-off shorter than this before a touchdown is a bounce of the same landing, s.
pub const BOUNCE_MAX_S: f64 = 1.0;
/// Relative speed below which the vehicle is at rest on the pad at the end, m/s.
pub const AT_REST_MPS: f64 = 0.1;

/// What the referee judges by: the touchdown limits and the board.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rules {
    /// Touchdown speed and tilt limits.
    pub limits: TouchdownLimits,
    /// The printed board every foot must be on (deploy/config/pad.toml), pad frame.
    pub board: optics::Board,
}

impl Rules {
    /// The shipped rules for a scenario: its airframe's limits and the pad file's board.
    pub fn of(scn: &sim::scenario::LoadedScenario) -> Result<Self, optics::pad::PadError> {
        let pad = optics::pad::PadModel::load(scn.pad_path())?;
        Ok(Self {
            limits: scn.touchdown,
            board: pad.board,
        })
    }
}

/// Collects the truth during a run.
#[derive(Debug, Clone, Default)]
pub struct Evaluator {
    /// Samples at 20 Hz.
    pub samples: Vec<Sample>,
    /// Every touchdown.
    pub touchdowns: Vec<Touchdown>,
    /// Obstacle collisions.
    pub collisions: u32,
    /// Crash reasons.
    pub crashes: Vec<String>,
    /// Time of the last lift-off, s.
    last_liftoff_s: Option<f64>,
}

impl Evaluator {
    /// Takes in one truth event, with the fsm's state at that moment.
    pub fn on_truth(&mut self, t: &TruthEvent, phase: MissionState) {
        match TruthKind::from_raw(t.kind) {
            Some(TruthKind::Touchdown) => {
                let [x, y] = t.rel_position_pad;
                let v = t.rel_velocity;
                let t_s = t.msg.capture_ns as f64 * 1e-9;
                self.touchdowns.push(Touchdown {
                    t_s,
                    on_pad: t.on_pad != 0,
                    error_m: x.hypot(y),
                    rel_speed_mps: (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt(),
                    vertical_mps: v[2].abs(),
                    horizontal_mps: v[0].hypot(v[1]),
                    tilt_deg: t.tilt_deg,
                    gear_pad: t.gear_pad,
                    airborne_s: self.last_liftoff_s.map_or(f64::INFINITY, |l| t_s - l),
                    phase,
                });
            }
            Some(TruthKind::Liftoff) => {
                self.last_liftoff_s = Some(t.msg.capture_ns as f64 * 1e-9);
            }
            Some(TruthKind::Collision) => self.collisions += 1,
            Some(TruthKind::Crash) => self.crashes.push(t.reason.as_str().to_string()),
            _ => {}
        }
    }

    /// Keeps one sample.
    pub fn sample(&mut self, s: Sample) {
        self.samples.push(s);
    }

    /// Touchdowns after take-off (a vehicle settling before it flew does not count).
    pub fn flown_touchdowns(&self) -> impl Iterator<Item = &Touchdown> {
        self.touchdowns
            .iter()
            .filter(|t| t.phase != MissionState::Idle)
    }

    /// The touchdown the vehicle ended on: the last one after take-off, wherever it was
    /// (a touch on the pad, a lift-off and a landing beside it ends beside it).
    pub fn final_touchdown(&self) -> Option<&Touchdown> {
        self.flown_touchdowns().last()
    }

    /// The first contact of the final landing: the last touchdown after a flight longer
    /// than a bounce ([`BOUNCE_MAX_S`]); its speeds and tilt are the landing's.
    pub fn landing_contact(&self) -> Option<&Touchdown> {
        self.flown_touchdowns()
            .filter(|t| t.airborne_s >= BOUNCE_MAX_S)
            .last()
            .or_else(|| self.flown_touchdowns().next())
    }
}

/// How the run ended, as the referee saw it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum End {
    /// The fsm reached Landed.
    Landed,
    /// The fsm stopped in SafeLand or Abort and the vehicle is down and disarmed.
    SafeLanded,
    /// The simulator reported a crash.
    Crashed,
    /// The scenario's time ran out.
    Timeout,
    /// SIGINT (Ctrl-C) or SIGTERM stopped the run.
    Interrupted,
    /// The simulator's process exited during the mission (`--processes`): no world left.
    ProcessDied,
    /// After a fault to a process the vehicle came down and disarmed, the fsm or not.
    DownAfterFault,
}

impl End {
    /// The end a mission state means: Landed, or SafeLand / Abort once the vehicle is
    /// `down` (disarmed); `None` while the mission goes on.
    pub fn reached(phase: MissionState, down: bool) -> Option<End> {
        match phase {
            MissionState::Landed => Some(End::Landed),
            MissionState::SafeLand | MissionState::Abort if down => Some(End::SafeLanded),
            _ => None,
        }
    }
}

/// What the run measured besides the flight log.
#[derive(Debug, Clone, Default)]
pub struct RunStats {
    /// Compute time of every planning call, ms.
    pub planning_ms: Vec<f64>,
    /// Successful plans (the first included).
    pub plans: u64,
}

/// The referee of both run modes: it reads the fsm's status, the planner's statistics
/// and the simulator's evaluator-only truth, exactly as `landing run` and `landing run
/// --processes` receive them, and decides when and how the run ended by one rule: the
/// fsm reached Landed, or SafeLand/Abort with the vehicle disarmed (the truth's armed
/// flag), or the simulator reported a crash, or after a fault to a process the vehicle is
/// down and disarmed; the run goes on one simulated second after that so the touchdown
/// settles in the log.
#[derive(Debug, Default)]
pub struct Referee {
    /// The truth collected.
    pub eval: Evaluator,
    /// Planning statistics.
    pub stats: RunStats,
    /// The fsm's transitions, from its status messages.
    pub transitions: Vec<fsm::Transition>,
    /// The fsm's state as its last status said.
    pub phase: MissionState,
    last_state: Option<TruthState>,
    ended: Option<(End, u64)>,
    /// A process was killed, hung or exited: the run ends once the vehicle is down.
    faulted: bool,
    /// The clock origin of the status messages' `since_ns` (0 in lockstep).
    start_ns: u64,
}

/// One simulated second: how long the run goes on after its end.
const SETTLE_NS: u64 = 1_000_000_000;

impl Referee {
    /// A referee whose status times count from `start_ns` (the status's clock).
    pub fn new(start_ns: u64) -> Self {
        Self {
            start_ns,
            ..Self::default()
        }
    }

    /// The fsm's status.
    pub fn on_status(&mut self, st: &FsmStatus) {
        let state = MissionState::from_raw(st.state).unwrap_or(MissionState::Idle);
        if state != self.phase {
            self.transitions.push(fsm::Transition {
                at_ns: st.since_ns.saturating_sub(self.start_ns),
                from: MissionState::from_raw(st.previous).unwrap_or(self.phase),
                to: state,
                reason: st.reason.as_str().to_string(),
            });
            self.phase = state;
        }
        self.check_end();
    }

    /// The planner's statistics of one call that took `planning_ms` of compute.
    pub fn on_planner_stats(&mut self, s: &PlannerStats, planning_ms: f64) {
        self.stats.planning_ms.push(planning_ms);
        if s.success != 0 {
            self.stats.plans += 1;
        }
    }

    /// A truth event (touchdown, collision, crash).
    pub fn on_truth(&mut self, t: &TruthEvent) {
        self.eval.on_truth(t, self.phase);
        let collision = t.kind == TruthKind::Collision as u32;
        if (is_crash(t) || collision) && self.ended.is_none() {
            self.ended = Some((End::Crashed, self.sim_time_ns()));
        }
    }

    /// The truth state last received.
    pub fn last_state(&self) -> Option<&TruthState> {
        self.last_state.as_ref()
    }

    /// The truth state (20 Hz): a flight-log sample.
    pub fn on_truth_state(&mut self, s: &TruthState) {
        self.eval.sample(Sample::from_truth(s, self.phase));
        self.last_state = Some(*s);
        self.check_end();
    }

    /// A fault to a process (`--inject`, a stage that exited): from now on the run also
    /// ends when the vehicle is down and disarmed, whoever brought it down (the fsm, or
    /// PX4's offboard-loss failsafe with the fsm gone).
    pub fn on_fault(&mut self) {
        self.faulted = true;
        self.check_end();
    }

    fn check_end(&mut self) {
        if self.ended.is_none() {
            let down = self.last_state.is_some_and(|s| s.armed == 0);
            let at = self.sim_time_ns();
            self.ended = End::reached(self.phase, down).map(|e| (e, at));
            let on_something = self
                .last_state
                .is_some_and(|s| Contact::from_raw(s.contact) != Some(Contact::Airborne));
            if self.ended.is_none() && self.faulted && down && on_something {
                self.ended = Some((End::DownAfterFault, at));
            }
        }
    }

    /// Simulated time of the newest truth state, ns.
    pub fn sim_time_ns(&self) -> u64 {
        self.last_state.map_or(0, |s| s.sim_time_ns)
    }

    /// Horizontal distance to the pad now, m.
    pub fn distance_to_pad(&self) -> Option<f64> {
        self.last_state.as_ref().and_then(distance_to_pad)
    }

    /// The end, once the run has gone on a second past it.
    pub fn finished(&self) -> Option<End> {
        self.ended
            .filter(|(_, at)| self.sim_time_ns() >= at + SETTLE_NS)
            .map(|(e, _)| e)
    }
}

/// The outcome of a run and the referee's one-line reason, by the rules: a crash or any
/// contact with an obstacle is `crashed`; any touchdown after take-off beyond a limit is
/// `hard_landing`; `landed` needs the fsm's Landed and, at the end of the run, the
/// vehicle disarmed and at rest on the pad with every foot on the board; Landed
/// anywhere else is `off_pad`.
pub fn verdict(
    end: End,
    eval: &Evaluator,
    last: Option<&TruthState>,
    rules: &Rules,
) -> (Outcome, String) {
    match end {
        End::Crashed => {
            let why = if eval.collisions > 0 {
                "touched an obstacle".to_string()
            } else {
                eval.crashes.join("; ")
            };
            return (Outcome::Crashed, why);
        }
        End::Timeout => return (Outcome::Timeout, "the scenario's time ran out".into()),
        End::Interrupted => {
            return (
                Outcome::Interrupted,
                "stopped by a signal (Ctrl-C or SIGTERM)".into(),
            );
        }
        End::ProcessDied => {
            return (
                Outcome::ProcessDied,
                "the simulator's process exited during the mission".into(),
            );
        }
        End::DownAfterFault => {}
        End::Landed | End::SafeLanded => {}
    }
    let l = &rules.limits;
    for t in eval.flown_touchdowns() {
        let over = [
            (
                t.vertical_mps,
                l.max_vertical_speed_mps,
                "vertical speed",
                "m/s",
            ),
            (
                t.horizontal_mps,
                l.max_horizontal_speed_mps,
                "horizontal speed",
                "m/s",
            ),
            (t.tilt_deg, l.max_tilt_deg, "tilt", "deg"),
        ]
        .into_iter()
        .find(|(v, max, _, _)| !within(*v, *max));
        if let Some((v, max, what, unit)) = over {
            let on = if t.on_pad { "pad" } else { "ground" };
            return (
                Outcome::HardLanding,
                format!(
                    "touchdown on the {on} at {:.2} s: {what} {v:.2} {unit} above the limit {max} {unit}",
                    t.t_s
                ),
            );
        }
    }
    if end == End::SafeLanded {
        return (
            Outcome::SafeLanded,
            "the fsm ended in safe-land or abort".into(),
        );
    }
    if end == End::DownAfterFault {
        return (
            Outcome::SafeLanded,
            "down and disarmed after a fault to a process".into(),
        );
    }
    let Some(s) = last else {
        return (Outcome::OffPad, "no truth state at the end".into());
    };
    if Contact::from_raw(s.contact) != Some(Contact::Pad) {
        let where_ = match Contact::from_raw(s.contact) {
            Some(Contact::Ground) => "on the ground",
            _ => "in the air",
        };
        return (
            Outcome::OffPad,
            format!("at the end the vehicle is {where_}, not on the pad"),
        );
    }
    if s.armed != 0 {
        return (
            Outcome::OffPad,
            "at the end the vehicle is still armed".into(),
        );
    }
    // At rest on a pad that turns moves with the pad's point under it, not its centre.
    let [x, y, z] = s.vehicle_velocity_rel_pad;
    let rel = (x * x + y * y + z * z).sqrt();
    if !within(rel, AT_REST_MPS) {
        return (
            Outcome::OffPad,
            format!("at the end the vehicle moves at {rel:.2} m/s on the pad"),
        );
    }
    if let Some((k, out)) = s
        .gear_pad
        .iter()
        .map(|f| rules.board.outside_m(f.x, f.y))
        .enumerate()
        .find(|(_, d)| !within(*d, 0.0))
    {
        return (
            Outcome::OffPad,
            format!("foot {k} rests {out:.3} m beyond the board's edge"),
        );
    }
    (
        Outcome::Landed,
        "at rest on the pad, disarmed, every foot on the board".into(),
    )
}

/// `v <= max`, false for NaN: a value the referee cannot read never passes.
fn within(v: f64, max: f64) -> bool {
    v <= max
}

/// A stage's compute time from the stamp it closed last: exit - enter of the newest
/// stamp of `stage` in `h`, ms.
pub fn stage_ms(h: &ipc_types::msg::Header, stage: ipc_types::msg::Stage) -> Option<f64> {
    h.stages()
        .iter()
        .rev()
        .find(|s| s.stage == stage as u32)
        .map(|s| s.exit_ns.saturating_sub(s.enter_ns) as f64 * 1e-6)
}

impl Evaluator {
    /// The evaluator's record as the flight log the summary and the plots read.
    pub fn flight_log(
        &self,
        name: &str,
        seed: u64,
        obstacles: Vec<([f64; 3], [f64; 3])>,
    ) -> FlightLog {
        let eval = self;
        let samples = eval
            .samples
            .iter()
            .map(|s| FlightSample {
                t_s: s.t_s,
                uav: s.uav,
                ugv_pad: s.pad,
                phase: s.phase.name().to_string(),
                uav_velocity: s.uav_velocity,
                ugv_velocity: s.pad_velocity,
            })
            .collect();
        let touchdown = eval.final_touchdown().map(|t| {
            let at = eval
                .samples
                .iter()
                .rev()
                .find(|s| s.t_s <= t.t_s)
                .or(eval.samples.last());
            flight_log::Touchdown {
                t_s: t.t_s,
                uav: at.map_or([0.0; 3], |s| s.uav),
                pad: at.and_then(|s| s.pad).unwrap_or([0.0; 3]),
                error_m: t.error_m,
                rel_speed_mps: t.rel_speed_mps,
                on_pad: t.on_pad,
            }
        });
        let contact = eval.landing_contact().map(|t| TouchdownContact {
            vertical_speed_mps: t.vertical_mps,
            horizontal_speed_mps: t.horizontal_mps,
            tilt_deg: t.tilt_deg,
        });
        FlightLog {
            scenario: name.to_string(),
            seed,
            samples,
            obstacles,
            touchdown,
            contact,
        }
    }
}
