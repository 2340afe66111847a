//! `sim`: the world and PX4 as a process: `sim::stage::SimStage` on the wall clock, its
//! autopilot's MAVLink on UDP toward px4-link, or with `--px4-sitl` PX4 SITL's simulator
//! API on TCP for real PX4; frames and truth on iceoryx2 (deploy/graph.toml).

use std::net::SocketAddr;
use std::process::ExitCode;

use anyhow::Result;
use clap::Parser;
use ipc_types::topics::{self, HIL_FROM_PX4, HIL_TO_PX4};
use runtime::{Reply, StageArgs, TcpServerLink, UdpLink};
use sim::stage::SimFlags;

/// The landing stack's simulator: quadrotor, PX4-like autopilot over MAVLink, moving pad.
#[derive(Debug, Parser)]
#[command(name = "sim", version, about)]
struct Args {
    #[command(flatten)]
    stage: StageArgs,
    #[command(flatten)]
    sim: SimFlags,
    /// Where the simulated autopilot listens for MAVLink.
    #[arg(long, default_value = "127.0.0.1:14580")]
    mavlink_listen: SocketAddr,
    /// The companion's MAVLink address (px4-link's, default 127.0.0.1:14540): where the
    /// autopilot sends, and the only address it takes datagrams from.
    #[arg(long, default_value = "127.0.0.1:14540")]
    mavlink_remote: SocketAddr,
}

fn main() -> ExitCode {
    runtime::process_main("info", run)
}

fn run(args: &Args) -> Result<()> {
    let ipc = args.stage.ipc()?;
    let zero = runtime::unix_ns_at_monotonic_zero();
    let mut stage = args.sim.stage(&args.stage.deploy(), zero)?;
    let mut link: Box<dyn stage::External> = match args.sim.px4_sitl {
        Some(addr) => Box::new(TcpServerLink::bind(addr, HIL_FROM_PX4, HIL_TO_PX4)?),
        None => {
            let (local, remote) = (args.mavlink_listen, Some(args.mavlink_remote));
            let udp = UdpLink::bind(
                local,
                remote,
                Reply::OnlyRemote,
                topics::MAVLINK_TO_PX4,
                topics::MAVLINK_FROM_PX4,
            )?
            .with_foreign_topic(topics::MAVLINK_FOREIGN);
            tracing::info!(mavlink = %udp.local_addr(), "sim");
            Box::new(udp)
        }
    };
    runtime::serve(&args.stage, &ipc, &mut stage, Some(link.as_mut()), None)?;
    Ok(())
}
