//! `recorder`: every topic of the graph into one MCAP file (Foxglove schemas, JSON for
//! everything plottable), flushed every second so that it reads back if killed, finished
//! on SIGTERM. Everything it does is `recorder::process::run` (the node, the recording,
//! its metadata, the iceoryx2 driver) and `recorder::RecorderStage`; this file parses
//! the flags.

use std::process::ExitCode;

use anyhow::Result;
use clap::Parser;
use recorder::process::RecorderArgs;
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
    recorder::process::run(&args.stage, &args.recorder)?;
    Ok(())
}
