//! `landing run`: one whole autonomous landing mission in the simulator, with a
//! progress line, a summary, and optionally JSON, plots and a recording.

use std::io::{IsTerminal, Write};
use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use ipc_types::msg::MissionState;
use stack_config::deploy_dir;

use crate::config_cmd::StackConfig;
use crate::flight_log::{
    FlightLog, FlightSample, Outcome, RunSummary, Touchdown, TouchdownContact,
};
use crate::plot;
use crate::run_eval::{self, Evaluator, Referee, Rules};
use crate::run_lockstep::{self, Recording};
use crate::run_processes;
use recorder::Recorder;

/// Where the evaluator's ground truth of a run recorded in `pipeline` goes: `run.mcap`
/// -> `run.truth.mcap`.
pub fn truth_path(pipeline: &std::path::Path) -> PathBuf {
    let stem = pipeline
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "recording".into());
    pipeline.with_file_name(format!("{stem}.truth.mcap"))
}

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
    inject: Vec<crate::inject::Injection>,
}

/// The evaluator's record as the flight log the summary and the plots read.
pub(crate) fn flight_log(
    name: &str,
    seed: u64,
    eval: &Evaluator,
    obstacles: Vec<([f64; 3], [f64; 3])>,
) -> FlightLog {
    let samples = eval
        .samples
        .iter()
        .map(|s| FlightSample {
            t_s: s.t_s,
            uav: s.uav,
            ugv_pad: s.pad,
            phase: s.phase.name().to_string(),
            uav_velocity: s.uav_velocity,
            ugv_velocity: s.pad_velocity,
        })
        .collect();
    let touchdown = eval.final_touchdown().map(|t| {
        let at = eval
            .samples
            .iter()
            .rev()
            .find(|s| s.t_s <= t.t_s)
            .or(eval.samples.last());
        Touchdown {
            t_s: t.t_s,
            uav: at.map_or([0.0; 3], |s| s.uav),
            pad: at.and_then(|s| s.pad).unwrap_or([0.0; 3]),
            error_m: t.error_m,
            rel_speed_mps: t.rel_speed_mps,
            on_pad: t.on_pad,
        }
    });
    let contact = eval.landing_contact().map(|t| TouchdownContact {
        vertical_speed_mps: t.vertical_mps,
        horizontal_speed_mps: t.horizontal_mps,
        tilt_deg: t.tilt_deg,
    });
    FlightLog {
        scenario: name.to_string(),
        seed,
        samples,
        obstacles,
        touchdown,
        contact,
    }
}

/// Runs the mission and reports; exit code 1 when it did not land on the pad.
pub fn run(args: &RunArgs, ipc_prefix: Option<&str>) -> Result<bool> {
    let deploy = args.deploy_dir.clone().unwrap_or_else(deploy_dir);
    let cfg_path = args
        .config
        .clone()
        .unwrap_or_else(|| deploy.join("config").join("landing.toml"));
    let cfg = StackConfig::load(&cfg_path)?;
    let scn = sim::scenario::load(&args.scenario, &deploy)?;
    // Both modes run what the graph declares; checked before anything starts.
    let graph_path = args
        .graph
        .clone()
        .unwrap_or_else(|| graph::default_path(&deploy));
    let graph = graph::Graph::load(&graph_path)?;
    // Faults go to processes of this graph, in the processes mode only.
    if !args.inject.is_empty() && !args.processes {
        anyhow::bail!("--inject needs --processes (faults are done to the stage processes)");
    }
    let mut injections = args.inject.clone();
    for i in &mut injections {
        i.resolve(&graph).map_err(anyhow::Error::msg)?;
    }
    let seed = args.seed.unwrap_or(scn.scenario.seed);
    let fsm_cfg = run_lockstep::mission(&cfg, &scn)?;
    let rules = Rules::of(&scn)?;
    let mut rec = Recording {
        skip: cfg.recorder.skip.clone(),
        ..Recording::default()
    };
    let mut meta = recorder::metadata::stack(Some(&cfg_path), &graph_path)?;
    meta.insert("scenario".into(), scn.scenario.name.clone());
    meta.insert("seed".into(), seed.to_string());
    meta.insert(
        "mode".into(),
        if args.processes {
            "processes"
        } else {
            "lockstep"
        }
        .into(),
    );
    if let Some(p) = &args.record {
        // As --plot does: a new directory for the outputs is made, not refused.
        if let Some(dir) = p.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("--record: cannot create {}", dir.display()))?;
        }
        let mut truth = Recorder::create(&truth_path(p))?;
        truth.write_metadata("landing", meta.clone())?;
        rec.truth = Some(truth);
    }
    let config_error =
        |e: stack_config::Invalid| anyhow::anyhow!("[recorder] {}: {}", e.key, e.message);
    // In lockstep this process records the pipeline and serves the live view, with the
    // recorder process's code; --processes starts that process for them.
    if !args.processes && (args.record.is_some() || args.live) {
        let mut options = cfg.recorder.options().map_err(config_error)?;
        if args.raw_images {
            options.images = recorder::ImageFormat::Raw;
        }
        // The mounts as the recorder process reads them.
        let text = std::fs::read_to_string(&cfg_path)
            .with_context(|| format!("reading {}", cfg_path.display()))?;
        (options.body_from_camera, options.body_from_depth) = recorder::config::mounts(&text)?;
        let mut pipeline = match &args.record {
            Some(p) => {
                let mut r = Recorder::with_options(p, options)?;
                r.write_metadata("landing", meta)?;
                r
            }
            None => Recorder::without_file(options),
        };
        if args.live {
            let at = pipeline.serve_live(cfg.recorder.live_socket().map_err(config_error)?)?;
            eprintln!("  live view: ws://{at} (Foxglove: Open connection)");
        }
        rec.pipeline = Some(pipeline);
    }
    if args.processes && args.live {
        let at = cfg.recorder.live_socket().map_err(config_error)?;
        eprintln!(
            "  live view: ws://{at} (Foxglove: Open connection; the recorder process serves it)"
        );
    }
    let tty = std::io::stderr().is_terminal();
    eprintln!(
        "run: {} (seed {seed}, {}): {}",
        scn.scenario.name,
        if args.processes {
            "processes"
        } else {
            "lockstep"
        },
        scn.scenario.description
    );
    let progress = |t: f64, state: MissionState, d: Option<f64>| {
        let d = d.map_or("-".to_string(), |d| format!("{d:.2} m"));
        let line = format!("[{t:6.1} s] {:<13} to pad {d}", state.name());
        if tty {
            eprint!("\r{line}   ");
            let _ = std::io::stderr().flush();
        } else if (t as u64).is_multiple_of(10) {
            eprintln!("{line}");
        }
    };
    // Ctrl-C and SIGTERM end the run as `interrupted`, with its summary, in both modes.
    runtime::shutdown::install();
    let mut died = None;
    let mut faults = Vec::new();
    let (end, referee) = if args.processes {
        let log_dir = args.log_dir.clone().unwrap_or_else(|| {
            std::env::temp_dir().join(format!("landing-run-{}", std::process::id()))
        });
        let launch = run_processes::Launch {
            scenario: &scn,
            seed,
            config: &cfg_path,
            deploy: &deploy,
            log_dir: &log_dir,
            ipc_prefix,
            graph: &graph,
            graph_path: &graph_path,
            injections: &injections,
            recorder: run_processes::RecorderLaunch {
                out: args.record.as_deref(),
                raw_images: args.raw_images,
                live: args.live,
            },
            signing_key: &cfg.px4_link.signing_key,
            realtime: args.realtime,
        };
        let r = run_processes::run(&launch, &mut rec.truth, progress)?;
        if tty {
            eprintln!();
        }
        eprintln!("  process logs: {}", log_dir.display());
        died = r.died;
        faults = r.faults;
        (r.end, r.referee)
    } else {
        let setup = run_lockstep::Setup {
            scenario: &scn,
            seed,
            config: &cfg,
            fsm: fsm_cfg,
        };
        let mut driver = run_lockstep::driver(&graph, &setup, |_| None)?;
        let mut referee = Referee::new(0);
        let end = run_lockstep::run(
            &mut driver,
            scn.scenario.duration_s,
            &mut referee,
            &mut rec,
            args.live,
            progress,
        )?;
        if tty {
            eprintln!();
        }
        (end, referee)
    };
    let last_state = referee.last_state().copied();
    let Referee {
        eval,
        stats,
        transitions,
        ..
    } = referee;
    for t in &transitions {
        eprintln!(
            "  {:7.2} s  {:>13} -> {:<13} {}",
            t.at_ns as f64 * 1e-9,
            t.from.name(),
            t.to.name(),
            t.reason
        );
    }
    for t in &eval.touchdowns {
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
    for c in &eval.crashes {
        eprintln!("  crash: {c}");
    }
    let obstacles = scn
        .scenario
        .obstacles
        .iter()
        .map(|b| (b.min_m, b.max_m))
        .collect();
    let log = flight_log(&scn.scenario.name, seed, &eval, obstacles);
    let (outcome, why) = run_eval::verdict(end, &eval, last_state.as_ref(), &rules);
    let why = died.unwrap_or(why);
    eprintln!("  referee: {outcome}: {why}");
    let replans = u32::try_from(stats.plans.saturating_sub(1)).unwrap_or(u32::MAX);
    let mut summary = RunSummary::from_log(
        &log,
        outcome,
        &stats.planning_ms,
        replans,
        Some(eval.collisions),
    );
    summary.referee = why;
    for f in &mut faults {
        f.outcome = outcome.name().to_string();
        eprintln!("  fault: {} {} at {:.2} s", f.fault, f.process, f.at_s);
    }
    summary.faults = faults;
    if let Some(dir) = &args.plot {
        let mut written = plot::write_plots(dir, &log)?;
        if !stats.planning_ms.is_empty() {
            let p = dir.join("planning_ms.png");
            plot::write_histogram(&p, "planning time per call (ms)", &stats.planning_ms)?;
            written.push(p);
        }
        for p in written {
            eprintln!("  plot: {}", p.display());
        }
    }
    for r in [rec.pipeline.take(), rec.truth.take()]
        .into_iter()
        .flatten()
    {
        let path = r.path().to_path_buf();
        let file = r.has_file();
        let n = r.finish()?;
        if !file {
            continue;
        }
        eprintln!("  recording: {} ({n} messages)", path.display());
    }
    if args.processes
        && let Some(p) = &args.record
    {
        eprintln!("  recording: {} (the recorder process)", p.display());
    }
    if args.json {
        println!("{}", serde_json::to_string(&summary)?);
    } else {
        println!("{summary}");
    }
    Ok(outcome == Outcome::Landed)
}
