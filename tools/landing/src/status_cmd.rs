//! `landing status`: the watchdog's view of a running stack, once or live. Each process
//! with its liveness, how long ago it last beat, its missed deadlines; the mission's
//! phase, the newest fault, the watchdog's decision and whether it ordered a landing.

use std::fmt::Write as _;
use std::time::{Duration, Instant};

use anyhow::{Result, bail};
use clap::Args;
use ipc_types::msg::{Liveness, MissionState, WatchdogView};
use ipc_types::services;
use runtime::{Ipc, IpcPrefix, monotonic_ns};

/// Arguments of `landing status`.
#[derive(Debug, Args)]
pub struct StatusArgs {
    /// Keep printing each new view until Ctrl-C.
    #[arg(long)]
    watch: bool,
    /// Print the view as one JSON object.
    #[arg(long)]
    json: bool,
    /// How long to wait for a view, s.
    #[arg(long, default_value_t = 3.0)]
    wait_s: f64,
}

/// Runs `landing status` against the stack under `prefix`.
pub fn run(args: &StatusArgs, prefix: Option<&str>) -> Result<()> {
    if !(args.wait_s.is_finite() && args.wait_s > 0.0 && args.wait_s <= 3600.0) {
        bail!(
            "--wait-s {}: not allowed (allowed: more than 0, at most 3600 seconds)",
            args.wait_s
        );
    }
    let prefix = IpcPrefix::from_flag_or_env(prefix)?;
    let ipc = Ipc::open("landing-status", &prefix)?;
    let views = ipc.subscriber::<WatchdogView>(services::WATCHDOG_VIEW)?;
    let wait = Duration::from_secs_f64(args.wait_s);
    let mut deadline = Instant::now() + wait;
    loop {
        let mut newest = None;
        while let Some(v) = views.receive()? {
            newest = Some(*v.payload());
        }
        match newest {
            Some(v) => {
                if args.json {
                    println!("{}", serde_json::to_string(&json(&v))?);
                } else {
                    print!("{}", text(&v, prefix.as_str(), monotonic_ns()));
                }
                if !args.watch {
                    return Ok(());
                }
                deadline = Instant::now() + wait;
            }
            None if Instant::now() >= deadline => bail!(
                "no watchdog view under prefix `{}` within {} s (is the stack running, with its watchdog?)",
                prefix.as_str(),
                args.wait_s
            ),
            None => {}
        }
        if ipc.shutdown_requested() {
            return Ok(());
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn phase(v: &WatchdogView) -> &'static str {
    MissionState::from_raw(v.phase).map_or("?", MissionState::name)
}

fn ago(now_ns: u64, at_ns: u64) -> String {
    if at_ns == 0 {
        "-".into()
    } else {
        format!("{:.0} ms ago", now_ns.saturating_sub(at_ns) as f64 * 1e-6)
    }
}

/// The view as text, ages against `now_ns` (the same monotonic clock).
pub fn text(v: &WatchdogView, prefix: &str, now_ns: u64) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "stack {prefix} · phase {} · faults {} · safe landing ordered: {}",
        phase(v),
        v.faults,
        if v.safe_land_ordered == 1 {
            "yes"
        } else {
            "no"
        }
    );
    let _ = writeln!(
        s,
        "  {:<14} {:<9} {:>14} {:>7} {:>8}  found hung/dead",
        "process", "state", "last beat", "missed", "restarts"
    );
    for p in v.watched() {
        let _ = writeln!(
            s,
            "  {:<14} {:<9} {:>14} {:>7} {:>8}  {}",
            p.name.as_str(),
            Liveness::from_raw(p.liveness).name(),
            ago(now_ns, p.last_heartbeat_ns),
            p.missed_deadlines,
            p.restarts,
            ago(now_ns, p.fault_ns),
        );
    }
    // A process systemd gave up on stays dead: the stack runs without it.
    for name in degraded(v) {
        let _ = writeln!(s, "  DEGRADED: {name} is dead and not back");
    }
    let or_dash = |t: &str| {
        if t.is_empty() {
            "-".to_string()
        } else {
            t.to_string()
        }
    };
    let _ = writeln!(
        s,
        "  last fault: {} ({})",
        or_dash(v.last_fault.as_str()),
        ago(now_ns, v.last_fault_ns)
    );
    let _ = writeln!(s, "  decision: {}", or_dash(v.action.as_str()));
    s
}

/// The view as JSON.
pub fn json(v: &WatchdogView) -> serde_json::Value {
    let processes: Vec<_> = v
        .watched()
        .iter()
        .map(|p| {
            serde_json::json!({
                "name": p.name.as_str(),
                "state": Liveness::from_raw(p.liveness).name(),
                "missed_deadlines": p.missed_deadlines,
                "last_heartbeat_ns": p.last_heartbeat_ns,
                "fault_ns": p.fault_ns,
                "restarts": p.restarts,
                "rejoined_ns": p.rejoined_ns,
            })
        })
        .collect();
    serde_json::json!({
        "phase": phase(v),
        "faults": v.faults,
        "safe_land_ordered": v.safe_land_ordered == 1,
        "order_ns": v.order_ns,
        "last_fault": v.last_fault.as_str(),
        "last_fault_ns": v.last_fault_ns,
        "decision": v.action.as_str(),
        "degraded": degraded(v),
        "processes": processes,
    })
}

/// The watched processes that are dead (and not back).
fn degraded(v: &WatchdogView) -> Vec<&str> {
    v.watched()
        .iter()
        .filter(|p| Liveness::from_raw(p.liveness) == Liveness::Dead)
        .map(|p| p.name.as_str())
        .collect()
}
