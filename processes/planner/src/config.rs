//! The `[planner]` section of the stack configuration. Defaults are the paper's.

use serde::Deserialize;
use stack_config::{Invalid, Validate, check_range};

/// What the planner reads from `landing.toml`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PlannerConfig {
    /// Grid resolution for maps built from boxes (`landing plan`), m.
    pub resolution: f64,
    /// Obstacle inflation for maps built from boxes, m.
    pub inflation: f64,
    /// Weight of the smoothness (jerk) term.
    pub lambda_smooth: f64,
    /// Weight of the collision term.
    pub lambda_collision: f64,
    /// Weight of the feasibility term.
    pub lambda_feasibility: f64,
    /// Weight of the fitness term (refinement after time re-allocation).
    pub lambda_fitness: f64,
    /// Speed limit, m/s (20 m/s chases a 50 km/h vehicle with margin).
    pub max_vel: f64,
    /// Acceleration limit, m/s^2.
    pub max_acc: f64,
    /// Control point spacing of the initial curve, m.
    pub control_point_spacing: f64,
    /// Clearance sf beyond the inflated surface the collision term asks for, m.
    pub clearance: f64,
    /// L-BFGS memory.
    pub lbfgs_memory: usize,
    /// L-BFGS iteration limit per optimization.
    pub max_iterations: usize,
    /// L-BFGS relative gradient tolerance of the final passes (polish of the first
    /// collision-free curve, refinement after time re-allocation).
    pub g_tolerance: f64,
    /// L-BFGS relative gradient tolerance while the curve still collides: a rebound round
    /// only has to move the points out, and its exact optimum is thrown away when the next
    /// round adds pairs (0.05: half the work of 0.01 on dense fields).
    pub rebound_g_tolerance: f64,
    /// Rebound rounds before a plan is given up, over both attempts: the first (from the
    /// straight initialization) gets at most half, the restart from the A* path the rest.
    pub max_rebounds: usize,
    /// Consecutive rebound rounds that find only collisions the existing pairs already
    /// cover (no new obstacle, the collision weight doubled each time) before the attempt
    /// is given up as stuck.
    pub max_stalled_rounds: usize,
    /// Work a plan may spend before it is given up, in L-BFGS iterations; an A* expansion
    /// counts 1/24 (what it costs beside an iteration on ~45 control points). A ceiling for
    /// the pathological plan (200: ~1.6 ms on the development VM), not a deadline: a plan
    /// that needs more is rare (2% of the benchmark's densest fields) and late anyway, and
    /// the replanning tries again from where the drone is then.
    pub work_budget: usize,
    /// Fitness ellipsoid, axial semi-axis a, m.
    pub fitness_axial: f64,
    /// Fitness ellipsoid, radial semi-axis b, m.
    pub fitness_radial: f64,
    /// Replan after travelling this far along the current plan, m.
    pub replan_distance_m: f64,
    /// Replan when the goal moved more than this, m.
    pub goal_tolerance_m: f64,
    /// How far ahead the current trajectory is checked for collisions, s.
    pub collision_horizon_s: f64,
    /// A predicted collision closer than this, with replanning failed, stops the drone, s.
    pub emergency_horizon_s: f64,
    /// A* expansion limit per search.
    pub max_astar_expansions: usize,
}

impl Default for PlannerConfig {
    fn default() -> Self {
        Self {
            resolution: 0.15,
            inflation: 0.299,
            lambda_smooth: 1.0,
            lambda_collision: 8.5,
            lambda_feasibility: 0.1,
            lambda_fitness: 1.0,
            max_vel: 3.0,
            max_acc: 6.0,
            control_point_spacing: 0.4,
            clearance: 0.5,
            lbfgs_memory: 16,
            max_iterations: 200,
            g_tolerance: 0.01,
            rebound_g_tolerance: 0.05,
            max_rebounds: 20,
            max_stalled_rounds: 3,
            work_budget: 200,
            fitness_axial: 20.0,
            fitness_radial: 1.0,
            replan_distance_m: 1.5,
            goal_tolerance_m: 0.3,
            collision_horizon_s: 3.0,
            emergency_horizon_s: 1.0,
            max_astar_expansions: 200_000,
        }
    }
}

impl Validate for PlannerConfig {
    fn validate(&self) -> Result<(), Invalid> {
        check_range("resolution", self.resolution, 0.02, 2.0)?;
        check_range("inflation", self.inflation, 0.0, 5.0)?;
        check_range("lambda_smooth", self.lambda_smooth, 0.0, 1e4)?;
        check_range("lambda_collision", self.lambda_collision, 0.0, 1e4)?;
        check_range("lambda_feasibility", self.lambda_feasibility, 0.0, 1e4)?;
        check_range("lambda_fitness", self.lambda_fitness, 0.0, 1e4)?;
        check_range("max_vel", self.max_vel, 0.1, 20.0)?;
        check_range("max_acc", self.max_acc, 0.1, 30.0)?;
        check_range(
            "control_point_spacing",
            self.control_point_spacing,
            0.05,
            5.0,
        )?;
        check_range("clearance", self.clearance, 0.01, 5.0)?;
        check_range("lbfgs_memory", self.lbfgs_memory, 1, 64)?;
        check_range("max_iterations", self.max_iterations, 1, 10_000)?;
        check_range("g_tolerance", self.g_tolerance, 1e-9, 10.0)?;
        check_range("rebound_g_tolerance", self.rebound_g_tolerance, 1e-9, 10.0)?;
        check_range("max_rebounds", self.max_rebounds, 0, 100)?;
        check_range("max_stalled_rounds", self.max_stalled_rounds, 1, 100)?;
        check_range("work_budget", self.work_budget, 10, 1_000_000)?;
        check_range("fitness_axial", self.fitness_axial, 0.01, 1000.0)?;
        check_range("fitness_radial", self.fitness_radial, 0.01, 1000.0)?;
        check_range("replan_distance_m", self.replan_distance_m, 0.1, 100.0)?;
        check_range("goal_tolerance_m", self.goal_tolerance_m, 0.0, 100.0)?;
        check_range("collision_horizon_s", self.collision_horizon_s, 0.1, 60.0)?;
        check_range("emergency_horizon_s", self.emergency_horizon_s, 0.0, 10.0)?;
        check_range(
            "max_astar_expansions",
            self.max_astar_expansions,
            100,
            10_000_000,
        )?;
        Ok(())
    }
}
