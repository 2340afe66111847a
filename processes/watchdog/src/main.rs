//! `watchdog`: supervises the stack. Reads every vehicle process's heartbeat and iceoryx2
//! node (through the runtime's supervision source), vehicle/state, fsm/status,
//! fsm/setpoint, pad/observation and camera/frame; publishes safety/command and
//! watchdog/view (deploy/graph.toml). What it decides is `watchdog::WatchdogStage`.

use std::process::ExitCode;
use std::time::Duration;

use anyhow::{Context, Result};
use clap::Parser;
use runtime::{IpcPrefix, StageArgs, Supervision};
use stack_config::Validate;
use watchdog::{WatchdogStage, WatchdogStageConfig, watched_processes};

/// Supervises the stack: finds dead and hung processes and silent or broken data paths,
/// and orders a safe landing when the policy says so.
#[derive(Debug, Parser)]
#[command(name = "watchdog", version, about)]
struct Args {
    #[command(flatten)]
    stage: StageArgs,
}

fn main() -> ExitCode {
    runtime::process_main("info", run)
}

fn run(args: &Args) -> Result<()> {
    let (ipc, cfg): (_, WatchdogStageConfig) = args.stage.load("watchdog")?;
    cfg.validate()
        .map_err(|e| anyhow::anyhow!("watchdog.{}: {}", e.key, e.message))?;
    let path = args
        .stage
        .graph
        .clone()
        .unwrap_or_else(|| graph::default_path(&args.stage.deploy()));
    let graph = graph::Graph::load(&path)?;
    let processes = watched_processes(&graph);
    let prefix = IpcPrefix::resolve(args.stage.ipc_prefix.as_deref(), &ipc.prefix)?;
    let deadlines: Vec<(String, Duration)> = processes
        .iter()
        .map(|(n, ms)| (n.clone(), Duration::from_secs_f64(ms * 1e-3)))
        .collect();
    let mut source = Supervision::open(
        "watchdog",
        &prefix,
        &deadlines,
        Duration::from_millis(cfg.node_poll_ms),
    )
    .context("the supervision source")?;
    tracing::info!(
        processes = ?processes.iter().map(|(n, _)| n.as_str()).collect::<Vec<_>>(),
        "watching"
    );
    let mut stage = WatchdogStage::from_config(&cfg, &processes)?;
    runtime::serve(&args.stage, &ipc, &mut stage, Some(&mut source), None)?;
    Ok(())
}
