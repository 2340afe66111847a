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
use px4_link::config::Px4LinkConfig;
use px4_protocol::signing::{Signer, SigningKey};
use runtime::StageArgs;
use stack_config::Validate;

/// The MAVLink link between the stack and PX4 (or the simulator).
#[derive(Debug, Parser)]
#[command(name = "px4-link", version, about)]
struct Args {
    #[command(flatten)]
    stage: StageArgs,
    /// Link to open, overriding the config: udp:HOST:PORT to listen on, or
    /// serial:DEVICE:BAUD (e.g. serial:/dev/ttyTHS1:921600).
    #[arg(long)]
    link: Option<String>,
    /// Where to send before the autopilot is heard, HOST:PORT (UDP only).
    #[arg(long)]
    remote: Option<String>,
}

/// The link id px4-link signs with (one link per companion).
const LINK_ID: u8 = 1;

fn main() -> ExitCode {
    runtime::process_main("info", run)
}

fn run(args: &Args) -> Result<()> {
    let (ipc, mut cfg): (_, Px4LinkConfig) = args.stage.load("px4_link")?;
    if let Some(l) = &args.link {
        cfg.link = l.clone();
    }
    if let Some(r) = &args.remote {
        cfg.remote = r.clone();
    }
    cfg.validate()
        .map_err(|e| anyhow!("--link/--remote: {}", e.message))?;
    let address = cfg.address().map_err(|e| anyhow!(e.message))?;
    let remote = cfg.remote_address().map_err(|e| anyhow!(e.message))?;
    // The key is read before the link opens: a key others may read stops the start.
    let signer = match cfg.signing_key_path(&args.stage.config_dir()) {
        Some(path) => Some(Signer::new(
            SigningKey::load(&path)?,
            LINK_ID,
            runtime::unix_ns_at_monotonic_zero(),
        )),
        None => None,
    };
    let mut link = transport::Transport::open(&address, remote)?;
    tracing::info!(link = %cfg.link, signed = signer.is_some(), "px4-link");
    let mut stage = LinkStage::new(cfg.settings(), link.framing(), signer);
    runtime::serve(&args.stage, &ipc, &mut stage, Some(&mut link), None)?;
    Ok(())
}
