//! `landing bench latency`: camera frame -> setpoint on the MAVLink wire with every stage
//! its own process and the simulator on the same machine, in one command. It flies the
//! scenario with `--processes --record` twice, with the configuration as shipped and with
//! `[px4_link] new_setpoints_at_once` the other way (the one difference: at once, or
//! waiting for the setpoint stream), and reads each recording with `landing latency`'s
//! analysis. Both rows, same scenario, same seed.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, Result, bail};
use clap::Args;
use serde::Serialize;

use evaluation::latency::{Percentiles, analyse};

/// Arguments of `landing bench latency`.
#[derive(Debug, Args)]
pub struct LatencyBenchArgs {
    /// The scenario flown.
    #[arg(long, default_value = "paper-sim")]
    scenario: String,
    /// Give the camera -> fsm -> px4-link path the deployment's SCHED_FIFO priorities
    /// (`landing run --realtime`; needs root or CAP_SYS_NICE).
    #[arg(long)]
    realtime: bool,
    /// The stack configuration (default: the deploy directory's config/landing.toml).
    #[arg(long, value_name = "FILE.toml")]
    config: Option<PathBuf>,
    /// Where the recordings and the modified config go (default: a new temporary
    /// directory, removed after).
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Print the rows as JSON.
    #[arg(long)]
    json: bool,
}

/// One configuration's measurement.
#[derive(Debug, Clone, Serialize)]
pub struct LatencyRow {
    /// Which configuration.
    pub config: String,
    /// Camera frame delivered -> first setpoint from it on the wire, ms.
    pub end_to_end_ms: Option<Percentiles>,
    /// Capture timestamp -> that setpoint on the wire (the camera's own latency too), ms.
    pub capture_to_wire_ms: Option<Percentiles>,
    /// Each stage's share, p50 / p99, ms.
    pub stages: Vec<(String, f64, f64)>,
}

/// Flies once with `config` and analyses the recording `out`.
fn fly(args: &LatencyBenchArgs, config: &Path, out: &Path, name: &str) -> Result<LatencyRow> {
    eprintln!("bench latency: {} --processes, {name}...", args.scenario);
    let exe = std::env::current_exe().context("finding this landing binary")?;
    let mut cmd = Command::new(exe);
    cmd.args([
        "run",
        "--scenario",
        &args.scenario,
        "--processes",
        "--config",
    ])
    .arg(config)
    .arg("--record")
    .arg(out);
    if args.realtime {
        cmd.arg("--realtime");
    }
    let o = cmd.output().context("running landing run")?;
    if !out.exists() {
        bail!(
            "the flight left no recording ({}): {}",
            out.display(),
            String::from_utf8_lossy(&o.stderr)
                .lines()
                .last()
                .unwrap_or("")
        );
    }
    let r = analyse(out)?;
    Ok(LatencyRow {
        config: name.to_string(),
        end_to_end_ms: r.end_to_end_ms,
        capture_to_wire_ms: r.capture_to_wire_ms,
        stages: r
            .stages
            .iter()
            .map(|(k, p)| (k.clone(), p.p50, p.p99))
            .collect(),
    })
}

/// Runs `landing bench latency`.
pub fn run(args: &LatencyBenchArgs) -> Result<()> {
    let deploy = stack_config::deploy_dir();
    let shipped = args
        .config
        .clone()
        .unwrap_or_else(|| deploy.join("config").join("landing.toml"));
    let text = std::fs::read_to_string(&shipped)
        .with_context(|| format!("reading {}", shipped.display()))?;
    let (on, off) = (
        "new_setpoints_at_once = true",
        "new_setpoints_at_once = false",
    );
    let (other, other_text) = if text.contains(on) {
        (off, text.replace(on, off))
    } else if text.contains(off) {
        (on, text.replace(off, on))
    } else {
        bail!(
            "{}: no `new_setpoints_at_once = true` or `= false` line under [px4_link] to turn over",
            shipped.display()
        );
    };
    let temporary = args.out.is_none();
    let dir = args.out.clone().unwrap_or_else(|| {
        std::env::temp_dir().join(format!("landing-bench-latency-{}", std::process::id()))
    });
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    // The files the config names (calibrations, the pad) are read beside it: copy them.
    let config_dir = shipped.parent().unwrap_or(Path::new("."));
    for entry in std::fs::read_dir(config_dir)
        .with_context(|| format!("reading {}", config_dir.display()))?
    {
        let path = entry?.path();
        if let Some(name) = path.file_name()
            && path.is_file()
            && path != shipped
        {
            std::fs::copy(&path, dir.join(name))
                .with_context(|| format!("copying {}", path.display()))?;
        }
    }
    let turned = dir.join("turned-over.toml");
    std::fs::write(&turned, other_text)?;
    let rows = vec![
        fly(args, &shipped, &dir.join("shipped.mcap"), "as shipped")?,
        fly(args, &turned, &dir.join("turned-over.mcap"), other)?,
    ];
    if temporary {
        let _ = std::fs::remove_dir_all(&dir);
    }
    if args.json {
        println!("{}", serde_json::to_string(&rows)?);
        return Ok(());
    }
    println!(
        "{:<30} {:>7} {:>7} {:>7} {:>7} {:>8} {:>6}",
        "frame -> wire, ms", "p50", "p90", "p99", "max", "cap p50", "frames"
    );
    for r in &rows {
        match (&r.end_to_end_ms, &r.capture_to_wire_ms) {
            (Some(e), Some(c)) => println!(
                "{:<30} {:>7.2} {:>7.2} {:>7.2} {:>7.2} {:>8.1} {:>6}",
                r.config, e.p50, e.p90, e.p99, e.max, c.p50, e.count
            ),
            _ => println!("{:<30} no setpoint derived from a camera frame", r.config),
        }
        let stages: Vec<String> = r
            .stages
            .iter()
            .map(|(k, p50, p99)| format!("{k} {p50:.2}/{p99:.2}"))
            .collect();
        println!("  per stage p50/p99: {}", stages.join(", "));
    }
    Ok(())
}
