//! The planner as a pipeline stage: the newest goal, vehicle state and map are kept as
//! they come; every tick (`DECIDE_PERIOD_NS`) the replanning policy is consulted and a
//! plan, a stop or nothing goes out.

use ipc_types::msg::{Header, OccupancyMapHeader, PlannerGoal, Stage as StageId};
use ipc_types::topics;
use stage::{Counter, Input, Message, Outbox, Stage, StageError};

use crate::{CellView, PlannerConfig, PlannerNode, State};

/// How often the policy is consulted, ns (50 Hz: a new goal or map waits at most this).
pub const DECIDE_PERIOD_NS: u64 = 20_000_000;

/// The `planner` node.
pub struct PlannerStage {
    node: PlannerNode,
    vehicle: Option<(State, Header)>,
    goal: Option<PlannerGoal>,
    /// The newest map, copied so the publisher's buffer is released at once.
    map_header: Option<OccupancyMapHeader>,
    cells: Vec<u8>,
    counts: Counts,
    /// Emergency stops published in a row: logged at the first and when they end, not
    /// each (the policy republishes one every step while the collision stays ahead).
    emergency_run: u64,
}

#[derive(Debug, Default, Clone, Copy)]
struct Counts {
    steps: u64,
    states: u64,
    goals: u64,
    maps: u64,
    bad_maps: u64,
    plans: u64,
    failed: u64,
    trajectories: u64,
    emergency_stops: u64,
}

impl PlannerStage {
    /// The one way the stage is built, wherever it runs (its process, the lockstep
    /// registry): from its `[planner]` section.
    pub fn from_config(cfg: &PlannerConfig) -> Self {
        Self {
            node: PlannerNode::new(cfg.clone()),
            vehicle: None,
            goal: None,
            map_header: None,
            cells: Vec::new(),
            counts: Counts::default(),
            emergency_run: 0,
        }
    }
}

impl Stage for PlannerStage {
    fn name(&self) -> &'static str {
        "planner"
    }

    fn tick_period_ns(&self) -> Option<u64> {
        Some(DECIDE_PERIOD_NS)
    }

    fn on_input(
        &mut self,
        _now_ns: u64,
        input: Input<'_>,
        _out: &mut dyn Outbox,
    ) -> Result<(), StageError> {
        match input.msg {
            Message::VehicleState(v) => {
                self.counts.states += 1;
                if let Some(s) = State::from_vehicle(v) {
                    self.vehicle = Some((s, v.msg));
                }
            }
            Message::PlannerGoal(g) => {
                self.counts.goals += 1;
                self.goal = Some(*g);
            }
            Message::OccupancyMap(h, cells) => {
                self.counts.maps += 1;
                if CellView::new(h, cells).is_some() {
                    self.cells.clear();
                    self.cells.extend_from_slice(cells);
                    self.map_header = Some(*h);
                } else {
                    self.counts.bad_maps += 1;
                }
            }
            _ => {}
        }
        Ok(())
    }

    fn on_tick(&mut self, now_ns: u64, out: &mut dyn Outbox) -> Result<(), StageError> {
        let Some((state, input)) = &self.vehicle else {
            return Ok(());
        };
        let view = self
            .map_header
            .as_ref()
            .and_then(|h| CellView::new(h, &self.cells));
        let o = self
            .node
            .step(now_ns, state, self.goal.as_ref(), view.as_ref(), input);
        self.counts.steps += 1;
        if let Some(t) = &o.trajectory {
            self.counts.trajectories += 1;
            out.publish(topics::PLANNER_TRAJECTORY, Message::Trajectory(t))?;
            if t.emergency != 0 {
                self.counts.emergency_stops += 1;
                if self.emergency_run == 0 {
                    tracing::warn!(id = t.id, "emergency stop published");
                }
                self.emergency_run += 1;
            } else if self.emergency_run > 0 {
                tracing::info!(in_a_row = self.emergency_run, "emergency stops ended");
                self.emergency_run = 0;
            }
        }
        if let Some(mut s) = o.stats {
            self.counts.plans += 1;
            if s.success == 0 {
                self.counts.failed += 1;
            }
            // The planning time is this stamp's exit - enter: the driver closes it when
            // the statistics leave, right after the plan.
            s.msg.push_stage(StageId::Planner, now_ns, now_ns);
            out.publish(topics::PLANNER_STATS, Message::PlannerStats(&s))?;
        }
        Ok(())
    }

    fn counters(&self) -> Vec<Counter> {
        let c = self.counts;
        vec![
            ("steps", c.steps),
            ("states", c.states),
            ("goals", c.goals),
            ("maps", c.maps),
            ("bad_maps", c.bad_maps),
            ("plans", c.plans),
            ("failed", c.failed),
            ("trajectories", c.trajectories),
            ("emergency_stops", c.emergency_stops),
        ]
    }
}
