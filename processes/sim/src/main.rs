//! `sim`: the simulator as its own process, standing in for the world and for PX4.
//!
//! Steps the scenario's world on the wall clock at 500 Hz, speaks MAVLink 2 on UDP as
//! PX4 SITL does toward px4-link, and publishes the evaluator-only ground-truth events.
//! Everything it does is library code (`sim::lockstep`, `sim::px4`); this file only
//! binds it to the clock, the socket and iceoryx2.

use std::net::SocketAddr;
use std::process::ExitCode;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use clap::Parser;
use ipc_types::msg::TruthKind;
use ipc_types::runtime::config::deploy_dir;
use ipc_types::runtime::{Ipc, IpcPrefix, logging};
use ipc_types::services;
use sim::lockstep::Simulator;
use sim::px4::endpoint::{EndpointConfig, SimVehicle};

/// The landing stack's simulator: quadrotor, PX4-like autopilot over MAVLink, moving pad.
#[derive(Debug, Parser)]
#[command(name = "sim", version, about)]
struct Args {
    /// Scenario name (from deploy/scenarios/) or TOML file.
    #[arg(long, default_value = "paper-sim")]
    scenario: String,
    /// Seed of every random process (default: the scenario's).
    #[arg(long)]
    seed: Option<u64>,
    /// The deploy directory (default: $LANDING_DEPLOY_DIR, else found above the current
    /// directory or the executable).
    #[arg(long)]
    deploy_dir: Option<std::path::PathBuf>,
    /// iceoryx2 prefix (default: $LANDING_IPC_PREFIX, else `landing_`).
    #[arg(long)]
    ipc_prefix: Option<String>,
    /// Where the simulated autopilot listens for MAVLink.
    #[arg(long, default_value = "127.0.0.1:14580")]
    mavlink_listen: SocketAddr,
    /// Where it sends MAVLink before a companion has spoken (px4-link's default port).
    #[arg(long, default_value = "127.0.0.1:14540")]
    mavlink_remote: SocketAddr,
    /// Simulated seconds per wall-clock second.
    #[arg(long, default_value_t = 1.0)]
    speed: f64,
    /// Stop after this many simulated seconds (default: the scenario's duration).
    #[arg(long)]
    duration_s: Option<f64>,
}

fn main() -> ExitCode {
    let args = Args::parse();
    logging::init("info");
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn run(args: &Args) -> Result<()> {
    if !(args.speed.is_finite() && args.speed > 0.0 && args.speed <= 100.0) {
        anyhow::bail!(
            "--speed {} is not allowed (allowed: above 0, at most 100)",
            args.speed
        );
    }
    let deploy = args.deploy_dir.clone().unwrap_or_else(deploy_dir);
    let scenario = sim::scenario::load(&args.scenario, &deploy)?;
    let seed = args.seed.unwrap_or(scenario.scenario.seed);
    let duration_s = args.duration_s.unwrap_or(scenario.scenario.duration_s);
    let simulator = Simulator::new(&scenario, seed)?;
    let config = EndpointConfig {
        listen: args.mavlink_listen,
        remote: Some(args.mavlink_remote),
        ..EndpointConfig::default()
    };
    let mut vehicle = SimVehicle::with_simulator(simulator, config)?;

    let prefix = IpcPrefix::from_flag_or_env(args.ipc_prefix.as_deref())?;
    let ipc = Ipc::open("sim", &prefix)?;
    let mut truth = ipc.publisher::<ipc_types::msg::TruthEvent>(services::SIM_TRUTH)?;
    let mut heartbeat = ipc.heartbeat(Duration::from_millis(500))?;
    tracing::info!(
        scenario = %scenario.scenario.name,
        seed,
        mavlink = %vehicle.endpoint().local_addr(),
        "simulator running"
    );

    let stop = AtomicBool::new(false);
    let until = Instant::now() + Duration::from_secs_f64(duration_s / args.speed + 1.0);
    let end_ns = (duration_s * 1e9) as u64;
    let mut steps: u64 = 0;
    let mut failure = None;
    vehicle
        .run_realtime(until, &stop, args.speed, |sim, report| {
            for t in &report.truth {
                tracing::info!(kind = ?TruthKind::from_raw(t.kind), on_pad = t.on_pad, "ground truth");
                if let Err(e) = truth.send(t.msg, t) {
                    failure = Some(e);
                    return false;
                }
            }
            steps += 1;
            if steps.is_multiple_of(50) {
                if let Err(e) = heartbeat.beat() {
                    failure = Some(e);
                    return false;
                }
                // SIGINT/SIGTERM end the run cleanly.
                if ipc.node().wait(Duration::ZERO).is_err() {
                    tracing::info!("signal: stopping");
                    return false;
                }
            }
            sim.time_ns() < end_ns
        })
        .context("simulation")?;
    if let Some(e) = failure {
        return Err(e).context("publishing");
    }
    Ok(())
}
