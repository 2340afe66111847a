//! Service names: the one place that says which topic is called what.
//!
//! A topic is a publish-subscribe service plus an event service of the same name (iceoryx2
//! tells them apart by messaging pattern); publishers notify the event after each send so
//! that subscribers can sleep in a wait set instead of polling.

/// Downward camera frames from the simulator (camera-ingest's `sim` backend).
pub const SIM_CAMERA: &str = "landing/sim/camera";
/// Forward depth frames from the simulator (depth-map's `sim` backend).
pub const SIM_DEPTH: &str = "landing/sim/depth";
/// Ground-truth events (touchdown, collision, crash). Evaluator only: no pipeline process
/// may open it.
pub const SIM_TRUTH: &str = "landing/sim/truth";
/// Where the vehicle and the pad really are, 20 Hz. Evaluator only: no pipeline process
/// may open it.
pub const SIM_TRUTH_STATE: &str = "landing/sim/truth_state";
/// Camera frames as the pipeline sees them (camera-ingest).
pub const CAMERA_FRAME: &str = "landing/camera/frame";
/// Depth frames as the pipeline sees them.
pub const DEPTH_FRAME: &str = "landing/depth/frame";
/// Pad observations (aruco-pnp).
pub const PAD_OBSERVATION: &str = "landing/pad/observation";
/// Estimated vehicle state (px4-link).
pub const VEHICLE_STATE: &str = "landing/vehicle/state";
/// Visual-inertial odometry (the simulator's VIO, or a tracking camera's driver).
pub const VIO_ODOMETRY: &str = "landing/vio/odometry";
/// Local occupancy window (depth-map).
pub const MAP_OCCUPANCY: &str = "landing/map/occupancy";
/// Goals for the planner (fsm).
pub const PLANNER_GOAL: &str = "landing/planner/goal";
/// Planned trajectories (planner).
pub const PLANNER_TRAJECTORY: &str = "landing/planner/trajectory";
/// Planning statistics (planner).
pub const PLANNER_STATS: &str = "landing/planner/stats";
/// Requests to the autopilot (fsm -> px4-link).
pub const PX4_REQUEST: &str = "landing/px4/request";
/// Outcomes of those requests (px4-link -> fsm).
pub const PX4_OUTCOME: &str = "landing/px4/outcome";
/// Setpoints for the autopilot (fsm).
pub const FSM_SETPOINT: &str = "landing/fsm/setpoint";
/// Each setpoint as it went on the MAVLink wire, stamped by px4-link (latency profiling).
pub const PX4_SETPOINT_SENT: &str = "landing/px4/setpoint_sent";
/// Mission status (fsm).
pub const FSM_STATUS: &str = "landing/fsm/status";
/// Safety orders (watchdog, operator).
pub const SAFETY_COMMAND: &str = "landing/safety/command";
/// The watchdog's view of every process.
pub const WATCHDOG_VIEW: &str = "landing/watchdog/view";
/// Faults to inject into processes' outputs (fault tests only: a process listens only
/// when started with `LANDING_FAULT_INJECTION=1`).
pub const FAULT_INJECT: &str = "landing/fault/inject";
/// Benchmarks and tests.
pub const BENCH_FRAME: &str = "landing/bench/frame";

/// Prefix of the per-process heartbeat event services: `landing/heartbeat/<process>`.
pub const HEARTBEAT_PREFIX: &str = "landing/heartbeat/";

/// The heartbeat event service of `process`.
pub fn heartbeat(process: &str) -> String {
    format!("{HEARTBEAT_PREFIX}{process}")
}

/// Every topic a pipeline process may open; the simulator's truth topic is not among them.
pub const PIPELINE_TOPICS: &[&str] = &[
    SIM_CAMERA,
    SIM_DEPTH,
    CAMERA_FRAME,
    DEPTH_FRAME,
    PAD_OBSERVATION,
    VEHICLE_STATE,
    VIO_ODOMETRY,
    MAP_OCCUPANCY,
    PLANNER_GOAL,
    PLANNER_TRAJECTORY,
    PLANNER_STATS,
    PX4_REQUEST,
    PX4_OUTCOME,
    FSM_SETPOINT,
    PX4_SETPOINT_SENT,
    FSM_STATUS,
    SAFETY_COMMAND,
    WATCHDOG_VIEW,
];
