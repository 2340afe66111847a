//! `landing doctor`: the preflight checks (`stack::doctor`), one line each.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Result, bail};
use clap::Args;
use stack::doctor::{DoctorOptions, run};

/// Arguments of `landing doctor`.
#[derive(Debug, Args)]
pub struct DoctorArgs {
    /// The stack file [default: deploy/config/landing.toml of the deploy directory].
    #[arg(long)]
    config: Option<PathBuf>,
    /// Where recordings go [default: /var/lib/landing/recordings when it exists, else
    /// the current directory].
    #[arg(long)]
    recordings: Option<PathBuf>,
    /// Least free space for recordings, GB.
    #[arg(long, default_value_t = 2.0)]
    min_free_gb: f64,
    /// How long to wait for each answer of the autopilot, s.
    #[arg(long, default_value_t = 3.0)]
    timeout_s: f64,
    /// Print one JSON array of the checks instead of lines.
    #[arg(long)]
    json: bool,
}

/// Runs the checks; `Ok(false)` when one failed.
pub fn run_doctor(args: &DoctorArgs, ipc_prefix: Option<&str>) -> Result<bool> {
    if !(args.timeout_s.is_finite() && (0.1..=60.0).contains(&args.timeout_s)) {
        bail!(
            "--timeout-s {} is not allowed (allowed: 0.1 to 60)",
            args.timeout_s
        );
    }
    if !(args.min_free_gb.is_finite() && args.min_free_gb >= 0.0) {
        bail!(
            "--min-free-gb {} is not allowed (allowed: 0 or more)",
            args.min_free_gb
        );
    }
    let config = args
        .config
        .clone()
        .unwrap_or_else(|| stack_config::deploy_dir().join("config/landing.toml"));
    let recordings = args.recordings.clone().unwrap_or_else(|| {
        let vehicle = PathBuf::from("/var/lib/landing/recordings");
        if vehicle.is_dir() {
            vehicle
        } else {
            PathBuf::from(".")
        }
    });
    let opts = DoctorOptions {
        recordings,
        min_free_gb: args.min_free_gb,
        timeout: Duration::from_secs_f64(args.timeout_s),
        ipc_prefix: ipc_prefix.map(str::to_string),
    };
    let checks = run(&config, &opts);
    if args.json {
        println!("{}", serde_json::to_string_pretty(&checks)?);
    } else {
        for c in &checks {
            println!(
                "{:<4}  {:<22} {}",
                if c.ok { "ok" } else { "FAIL" },
                c.name,
                c.detail
            );
        }
    }
    Ok(checks.iter().all(|c| c.ok))
}
