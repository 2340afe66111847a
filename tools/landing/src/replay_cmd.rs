//! `landing replay run.mcap --stage STAGE`: one stage of a recorded flight run again on
//! the lockstep driver, fed from the recording, its outputs compared with the flight's
//! (`stack::replay`).

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use stack::replay::{self, ReplayReport, Request};

/// Arguments of `landing replay`.
#[derive(Debug, Args)]
pub struct ReplayArgs {
    /// The recording (made with --raw-images for aruco-pnp).
    #[arg(value_name = "FILE.mcap")]
    pub(crate) file: PathBuf,
    /// The stage to run again: aruco-pnp (a --raw-images recording), depth-map, planner
    /// or fsm.
    #[arg(long)]
    pub(crate) stage: String,
    /// The deploy directory (scenarios, calibrations; default: found as `landing run`
    /// finds it).
    #[arg(long)]
    pub(crate) deploy_dir: Option<PathBuf>,
    /// Run the stage with this stack configuration instead of the flight's (its
    /// metadata): what the change would have done to the flight's outputs, on the same
    /// inputs.
    #[arg(long, value_name = "FILE.toml")]
    pub(crate) config: Option<PathBuf>,
    /// Print the result as JSON.
    #[arg(long)]
    pub(crate) json: bool,
}

/// Runs `landing replay`; `false` when the replay did not reproduce the flight.
pub fn run(args: &ReplayArgs) -> Result<bool> {
    let report = replay::replay(&Request {
        file: args.file.clone(),
        stage: args.stage.clone(),
        deploy: (args.deploy_dir.clone()).unwrap_or_else(stack_config::deploy_dir),
        config: args.config.clone(),
    })?;
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print(&report);
    }
    Ok(report.reproduced())
}

fn print(r: &ReplayReport) {
    println!(
        "replay {}: {} inputs; {} outputs in flight, {} replayed: {} identical, {} different, {} missing, {} extra",
        r.stage,
        r.inputs,
        r.recorded,
        r.replayed,
        r.identical,
        r.different,
        r.missing.len(),
        r.extra
    );
    if r.lost > 0 {
        println!(
            "  the recording lost {} {}s (the recorder fell behind); the {} recorded after the first loss are not compared",
            r.lost,
            r.unit(),
            r.not_compared
        );
    }
    for f in &r.flown {
        println!("  in flight: {f}");
    }
    for d in &r.differences {
        println!("  {d}");
    }
}
