//! `fsm`: the landing mission as its own process.
//!
//! Reads vehicle/state, pad/observation, planner/trajectory, px4/outcome and
//! safety/command; publishes fsm/setpoint (50 Hz), planner/goal, px4/request and
//! fsm/status. Everything it decides is `fsm::Fsm`; this file binds it to iceoryx2 and
//! the clock.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::{Context, Result};
use clap::Parser;
use fsm::{Fsm, FsmConfig};
use ipc_types::msg::{
    FsmStatus, LinkOutcome, LinkRequest, PadObservation, PlannerGoal, SafetyCommand, Setpoint,
    Trajectory, VehicleState,
};
use ipc_types::services;
use runtime::ipc::{Wake, run_wait_loop};
use runtime::{Ipc, IpcPrefix, monotonic_ns};
use stack_config::{IpcConfig, Validate, load_process_or_default};

/// Flies the landing mission: take off, find the pad, track it, descend, land on it.
#[derive(Debug, Parser)]
#[command(name = "fsm", version, about)]
struct Args {
    /// Stack configuration (reads [ipc] and [fsm]; defaults when absent).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Preset point (where to wait for the pad), x,y,z in metres, world ENU; overrides
    /// [fsm] preset_m.
    #[arg(long, value_name = "X,Y,Z")]
    preset: Option<String>,
    /// Height above the pad below which the vehicle commits to touchdown, m; overrides
    /// [fsm] commit_height_m.
    #[arg(long)]
    commit_height: Option<f64>,
    /// iceoryx2 prefix (default: $LANDING_IPC_PREFIX, else [ipc] prefix).
    #[arg(long)]
    ipc_prefix: Option<String>,
}

fn main() -> ExitCode {
    runtime::process_main("info", run)
}

fn parse_xyz(s: &str) -> Option<[f64; 3]> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse().ok())
        .collect::<Option<_>>()?;
    match v.as_slice() {
        [x, y, z] => Some([*x, *y, *z]),
        _ => None,
    }
}

fn run(args: &Args) -> Result<()> {
    let (ipc_cfg, mut cfg): (IpcConfig, FsmConfig) =
        load_process_or_default(args.config.as_deref(), "fsm")?;
    if let Some(p) = &args.preset {
        cfg.preset_m = parse_xyz(p).ok_or_else(|| {
            anyhow::anyhow!("--preset `{p}` is not allowed (allowed: three numbers x,y,z in m)")
        })?;
    }
    if let Some(h) = args.commit_height {
        cfg.commit_height_m = h;
    }
    cfg.validate()
        .map_err(|e| anyhow::anyhow!("--preset/--commit-height: fsm.{}: {}", e.key, e.message))?;
    let prefix = IpcPrefix::resolve(args.ipc_prefix.as_deref(), &ipc_cfg.prefix)?;
    let ipc = Ipc::open("fsm", &prefix)?;
    let states = ipc
        .subscriber::<VehicleState>(services::VEHICLE_STATE)
        .context("vehicle state")?;
    let observations = ipc
        .subscriber::<PadObservation>(services::PAD_OBSERVATION)
        .context("pad observations")?;
    let trajectories = ipc
        .subscriber::<Trajectory>(services::PLANNER_TRAJECTORY)
        .context("trajectories")?;
    let outcomes = ipc
        .subscriber::<LinkOutcome>(services::PX4_OUTCOME)
        .context("px4 outcomes")?;
    let safety = ipc
        .subscriber::<SafetyCommand>(services::SAFETY_COMMAND)
        .context("safety commands")?;
    let mut setpoints = ipc.publisher::<Setpoint>(services::FSM_SETPOINT)?;
    let mut goals = ipc.publisher::<PlannerGoal>(services::PLANNER_GOAL)?;
    let mut requests = ipc.publisher::<LinkRequest>(services::PX4_REQUEST)?;
    let mut statuses = ipc.publisher::<FsmStatus>(services::FSM_STATUS)?;
    let mut heartbeat = ipc.heartbeat(Duration::from_millis(ipc_cfg.heartbeat_deadline_ms))?;

    let beat_ns = ipc_cfg.heartbeat_period_ms * 1_000_000;
    tracing::info!(preset = ?cfg.preset_m, commit_height_m = cfg.commit_height_m, "fsm running");
    let mut fsm = Fsm::new(cfg);
    let period = Duration::from_nanos(fsm.tick_period_ns());
    let mut last_beat = 0u64;
    let mut counts = Counts::default();
    let mut failure: Option<anyhow::Error> = None;
    let exit = run_wait_loop(
        &[
            states.listener(),
            observations.listener(),
            trajectories.listener(),
            outcomes.listener(),
            safety.listener(),
        ],
        &[],
        Some(period),
        |wake| {
            let now = monotonic_ns();
            let result = (|| -> Result<()> {
                while let Some(s) = states.receive()? {
                    counts.states += 1;
                    fsm.on_vehicle_state(now, s.payload());
                }
                while let Some(o) = observations.receive()? {
                    counts.observations += 1;
                    fsm.on_observation(now, o.payload());
                }
                while let Some(t) = trajectories.receive()? {
                    counts.trajectories += 1;
                    fsm.on_trajectory(t.payload());
                }
                while let Some(o) = outcomes.receive()? {
                    counts.outcomes += 1;
                    fsm.on_outcome(o.payload());
                }
                let mut ordered = false;
                while let Some(c) = safety.receive()? {
                    counts.safety += 1;
                    fsm.on_safety(now, c.payload());
                    ordered = true;
                }
                // The mission steps on its own clock; a safety order acts at once.
                if matches!(wake, Wake::Tick) || ordered {
                    let out = fsm.tick(now);
                    counts.ticks += 1;
                    for r in &out.requests {
                        requests.send(r.msg, r)?;
                        counts.requests += 1;
                    }
                    if let Some(g) = &out.goal {
                        goals.send(g.msg, g)?;
                        counts.goals += 1;
                    }
                    if let Some(sp) = &out.setpoint {
                        setpoints.send(sp.msg, sp)?;
                        counts.setpoints += 1;
                    }
                    if let Some(st) = &out.status {
                        statuses.send(st.msg, st)?;
                    }
                }
                if now.saturating_sub(last_beat) >= beat_ns {
                    last_beat = now;
                    heartbeat.beat()?;
                }
                Ok(())
            })();
            match result {
                Ok(()) => true,
                Err(e) => {
                    failure = Some(e);
                    false
                }
            }
        },
    )?;
    if let Some(e) = failure {
        return Err(e);
    }
    tracing::info!(
        state = fsm.state().name(),
        ticks = counts.ticks,
        states = counts.states,
        observations = counts.observations,
        trajectories = counts.trajectories,
        outcomes = counts.outcomes,
        safety = counts.safety,
        requests = counts.requests,
        goals = counts.goals,
        setpoints = counts.setpoints,
        "fsm stopped"
    );
    tracing::info!(?exit, "fsm exiting");
    Ok(())
}

/// Messages taken in and published, logged when the process stops.
#[derive(Debug, Default)]
struct Counts {
    /// Mission steps (one per tick or safety order).
    ticks: u64,
    /// Inputs: vehicle states, pad observations, trajectories, link outcomes, safety
    /// orders.
    states: u64,
    observations: u64,
    trajectories: u64,
    outcomes: u64,
    safety: u64,
    /// Outputs: link requests, planner goals, setpoints.
    requests: u64,
    goals: u64,
    setpoints: u64,
}
