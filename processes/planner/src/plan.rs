//! One plan: initialization, A*-guided rebound with L-BFGS, time re-allocation with
//! fitness refinement, and a final independent-of-the-optimizer acceptance check.

use ipc_types::msg::MAX_CONTROL_POINTS;
use nalgebra::Vector3;

use crate::astar::{AStar, TIE_BREAK};
use crate::config::PlannerConfig;
use crate::cost::{Cost, Pair, Weights};
use crate::lbfgs::{Lbfgs, LbfgsSettings, Objective, Stop};
use crate::map::OccupancyQuery;
use crate::precond::JerkPreconditioner;
use bspline::{BSpline, Quintic, SegmentSampler, State, end_points, fit};

/// Why no trajectory was produced. Nothing is ever returned that failed the final check.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    /// A start or goal component is NaN or infinite.
    #[error("start or goal is not finite")]
    NotFinite,
    /// The start lies outside the map.
    #[error("start is outside the map")]
    StartOutsideMap,
    /// The start lies in an occupied or inflated cell (the planner does not escape: the
    /// caller keeps its current trajectory or stops).
    #[error("start is inside an obstacle's inflation")]
    StartOccupied,
    /// No free cell within 2 m of the goal.
    #[error("no free goal within 2 m of the requested one")]
    NoFreeGoal,
    /// A* found no way around an obstacle.
    #[error("no path around an obstacle")]
    NoPath,
    /// The rebound rounds ran out with the trajectory still colliding.
    #[error("trajectory still collides after the rebound rounds")]
    Collides,
    /// The work budget (`PlannerConfig::work_budget`) ran out first.
    #[error("work budget spent before a collision-free trajectory")]
    OverBudget,
    /// The trajectory leaves the map or exceeds the limits after time re-allocation.
    #[error("trajectory infeasible: {0}")]
    Infeasible(&'static str),
}

/// A goal: a state to reach; for a rendezvous the position is where the target is now and
/// moves with `state.v`, so the planner aims where it will be on arrival.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Goal {
    /// Target state (position, velocity, acceleration).
    pub state: State,
    /// True when the target moves at `state.v` (rendezvous with the pad).
    pub moving: bool,
}

/// A successful plan.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// The trajectory: starts at the start state and ends at `goal`.
    pub spline: BSpline,
    /// The goal position actually used (clamped into the map, moved out of obstacles,
    /// predicted for a moving target).
    pub goal: Vector3<f64>,
    /// True when the goal was clamped or moved to the nearest free cell.
    pub goal_adjusted: bool,
}

/// What the last call did, success or not.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PlanStats {
    /// L-BFGS iterations over all optimizations.
    pub iterations: u32,
    /// Rebound rounds.
    pub rebounds: u32,
    /// Time re-allocations.
    pub reallocations: u32,
    /// Restarts from the A* path after the first initialization failed.
    pub restarts: u32,
    /// Cells A* expanded over all its searches.
    pub astar_expansions: u64,
}

/// The planner: settings and every buffer reused from plan to plan.
#[derive(Debug, Clone)]
pub struct Planner {
    cfg: PlannerConfig,
    lbfgs: Lbfgs,
    astar: AStar,
    pairs: Vec<Vec<Pair>>,
    path: Vec<Vector3<f64>>,
    x: Vec<f64>,
    grad: Vec<Vector3<f64>>,
    marks: Vec<bool>,
    precond: JerkPreconditioner,
    extra: Vec<f64>,
    sampler: SegmentSampler,
    stats: PlanStats,
    expansions_at_start: u64,
}

/// Fraction of a pair's collision curvature at the clearance (6 sf lambda_collision) added
/// to L-BFGS's initial Hessian at points with pairs (0.03-0.3 measured alike; 1 is worse).
const PAIR_STIFFNESS: f64 = 0.1;

/// A* expansions that cost about one L-BFGS iteration in the work budget (measured on the
/// benchmark's fields: ~0.3 us an expansion, ~7 us an iteration on 45 control points).
pub const EXPANSIONS_PER_ITERATION: u64 = 24;

/// Heuristic weight of the start-to-goal A* that seeds the restart.
const RESTART_ASTAR_WEIGHT: f32 = 2.0;

/// L-BFGS iterations of the polish at the tight tolerance once a curve is collision-free
/// (30: on the benchmark's fields the same mean jerk as polishing to convergence, within
/// 1%, and a shorter tail).
const POLISH_ITERATIONS: usize = 30;

/// Time re-allocations per plan before the limits are called infeasible.
const MAX_REALLOCATIONS: u32 = 5;

/// The optimizer aims this far inside the limits: the weak feasibility term settles a few
/// per cent beyond its target where collision pairs push, and time re-allocation alone
/// cannot undo that.
const FEASIBILITY_MARGIN: f64 = 0.95;

/// How far the final check tolerates limits being exceeded (sampling and rounding).
pub const LIMIT_TOLERANCE: f64 = 1.05;

impl Planner {
    /// A planner with `cfg` (assumed validated).
    pub fn new(cfg: PlannerConfig) -> Self {
        let lbfgs = Lbfgs::new(LbfgsSettings {
            memory: cfg.lbfgs_memory,
            max_iterations: cfg.max_iterations,
            g_tolerance: cfg.g_tolerance,
            ..LbfgsSettings::default()
        });
        let astar = AStar::new(cfg.max_astar_expansions);
        Self {
            cfg,
            lbfgs,
            astar,
            pairs: Vec::new(),
            path: Vec::new(),
            x: Vec::new(),
            grad: Vec::new(),
            marks: Vec::new(),
            precond: JerkPreconditioner::default(),
            extra: Vec::new(),
            sampler: SegmentSampler::default(),
            stats: PlanStats::default(),
            expansions_at_start: 0,
        }
    }

    /// The settings.
    pub fn config(&self) -> &PlannerConfig {
        &self.cfg
    }

    /// What the last call to [`Planner::plan`] did.
    pub fn stats(&self) -> PlanStats {
        self.stats
    }

    /// Effective limits: the configured ones, raised to what the end states themselves
    /// demand (a start faster than the limit cannot be made slower at t = 0).
    fn limits(&self, start: &State, goal: &State) -> (f64, f64) {
        let v = self.cfg.max_vel.max(start.v.norm()).max(goal.v.norm());
        let a = self.cfg.max_acc.max(start.a.norm()).max(goal.a.norm());
        (v, a)
    }

    /// Plans from `start` to `goal` on `map`.
    pub fn plan<M: OccupancyQuery + ?Sized>(
        &mut self,
        map: &M,
        start: &State,
        goal: &Goal,
    ) -> Result<Plan, PlanError> {
        self.stats = PlanStats::default();
        self.expansions_at_start = self.astar.expansions;
        let result = self.plan_inner(map, start, goal);
        self.stats.astar_expansions = self.astar.expansions.wrapping_sub(self.expansions_at_start);
        result
    }

    fn plan_inner<M: OccupancyQuery + ?Sized>(
        &mut self,
        map: &M,
        start: &State,
        goal: &Goal,
    ) -> Result<Plan, PlanError> {
        let map = &Bounded::new(map);
        if !start.is_finite() || !goal.state.is_finite() {
            return Err(PlanError::NotFinite);
        }
        let (lo, hi) = map.bounds();
        if (0..3).any(|i| start.p[i] < lo[i] || start.p[i] > hi[i]) {
            return Err(PlanError::StartOutsideMap);
        }
        if map.is_occupied(&start.p) {
            return Err(PlanError::StartOccupied);
        }
        let (vlim, alim) = self.limits(start, &goal.state);
        let mut end = goal.state;
        let mut duration = self.duration(start, &end, vlim, alim);
        if goal.moving {
            // Aim where the target will be on arrival (two fixed-point steps).
            for _ in 0..2 {
                end.p = goal.state.p + goal.state.v * duration;
                duration = self.duration(start, &end, vlim, alim);
            }
            end.p = goal.state.p + goal.state.v * duration;
        }
        let (gp, adjusted) = self.free_goal(map, &end.p).ok_or(PlanError::NoFreeGoal)?;
        if adjusted {
            end.p = gp;
            duration = self.duration(start, &end, vlim, alim);
        }
        let first = self
            .initial(start, &end, duration, vlim)
            .ok_or(PlanError::Infeasible("initialization failed"))?;
        // The first attempt gets half the rounds and (roughly) half the work: most plans
        // that succeed at all do so within a few rounds, and a stuck one is better restarted
        // from the A* path than ground on.
        let first_rounds = self.cfg.max_rebounds / 2;
        let spline = match self.solve(map, first, start, &end, vlim, alim, first_rounds, 0.5) {
            Ok(s) => s,
            Err(
                e @ (PlanError::Collides
                | PlanError::NoPath
                | PlanError::OverBudget
                | PlanError::Infeasible(_)),
            ) => {
                // Fallback: start again from the A* path between start and goal (the
                // straight initialization may sit in a pocket the rebound cannot leave).
                let Some(second) = self.initial_from_path(map, start, &end, vlim, alim) else {
                    return Err(if self.remaining() == 0 {
                        PlanError::OverBudget
                    } else {
                        e
                    });
                };
                self.stats.restarts += 1;
                let rounds =
                    self.cfg.max_rebounds - (self.stats.rebounds as usize).min(first_rounds);
                self.solve(map, second, start, &end, vlim, alim, rounds, 1.0)?
            }
            Err(e) => return Err(e),
        };
        Ok(Plan {
            spline,
            goal: end.p,
            goal_adjusted: adjusted,
        })
    }

    /// The back end on one initial curve: at most `max_rounds` rebound rounds (and no more
    /// than the `share` of the work budget, counted from the plan's start), time
    /// re-allocation with refinement, and the final check.
    #[allow(clippy::too_many_arguments)]
    fn solve<M: OccupancyQuery + ?Sized>(
        &mut self,
        map: &M,
        mut spline: BSpline,
        start: &State,
        end: &State,
        vlim: f64,
        alim: f64,
        max_rounds: usize,
        share: f64,
    ) -> Result<BSpline, PlanError> {
        // This attempt may spend up to `share` of the whole budget (what is left of it).
        let limit = (self.cfg.work_budget as f64 * share) as usize;
        let n = spline.points.len();
        self.pairs.iter_mut().for_each(|p| p.clear());
        self.pairs.resize_with(n, Vec::new);
        let mut w = Weights {
            smooth: self.cfg.lambda_smooth,
            collision: self.cfg.lambda_collision,
            feasibility: self.cfg.lambda_feasibility,
            fitness: 0.0,
        };
        // Front end: pairs for the initial curve's collisions.
        if self.add_pairs(map, &spline)? == Found::Colliding {
            return Err(PlanError::NoPath);
        }
        let mut reference: Option<Vec<Vector3<f64>>> = None;
        let mut rounds = 0usize;
        let mut stalled = 0usize;
        // Loose tolerance while the curve collides; the first collision-free curve is
        // then polished at the tight one (and kept, in case the budget runs out after).
        let mut polished = false;
        let mut fallback: Option<BSpline> = None;
        loop {
            let left = limit.saturating_sub(self.spent());
            if left == 0 {
                return fallback.ok_or(PlanError::OverBudget);
            }
            // The polish only smooths a curve already found: a short pass, not a search.
            let cap = if polished && reference.is_none() {
                POLISH_ITERATIONS
            } else {
                self.cfg.max_iterations
            };
            self.lbfgs
                .set_max_iterations(self.cfg.max_iterations.min(left).min(cap));
            self.lbfgs.set_g_tolerance(if polished {
                self.cfg.g_tolerance
            } else {
                self.cfg.rebound_g_tolerance
            });
            self.optimize(map, &mut spline, w, vlim, alim, reference.as_deref());
            let found = match self.add_pairs(map, &spline) {
                Ok(found) => found,
                Err(e) => return fallback.ok_or(e),
            };
            match found {
                Found::Clear => {}
                found => {
                    rounds += 1;
                    self.stats.rebounds += 1;
                    if rounds > max_rounds {
                        return fallback.ok_or(PlanError::Collides);
                    }
                    if found == Found::Colliding {
                        // Same obstacles, same directions: push harder, unless that
                        // already failed several times in a row (the points sit between
                        // pairs that pull opposite ways: more weight does not move them).
                        stalled += 1;
                        if stalled >= self.cfg.max_stalled_rounds {
                            return fallback.ok_or(PlanError::Collides);
                        }
                        w.collision *= 2.0;
                    } else {
                        stalled = 0;
                    }
                    continue;
                }
            }
            if !polished {
                polished = true;
                if self.accept(map, &spline, vlim, alim).is_ok() {
                    fallback = Some(spline.clone());
                }
                continue;
            }
            let (v, a) = spline.max_vel_acc();
            let ratio = (v / vlim).max((a / alim).sqrt());
            if ratio > 1.02 && self.stats.reallocations < MAX_REALLOCATIONS {
                self.stats.reallocations += 1;
                // Same control points, longer knots: the same path, slower; then refit the
                // fixed ends to the end states and refine near the stretched curve.
                let r = spline.points.clone();
                spline.ts *= (ratio * 1.02).min(4.0);
                let s3 = end_points(start, spline.ts);
                let e3 = end_points(end, spline.ts);
                spline.points[..3].copy_from_slice(&s3);
                spline.points[n - 3..].copy_from_slice(&e3);
                reference = Some(r);
                w.fitness = self.cfg.lambda_fitness;
                continue;
            }
            break;
        }
        match self.accept(map, &spline, vlim, alim) {
            Ok(()) => Ok(spline),
            Err(e) => fallback.ok_or(e),
        }
    }

    /// An initial curve along the A* path from start to goal, timed with a
    /// minimum-jerk profile along its length.
    fn initial_from_path<M: OccupancyQuery + ?Sized>(
        &mut self,
        map: &M,
        start: &State,
        end: &State,
        vlim: f64,
        alim: f64,
    ) -> Option<BSpline> {
        let mut path = std::mem::take(&mut self.path);
        self.astar.max_expansions = self.expansion_cap(self.remaining());
        // Start to goal floods the field at the tie-break weight (up to 14k cells at 0.2
        // pillars/m^2); weighted A* finds a path within 2x of the shortest in a third of
        // the expansions, and the rebound reshapes it anyway.
        self.astar.weight = RESTART_ASTAR_WEIGHT;
        let found = self.astar.search(map, &start.p, &end.p, &mut path);
        self.astar.weight = TIE_BREAK;
        let result = if found && path.len() >= 2 {
            let mut cum = Vec::with_capacity(path.len());
            let mut len = 0.0;
            cum.push(0.0);
            for w in path.windows(2) {
                len += (w[1] - w[0]).norm();
                cum.push(len);
            }
            let t = (1.875 * len / vlim).max((5.8 * len / alim).sqrt()).max(0.2) * 1.1;
            let ts0 = self.cfg.control_point_spacing / vlim * 1.2;
            let k = ((t / ts0).ceil() as usize + 1).clamp(5, MAX_CONTROL_POINTS - 2);
            let ts = t / (k - 1) as f64;
            let mut seg = 0;
            let samples: Vec<Vector3<f64>> = (0..k)
                .map(|i| {
                    let tau = i as f64 / (k - 1) as f64;
                    let s = len * tau * tau * tau * (10.0 - 15.0 * tau + 6.0 * tau * tau);
                    while seg + 2 < cum.len() && cum[seg + 1] < s {
                        seg += 1;
                    }
                    let l = (cum[seg + 1] - cum[seg]).max(1e-12);
                    path[seg] + (path[seg + 1] - path[seg]) * ((s - cum[seg]) / l).clamp(0.0, 1.0)
                })
                .collect();
            fit(&samples, ts, start, end)
        } else {
            None
        };
        self.path = path;
        result
    }

    /// Work spent by this plan so far, in L-BFGS iterations (see
    /// `PlannerConfig::work_budget`).
    fn spent(&self) -> usize {
        self.stats.iterations as usize
            + (self.astar.expansions.wrapping_sub(self.expansions_at_start)
                / EXPANSIONS_PER_ITERATION) as usize
    }

    /// Work left in this plan's budget.
    fn remaining(&self) -> usize {
        self.cfg.work_budget.saturating_sub(self.spent())
    }

    /// A* expansions that `work` units pay for, within the configured limit.
    fn expansion_cap(&self, work: usize) -> usize {
        self.cfg
            .max_astar_expansions
            .min(work.saturating_mul(EXPANSIONS_PER_ITERATION as usize))
    }

    /// Duration of the initial quintic: long enough that its speed and acceleration stay
    /// within the limits.
    fn duration(&self, start: &State, end: &State, vlim: f64, alim: f64) -> f64 {
        let dist = (end.p - start.p).norm();
        let mut t = (1.875 * dist / vlim)
            .max((5.8 * dist / alim).sqrt())
            .max(0.2);
        for _ in 0..8 {
            let q = Quintic::new(start, end, t);
            let (mut v, mut a) = (0.0f64, 0.0f64);
            for k in 0..=32 {
                let s = q.eval(t * k as f64 / 32.0);
                v = v.max(s.v.norm());
                a = a.max(s.a.norm());
            }
            let ratio = (v / vlim).max((a / alim).sqrt());
            if ratio <= 1.0 {
                break;
            }
            t *= ratio * 1.05;
        }
        t
    }

    /// The initial B-spline: the quintic sampled every ts, fitted.
    fn initial(&self, start: &State, end: &State, duration: f64, vlim: f64) -> Option<BSpline> {
        let ts0 = self.cfg.control_point_spacing / vlim * 1.2;
        let k = ((duration / ts0).ceil() as usize + 1).clamp(5, MAX_CONTROL_POINTS - 2);
        let ts = duration / (k - 1) as f64;
        let q = Quintic::new(start, end, duration);
        let samples: Vec<Vector3<f64>> = (0..k).map(|i| q.eval(i as f64 * ts).p).collect();
        fit(&samples, ts, start, end)
    }

    /// The goal moved inside the map (half a cell from its faces) and, when occupied, to
    /// the nearest free cell centre within 2 m.
    fn free_goal<M: OccupancyQuery + ?Sized>(
        &self,
        map: &M,
        goal: &Vector3<f64>,
    ) -> Option<(Vector3<f64>, bool)> {
        let (lo, hi) = map.bounds();
        let res = map.resolution();
        let mut g = *goal;
        for i in 0..3 {
            g[i] = g[i].clamp(
                lo[i] + 0.5 * res,
                (hi[i] - 0.5 * res).max(lo[i] + 0.5 * res),
            );
        }
        let clamped = (g - goal).norm() > 1e-9;
        if !map.is_occupied(&g) {
            return Some((g, clamped));
        }
        let r = (2.0 / res).ceil() as i32;
        let mut best: Option<(f64, Vector3<f64>)> = None;
        for dz in -r..=r {
            for dy in -r..=r {
                for dx in -r..=r {
                    let off = Vector3::new(dx as f64, dy as f64, dz as f64) * res;
                    let d = off.norm();
                    if d > 2.0 || best.is_some_and(|(bd, _)| bd <= d) {
                        continue;
                    }
                    let p = g + off;
                    if (0..3).all(|i| p[i] > lo[i] && p[i] < hi[i]) && !map.is_occupied(&p) {
                        best = Some((d, p));
                    }
                }
            }
        }
        best.map(|(_, p)| (p, true))
    }

    /// Runs L-BFGS on the free control points, stopping early when a control point
    /// enters an obstacle no pair knows about (the caller then adds pairs).
    fn optimize<M: OccupancyQuery + ?Sized>(
        &mut self,
        map: &M,
        spline: &mut BSpline,
        w: Weights,
        vlim: f64,
        alim: f64,
        reference: Option<&[Vector3<f64>]>,
    ) {
        let n = spline.points.len();
        if n < 7 {
            return;
        }
        self.x.clear();
        for p in &spline.points[3..n - 3] {
            self.x.extend_from_slice(p.as_slice());
        }
        self.grad.clear();
        self.grad.resize(n, Vector3::zeros());
        let cost = Cost {
            q: &mut spline.points,
            grad: &mut self.grad,
            pairs: &self.pairs,
            w,
            ts: spline.ts,
            max_vel: vlim * FEASIBILITY_MARGIN,
            max_acc: alim * FEASIBILITY_MARGIN,
            clearance: self.cfg.clearance,
            reference,
            fitness_inv2: (
                1.0 / (self.cfg.fitness_axial * self.cfg.fitness_axial),
                1.0 / (self.cfg.fitness_radial * self.cfg.fitness_radial),
            ),
        };
        // H0: the jerk Hessian, stiffened a little where pairs push, so that a first step
        // does not fling a constrained point across its obstacle.
        self.extra.clear();
        let stiff = PAIR_STIFFNESS * w.collision * 6.0 * self.cfg.clearance;
        self.extra.extend((3..n - 3).map(|i| {
            if self.pairs.get(i).is_some_and(|p| !p.is_empty()) {
                stiff
            } else {
                0.0
            }
        }));
        let use_pre = self.precond.factor(n, w.smooth, &self.extra);
        let mut rebound = Rebound {
            cost,
            map,
            tol: 0.1 * map.resolution(),
            precond: if use_pre { Some(&self.precond) } else { None },
        };
        let report = self.lbfgs.minimize(&mut rebound, &mut self.x);
        self.stats.iterations += report.iterations as u32;
        if report.stop == Stop::NotFinite || !self.x.iter().all(|v| v.is_finite()) {
            return;
        }
        for (k, i) in (3..n - 3).enumerate() {
            spline.points[i] = Vector3::new(self.x[3 * k], self.x[3 * k + 1], self.x[3 * k + 2]);
        }
    }

    /// Finds control-polygon and curve collisions and adds {p, v} pairs for them.
    fn add_pairs<M: OccupancyQuery + ?Sized>(
        &mut self,
        map: &M,
        spline: &BSpline,
    ) -> Result<Found, PlanError> {
        let q = &spline.points;
        let n = q.len();
        let res = map.resolution();
        self.marks.clear();
        self.marks.resize(n, false);
        let mut any = false;
        // Control polygon.
        for i in 0..n - 1 {
            let len = (q[i + 1] - q[i]).norm();
            let steps = ((len / (0.5 * res)).ceil() as usize).max(1);
            for k in 0..=steps {
                let p = q[i] + (q[i + 1] - q[i]) * (k as f64 / steps as f64);
                if map.is_occupied(&p) {
                    self.marks[i] = true;
                    self.marks[i + 1] = true;
                    any = true;
                    break;
                }
            }
        }
        // The curve itself (it may cut a corner the polygon does not).
        self.sampler.prepare(samples_per_segment(spline, res));
        for s in 0..n - 3 {
            for k in 0..self.sampler.per_segment() {
                if map.is_occupied(&self.sampler.position(q, s, k)) {
                    self.marks[s + 1] = true;
                    self.marks[s + 2] = true;
                    any = true;
                    break;
                }
            }
        }
        if map.is_occupied(&spline.eval(spline.duration()).p) {
            self.marks[n - 3] = true;
            any = true;
        }
        if !any {
            return Ok(Found::Clear);
        }
        let mut added = false;
        let mut i = 0;
        while i < n {
            if !self.marks[i] {
                i += 1;
                continue;
            }
            let a = i;
            while i < n && self.marks[i] {
                i += 1;
            }
            let b = i - 1;
            // Which points get a new pair: the occupied ones (EGO-Planner), unless an
            // existing pair already says the point is inside that pair's obstacle (then
            // it is not a new obstacle, the weights must do it). A run that clips a
            // corner without any occupied control point gives its points pairs instead.
            let range = a.max(3)..=b.min(n - 4);
            let occupied: Vec<bool> = (0..n)
                .map(|j| range.contains(&j) && map.is_occupied(&q[j]))
                .collect();
            let any_occupied = occupied.iter().any(|&o| o);
            let tol = 0.1 * res;
            let wanted = |j: usize, pairs: &[Vec<Pair>]| {
                if any_occupied {
                    occupied[j] && pairs[j].iter().all(|e| (q[j] - e.p).dot(&e.v) >= tol)
                } else {
                    true
                }
            };
            if !range.clone().any(|j| wanted(j, &self.pairs)) {
                continue;
            }
            // Free control points on either side of the run.
            let mut lo_id = a.saturating_sub(1);
            while lo_id > 0 && map.is_occupied(&q[lo_id]) {
                lo_id -= 1;
            }
            let mut hi_id = (b + 1).min(n - 1);
            while hi_id < n - 1 && map.is_occupied(&q[hi_id]) {
                hi_id += 1;
            }
            // At the ends, the curve's own end points (the start and the goal) are free.
            let from = if map.is_occupied(&q[lo_id]) {
                spline.eval(0.0).p
            } else {
                q[lo_id]
            };
            let to = if map.is_occupied(&q[hi_id]) {
                spline.eval(spline.duration()).p
            } else {
                q[hi_id]
            };
            let mut path = std::mem::take(&mut self.path);
            self.astar.max_expansions = self.expansion_cap(self.remaining());
            let ok = self.astar.search(map, &from, &to, &mut path);
            if ok {
                for j in range.clone() {
                    if !wanted(j, &self.pairs) {
                        continue;
                    }
                    if let Some(pair) = pair_for(map, q, j, &path) {
                        let count = self.pairs[j].len();
                        match self.pairs[j].iter_mut().find(|e| e.v.dot(&pair.v) > 0.9) {
                            // A corner clip that its pair already pushed out of, and the
                            // curve still clips: re-anchor it so the point moves further.
                            Some(e) if !any_occupied && (q[j] - e.p).dot(&e.v) > tol => {
                                e.p = q[j];
                                added = true;
                            }
                            Some(_) => {}
                            None if count < 16 => {
                                self.pairs[j].push(pair);
                                added = true;
                            }
                            None => {}
                        }
                    }
                }
            }
            self.path = path;
            if !ok {
                return Err(PlanError::NoPath);
            }
        }
        Ok(if added {
            Found::NewPairs
        } else {
            Found::Colliding
        })
    }

    /// The final check, by dense sampling of the curve: inside the map, collision-free,
    /// within the limits (5% tolerance), finite.
    fn accept<M: OccupancyQuery + ?Sized>(
        &self,
        map: &M,
        spline: &BSpline,
        vlim: f64,
        alim: f64,
    ) -> Result<(), PlanError> {
        if spline.points.len() > MAX_CONTROL_POINTS
            || !spline
                .points
                .iter()
                .all(|p| p.iter().all(|v| v.is_finite()))
            || !(spline.ts.is_finite() && spline.ts > 0.0)
        {
            return Err(PlanError::Infeasible("not finite"));
        }
        let (lo, hi) = map.bounds();
        let per_seg = samples_per_segment(spline, map.resolution());
        let total = (spline.points.len() - 3) * per_seg;
        for k in 0..=total {
            let t = spline.duration() * k as f64 / total as f64;
            let s = spline.eval(t);
            if (0..3).any(|i| s.p[i] < lo[i] || s.p[i] > hi[i]) {
                return Err(PlanError::Infeasible("leaves the map"));
            }
            if map.is_occupied(&s.p) {
                return Err(PlanError::Collides);
            }
            if s.v.norm() > vlim * LIMIT_TOLERANCE {
                return Err(PlanError::Infeasible("velocity limit"));
            }
            if s.a.norm() > alim * LIMIT_TOLERANCE {
                return Err(PlanError::Infeasible("acceleration limit"));
            }
        }
        Ok(())
    }
}

/// The map as the planner's own checks see it: outside the bounds is blocked, so that the
/// rebound pulls a control point back in rather than letting it wander into unmapped space.
struct Bounded<'a, M: ?Sized> {
    map: &'a M,
    lo: Vector3<f64>,
    hi: Vector3<f64>,
}

impl<'a, M: OccupancyQuery + ?Sized> Bounded<'a, M> {
    fn new(map: &'a M) -> Self {
        let (lo, hi) = map.bounds();
        Self { map, lo, hi }
    }
}

impl<M: OccupancyQuery + ?Sized> OccupancyQuery for Bounded<'_, M> {
    fn resolution(&self) -> f64 {
        self.map.resolution()
    }

    #[inline]
    fn is_occupied(&self, p: &Vector3<f64>) -> bool {
        // `!(a <= b)` so that NaN is blocked too.
        (0..3).any(|i| !(self.lo[i] <= p[i] && p[i] <= self.hi[i])) || self.map.is_occupied(p)
    }

    fn bounds(&self) -> (Vector3<f64>, Vector3<f64>) {
        (self.lo, self.hi)
    }
}

/// The cost with EGO-Planner's early stop: after a few iterations, a free control point
/// in an occupied cell that none of its pairs puts inside an obstacle has hit a new
/// obstacle, and converging further only pulls the rest of the curve around it.
struct Rebound<'a, 'm, M: ?Sized> {
    cost: Cost<'a>,
    map: &'m M,
    tol: f64,
    precond: Option<&'m JerkPreconditioner>,
}

/// Iterations before the early stop is consulted (EGO-Planner: 3): the first steps of a
/// fresh optimization move the points far and through obstacles they then leave.
const EARLY_STOP_AFTER: usize = 3;

impl<M: OccupancyQuery + ?Sized> Objective for Rebound<'_, '_, M> {
    fn eval(&mut self, x: &[f64], g: &mut [f64]) -> f64 {
        self.cost.eval(x, g)
    }

    fn precondition(&mut self, d: &mut [f64]) -> bool {
        self.precond.is_some_and(|p| p.apply(d))
    }

    fn cancel(&mut self, x: &[f64], iteration: usize) -> bool {
        if iteration <= EARLY_STOP_AFTER {
            return false;
        }
        x.chunks_exact(3).enumerate().any(|(k, c)| {
            let q = Vector3::new(c[0], c[1], c[2]);
            self.map.is_occupied(&q)
                && self
                    .cost
                    .pairs
                    .get(k + 3)
                    .is_none_or(|ps| ps.iter().all(|e| (q - e.p).dot(&e.v) >= self.tol))
        })
    }
}

/// What a collision search found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Found {
    /// No collision.
    Clear,
    /// Collisions, and new pairs for them.
    NewPairs,
    /// Collisions that the existing pairs already cover.
    Colliding,
}

/// Curve samples per knot interval so that consecutive samples are at most a third of a
/// cell apart.
fn samples_per_segment(spline: &BSpline, res: f64) -> usize {
    let (v, _) = spline.max_vel_acc();
    ((v * spline.ts / (res / 3.0)).ceil() as usize).clamp(2, 200)
}

/// The {p, v} pair of control point `j` from the A* `path`: the plane through `q[j]`
/// normal to the local tangent cuts the path at a point; `v` points there, `p` is the
/// last free point walking from the cut back to `q[j]` (`q[j]` itself when free).
fn pair_for<M: OccupancyQuery + ?Sized>(
    map: &M,
    q: &[Vector3<f64>],
    j: usize,
    path: &[Vector3<f64>],
) -> Option<Pair> {
    let tangent = q[j + 1] - q[j - 1];
    let tn = tangent.norm();
    let mut cut = None;
    if tn > 1e-9 && path.len() >= 2 {
        let t = tangent / tn;
        for w in path.windows(2) {
            let s0 = (w[0] - q[j]).dot(&t);
            let s1 = (w[1] - q[j]).dot(&t);
            if s0 <= 0.0 && s1 > 0.0 || s0 >= 0.0 && s1 < 0.0 {
                let f = s0 / (s0 - s1);
                cut = Some(w[0] + (w[1] - w[0]) * f);
                break;
            }
        }
    }
    let cut = match cut {
        Some(c) => c,
        None => *path.iter().min_by(|a, b| {
            (*a - q[j])
                .norm_squared()
                .total_cmp(&(*b - q[j]).norm_squared())
        })?,
    };
    let dir = cut - q[j];
    let dist = dir.norm();
    if dist < 1e-6 {
        return None;
    }
    let v = dir / dist;
    if !map.is_occupied(&q[j]) {
        return Some(Pair { p: q[j], v });
    }
    let step = 0.5 * map.resolution();
    let steps = (dist / step).ceil() as usize;
    let mut last_free = cut;
    for k in 1..=steps {
        let p = cut - v * (k as f64 * step).min(dist);
        if map.is_occupied(&p) {
            return Some(Pair { p: last_free, v });
        }
        last_free = p;
    }
    Some(Pair { p: last_free, v })
}

/// An emergency-stop trajectory: from `start` to rest along the current velocity,
/// decelerating at about `max_acc` (a quintic, so the peak is ~1.5x the mean).
pub fn stop_trajectory(start: &State, max_acc: f64) -> Option<BSpline> {
    if !start.is_finite() || !(max_acc > 0.0) {
        return None;
    }
    let speed = start.v.norm();
    let t = (1.5 * speed / max_acc + start.a.norm() / max_acc).max(0.3);
    let end = State::at_rest(start.p + start.v * (0.5 * t));
    let q = Quintic::new(start, &end, t);
    let k = 12usize;
    let ts = t / (k - 1) as f64;
    let samples: Vec<Vector3<f64>> = (0..k).map(|i| q.eval(i as f64 * ts).p).collect();
    fit(&samples, ts, start, &end)
}

#[cfg(test)]
#[path = "plan_test.rs"]
mod tests;
