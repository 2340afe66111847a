//! planner: EGO-Planner-style local trajectory planning for the landing stack.
//!
//! [`Planner::plan`] takes a map ([`OccupancyQuery`]), the current state and a goal, and
//! returns a uniform cubic B-spline: a quintic initialization fitted to control points,
//! collisions of the control polygon resolved by A*-guided {p, v} pairs and L-BFGS
//! ("rebound"), time re-allocation with a fitness refinement, and a final dense check.
//! [`ReplanPolicy`] decides when to plan again. The B-spline itself is the `bspline`
//! crate's, which the fsm samples without depending on the planner. No IPC, no clock:
//! the `planner` binary binds it to iceoryx2 and `landing plan` calls it offline. See
//! `docs/planning.md`.

// `!(x > 0.0)` is how this crate rejects NaN along with the out-of-range values; index
// loops over control points read like the formulas they implement.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]

pub mod astar;
pub mod config;
pub mod cost;
pub mod fields;
pub mod lbfgs;
pub mod map;
pub mod node;
pub mod plan;
pub mod precond;
pub mod replan;
pub mod stage;

/// The curve every plan is (the `bspline` crate, shared with the fsm that samples it).
pub use bspline::{BSpline, State};
pub use config::PlannerConfig;
pub use map::{Aabb, CellView, GridMap, MapError, OccupancyQuery};
pub use node::{Output, PlannerNode, to_message};
pub use plan::{
    EXPANSIONS_PER_ITERATION, Goal, LIMIT_TOLERANCE, Plan, PlanError, PlanStats, Planner,
    stop_trajectory,
};
pub use replan::{Decision, OnFailure, Reason, ReplanPolicy, predicted_collision};
pub use stage::PlannerStage;
