//! `fsm`: the landing mission as its own process. Reads vehicle/state, pad/observation,
//! planner/trajectory, px4/outcome and safety/command; publishes fsm/setpoint,
//! planner/goal, px4/request and fsm/status (deploy/graph.toml). Everything it decides
//! is `fsm::FsmStage`; this file builds it and hands it to the iceoryx2 driver.

use std::process::ExitCode;

use anyhow::{Result, anyhow};
use clap::Parser;
use fsm::{FsmConfig, FsmStage};
use runtime::StageArgs;
use stack_config::Validate;

/// Flies the landing mission: take off, find the pad, track it, descend, land on it.
#[derive(Debug, Parser)]
#[command(name = "fsm", version, about)]
struct Args {
    #[command(flatten)]
    stage: StageArgs,
    /// Preset point (where to wait for the pad), x,y,z in metres, world ENU; overrides
    /// [fsm] preset_m.
    #[arg(long, value_name = "X,Y,Z")]
    preset: Option<String>,
    /// Height above the pad below which the vehicle commits to touchdown, m; overrides
    /// [fsm] commit_height_m.
    #[arg(long)]
    commit_height: Option<f64>,
    /// Never search for the pad higher than this, m (where the camera still reads the
    /// pad's largest marker); the lower of this and [fsm] search_height_max_m holds.
    #[arg(long)]
    search_height_max: Option<f64>,
}

fn main() -> ExitCode {
    runtime::process_main("info", run)
}

fn run(args: &Args) -> Result<()> {
    let (ipc, mut cfg): (_, FsmConfig) = args.stage.load("fsm")?;
    if let Some(p) = &args.preset {
        let v: Vec<f64> = p.split(',').filter_map(|s| s.trim().parse().ok()).collect();
        let [x, y, z] = v[..] else {
            return Err(anyhow!(
                "--preset `{p}` is not allowed (allowed: three numbers x,y,z in m)"
            ));
        };
        cfg.preset_m = [x, y, z];
    }
    if let Some(h) = args.commit_height {
        cfg.commit_height_m = h;
    }
    if let Some(h) = args.search_height_max {
        cfg.search_height_max_m = Some(cfg.search_height_max_m.map_or(h, |c| c.min(h)));
    }
    cfg.validate().map_err(|e| {
        anyhow!(
            "--preset/--commit-height/--search-height-max: fsm.{}: {}",
            e.key,
            e.message
        )
    })?;
    tracing::info!(preset = ?cfg.preset_m, commit_height_m = cfg.commit_height_m, "fsm");
    runtime::serve(
        &args.stage,
        &ipc,
        &mut FsmStage::from_config(&cfg),
        None,
        None,
    )?;
    Ok(())
}
