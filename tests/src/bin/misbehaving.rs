//! `misbehaving`: a misbehaving stage (`landing_tests::misbehaving`) as its own process,
//! served by the iceoryx2 driver as aruco-pnp; for the runtime's fault tests.

use std::process::ExitCode;

use anyhow::Result;
use clap::Parser;
use landing_tests::misbehaving::{Misbehaving, Misbehaviour};
use runtime::StageArgs;

/// Serves as aruco-pnp, then misbehaves.
#[derive(Debug, Parser)]
#[command(name = "misbehaving", version, about)]
struct Args {
    #[command(flatten)]
    stage: StageArgs,
    /// panic, hang, fail or nan.
    #[arg(long)]
    mode: Misbehaviour,
    /// After this many ticks of 20 ms.
    #[arg(long, default_value_t = 25)]
    after: u64,
}

fn main() -> ExitCode {
    runtime::process_main("info", run)
}

fn run(args: &Args) -> Result<()> {
    let ipc = args.stage.ipc()?;
    runtime::serve(
        &args.stage,
        &ipc,
        &mut Misbehaving::new(args.mode, args.after),
        None,
        None,
    )?;
    Ok(())
}
