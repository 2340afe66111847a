//! `recorder`: every topic of the graph into one MCAP file (Foxglove schemas, JSON for
//! everything plottable), flushed every second so that it reads back if killed, finished
//! on SIGTERM. Everything it does is `recorder::RecorderStage` (built from its section,
//! the config file and the graph by `from_config`); this file hands it to the iceoryx2
//! driver with a node of its own, and finishes the file whatever ended the run.

use std::process::ExitCode;
use std::time::Duration;

use anyhow::{Context, Result};
use clap::Parser;
use recorder::process::RecorderArgs;
use recorder::{RecorderConfig, RecorderStage};
use runtime::StageArgs;

/// Records every topic of the landing pipeline into one MCAP file for Foxglove.
#[derive(Debug, Parser)]
#[command(name = "recorder", version, about)]
struct Args {
    #[command(flatten)]
    stage: StageArgs,
    #[command(flatten)]
    recorder: RecorderArgs,
}

fn main() -> ExitCode {
    runtime::process_main("info", run)
}

fn run(args: &Args) -> Result<()> {
    let (ipc, cfg): (_, RecorderConfig) = args.stage.load("recorder")?;
    let graph =
        (args.stage.graph.clone()).unwrap_or_else(|| graph::default_path(&args.stage.deploy()));
    let config = args.stage.config.as_deref();
    let (mut stage, spec, out) = RecorderStage::from_config(cfg, &args.recorder, config, &graph)?;
    let deadline = Duration::from_millis(500);
    let served = runtime::serve_spec(&args.stage, &ipc, &spec, deadline, &mut stage, None);
    // The file is finished whatever ended the run.
    let n = stage.finish().with_context(|| format!("finishing {out}"))?;
    served?;
    tracing::info!(messages = n, out = %out, "recording finished");
    Ok(())
}
