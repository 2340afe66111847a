//! When to replan: a pure policy (time is an argument), so the process and tests share it.

use nalgebra::Vector3;

use crate::map::OccupancyQuery;
use bspline::BSpline;

/// Why a new plan is wanted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Reason {
    /// No trajectory yet.
    NoTrajectory,
    /// The goal moved beyond the tolerance or changed mode.
    NewGoal,
    /// The drone travelled the replanning distance since the last plan.
    Distance,
    /// The current trajectory is predicted to collide this many seconds ahead.
    Collision(f64),
}

/// The policy's answer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Decision {
    /// Keep flying the current trajectory.
    Keep,
    /// Plan again.
    Replan(Reason),
}

/// What to do when a replan failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OnFailure {
    /// Keep the current trajectory (it is not predicted to collide soon).
    KeepCurrent,
    /// Publish an emergency stop: a collision is less than the emergency horizon ahead.
    EmergencyStop,
}

/// Replanning policy state: where the last plan started and for which goal.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplanPolicy {
    replan_distance_m: f64,
    goal_tolerance_m: f64,
    collision_horizon_s: f64,
    emergency_horizon_s: f64,
    last_plan_at: Option<Vector3<f64>>,
    last_goal: Option<(Vector3<f64>, u32)>,
}

impl ReplanPolicy {
    /// A policy with the given distances (m) and horizons (s).
    pub fn new(
        replan_distance_m: f64,
        goal_tolerance_m: f64,
        collision_horizon_s: f64,
        emergency_horizon_s: f64,
    ) -> Self {
        Self {
            replan_distance_m,
            goal_tolerance_m,
            collision_horizon_s,
            emergency_horizon_s,
            last_plan_at: None,
            last_goal: None,
        }
    }

    /// Decides at `now_s` (seconds on the trajectory's clock, 0 = its start) whether the
    /// drone at `position` should replan toward `goal` (position, raw mode), given the
    /// current trajectory (if any) and map.
    pub fn decide<M: OccupancyQuery + ?Sized>(
        &self,
        now_s: f64,
        position: &Vector3<f64>,
        goal: (Vector3<f64>, u32),
        current: Option<&BSpline>,
        map: &M,
    ) -> Decision {
        let Some(traj) = current else {
            return Decision::Replan(Reason::NoTrajectory);
        };
        if let Some(t) = predicted_collision(traj, now_s, self.collision_horizon_s, map) {
            return Decision::Replan(Reason::Collision(t - now_s));
        }
        match self.last_goal {
            Some((g, mode)) if mode == goal.1 && (g - goal.0).norm() <= self.goal_tolerance_m => {}
            _ => return Decision::Replan(Reason::NewGoal),
        }
        if self
            .last_plan_at
            .is_none_or(|p| (p - position).norm() >= self.replan_distance_m)
        {
            return Decision::Replan(Reason::Distance);
        }
        Decision::Keep
    }

    /// Records that a plan from `position` toward `goal` was published.
    pub fn planned(&mut self, position: &Vector3<f64>, goal: (Vector3<f64>, u32)) {
        self.last_plan_at = Some(*position);
        self.last_goal = Some(goal);
    }

    /// What to do after a failed replan, given why it was attempted.
    pub fn on_failure(&self, reason: Reason) -> OnFailure {
        match reason {
            Reason::Collision(dt) if dt < self.emergency_horizon_s => OnFailure::EmergencyStop,
            _ => OnFailure::KeepCurrent,
        }
    }
}

/// The first time in `now_s..now_s + horizon_s` at which `traj` enters an occupied cell.
pub fn predicted_collision<M: OccupancyQuery + ?Sized>(
    traj: &BSpline,
    now_s: f64,
    horizon_s: f64,
    map: &M,
) -> Option<f64> {
    let end = (now_s + horizon_s).min(traj.duration());
    let (v, _) = traj.max_vel_acc();
    let dt = (map.resolution() / 3.0 / v.max(0.1)).max(1e-3);
    let mut t = now_s.max(0.0);
    while t <= end {
        if map.is_occupied(&traj.eval(t).p) {
            return Some(t);
        }
        t += dt;
    }
    None
}

#[cfg(test)]
#[path = "replan_test.rs"]
mod tests;
