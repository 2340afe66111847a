//! The watchdog as a pipeline stage: liveness events (`watchdog/liveness`, served by the
//! runtime's supervision source in a process; none in lockstep), the vehicle state, the
//! mission status, setpoints, pad observations and camera frames in; `safety/command`
//! (repeated while it stands, so a restarted px4-link still gets it) and `watchdog/view`
//! out.

use ipc_types::msg::{
    CameraFrameHeader, Header, LandedState, MissionState, PadObservation, ProcessEventKind,
    SafetyCommand, Setpoint, Stage as StageId, Text, VehicleState,
};
use ipc_types::topics;
use serde::Deserialize;
use stack_config::{Invalid, Validate, check_range};
use stage::{Counter, Input, Message, Outbox, Stage, StageError};

use crate::{Action, Budget, PathRule, Policy, Watchdog, WatchdogConfig, WatchedProcess};

/// The processes whose loss in the air always lands: nothing else flies the vehicle.
pub const CRITICAL: &[&str] = &["fsm", "px4-link"];

/// `[watchdog]` of the stack configuration.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WatchdogStageConfig {
    /// How often the deadlines are looked at, ms (the resolution of a hang's detection).
    pub tick_ms: u64,
    /// How often the stack's iceoryx2 nodes are listed for dead ones, ms (the resolution
    /// of a death's detection).
    pub node_poll_ms: u64,
    /// How often the view is published (and a standing order repeated), ms.
    pub view_period_ms: u64,
    /// How long each path and a dead process may be gone before it is a loss.
    pub ride_through: RideThroughConfig,
    /// The fsm's pad estimate counts as fresh this long after the last observation, ms.
    pub pad_fresh_ms: f64,
    /// What to do about a non-critical loss in the air, per phase.
    pub policy: PolicyConfig,
}

/// `[watchdog.ride_through]`: a short outage is flown through, a longer one is a loss
/// (docs/faults.md says why each budget is what it is).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RideThroughConfig {
    /// A watched process found dead waits this long for its restart (systemd's
    /// RestartSec and the process's start) before it is a loss, ms; 0: at once.
    pub restart_ms: f64,
    /// The autopilot's telemetry (new telemetry in vehicle/state) in the air, ms
    /// (critical: past it, land).
    pub telemetry_ms: PhaseBudget,
    /// Setpoints while the fsm flies offboard, ms (critical: past it, land).
    pub setpoints_ms: PhaseBudget,
    /// Camera frames, ms (past it, the policy's action).
    pub camera_ms: PhaseBudget,
    /// Pad observations carrying only garbage, ms (their silence is no fault: the pad
    /// may be out of view; past it, the policy's action).
    pub observations_ms: PhaseBudget,
}

/// A budget per mission phase, ms: `default` for every phase not named.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhaseBudget {
    /// Every phase not named.
    pub default: f64,
    /// Taking off.
    pub takeoff: Option<f64>,
    /// Going to the preset point.
    pub go_to_preset: Option<f64>,
    /// Waiting for the pad there.
    pub wait_for_pad: Option<f64>,
    /// Tracking the pad.
    pub track: Option<f64>,
    /// Following where the pad should be.
    pub lost: Option<f64>,
    /// Descending onto the pad.
    pub descend: Option<f64>,
    /// The touchdown.
    pub land: Option<f64>,
}

impl PhaseBudget {
    /// `ms` in every phase.
    pub const fn flat(ms: f64) -> Self {
        Self {
            default: ms,
            takeoff: None,
            go_to_preset: None,
            wait_for_pad: None,
            track: None,
            lost: None,
            descend: None,
            land: None,
        }
    }

    fn named(&self) -> [(MissionState, Option<f64>); 7] {
        use MissionState as M;
        [
            (M::Takeoff, self.takeoff),
            (M::GoToPreset, self.go_to_preset),
            (M::WaitForPad, self.wait_for_pad),
            (M::Track, self.track),
            (M::Lost, self.lost),
            (M::Descend, self.descend),
            (M::Land, self.land),
        ]
    }

    /// As the library's budget.
    pub fn budget(&self) -> Budget {
        Budget {
            by_phase: self
                .named()
                .into_iter()
                .filter_map(|(p, ms)| ms.map(|ms| (p, ms)))
                .collect(),
            otherwise: self.default,
        }
    }

    fn validate(&self, key: &str) -> Result<(), Invalid> {
        check_range(&format!("{key}.default"), self.default, 10.0, 60_000.0)?;
        for (phase, ms) in self.named() {
            if let Some(ms) = ms {
                check_range(&format!("{key}.{}", phase.name()), ms, 10.0, 60_000.0)?;
            }
        }
        Ok(())
    }
}

impl Default for RideThroughConfig {
    /// Why each number: docs/faults.md, "Riding through".
    fn default() -> Self {
        Self {
            restart_ms: 600.0,
            telemetry_ms: PhaseBudget {
                land: Some(800.0),
                ..PhaseBudget::flat(1500.0)
            },
            setpoints_ms: PhaseBudget::flat(700.0),
            camera_ms: PhaseBudget {
                land: Some(1000.0),
                ..PhaseBudget::flat(2500.0)
            },
            observations_ms: PhaseBudget::flat(1000.0),
        }
    }
}

impl Validate for RideThroughConfig {
    fn validate(&self) -> Result<(), Invalid> {
        check_range("ride_through.restart_ms", self.restart_ms, 0.0, 60_000.0)?;
        self.telemetry_ms.validate("ride_through.telemetry_ms")?;
        self.setpoints_ms.validate("ride_through.setpoints_ms")?;
        self.camera_ms.validate("ride_through.camera_ms")?;
        self.observations_ms
            .validate("ride_through.observations_ms")
    }
}

/// `[watchdog.policy]`: "land", "hold" or "continue" for the descent and the touchdown,
/// and for every other phase.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PolicyConfig {
    /// While descending onto the pad.
    pub descend: Action,
    /// During the touchdown.
    pub land: Action,
    /// Every other phase (take-off, going to the preset, waiting, tracking).
    pub otherwise: Action,
}

impl Default for PolicyConfig {
    fn default() -> Self {
        let p = Policy::default();
        Self {
            descend: p.get(MissionState::Descend),
            land: p.get(MissionState::Land),
            otherwise: p.otherwise,
        }
    }
}

impl Default for WatchdogStageConfig {
    fn default() -> Self {
        Self {
            tick_ms: 10,
            node_poll_ms: 20,
            view_period_ms: 200,
            ride_through: RideThroughConfig::default(),
            pad_fresh_ms: 500.0,
            policy: PolicyConfig::default(),
        }
    }
}

impl Validate for WatchdogStageConfig {
    fn validate(&self) -> Result<(), Invalid> {
        check_range("tick_ms", self.tick_ms, 1, 1000)?;
        check_range("node_poll_ms", self.node_poll_ms, 1, 1000)?;
        check_range("view_period_ms", self.view_period_ms, 10, 10_000)?;
        check_range("pad_fresh_ms", self.pad_fresh_ms, 10.0, 60_000.0)?;
        self.ride_through.validate()
    }
}

impl WatchdogStageConfig {
    /// What the watchdog watches: `processes` (graph node name, heartbeat deadline in ms),
    /// the fsm and px4-link critical, and the data paths.
    pub fn watchdog_config(&self, processes: &[(String, f64)]) -> WatchdogConfig {
        use MissionState as M;
        let offboard = vec![M::GoToPreset, M::WaitForPad, M::Track, M::Descend, M::Land];
        WatchdogConfig {
            processes: processes
                .iter()
                .map(|(name, deadline_ms)| WatchedProcess {
                    name: name.clone(),
                    deadline_ms: *deadline_ms,
                    critical: CRITICAL.contains(&name.as_str()),
                    restart_ms: self.ride_through.restart_ms,
                })
                .collect(),
            paths: vec![
                PathRule {
                    topic: topics::VEHICLE_STATE.into(),
                    phases: Vec::new(),
                    silence: self.ride_through.telemetry_ms.budget(),
                    garbage: self.ride_through.telemetry_ms.budget(),
                    critical: true,
                },
                PathRule {
                    topic: topics::FSM_SETPOINT.into(),
                    phases: offboard,
                    silence: self.ride_through.setpoints_ms.budget(),
                    garbage: self.ride_through.setpoints_ms.budget(),
                    critical: true,
                },
                PathRule {
                    topic: topics::CAMERA_FRAME.into(),
                    phases: Vec::new(),
                    silence: self.ride_through.camera_ms.budget(),
                    garbage: self.ride_through.camera_ms.budget(),
                    critical: false,
                },
                // Observations stop whenever the pad is out of view: garbage only.
                PathRule {
                    topic: topics::PAD_OBSERVATION.into(),
                    phases: Vec::new(),
                    silence: Budget::flat(f64::INFINITY),
                    garbage: self.ride_through.observations_ms.budget(),
                    critical: false,
                },
            ],
            policy: Policy {
                by_phase: vec![
                    (M::Descend, self.policy.descend),
                    (M::Land, self.policy.land),
                ],
                otherwise: self.policy.otherwise,
            },
        }
    }
}

#[derive(Debug, Default, Clone, Copy)]
struct Counts {
    beats: u64,
    deaths: u64,
    messages: u64,
    garbage: u64,
    faults: u64,
    orders: u64,
    views: u64,
}

/// The watchdog stage.
pub struct WatchdogStage {
    dog: Watchdog,
    cfg: WatchdogStageConfig,
    phase: MissionState,
    pad_valid: bool,
    airborne: bool,
    last_pad_ns: Option<u64>,
    /// The newest autopilot telemetry time seen in a vehicle state.
    last_telemetry_ns: u64,
    order: Option<SafetyCommand>,
    next_view_ns: u64,
    /// Sequence numbers, one per topic: a reader counts a gap as a lost message.
    view_seq: u64,
    order_seq: u64,
    counts: Counts,
}

impl WatchdogStage {
    /// The one way the stage is built, wherever it runs (its process, the lockstep
    /// registry): from its `[watchdog]` section (validated by the caller), watching
    /// `processes` (name, heartbeat deadline ms: the graph's, `watched_processes`; none
    /// in lockstep, where no process can die).
    pub fn from_config(
        cfg: &WatchdogStageConfig,
        processes: &[(String, f64)],
    ) -> Result<Self, crate::ConfigError> {
        Ok(Self {
            dog: Watchdog::new(cfg.watchdog_config(processes))?,
            cfg: cfg.clone(),
            phase: MissionState::Idle,
            pad_valid: false,
            airborne: false,
            last_pad_ns: None,
            last_telemetry_ns: 0,
            order: None,
            next_view_ns: 0,
            view_seq: 0,
            order_seq: 0,
            counts: Counts::default(),
        })
    }

    /// The supervisor, to read its view.
    pub fn watchdog(&self) -> &Watchdog {
        &self.dog
    }

    fn header(seq: &mut u64, now_ns: u64) -> Header {
        *seq += 1;
        let mut h = Header::captured_at(now_ns);
        h.seq = *seq;
        h.push_stage(StageId::Watchdog, now_ns, now_ns);
        h
    }

    fn mission(&mut self, now_ns: u64) {
        let fresh = self.pad_valid
            && self
                .last_pad_ns
                .is_some_and(|t| now_ns.saturating_sub(t) as f64 * 1e-6 <= self.cfg.pad_fresh_ms);
        self.dog.mission(self.phase, self.airborne, fresh, now_ns);
    }
}

fn finite(v: &[f64]) -> bool {
    v.iter().all(|x| x.is_finite() && x.abs() < 1e6)
}

fn sane_state(s: &VehicleState) -> bool {
    let p = &s.world_from_body;
    finite(&p.translation) && finite(&p.rotation_xyzw) && finite(&s.velocity)
}

fn sane_setpoint(s: &Setpoint) -> bool {
    finite(&s.position) && finite(&s.velocity) && finite(&s.acceleration) && s.yaw.is_finite()
}

fn sane_observation(o: &PadObservation) -> bool {
    let (c, w) = (&o.camera_from_pad, &o.world_from_pad);
    finite(&c.translation)
        && finite(&c.rotation_xyzw)
        && finite(&w.translation)
        && finite(&w.rotation_xyzw)
        && o.reprojection_error_px.is_finite()
}

fn sane_frame(h: &CameraFrameHeader, pixels: &[u8]) -> bool {
    h.width > 0 && h.height > 0 && h.expected_len().is_some_and(|n| n <= pixels.len())
}

impl Stage for WatchdogStage {
    fn name(&self) -> &'static str {
        "watchdog"
    }

    fn tick_period_ns(&self) -> Option<u64> {
        Some(self.cfg.tick_ms * 1_000_000)
    }

    fn on_input(
        &mut self,
        now_ns: u64,
        input: Input<'_>,
        _out: &mut dyn Outbox,
    ) -> Result<(), StageError> {
        let (topic, sane) = match input.msg {
            Message::ProcessEvent(e) => {
                match ProcessEventKind::from_raw(e.kind) {
                    Some(ProcessEventKind::Beat) => {
                        self.counts.beats += 1;
                        self.dog.beat(e.process.as_str(), now_ns);
                    }
                    Some(ProcessEventKind::Died) => {
                        self.counts.deaths += 1;
                        self.dog.died(e.process.as_str(), now_ns);
                    }
                    Some(ProcessEventKind::Cpu) => {
                        self.dog.cpu(e.process.as_str(), e.msg.capture_ns, e.cpu_ns);
                    }
                    None => {}
                }
                return Ok(());
            }
            Message::VehicleState(s) => {
                let sane = sane_state(s);
                if sane {
                    self.airborne = matches!(
                        LandedState::from_raw(s.landed_state),
                        LandedState::InAir | LandedState::Takeoff | LandedState::Landing
                    );
                }
                // px4-link publishes a state at least every 100 ms, telemetry or not: the
                // path is alive when the autopilot's telemetry in it is new.
                let new = s.link.last_telemetry_ns > self.last_telemetry_ns;
                if sane && !new {
                    return Ok(());
                }
                self.last_telemetry_ns = self.last_telemetry_ns.max(s.link.last_telemetry_ns);
                (topics::VEHICLE_STATE, sane)
            }
            Message::FsmStatus(s) => {
                // An fsm in Idle in the air is a restarted one: the mission is still in
                // the state it was in, which the view keeps for the new fsm to resume.
                match MissionState::from_raw(s.state) {
                    Some(MissionState::Idle) if self.airborne => {}
                    Some(p) => self.phase = p,
                    None => {}
                }
                self.pad_valid = s.pad_valid == 1;
                (topics::FSM_STATUS, true)
            }
            Message::Setpoint(s) => (topics::FSM_SETPOINT, sane_setpoint(s)),
            Message::PadObservation(o) => {
                let sane = sane_observation(o);
                if sane {
                    self.last_pad_ns = Some(now_ns);
                }
                (topics::PAD_OBSERVATION, sane)
            }
            Message::CameraFrame(h, px) => (topics::CAMERA_FRAME, sane_frame(h, px)),
            _ => return Ok(()),
        };
        self.counts.messages += 1;
        if !sane {
            self.counts.garbage += 1;
        }
        self.dog.message(topic, now_ns, sane);
        Ok(())
    }

    fn on_tick(&mut self, now_ns: u64, out: &mut dyn Outbox) -> Result<(), StageError> {
        self.mission(now_ns);
        let o = self.dog.tick(now_ns);
        for (_, f) in &o.faults {
            self.counts.faults += 1;
            tracing::warn!(fault = %f.describe(), "watchdog: fault");
        }
        for (p, ms) in &o.rejoins {
            tracing::info!(process = p.as_str(), after_ms = ms, "watchdog: rejoined");
        }
        for d in &o.decisions {
            tracing::warn!(action = d.action.name(), "watchdog: {}", d.why);
        }
        let mut send_now = false;
        if let Some((action, why)) = o.order {
            self.counts.orders += 1;
            tracing::error!(action = ?action, "watchdog orders: {why}");
            self.order = Some(SafetyCommand {
                msg: Header::default(),
                action: action as u32,
                reserved: 0,
                source: Text::new("watchdog"),
                reason: Text::new(&why),
            });
            send_now = true;
        }
        // Repeated while in the air (a restarted px4-link still gets it); down, it is over.
        if !self.airborne {
            self.order = None;
        }
        let view_due = now_ns >= self.next_view_ns;
        if (send_now || view_due)
            && let Some(mut c) = self.order
        {
            c.msg = Self::header(&mut self.order_seq, now_ns);
            out.publish(topics::SAFETY_COMMAND, Message::SafetyCommand(&c))?;
        }
        if view_due || send_now || !o.faults.is_empty() {
            self.next_view_ns = now_ns + self.cfg.view_period_ms * 1_000_000;
            let mut v = self.dog.view();
            v.msg = Self::header(&mut self.view_seq, now_ns);
            self.counts.views += 1;
            out.publish(topics::WATCHDOG_VIEW, Message::WatchdogView(&v))?;
        }
        Ok(())
    }

    fn counters(&self) -> Vec<Counter> {
        let c = &self.counts;
        vec![
            ("beats", c.beats),
            ("deaths", c.deaths),
            ("messages", c.messages),
            ("garbage", c.garbage),
            ("faults", c.faults),
            ("orders", c.orders),
            ("views", c.views),
        ]
    }
}

/// The processes a watchdog of `graph` watches: every vehicle node but itself, with its
/// heartbeat deadline, ms.
pub fn watched_processes(graph: &graph::Graph) -> Vec<(String, f64)> {
    graph
        .vehicle_nodes()
        .filter(|n| n.name != "watchdog")
        .map(|n| (n.name.clone(), n.heartbeat_deadline_ms as f64))
        .collect()
}

#[cfg(test)]
#[path = "stage_test.rs"]
mod numbering_tests;
