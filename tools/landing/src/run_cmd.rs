//! `landing run`: one whole autonomous landing mission in the simulator
//! (`stack::mission`), with a progress line, a summary, and optionally JSON, plots and a
//! recording.

use std::io::{IsTerminal, Write};
use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use evaluation::{Outcome, plot};
use stack::mission::{Event, Mission};
use stack_config::deploy_dir;

/// Arguments of `landing run`.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// Scenario name (from deploy/scenarios/) or TOML file.
    #[arg(long, default_value = "paper-sim")]
    scenario: String,
    /// Seed of every random process (default: the scenario's).
    #[arg(long)]
    seed: Option<u64>,
    /// Stack configuration (default: the deploy directory's config/landing.toml).
    #[arg(long)]
    config: Option<PathBuf>,
    /// The deploy directory (default: found above the current directory or executable).
    #[arg(long)]
    deploy_dir: Option<PathBuf>,
    /// The dataflow graph to run (default: the deploy directory's graph.toml): a graph
    /// with a stage of your own runs it in both modes (see docs/ARCHITECTURE.md).
    #[arg(long, value_name = "FILE")]
    graph: Option<PathBuf>,
    /// Print the summary as one JSON object on stdout.
    #[arg(long)]
    json: bool,
    /// Start every stage as its own OS process (the nodes of the deploy directory's
    /// graph.toml: sim, camera-ingest, aruco-pnp, depth-map, planner, fsm, px4-link)
    /// over iceoryx2 and MAVLink/UDP on the wall clock, as systemd does on the vehicle,
    /// instead of the one-process lockstep.
    #[arg(long)]
    processes: bool,
    /// Record every topic of the pipeline into an MCAP file for Foxglove: the camera
    /// (JPEG), depth, the transform tree, the 3-D scene (map, trajectory, pad), the
    /// mission's log and every message as plottable JSON, with the config, the graph and
    /// the git revision as metadata (`landing mcap info FILE` lists it; docs/recording.md).
    /// --processes runs the `recorder` process for it. The simulator's ground truth goes
    /// to FILE.truth.mcap beside it.
    #[arg(long, value_name = "FILE.mcap")]
    record: Option<PathBuf>,
    /// --processes: give the camera -> fsm -> px4-link path the real-time priorities the
    /// vehicle's systemd units give it (SCHED_FIFO, deploy/systemd/*.d; needs root or
    /// CAP_SYS_NICE), as the latency table in docs/recording.md is measured.
    #[arg(long, requires = "processes")]
    realtime: bool,
    /// --processes: the simulated autopilot and px4-link talk through a MAVLink router
    /// (mavlink-router's routing: targeted messages to where their system was seen,
    /// the rest to everyone), with a second ground station (system 255) sending its own
    /// heartbeats and requests through it; the summary counts every datagram per
    /// endpoint (`router` in --json).
    #[arg(long, requires = "processes")]
    router: bool,
    /// Serve the flight live to Foxglove (Open connection > ws://ADDRESS, Foxglove's
    /// WebSocket protocol) on [recorder] live_address, loopback by default: every topic
    /// --record keeps, as it is published. In lockstep the simulation then keeps to the
    /// wall clock's pace.
    #[arg(long)]
    live: bool,
    /// --record: camera frames raw (foxglove.RawImage) instead of JPEG, bit-exact: what
    /// `landing replay --stage aruco-pnp` needs.
    #[arg(long, requires = "record")]
    raw_images: bool,
    /// Write a top view and a 3-D view of the UAV and UGV trajectories (top.png, 3d.png)
    /// and a histogram of the planning times into this directory.
    #[arg(long, value_name = "DIR")]
    plot: Option<PathBuf>,
    /// --processes: where each process's log goes (default: a new directory under the
    /// system's temporary directory).
    #[arg(long, value_name = "DIR")]
    log_dir: Option<PathBuf>,
    /// --processes: a fault to do in flight, FAULT:PROCESS@WHEN (repeatable): FAULT kill
    /// (SIGKILL), stop (SIGSTOP, a hang), restart (SIGKILL, then started again, as
    /// systemd would), delay:MS, drop:FRACTION or corrupt (the process's outputs), or a
    /// world fault: cut:SECONDS:TOPIC (the topic stops, then comes back: cut:2:sim/camera,
    /// cut:1:mavlink/from-px4), blank:SECONDS:sim/camera (the images show nothing: the pad
    /// hidden) or garbage:N:px4-link (random datagrams at its MAVLink port); PROCESS a
    /// node of the graph; WHEN a mission state (takeoff,
    /// track, descend, land) or seconds after the start. The summary lists the faults,
    /// when the watchdog found each and what it decided (docs/faults.md).
    #[arg(long, value_name = "FAULT:PROCESS@WHEN")]
    inject: Vec<stack::inject::Injection>,
    /// --processes: who flies the vehicle: the built-in PX4-like autopilot, or real PX4
    /// SITL (your own build, --px4) on the simulator's PX4 simulator API, GPS-denied on
    /// the forwarded VIO, flying PX4's iris (docs/px4-sitl.md).
    #[arg(
        long,
        value_enum,
        default_value = "builtin",
        requires_if("px4-sitl", "px4")
    )]
    autopilot: Autopilot,
    /// --autopilot px4-sitl: the PX4 SITL build directory (PX4-Autopilot/build/
    /// px4_sitl_default after `make px4_sitl_default`).
    #[arg(long, value_name = "DIR")]
    px4: Option<PathBuf>,
}

/// Who flies the vehicle in `landing run`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Autopilot {
    /// The simulator's own PX4-like autopilot.
    Builtin,
    /// Real PX4 SITL through the simulator's PX4 simulator API.
    Px4Sitl,
}

/// Runs the mission and reports; `Ok(false)` (exit code 1) when it did not land on the pad.
pub fn run(args: &RunArgs, ipc_prefix: Option<&str>) -> Result<bool> {
    let mission = Mission {
        scenario: args.scenario.clone(),
        seed: args.seed,
        deploy: args.deploy_dir.clone().unwrap_or_else(deploy_dir),
        config: args.config.clone(),
        graph: args.graph.clone(),
        processes: args.processes,
        record: args.record.clone(),
        raw_images: args.raw_images,
        live: args.live,
        realtime: args.realtime,
        router: args.router,
        log_dir: args.log_dir.clone(),
        inject: args.inject.clone(),
        ipc_prefix: ipc_prefix.map(str::to_string),
        px4: match args.autopilot {
            Autopilot::Px4Sitl => args.px4.clone(),
            Autopilot::Builtin => None,
        },
    };
    let mode = if args.processes {
        "processes"
    } else {
        "lockstep"
    };
    let tty = std::io::stderr().is_terminal();
    // Ctrl-C and SIGTERM end the run as `interrupted`, with its summary, in both modes.
    runtime::shutdown::install();
    let flown = mission.fly(&mut |e| match e {
        Event::Start {
            scenario,
            seed,
            description,
        } => eprintln!("run: {scenario} (seed {seed}, {mode}): {description}"),
        Event::Live {
            address,
            by_recorder_process,
        } => {
            let by = if by_recorder_process {
                "; the recorder process serves it"
            } else {
                ""
            };
            eprintln!("  live view: ws://{address} (Foxglove: Open connection{by})");
        }
        Event::Progress {
            t_s,
            state,
            to_pad_m,
        } => {
            let d = to_pad_m.map_or("-".to_string(), |d| format!("{d:.2} m"));
            let line = format!("[{t_s:6.1} s] {:<13} to pad {d}", state.name());
            if tty {
                eprint!("\r{line}   ");
                let _ = std::io::stderr().flush();
            } else if (t_s as u64).is_multiple_of(10) {
                eprintln!("{line}");
            }
        }
    })?;
    if tty {
        eprintln!();
    }
    if let Some(dir) = &flown.log_dir {
        eprintln!("  process logs: {}", dir.display());
    }
    for t in &flown.transitions {
        eprintln!(
            "  {:7.2} s  {:>13} -> {:<13} {}",
            t.at_ns as f64 * 1e-9,
            t.from.name(),
            t.to.name(),
            t.reason
        );
    }
    for t in &flown.eval.touchdowns {
        eprintln!(
            "  {:7.2} s  touchdown on the {} {:.3} m from the pad centre at {:.2} m/s down, {:.2} m/s sideways, tilt {:.1} deg ({})",
            t.t_s,
            if t.on_pad { "pad" } else { "ground" },
            t.error_m,
            t.vertical_mps,
            t.horizontal_mps,
            t.tilt_deg,
            t.phase.name()
        );
    }
    for c in &flown.eval.crashes {
        eprintln!("  crash: {c}");
    }
    let summary = &flown.summary;
    eprintln!("  referee: {}: {}", flown.outcome, summary.referee);
    for f in &summary.faults {
        eprintln!("  fault: {} {} at {:.2} s", f.fault, f.process, f.at_s);
    }
    if let Some(dir) = &args.plot {
        let mut written = plot::write_plots(dir, &flown.log)?;
        if !flown.planning_ms.is_empty() {
            let p = dir.join("planning_ms.png");
            plot::write_histogram(&p, "planning time per call (ms)", &flown.planning_ms)?;
            written.push(p);
        }
        for p in written {
            eprintln!("  plot: {}", p.display());
        }
    }
    for (path, n) in &flown.recordings {
        match n {
            Some(n) => eprintln!("  recording: {} ({n} messages)", path.display()),
            None => eprintln!("  recording: {} (the recorder process)", path.display()),
        }
    }
    if args.json {
        println!("{}", serde_json::to_string(summary)?);
    } else {
        println!("{summary}");
    }
    Ok(flown.outcome == Outcome::Landed)
}
