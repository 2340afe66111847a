//! `planner`: the local trajectory planner as its own process.
//!
//! Reads goals (landing/planner/goal), the vehicle state (landing/vehicle/state) and the
//! occupancy window (landing/map/occupancy); publishes B-spline trajectories
//! (landing/planner/trajectory) and planning statistics (landing/planner/stats).
//! Everything it decides is `planner::PlannerNode`; this file binds it to iceoryx2.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::{Context, Result};
use clap::Parser;
use ipc_types::msg::{
    Header, OccupancyMapHeader, PlannerGoal, PlannerStats, Trajectory, VehicleState,
};
use ipc_types::services;
use planner::{CellView, PlannerConfig, PlannerNode, State};
use runtime::ipc::{Wake, run_wait_loop};
use runtime::{Ipc, IpcPrefix, monotonic_ns};
use stack_config::{IpcConfig, load_process_or_default};

/// Plans collision-free B-spline trajectories to the goal and publishes them.
#[derive(Debug, Parser)]
#[command(name = "planner", version, about)]
struct Args {
    /// Stack configuration (reads [ipc] and [planner]; defaults when absent).
    #[arg(long)]
    config: Option<PathBuf>,
    /// iceoryx2 prefix (default: $LANDING_IPC_PREFIX, else [ipc] prefix).
    #[arg(long)]
    ipc_prefix: Option<String>,
}

fn main() -> ExitCode {
    runtime::process_main("info", run)
}

/// How often the replanning policy is consulted when no message wakes the loop.
const DECIDE_PERIOD: Duration = Duration::from_millis(20);

fn run(args: &Args) -> Result<()> {
    let (ipc_cfg, cfg): (IpcConfig, PlannerConfig) =
        load_process_or_default(args.config.as_deref(), "planner")?;
    let prefix = IpcPrefix::resolve(args.ipc_prefix.as_deref(), &ipc_cfg.prefix)?;
    let ipc = Ipc::open("planner", &prefix)?;
    let goals = ipc
        .subscriber::<PlannerGoal>(services::PLANNER_GOAL)
        .context("planner goals")?;
    let states = ipc
        .subscriber::<VehicleState>(services::VEHICLE_STATE)
        .context("vehicle state")?;
    let maps = ipc
        .slice_subscriber::<u8, OccupancyMapHeader>(services::MAP_OCCUPANCY)
        .context("occupancy map")?;
    let mut trajectories = ipc
        .publisher::<Trajectory>(services::PLANNER_TRAJECTORY)
        .context("trajectories")?;
    let mut stats_out = ipc
        .publisher::<PlannerStats>(services::PLANNER_STATS)
        .context("planner stats")?;
    let mut heartbeat = ipc.heartbeat(Duration::from_millis(ipc_cfg.heartbeat_deadline_ms))?;
    let tick = DECIDE_PERIOD.min(Duration::from_millis(ipc_cfg.heartbeat_period_ms));
    let mut node = PlannerNode::new(cfg);
    let mut vehicle: Option<(State, Header)> = None;
    let mut goal: Option<PlannerGoal> = None;
    // The newest map, copied out of shared memory so the publisher's slot is released.
    let mut map_header: Option<OccupancyMapHeader> = None;
    let mut cells: Vec<u8> = Vec::new();
    let mut counts = Counts::default();
    let mut last_beat = monotonic_ns();
    let beat_ns = ipc_cfg.heartbeat_period_ms * 1_000_000;
    tracing::info!("planner running");
    let mut failure = None;
    let exit = run_wait_loop(
        &[goals.listener(), states.listener(), maps.listener()],
        &[],
        Some(tick),
        |_wake: Wake| {
            // Every wake (data, tick) drains the inputs, then consults the policy.
            {
                if let Ok(Some(s)) = states.latest() {
                    let v = s.payload();
                    counts.states += 1;
                    if let Some(st) = State::from_vehicle(v) {
                        vehicle = Some((st, v.msg));
                    }
                }
                if let Ok(Some(g)) = goals.latest() {
                    counts.goals += 1;
                    goal = Some(*g.payload());
                }
                if let Ok(Some(m)) = maps.latest() {
                    let h = *m.user_header();
                    counts.maps += 1;
                    if CellView::new(&h, m.payload()).is_some() {
                        cells.clear();
                        cells.extend_from_slice(m.payload());
                        map_header = Some(h);
                    } else {
                        counts.bad_maps += 1;
                    }
                }
            }
            let now = monotonic_ns();
            if now.saturating_sub(last_beat) >= beat_ns {
                last_beat = now;
                if let Err(e) = heartbeat.beat() {
                    failure = Some(anyhow::Error::from(e));
                    return false;
                }
            }
            let Some((state, input)) = &vehicle else {
                return true;
            };
            let view = map_header.as_ref().and_then(|h| CellView::new(h, &cells));
            // The library reads no clock: the step (in practice the plan) is timed here.
            let before = monotonic_ns();
            let out = node.step(now, state, goal.as_ref(), view.as_ref(), input);
            counts.steps += 1;
            let step_ms = monotonic_ns().saturating_sub(before) as f64 * 1e-6;
            if let Some(t) = out.trajectory {
                counts.trajectories += 1;
                if let Err(e) = trajectories.send(t.msg, &t) {
                    failure = Some(anyhow::Error::from(e));
                    return false;
                }
                if t.emergency != 0 {
                    tracing::warn!(id = t.id, "emergency stop published");
                }
            }
            if let Some(mut s) = out.stats {
                s.planning_ms = step_ms;
                counts.plans += 1;
                if s.success == 0 {
                    counts.failed += 1;
                    tracing::debug!(bad_maps = counts.bad_maps, "plan failed");
                }
                if let Err(e) = stats_out.send(s.msg, &s) {
                    failure = Some(anyhow::Error::from(e));
                    return false;
                }
            }
            true
        },
    )?;
    if let Some(e) = failure {
        return Err(e);
    }
    tracing::info!(
        steps = counts.steps,
        states = counts.states,
        goals = counts.goals,
        maps = counts.maps,
        bad_maps = counts.bad_maps,
        plans = counts.plans,
        failed = counts.failed,
        trajectories = counts.trajectories,
        "planner stopped"
    );
    tracing::info!(?exit, "planner exiting");
    Ok(())
}

/// What the process counts, logged when it stops.
#[derive(Debug, Default)]
struct Counts {
    /// Decisions taken (one per wake with a vehicle state).
    steps: u64,
    /// Newest vehicle states, goals and maps taken in.
    states: u64,
    goals: u64,
    maps: u64,
    /// Maps whose header disagreed with their cells.
    bad_maps: u64,
    /// Planning calls, and those that failed.
    plans: u64,
    failed: u64,
    /// Trajectories published (plans, stops, emergency stops).
    trajectories: u64,
}
