//! `altitude-guard`: the toy stage of `landing_tests::toy` as its own process, bound
//! the way every stage binary is: build the stage, hand it to the iceoryx2 driver.

use std::process::ExitCode;

use anyhow::Result;
use clap::Parser;
use landing_tests::toy::AltitudeGuard;
use runtime::StageArgs;

/// Orders a safe landing the first time the armed vehicle is above a ceiling.
#[derive(Debug, Parser)]
#[command(name = "altitude-guard", version, about)]
struct Args {
    #[command(flatten)]
    stage: StageArgs,
    /// The ceiling, m (world z).
    #[arg(long)]
    ceiling_m: f64,
}

fn main() -> ExitCode {
    runtime::process_main("info", run)
}

fn run(args: &Args) -> Result<()> {
    let ipc = args.stage.ipc()?;
    runtime::serve(
        &args.stage,
        &ipc,
        &mut AltitudeGuard::new(args.ceiling_m),
        None,
        None,
    )?;
    Ok(())
}
