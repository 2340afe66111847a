//! `planner`: the local trajectory planner as its own process. Reads planner/goal,
//! vehicle/state and map/occupancy; publishes planner/trajectory and planner/stats
//! (deploy/graph.toml). Everything it decides is `planner::PlannerStage`; this file
//! builds it and hands it to the iceoryx2 driver.

use std::process::ExitCode;

use anyhow::Result;
use clap::Parser;
use planner::{PlannerConfig, PlannerStage};
use runtime::StageArgs;

/// Plans collision-free B-spline trajectories to the goal and publishes them.
#[derive(Debug, Parser)]
#[command(name = "planner", version, about)]
struct Args {
    #[command(flatten)]
    stage: StageArgs,
}

fn main() -> ExitCode {
    runtime::process_main("info", run)
}

fn run(args: &Args) -> Result<()> {
    let (ipc, cfg): (_, PlannerConfig) = args.stage.load("planner")?;
    runtime::serve(
        &args.stage,
        &ipc,
        &mut PlannerStage::from_config(&cfg),
        None,
        None,
    )?;
    Ok(())
}
