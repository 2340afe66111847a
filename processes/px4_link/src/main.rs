//! `px4-link`: the MAVLink link to PX4 as its own process. Reads fsm/setpoint,
//! px4/request and safety/command; publishes vehicle/state and px4/outcome
//! (deploy/graph.toml). Everything it decides is `px4_link::LinkStage`; this file opens
//! the UDP socket or serial port (`transport`) and hands both to the iceoryx2 driver.

mod serial_port;
mod transport;

use std::process::ExitCode;

use anyhow::{Result, anyhow};
use clap::Parser;
use px4_link::LinkStage;
use px4_link::config::{Px4LinkConfig, Px4LinkFlags};
use px4_protocol::signing::SigningKey;
use runtime::StageArgs;

/// The MAVLink link between the stack and PX4 (or the simulator).
#[derive(Debug, Parser)]
#[command(name = "px4-link", version, about)]
struct Args {
    #[command(flatten)]
    stage: StageArgs,
    #[command(flatten)]
    link: Px4LinkFlags,
}

fn main() -> ExitCode {
    runtime::process_main("info", run)
}

fn run(args: &Args) -> Result<()> {
    let (ipc, cfg): (_, Px4LinkConfig) = args.stage.load("px4_link")?;
    let cfg = args.link.apply(cfg).map_err(|e| anyhow!(e.message))?;
    let address = cfg.address().map_err(|e| anyhow!(e.message))?;
    let remote = cfg.remote_address().map_err(|e| anyhow!(e.message))?;
    // The key is read before the link opens: a key others may read stops the start.
    let key_path = cfg.signing_key_path(&args.stage.config_dir());
    let key = key_path.map(|p| SigningKey::load(&p)).transpose()?;
    let mut link = transport::Transport::open(&address, remote)?;
    tracing::info!(link = %cfg.link, signed = key.is_some(), "px4-link");
    let zero = runtime::unix_ns_at_monotonic_zero();
    let mut stage = LinkStage::from_config(&cfg, link.framing(), key, zero);
    runtime::serve(&args.stage, &ipc, &mut stage, Some(&mut link), None)?;
    Ok(())
}
