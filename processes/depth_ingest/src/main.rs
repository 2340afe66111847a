//! `depth-ingest`: a depth camera's frames as the pipeline's `landing/depth/frame`, read
//! from a RealSense (with the `realsense` build), a RealSense recording or a directory of
//! 16-bit PNGs on a capture thread
//! (`device`); each frame is checked and copied once into a loaned shared-memory sample
//! by `depth_ingest::DepthIngestStage`.

mod device;

use std::process::ExitCode;
use std::time::Duration;

use anyhow::{Result, anyhow};
use clap::Parser;
use depth_ingest::{DepthIngestConfig, DepthIngestStage, SourceFlags};
use runtime::StageArgs;

/// Publishes depth frames (landing/depth/frame) from a RealSense (`realsense:`, with the
/// `realsense` build), a RealSense .bag recording or a directory of 16-bit PNG depth
/// images, for depth-map `--input depth-frame`. A consumer
/// that lags loses old frames; nothing queues latency.
#[derive(Debug, Parser)]
#[command(name = "depth-ingest", version, about)]
struct Args {
    #[command(flatten)]
    stage: StageArgs,
    #[command(flatten)]
    source: SourceFlags,
}

fn main() -> ExitCode {
    runtime::process_main("info", run)
}

fn run(args: &Args) -> Result<()> {
    let (ipc, cfg): (_, DepthIngestConfig) = args.stage.load("depth_ingest")?;
    let source = args
        .source
        .resolve(&cfg, &args.stage.config_dir())
        .map_err(|e| anyhow!(e))?;
    let device = device::DepthDevice::open(&source)?;
    let (width, height) = device.size();
    tracing::info!(source = %source.spec, width, height, "depth-ingest");
    let mut stage = DepthIngestStage::new(width, height);
    let mut capture = device::DepthCapture::start(device)?;
    let deadline = Duration::from_millis(depth_ingest::HEARTBEAT_DEADLINE_MS);
    let spec = depth_ingest::node_spec();
    let served = runtime::serve_spec(
        &args.stage,
        &ipc,
        &spec,
        deadline,
        &mut stage,
        Some(&mut capture),
    );
    // Joined before `main` returns, whatever the driver did.
    capture.stop()?;
    Ok(served?)
}
