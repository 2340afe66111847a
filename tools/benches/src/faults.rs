//! `landing bench faults`: the fault matrix. Every process the watchdog watches is killed
//! (SIGKILL), stopped (SIGSTOP: a hang) and restarted (SIGKILL, then started again at
//! once, as systemd's `Restart=on-failure` does); the camera frames and pad observations
//! are delayed, half dropped and corrupted (for good, and for half a second: in the
//! publishers' ports); and the world fails (the camera unplugged and the telemetry lost
//! for 0.5, 1 and 2 s, the pad hidden, noise on the MAVLink port), while the fsm tracks
//! and while it descends (a restart also in the touchdown), one `landing run --processes
//! --inject` flight each. Each row says how the flight ended, how long the watchdog took
//! to find the fault, to order, and (a restart) until the new process was back in the
//! graph, and what it decided. The headline: fault -> safe-land order, p50 / p95 / max,
//! for dead and for hung processes, over the rows whose fault the watchdog landed for,
//! and death -> rejoin for the restarts. A row it decided to `continue` (over the pad)
//! may still see an order later, for a later fault: shown in its row, not in the
//! headline.

use std::path::PathBuf;
use std::process::Command;

use anyhow::{Context, Result, bail};
use clap::Args;
use serde::Serialize;
use serde_json::Value;

use evaluation::stats::percentile;

/// Arguments of `landing bench faults`.
#[derive(Debug, Args)]
pub struct FaultsArgs {
    /// The scenario flown.
    #[arg(long, default_value = "paper-sim")]
    scenario: String,
    /// Its seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// The processes to fault (default: every process the watchdog watches).
    #[arg(long, value_delimiter = ',')]
    processes: Vec<String>,
    /// The faults to each process, each `kill`, `stop` or `restart` (`--faults ''`: none).
    #[arg(long, value_delimiter = ',', default_value = "kill,stop,restart")]
    faults: Vec<String>,
    /// Faults in data paths and of the world, each FAULT:TARGET as `--inject` writes
    /// them: a process's outputs (camera-ingest's camera frames, aruco-pnp's pad
    /// observations), the camera unplugged and the autopilot's telemetry lost for 0.5, 1
    /// and 2 s, the pad hidden for 2 s (the camera's images blank), 5000 datagrams of
    /// noise at px4-link's port.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "delay:100:camera-ingest,drop:0.5:camera-ingest,corrupt:camera-ingest,corrupt:0.5:camera-ingest,delay:100:aruco-pnp,drop:0.5:aruco-pnp,corrupt:aruco-pnp,corrupt:0.5:aruco-pnp,cut:0.5:sim/camera,cut:1:sim/camera,cut:2:sim/camera,blank:2:sim/camera,cut:0.5:mavlink/from-px4,cut:1:mavlink/from-px4,cut:2:mavlink/from-px4,garbage:5000:px4-link"
    )]
    data_faults: Vec<String>,
    /// When, each a mission phase (`takeoff`, `track`, `descend`, `land`).
    #[arg(long, value_delimiter = ',', default_value = "track,descend")]
    phases: Vec<String>,
    /// When a `restart` is flown: a restarted px4-link or fsm must finish the touchdown.
    #[arg(long, value_delimiter = ',', default_value = "track,descend,land")]
    restart_phases: Vec<String>,
    /// Fly only part K of N of the matrix (every Nth flight from the Kth, K from 0): runs
    /// with K = 0 .. N-1 cover it between them in a fraction of the time (CI's fault test
    /// flies one part per run).
    #[arg(long, value_name = "K/N", value_parser = parse_part)]
    part: Option<(u64, u64)>,
    /// Print one JSON object instead of a Markdown table.
    #[arg(long)]
    json: bool,
    /// The deploy directory (default: found above the current directory or executable).
    #[arg(long)]
    deploy_dir: Option<PathBuf>,
}

/// One flight of the matrix.
#[derive(Debug, Clone, Serialize)]
struct Row {
    inject: String,
    fault: String,
    process: String,
    phase: String,
    outcome: String,
    /// When the fault was injected (s of simulated time); `None`: the flight never
    /// reached its phase.
    at_s: Option<f64>,
    touchdown_error_m: Option<f64>,
    detected_after_ms: Option<f64>,
    ordered_after_ms: Option<f64>,
    action: Option<String>,
    rejoined_after_ms: Option<f64>,
    /// The referee's line on how the flight ended.
    referee: String,
}

/// `K/N` with N from 1 to 100 and K below N.
fn parse_part(v: &str) -> Result<(u64, u64), String> {
    let bad = || format!("`{v}` is not K/N (N 1 to 100, K 0 to N-1, e.g. 0/4)");
    let (k, n) = v.split_once('/').ok_or_else(bad)?;
    let (k, n) = (
        k.parse::<u64>().map_err(|_| bad())?,
        n.parse::<u64>().map_err(|_| bad())?,
    );
    if n == 0 || n > 100 || k >= n {
        return Err(bad());
    }
    Ok((k, n))
}

/// Runs the matrix.
pub fn run(args: &FaultsArgs) -> Result<()> {
    let deploy = args
        .deploy_dir
        .clone()
        .unwrap_or_else(stack_config::deploy_dir);
    let processes = if args.processes.is_empty() {
        let graph = graph::Graph::load(&graph::default_path(&deploy))?;
        watchdog::watched_processes(&graph)
            .into_iter()
            .map(|(n, _)| n)
            .collect()
    } else {
        args.processes.clone()
    };
    for f in args.faults.iter().filter(|f| !f.is_empty()) {
        if !["kill", "stop", "restart"].contains(&f.as_str()) {
            bail!("--faults: `{f}` is not allowed (allowed: kill, stop, restart)");
        }
    }
    let exe = std::env::current_exe().context("finding the landing binary")?;
    // (fault, process) pairs: every process's, then the data paths'.
    let mut pairs: Vec<(String, String)> = Vec::new();
    for process in &processes {
        for fault in args.faults.iter().filter(|f| !f.is_empty()) {
            pairs.push((fault.clone(), process.clone()));
        }
    }
    for d in args.data_faults.iter().filter(|d| !d.is_empty()) {
        let Some((fault, process)) = d.rsplit_once(':') else {
            bail!("--data-faults: `{d}` is not FAULT:TARGET (e.g. drop:0.5:aruco-pnp)");
        };
        pairs.push((fault.to_string(), process.to_string()));
    }
    if args.phases.is_empty() {
        bail!("--phases: give at least one (takeoff, track, descend, land)");
    }
    let flights: Vec<(&String, &String, &String)> = pairs
        .iter()
        .flat_map(|(fault, process)| {
            let phases = if fault == "restart" {
                &args.restart_phases
            } else {
                &args.phases
            };
            phases.iter().map(move |phase| (fault, process, phase))
        })
        .enumerate()
        .filter(|(i, _)| args.part.is_none_or(|(k, n)| *i as u64 % n == k))
        .map(|(_, f)| f)
        .collect();
    let total = flights.len();
    let mut rows = Vec::with_capacity(total);
    for (fault, process, phase) in flights {
        let inject = format!("{fault}:{process}@{phase}");
        eprintln!("[{}/{total}] {inject}", rows.len() + 1);
        let out = Command::new(&exe)
            .args(["run", "--processes", "--json", "--scenario", &args.scenario])
            .args(["--seed", &args.seed.to_string(), "--inject", &inject])
            .arg("--deploy-dir")
            .arg(&deploy)
            .output()
            .with_context(|| format!("running {inject}"))?;
        let s: Value = serde_json::from_slice(&out.stdout).with_context(|| {
            format!(
                "{inject}: no summary; its stderr: {}",
                String::from_utf8_lossy(&out.stderr)
            )
        })?;
        let f = &s["faults"][0];
        rows.push(Row {
            inject: inject.clone(),
            fault: fault.to_string(),
            process: process.to_string(),
            phase: phase.to_string(),
            outcome: s["outcome"].as_str().unwrap_or("?").to_string(),
            at_s: f["at_s"].as_f64(),
            touchdown_error_m: s["touchdown_error_m"].as_f64(),
            detected_after_ms: f["detected_after_ms"].as_f64(),
            ordered_after_ms: f["ordered_after_ms"].as_f64(),
            action: f["action"].as_str().map(str::to_string),
            rejoined_after_ms: f["rejoined_after_ms"].as_f64(),
            referee: s["referee"].as_str().unwrap_or("").to_string(),
        });
    }
    let continued = |r: &Row| r.action.as_deref().is_some_and(|a| a.ends_with("continue"));
    // Detection over every row; the order over the rows landed for.
    let summary = |fault: &str, pick: fn(&Row) -> Option<f64>, landed_only: bool| {
        let v: Vec<f64> = rows
            .iter()
            .filter(|r| r.fault == fault)
            .filter(|r| !(landed_only && continued(r)))
            .filter_map(pick)
            .collect();
        serde_json::json!({
            "n": v.len(),
            "p50": percentile(&v, 50.0),
            "p95": percentile(&v, 95.0),
            "max": v.iter().copied().fold(0.0, f64::max),
        })
    };
    let headline = serde_json::json!({
        "dead": {
            "detected_ms": summary("kill", |r| r.detected_after_ms, false),
            "ordered_ms": summary("kill", |r| r.ordered_after_ms, true),
        },
        "hung": {
            "detected_ms": summary("stop", |r| r.detected_after_ms, false),
            "ordered_ms": summary("stop", |r| r.ordered_after_ms, true),
        },
        "restarted": {
            "rejoined_ms": summary("restart", |r| r.rejoined_after_ms, false),
        },
        "continued": rows.iter().filter(|r| continued(r)).count(),
    });
    if args.json {
        println!(
            "{}",
            serde_json::json!({
                "scenario": args.scenario,
                "seed": args.seed,
                "rows": rows,
                "summary": headline,
            })
        );
        return Ok(());
    }
    println!(
        "| fault | outcome | touchdown error (m) | detected (ms) | ordered (ms) | rejoined (ms) | watchdog's decision |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- |");
    let ms = |v: Option<f64>| v.map_or("-".to_string(), |x| format!("{x:.0}"));
    for r in &rows {
        println!(
            "| {} | {} | {} | {} | {} | {} | {} |",
            r.inject,
            r.outcome,
            r.touchdown_error_m
                .map_or("-".to_string(), |x| format!("{x:.2}")),
            ms(r.detected_after_ms),
            ms(r.ordered_after_ms),
            ms(r.rejoined_after_ms),
            r.action.as_deref().unwrap_or("-"),
        );
    }
    println!();
    // "p50 .. ms, p95 .. ms, max .. ms (n=..)" of one summary.
    let stats = |v: &Value| {
        let ms = |k: &str| v[k].as_f64().unwrap_or(0.0);
        format!(
            "p50 {:.0} ms, p95 {:.0} ms, max {:.0} ms (n={})",
            ms("p50"),
            ms("p95"),
            ms("max"),
            v["n"]
        )
    };
    for (name, key) in [("dead (kill)", "dead"), ("hung (stop)", "hung")] {
        println!(
            "{name}: found {}; landing order {}, the rows not continued",
            stats(&headline[key]["detected_ms"]),
            stats(&headline[key]["ordered_ms"]),
        );
    }
    println!(
        "restarted: death to rejoin {}",
        stats(&headline["restarted"]["rejoined_ms"])
    );
    Ok(())
}
