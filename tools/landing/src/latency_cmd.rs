//! `landing latency`: the latency report of a recording or of the running stack
//! (`evaluation::latency`), printed as a table or JSON, with its histogram.

use std::path::PathBuf;

use anyhow::{Result, bail};
use clap::Args;
use evaluation::latency::{Percentiles, analyse};
use evaluation::{latency_live, plot};

/// Arguments of `landing latency`.
#[derive(Debug, Args)]
pub struct LatencyArgs {
    /// The recording (`landing run --record`, or the `recorder` process).
    #[arg(value_name = "FILE.mcap", required_unless_present = "live")]
    file: Option<PathBuf>,
    /// Watch the running stack (the global --ipc-prefix, else $LANDING_IPC_PREFIX)
    /// instead of a recording: a summary line every --period, the whole report at the
    /// end (--seconds, or Ctrl-C).
    #[arg(long, conflicts_with = "file")]
    live: bool,
    /// --live: stop after this many seconds (default: at Ctrl-C).
    #[arg(long, requires = "live", value_name = "S", value_parser = positive_seconds)]
    seconds: Option<f64>,
    /// --live: a summary line this often, seconds.
    #[arg(long, requires = "live", value_name = "S", default_value = "2", value_parser = positive_seconds)]
    period: f64,
    /// --live: the graph whose topics to watch (default: the deploy directory's).
    #[arg(long, requires = "live", value_name = "FILE.toml")]
    graph: Option<PathBuf>,
    /// Print the result as one JSON object on stdout.
    #[arg(long)]
    json: bool,
    /// Write a histogram of the end-to-end latency (end_to_end_ms.png) here.
    #[arg(long, value_name = "DIR")]
    plot: Option<PathBuf>,
}

fn positive_seconds(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 && v <= 86_400.0 => Ok(v),
        _ => Err(format!(
            "`{s}` (allowed: seconds, more than 0, at most 86400)"
        )),
    }
}

fn row(name: &str, p: &Percentiles) -> String {
    format!(
        "{name:<34} {:>7.2} {:>7.2} {:>7.2} {:>7.2} {:>7}",
        p.p50, p.p90, p.p99, p.max, p.count
    )
}

/// Runs `landing latency` (`prefix`: the global --ipc-prefix, for --live).
pub fn run(args: &LatencyArgs, prefix: Option<&str>) -> Result<()> {
    let report = match &args.file {
        Some(file) => analyse(file)?,
        None => {
            let graph = args
                .graph
                .clone()
                .unwrap_or_else(|| graph::default_path(&stack_config::deploy_dir()));
            latency_live::watch(
                prefix,
                &graph,
                std::time::Duration::from_secs_f64(args.period),
                args.seconds,
            )?
        }
    };
    if let Some(dir) = &args.plot {
        std::fs::create_dir_all(dir)?;
        let p = dir.join("end_to_end_ms.png");
        plot::write_histogram(
            &p,
            "camera frame -> setpoint on the wire (ms)",
            &report.end_to_end_samples_ms,
        )?;
        eprintln!("  plot: {}", p.display());
    }
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!(
            "{:<34} {:>7} {:>7} {:>7} {:>7} {:>7}",
            "latency, ms", "p50", "p90", "p99", "max", "n"
        );
        if let Some(p) = &report.end_to_end_ms {
            println!("{}", row("end to end (frame -> wire)", p));
        }
        if let Some(p) = &report.capture_to_wire_ms {
            println!("{}", row("capture -> wire (camera's own too)", p));
        }
        for (k, p) in &report.stages {
            println!("{}", row(&format!("  {k}"), p));
        }
        println!("by publisher and topic:");
        for (k, p) in &report.topics {
            println!("{}", row(&format!("  {k}"), p));
        }
        println!("{:<34} {:>8} {:>7}", "topic", "rate Hz", "drops");
        for (t, r) in &report.rates_hz {
            let d = report.drops.get(t).copied().unwrap_or(0);
            println!("  {t:<32} {r:>8.1} {d:>7}");
        }
        if !report.cpu_percent.is_empty() {
            println!(
                "{:<34} {:>8} {:>7}",
                "cpu, % of one core", "mean", "max 1 s"
            );
            for (p, c) in &report.cpu_percent {
                println!("  {p:<32} {:>8.1} {:>7.1}", c.mean, c.max);
            }
        }
    }
    if report.end_to_end_ms.is_none() {
        eprintln!(
            "  no setpoint on the wire derives from a camera frame: was the pad tracked, and was px4/setpoint_sent recorded?"
        );
    }
    if let (Some(b), Some(file)) = (&report.broken, &args.file) {
        bail!("{}: {b}", file.display());
    }
    Ok(())
}
