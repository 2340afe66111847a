//! The planner process's logic without IPC: given the newest vehicle state, goal and map
//! at a time, decide, plan, and say what to publish. The binary only moves messages.

use ipc_types::msg::{
    GoalMode, Header, MAX_CONTROL_POINTS, PlannerGoal, PlannerStats, Stage, Trajectory,
};
use nalgebra::Vector3;

use crate::config::PlannerConfig;
use crate::map::OccupancyQuery;
use crate::plan::{Goal, Planner, stop_trajectory};
use crate::replan::{Decision, OnFailure, ReplanPolicy};
use bspline::{BSpline, State};

/// What one step asks the process to publish.
#[derive(Debug, Clone, Default)]
pub struct Output {
    /// A new trajectory (a plan, a stop, or an emergency stop).
    pub trajectory: Option<Trajectory>,
    /// Statistics of the planning call made in this step. `planning_ms` is 0: the
    /// library reads no clock; the call is timed by the planner's stage stamp.
    pub stats: Option<PlannerStats>,
}

/// How far the vehicle may be from the current trajectory for a replan to start from the
/// trajectory's state (continuity) instead of the measured one, m.
const CONTINUITY_M: f64 = 0.5;

/// The planner process's state between steps.
#[derive(Debug, Clone)]
pub struct PlannerNode {
    planner: Planner,
    policy: ReplanPolicy,
    current: Option<(BSpline, u64)>,
    next_id: u64,
    stopped_for: Option<u64>,
}

impl PlannerNode {
    /// A node with `cfg` (validated).
    pub fn new(cfg: PlannerConfig) -> Self {
        let policy = ReplanPolicy::new(
            cfg.replan_distance_m,
            cfg.goal_tolerance_m,
            cfg.collision_horizon_s,
            cfg.emergency_horizon_s,
        );
        Self {
            planner: Planner::new(cfg),
            policy,
            current: None,
            next_id: 1,
            stopped_for: None,
        }
    }

    /// The trajectory being flown and its start time (monotonic ns).
    pub fn current(&self) -> Option<&(BSpline, u64)> {
        self.current.as_ref()
    }

    /// One step at `now_ns`: `vehicle` is the newest measured state, `goal` the newest
    /// goal, `map` the newest map; `input` is the header the outputs derive from.
    pub fn step<M: OccupancyQuery + ?Sized>(
        &mut self,
        now_ns: u64,
        vehicle: &State,
        goal: Option<&PlannerGoal>,
        map: Option<&M>,
        input: &Header,
    ) -> Output {
        let mut out = Output::default();
        let Some(goal) = goal else {
            return out;
        };
        if !vehicle.is_finite() {
            return out;
        }
        let mode = GoalMode::from_raw(goal.mode);
        let start = self.start_state(now_ns, vehicle);
        if mode == GoalMode::Stop {
            if self.stopped_for != Some(goal.msg.seq) {
                self.stopped_for = Some(goal.msg.seq);
                let max_acc = self.planner.config().max_acc;
                out.trajectory = stop_trajectory(&start, max_acc)
                    .and_then(|s| self.publish(s, now_ns, false, input));
            }
            return out;
        }
        let Some(map) = map else {
            return out;
        };
        let target = Vector3::from(goal.position);
        let now_s = self
            .current
            .as_ref()
            .map(|(_, t0)| now_ns.saturating_sub(*t0) as f64 * 1e-9)
            .unwrap_or(0.0);
        let decision = self.policy.decide(
            now_s,
            &vehicle.p,
            (target, goal.mode),
            self.current.as_ref().map(|(s, _)| s),
            map,
        );
        let Decision::Replan(reason) = decision else {
            return out;
        };
        let g = Goal {
            state: State {
                p: target,
                v: Vector3::from(goal.velocity),
                a: Vector3::from(goal.acceleration),
            },
            moving: mode == GoalMode::Rendezvous,
        };
        let result = self.planner.plan(map, &start, &g);
        let st = self.planner.stats();
        let mut stats = PlannerStats {
            msg: Header::derived_from(input),
            trajectory_id: 0,
            planning_ms: 0.0,
            iterations: st.iterations,
            rebounds: st.rebounds,
            success: 0,
            reserved: 0,
        };
        match result {
            Ok(plan) => {
                out.trajectory = self.publish(plan.spline, now_ns, false, input);
                if let Some(t) = &out.trajectory {
                    stats.trajectory_id = t.id;
                    stats.success = 1;
                    self.policy.planned(&vehicle.p, (target, goal.mode));
                }
            }
            Err(e) => {
                tracing::debug!(error = %e, ?reason, "plan failed");
                if self.policy.on_failure(reason) == OnFailure::EmergencyStop {
                    let max_acc = self.planner.config().max_acc;
                    out.trajectory = stop_trajectory(&start, max_acc)
                        .and_then(|s| self.publish(s, now_ns, true, input));
                }
            }
        }
        out.stats = Some(stats);
        out
    }

    /// Where a new plan starts: on the current trajectory when the vehicle follows it,
    /// else the measured state.
    fn start_state(&self, now_ns: u64, vehicle: &State) -> State {
        if let Some((s, t0)) = &self.current {
            let st = s.eval(now_ns.saturating_sub(*t0) as f64 * 1e-9);
            if st.is_finite() && (st.p - vehicle.p).norm() < CONTINUITY_M {
                return st;
            }
        }
        *vehicle
    }

    /// The message for `spline`, which becomes the current trajectory; `None` (nothing
    /// published) when it does not fit the message or is not finite.
    fn publish(
        &mut self,
        spline: BSpline,
        now_ns: u64,
        emergency: bool,
        input: &Header,
    ) -> Option<Trajectory> {
        let t = to_message(&spline, self.next_id, now_ns, emergency, input)?;
        self.next_id += 1;
        self.current = Some((spline, now_ns));
        Some(t)
    }
}

/// A trajectory message for `spline`, or `None` when it has too many control points or a
/// non-finite number (NaN is never published).
pub fn to_message(
    spline: &BSpline,
    id: u64,
    start_ns: u64,
    emergency: bool,
    input: &Header,
) -> Option<Trajectory> {
    if spline.points.len() < 4
        || spline.points.len() > MAX_CONTROL_POINTS
        || !(spline.ts.is_finite() && spline.ts > 0.0)
        || !spline
            .points
            .iter()
            .all(|p| p.iter().all(|v| v.is_finite()))
    {
        return None;
    }
    let mut msg = Header::derived_from(input);
    msg.push_stage(Stage::Planner, start_ns, start_ns);
    let mut t = Trajectory {
        msg,
        id,
        start_ns,
        knot_interval_s: spline.ts,
        count: spline.points.len() as u32,
        emergency: u32::from(emergency),
        ..Trajectory::default()
    };
    for (dst, p) in t.control_points.iter_mut().zip(&spline.points) {
        *dst = [p.x, p.y, p.z];
    }
    Some(t)
}

#[cfg(test)]
#[path = "node_test.rs"]
mod tests;
