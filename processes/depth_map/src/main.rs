//! `depth-map`: the occupancy window as its own process. Reads depth frames
//! (sim/depth, or depth/frame with `--input depth-frame`) and vehicle/state; publishes
//! map/occupancy, written in place into a loaned shared-memory sample
//! (deploy/graph.toml). Everything it computes is `depth_map::DepthStage`; this file
//! builds it and hands it to the iceoryx2 driver.

use std::process::ExitCode;

use anyhow::{Result, anyhow};
use clap::Parser;
use depth_map::{DepthMapConfig, DepthStage, Input};
use runtime::StageArgs;

/// Builds the local occupancy map from depth frames and the vehicle state, and publishes
/// it after each frame and at least every publish_period_ms.
#[derive(Debug, Parser)]
#[command(name = "depth-map", version, about)]
struct Args {
    #[command(flatten)]
    stage: StageArgs,
    /// Where depth frames come from: `sim` (sim/depth) or `depth-frame` (depth/frame)
    /// [default: [depth_map] input, else sim].
    #[arg(long)]
    input: Option<String>,
}

fn main() -> ExitCode {
    runtime::process_main("info", run)
}

fn run(args: &Args) -> Result<()> {
    let (ipc, mut cfg): (_, DepthMapConfig) = args.stage.load("depth_map")?;
    if let Some(i) = args.input.as_deref() {
        cfg.input = Input::parse(i)
            .ok_or_else(|| anyhow!("--input `{i}` is not allowed (allowed: sim, depth-frame)"))?;
    }
    let mut stage = DepthStage::from_config(&cfg)?;
    tracing::info!(input = cfg.input.topic(), dims = ?stage.mapper().map().dims(), "depth-map");
    let rename = Some((Input::Sim.topic(), cfg.input.topic()));
    runtime::serve(&args.stage, &ipc, &mut stage, None, rename)?;
    Ok(())
}
