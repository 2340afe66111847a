//! The mission as a pipeline stage: every message in, the mission stepped on its own
//! clock (`[fsm] rate_hz`) and at once on a safety order.

use ipc_types::msg::MissionState;
use ipc_types::topics;
use stage::{Counter, Input, Message, Outbox, Stage, StageError};

use crate::pad_filter::Update;
use crate::{Fsm, FsmConfig};

/// The `fsm` node.
pub struct FsmStage {
    fsm: Fsm,
    counts: Counts,
    /// An observation the pad filter took came in this batch of inputs.
    pad_news: bool,
}

/// Messages taken in and published.
#[derive(Debug, Default, Clone, Copy)]
struct Counts {
    ticks: u64,
    states: u64,
    observations: u64,
    trajectories: u64,
    outcomes: u64,
    safety: u64,
    requests: u64,
    goals: u64,
    setpoints: u64,
}

impl FsmStage {
    /// The one way the stage is built, wherever it runs (its process, the lockstep
    /// registry): from its `[fsm]` section (validated by the caller; `landing run` puts
    /// the scenario's preset point and commit height in it).
    pub fn from_config(cfg: &FsmConfig) -> Self {
        Self {
            fsm: Fsm::new(cfg.clone()),
            counts: Counts::default(),
            pad_news: false,
        }
    }

    /// The mission, to read its state and transitions.
    pub fn fsm(&self) -> &Fsm {
        &self.fsm
    }

    /// One mission step and its outputs.
    fn step(&mut self, now_ns: u64, out: &mut dyn Outbox) -> Result<(), StageError> {
        let o = self.fsm.tick(now_ns);
        self.counts.ticks += 1;
        for r in &o.requests {
            out.publish(topics::PX4_REQUEST, Message::LinkRequest(r))?;
            self.counts.requests += 1;
        }
        if let Some(g) = &o.goal {
            out.publish(topics::PLANNER_GOAL, Message::PlannerGoal(g))?;
            self.counts.goals += 1;
        }
        if let Some(sp) = &o.setpoint {
            out.publish(topics::FSM_SETPOINT, Message::Setpoint(sp))?;
            self.counts.setpoints += 1;
        }
        if let Some(st) = &o.status {
            out.publish(topics::FSM_STATUS, Message::FsmStatus(st))?;
        }
        Ok(())
    }
}

impl Stage for FsmStage {
    fn name(&self) -> &'static str {
        "fsm"
    }

    fn tick_period_ns(&self) -> Option<u64> {
        Some(self.fsm.tick_period_ns())
    }

    fn on_input(
        &mut self,
        now_ns: u64,
        input: Input<'_>,
        out: &mut dyn Outbox,
    ) -> Result<(), StageError> {
        match input.msg {
            Message::VehicleState(s) => {
                self.counts.states += 1;
                self.fsm.on_vehicle_state(now_ns, s);
            }
            Message::PadObservation(o) => {
                self.counts.observations += 1;
                let u = self.fsm.on_observation(now_ns, o);
                self.pad_news |=
                    matches!(u, Update::Accepted | Update::Started | Update::Restarted);
            }
            Message::Trajectory(t) => {
                self.counts.trajectories += 1;
                self.fsm.on_trajectory(t);
            }
            Message::LinkOutcome(o) => {
                self.counts.outcomes += 1;
                self.fsm.on_outcome(o);
            }
            Message::WatchdogView(v) => self.fsm.on_watchdog_view(now_ns, v.phase),
            Message::SafetyCommand(c) => {
                self.counts.safety += 1;
                self.fsm.on_safety(now_ns, c);
                // A safety order acts at once, not at the next tick.
                self.step(now_ns, out)?;
            }
            _ => {}
        }
        Ok(())
    }

    /// Following the pad, a new observation is answered at once, not at the next tick:
    /// the setpoint that follows it is the end of the camera's latency chain.
    fn on_inputs_done(&mut self, now_ns: u64, out: &mut dyn Outbox) -> Result<(), StageError> {
        let following = matches!(
            self.fsm.state(),
            MissionState::Track | MissionState::Descend | MissionState::Land
        );
        if std::mem::take(&mut self.pad_news) && following {
            self.step(now_ns, out)?;
        }
        Ok(())
    }

    fn on_tick(&mut self, now_ns: u64, out: &mut dyn Outbox) -> Result<(), StageError> {
        self.step(now_ns, out)
    }

    fn counters(&self) -> Vec<Counter> {
        let c = self.counts;
        vec![
            ("ticks", c.ticks),
            ("states", c.states),
            ("observations", c.observations),
            ("trajectories", c.trajectories),
            ("outcomes", c.outcomes),
            ("safety", c.safety),
            ("requests", c.requests),
            ("goals", c.goals),
            ("setpoints", c.setpoints),
        ]
    }
}
