//! `landing map`'s scripted companion, a stage like the fsm it stands in for: it flies
//! through px4-link's requests and setpoints (OFFBOARD with the setpoint stream already
//! running, arm, climb, then slow legs that look at an obstacle from the front, both
//! sides and above) and sees only the vehicle state px4-link derives from telemetry.
//! Nothing here reads the simulator.

use ipc_types::msg::{
    Header, LinkOutcome, LinkOutcomeKind, LinkRequest, LinkRequestKind, Setpoint, Stage as StageId,
    VehicleState,
};
use ipc_types::topics;
use nalgebra::Vector3;
use stage::lockstep::{InputSpec, NodeSpec};
use stage::{Counter, Input, Message, Outbox, Stage, StageError};

/// The node's name.
pub const NAME: &str = "map-pilot";
/// Setpoints and decisions at 20 Hz.
const PERIOD_NS: u64 = 50_000_000;
/// How long the setpoint stream runs before OFFBOARD is asked for.
const STREAM_FIRST_NS: u64 = 1_200_000_000;
/// How long a refused or unanswered request waits before it is sent again.
const RETRY_NS: u64 = 1_000_000_000;
/// Climb rate, m/s.
const CLIMB_M_S: f64 = 0.5;
/// How long the vehicle holds at each waypoint.
const HOLD_NS: u64 = 1_500_000_000;

/// Where the script is.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    /// Waiting for the first vehicle state.
    Ground,
    /// Holding the ground position while OFFBOARD and arming are asked for.
    Requesting(LinkRequestKind),
    /// Climbing to the legs' height.
    Climb { since_ns: u64 },
    /// Flying leg `leg`; `arrived_ns`: when its waypoint was reached.
    Legs { leg: usize, arrived_ns: Option<u64> },
    /// Done: hovering at the last waypoint.
    Done,
}

/// The script: the legs' height and speed, and the point to look at.
#[derive(Debug, Clone)]
pub struct MapPilot {
    height_m: f64,
    speed_m_s: f64,
    look_at: Vector3<f64>,
    phase: Phase,
    state: Option<VehicleState>,
    /// The request in flight: its id, when it went out, and its answer once known.
    request: Option<(u64, u64, Option<LinkOutcomeKind>)>,
    next_id: u64,
    start: Vector3<f64>,
    target: Vector3<f64>,
    waypoints: Vec<Vector3<f64>>,
    /// When the setpoint stream started.
    since_ns: Option<u64>,
    counts: [u64; 3],
}

impl MapPilot {
    /// Flies legs at `height_m` and `speed_m_s` that look at `look_at`.
    pub fn new(height_m: f64, speed_m_s: f64, look_at: Vector3<f64>) -> Self {
        Self {
            height_m,
            speed_m_s,
            look_at,
            phase: Phase::Ground,
            state: None,
            request: None,
            next_id: 1,
            start: Vector3::zeros(),
            target: Vector3::zeros(),
            waypoints: Vec::new(),
            since_ns: None,
            counts: [0; 3],
        }
    }

    /// The node: vehicle state and request outcomes in, setpoints and requests out.
    pub fn spec() -> NodeSpec {
        let input = |topic: &str| InputSpec {
            topic: topic.to_string(),
            newest: false,
            delay: false,
            depth: None,
        };
        NodeSpec {
            name: NAME.to_string(),
            inputs: vec![input(topics::VEHICLE_STATE), input(topics::PX4_OUTCOME)],
            outputs: vec![
                topics::FSM_SETPOINT.to_string(),
                topics::PX4_REQUEST.to_string(),
            ],
            latency_ns: 0,
            periodic: None,
        }
    }

    /// The phases' names, indexed by the `phase` counter (for progress lines).
    pub const PHASES: [&'static str; 6] = [
        "on the ground",
        "setpoint stream",
        "arming",
        "take-off",
        "offboard legs",
        "done",
    ];

    fn phase_index(&self) -> u64 {
        match self.phase {
            Phase::Ground => 0,
            Phase::Requesting(LinkRequestKind::Offboard) => 1,
            Phase::Requesting(_) => 2,
            Phase::Climb { .. } => 3,
            Phase::Legs { .. } => 4,
            Phase::Done => 5,
        }
    }

    fn position(&self) -> Option<Vector3<f64>> {
        self.state
            .map(|s| Vector3::from(s.world_from_body.translation))
    }

    /// Sends `kind` (again after [`RETRY_NS`] without an acceptance); true once accepted.
    fn ask(
        &mut self,
        now_ns: u64,
        kind: LinkRequestKind,
        out: &mut dyn Outbox,
    ) -> Result<bool, StageError> {
        match self.request {
            Some((_, _, Some(LinkOutcomeKind::Accepted))) => {
                self.request = None;
                return Ok(true);
            }
            Some((_, sent, _)) if now_ns < sent + RETRY_NS => return Ok(false),
            _ => {}
        }
        let id = self.next_id;
        self.next_id += 1;
        self.request = Some((id, now_ns, None));
        let mut msg = Header::captured_at(now_ns);
        msg.push_stage(StageId::Bench, now_ns, now_ns);
        let r = LinkRequest {
            msg,
            id,
            kind: kind as u32,
            reserved: 0,
            altitude_m: 0.0,
        };
        self.counts[1] += 1;
        out.publish(topics::PX4_REQUEST, Message::LinkRequest(&r))?;
        Ok(false)
    }

    /// The legs: toward the obstacle, to each side of it, back, and above.
    fn legs(&self) -> Vec<Vector3<f64>> {
        let mut ahead = self.look_at - self.start;
        ahead.z = 0.0;
        let dist = ahead.norm().max(1e-6);
        let dir = ahead / dist;
        let side = Vector3::new(-dir.y, dir.x, 0.0);
        let mut near = self.start + dir * (0.4 * dist);
        near.z = self.height_m;
        vec![
            near,
            near - side * 1.5,
            near + side * 1.5,
            near,
            Vector3::new(near.x, near.y, self.height_m + 0.6),
        ]
    }

    /// Moves the target toward leg `leg`'s waypoint; the next phase.
    fn fly_legs(&mut self, now_ns: u64, leg: usize, arrived_ns: Option<u64>) -> Phase {
        let Some(w) = self.waypoints.get(leg).copied() else {
            return Phase::Done;
        };
        let to = w - self.target;
        let step = self.speed_m_s * PERIOD_NS as f64 * 1e-9;
        if to.norm() > step {
            self.target += to / to.norm() * step;
            return Phase::Legs { leg, arrived_ns };
        }
        self.target = w;
        let arrived = arrived_ns.unwrap_or(now_ns);
        if now_ns >= arrived + HOLD_NS {
            Phase::Legs {
                leg: leg + 1,
                arrived_ns: None,
            }
        } else {
            Phase::Legs {
                leg,
                arrived_ns: Some(arrived),
            }
        }
    }
}

impl Stage for MapPilot {
    fn name(&self) -> &'static str {
        NAME
    }

    fn tick_period_ns(&self) -> Option<u64> {
        Some(PERIOD_NS)
    }

    fn on_input(
        &mut self,
        _now_ns: u64,
        input: Input<'_>,
        _out: &mut dyn Outbox,
    ) -> Result<(), StageError> {
        match input.msg {
            Message::VehicleState(v) => self.state = Some(*v),
            Message::LinkOutcome(o) => self.on_outcome(o),
            _ => {}
        }
        Ok(())
    }

    fn on_tick(&mut self, now_ns: u64, out: &mut dyn Outbox) -> Result<(), StageError> {
        let since = self.since_ns.unwrap_or(now_ns);
        self.phase = match self.phase {
            Phase::Ground => match self.position() {
                Some(p) => {
                    // The setpoint stream starts here; OFFBOARD once it has run a while.
                    self.start = p;
                    self.target = p;
                    self.since_ns = Some(now_ns);
                    Phase::Requesting(LinkRequestKind::Offboard)
                }
                None => Phase::Ground,
            },
            Phase::Requesting(kind) if now_ns >= since + STREAM_FIRST_NS => {
                match (self.ask(now_ns, kind, out)?, kind) {
                    (true, LinkRequestKind::Offboard) => Phase::Requesting(LinkRequestKind::Arm),
                    (true, _) => Phase::Climb { since_ns: now_ns },
                    (false, _) => self.phase,
                }
            }
            Phase::Climb { since_ns } => {
                let t = now_ns.saturating_sub(since_ns) as f64 * 1e-9;
                self.target.z = (self.start.z + CLIMB_M_S * t).min(self.height_m);
                if self.position().is_some_and(|p| p.z > self.height_m - 0.1) {
                    self.target = self.position().unwrap_or(self.target);
                    self.target.z = self.height_m;
                    self.waypoints = self.legs();
                    Phase::Legs {
                        leg: 0,
                        arrived_ns: None,
                    }
                } else {
                    self.phase
                }
            }
            Phase::Legs { leg, arrived_ns } => self.fly_legs(now_ns, leg, arrived_ns),
            other => other,
        };
        if self.phase != Phase::Ground {
            let d = self.look_at - self.target;
            let mut msg = Header::captured_at(now_ns);
            msg.push_stage(StageId::Bench, now_ns, now_ns);
            let sp = Setpoint {
                msg,
                position: self.target.into(),
                velocity: [0.0; 3],
                acceleration: [0.0; 3],
                yaw: d.y.atan2(d.x),
                valid: Setpoint::POSITION | Setpoint::YAW,
                reserved: 0,
            };
            self.counts[0] += 1;
            out.publish(topics::FSM_SETPOINT, Message::Setpoint(&sp))?;
        }
        Ok(())
    }

    fn counters(&self) -> Vec<Counter> {
        vec![
            ("setpoints", self.counts[0]),
            ("requests", self.counts[1]),
            ("refused", self.counts[2]),
            ("phase", self.phase_index()),
            ("done", u64::from(self.phase == Phase::Done)),
        ]
    }
}

impl MapPilot {
    fn on_outcome(&mut self, o: &LinkOutcome) {
        if let Some((id, sent, _)) = self.request
            && o.id == id
        {
            let outcome = LinkOutcomeKind::from_raw(o.outcome);
            if outcome != LinkOutcomeKind::Accepted {
                self.counts[2] += 1;
            }
            self.request = Some((id, sent, Some(outcome)));
        }
    }
}
