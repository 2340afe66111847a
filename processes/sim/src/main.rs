//! `sim`: the simulator as its own process, standing in for the world and for PX4.
//! Steps the scenario's world on the wall clock at 500 Hz, speaks MAVLink 2 on UDP as
//! PX4 SITL's onboard link does toward px4-link, publishes sim/camera, sim/depth and the
//! evaluator-only truth (deploy/graph.toml). Everything it does is `sim::stage::SimStage`
//! paced by the wall clock; this file binds the UDP socket and hands both to the driver.

use std::net::SocketAddr;
use std::process::ExitCode;

use anyhow::Result;
use clap::Parser;
use ipc_types::topics;
use runtime::{Reply, StageArgs, UdpLink};
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
    let mut link = UdpLink::bind(
        args.mavlink_listen,
        Some(args.mavlink_remote),
        Reply::OnlyRemote,
        topics::MAVLINK_TO_PX4,
        topics::MAVLINK_FROM_PX4,
    )?
    .with_foreign_topic(topics::MAVLINK_FOREIGN);
    tracing::info!(mavlink = %link.local_addr(), "sim");
    runtime::serve(&args.stage, &ipc, &mut stage, Some(&mut link), None)?;
    Ok(())
}
