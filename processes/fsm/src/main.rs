//! `fsm`: the landing mission as its own process. Reads vehicle/state, pad/observation,
//! planner/trajectory, px4/outcome and safety/command; publishes fsm/setpoint,
//! planner/goal, px4/request and fsm/status (deploy/graph.toml). Everything it decides
//! is `fsm::FsmStage`; this file builds it and hands it to the iceoryx2 driver.

use std::process::ExitCode;

use anyhow::Result;
use clap::Parser;
use fsm::{FsmConfig, FsmStage};
use runtime::StageArgs;

/// Flies the landing mission: take off, find the pad, track it, descend, land on it.
#[derive(Debug, Parser)]
#[command(name = "fsm", version, about)]
struct Args {
    #[command(flatten)]
    stage: StageArgs,
    /// Preset point (where to wait for the pad), x,y,z in metres, world ENU; overrides
    /// [fsm] preset_m.
    #[arg(long, value_name = "X,Y,Z")]
    preset: Option<String>,
    /// Height above the pad below which the vehicle commits to touchdown, m; overrides
    /// [fsm] commit_height_m.
    #[arg(long)]
    commit_height: Option<f64>,
    /// Never search for the pad higher than this, m (where the camera still reads the
    /// pad's largest marker); the lower of this and [fsm] search_height_max_m holds.
    #[arg(long)]
    search_height_max: Option<f64>,
}

fn main() -> ExitCode {
    runtime::process_main("info", run)
}

fn run(args: &Args) -> Result<()> {
    let (ipc, cfg): (_, FsmConfig) = args.stage.load("fsm")?;
    let cfg = cfg.with_overrides(
        args.preset.as_deref(),
        args.commit_height,
        args.search_height_max,
    )?;
    tracing::info!(preset = ?cfg.preset_m, commit_height_m = cfg.commit_height_m, "fsm");
    runtime::serve(
        &args.stage,
        &ipc,
        &mut FsmStage::from_config(&cfg),
        None,
        None,
    )?;
    Ok(())
}
