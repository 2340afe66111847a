//! `landing inject FAULT:PROCESS`: a fault done now to a running stack (under
//! --ipc-prefix), for fault tests by hand. `kill` and `stop` signal the process (found in
//! /proc: its binary, started with that prefix), `cont` resumes a stopped one; `delay:MS`,
//! `drop:FRACTION`, `corrupt` and `clear` go to its output ports through
//! `landing/fault/inject`, which only processes started with `LANDING_FAULT_INJECTION=1`
//! take.

use anyhow::{Result, bail};
use clap::Args;
use ipc_types::msg::{FaultOrder, Header, PortFault, Text};
use ipc_types::services;
use runtime::{Ipc, IpcPrefix, monotonic_ns};

use crate::inject::{Fault, Injection};

/// Arguments of `landing inject`.
#[derive(Debug, Args)]
pub struct InjectArgs {
    /// FAULT:PROCESS: FAULT kill, stop, cont, delay:MS, drop:FRACTION, corrupt or clear;
    /// PROCESS a node of the graph (e.g. stop:planner, drop:0.5:aruco-pnp, clear:aruco-pnp);
    /// or cut:SECONDS:TOPIC, a topic stopped for a while (cut:2:sim/camera).
    fault: String,
}

/// The processes of the stack under `prefix` running `binary`: their command line or
/// environment names the prefix.
fn pids_of(binary: &str, prefix: &str) -> Vec<i32> {
    let Ok(dir) = std::fs::read_dir("/proc") else {
        return Vec::new();
    };
    let flag = format!("--ipc-prefix\0{prefix}\0");
    let env = format!("LANDING_IPC_PREFIX={prefix}\0");
    dir.filter_map(|e| e.ok())
        .filter_map(|e| e.file_name().to_str()?.parse::<i32>().ok())
        .filter(|pid| {
            let read = |f: &str| std::fs::read(format!("/proc/{pid}/{f}")).unwrap_or_default();
            let cmdline = String::from_utf8_lossy(&read("cmdline")).into_owned();
            let exe = cmdline.split('\0').next().unwrap_or("");
            let named = std::path::Path::new(exe)
                .file_name()
                .is_some_and(|n| n == binary);
            named
                && (cmdline.contains(&flag)
                    || String::from_utf8_lossy(&read("environ")).contains(&env))
        })
        .collect()
}

/// The order for `process`'s outputs: `fault` with `value`, on `topic` (else every
/// output), for `for_s` seconds (0: until cleared).
fn order(
    process: &str,
    (fault, value): (PortFault, f64),
    topic: Option<&str>,
    for_s: f64,
) -> FaultOrder {
    FaultOrder {
        process: Text::new(process),
        fault: fault as u32,
        value,
        topic: Text::new(topic.unwrap_or("")),
        for_s,
        ..FaultOrder::default()
    }
}

/// Runs `landing inject`.
pub fn run(args: &InjectArgs, prefix: Option<&str>) -> Result<()> {
    let prefix = IpcPrefix::from_flag_or_env(prefix)?;
    let order = match args.fault.split_once(':') {
        Some(("cont", p)) => return signal(p, prefix.as_str(), libc::SIGCONT),
        Some(("clear", p)) => order(p, (PortFault::Clear, 0.0), None, 0.0),
        _ => {
            // The --inject grammar, done now.
            let mut i: Injection = format!("{}@0", args.fault).parse().map_err(|_| {
                anyhow::anyhow!(
                    "`{}`: not allowed (allowed: FAULT:PROCESS, FAULT kill, stop, cont, delay:MS, drop:FRACTION, corrupt or clear; or cut:SECONDS:TOPIC)",
                    args.fault
                )
            })?;
            if i.topic.is_some() {
                let deploy = stack_config::deploy_dir();
                let graph = graph::Graph::load(&graph::default_path(&deploy))?;
                i.resolve(&graph).map_err(anyhow::Error::msg)?;
            }
            if i.fault == Fault::Restart {
                bail!(
                    "`{}`: restart needs the process's command line, which only `landing run --inject` has (a deployed stack: `kill`, and systemd restarts it)",
                    args.fault
                );
            }
            if let Some(sig) = i.fault.signal() {
                return signal(&i.process, prefix.as_str(), sig);
            }
            let for_s = i.fault.duration_s();
            match i.fault.order() {
                Some(o) => order(&i.process, o, i.topic.as_deref(), for_s),
                None => bail!(
                    "`{}`: garbage needs px4-link's UDP port, which only `landing run --inject` knows",
                    args.fault
                ),
            }
        }
    };
    let ipc = Ipc::open("landing-inject", &prefix)?;
    let mut orders = ipc.publisher::<FaultOrder>(services::FAULT_INJECT)?;
    orders.send(Header::captured_at(monotonic_ns()), &order)?;
    // The stages look at their orders every loop (at least every heartbeat, 50 ms): stay
    // until they have, the sample lives in this publisher's memory.
    std::thread::sleep(std::time::Duration::from_millis(300));
    println!(
        "ordered {} into {}'s outputs under `{}` (taken only if it runs with {}=1)",
        args.fault,
        order.process.as_str(),
        prefix.as_str(),
        runtime::port_faults::ENV
    );
    Ok(())
}

fn signal(process: &str, prefix: &str, sig: libc::c_int) -> Result<()> {
    let pids = pids_of(process, prefix);
    if pids.is_empty() {
        bail!("no `{process}` process of the stack under `{prefix}` runs here");
    }
    for pid in &pids {
        // SAFETY: a signal to a process of our own stack, found above.
        if unsafe { libc::kill(*pid, sig) } != 0 {
            bail!(
                "signalling {process} ({pid}): {}",
                std::io::Error::last_os_error()
            );
        }
    }
    println!("signalled {process} ({pids:?}) under `{prefix}`");
    Ok(())
}
