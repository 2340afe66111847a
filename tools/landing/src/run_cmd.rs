//! `landing run`: one whole autonomous landing mission in the simulator, with a
//! progress line, a summary, and optionally JSON, plots and a recording.

use std::io::{IsTerminal, Write};
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use aruco_pnp::PadEstimator;
use clap::Args;
use depth_map::DepthMapper;
use fsm::{Fsm, state_name};
use ipc_types::msg::MissionState;
use ipc_types::runtime::config::{self as cfgload, Validate, deploy_dir};
use optics::mount::down_camera_from_body;
use optics::{CameraCalibration, PadModel};
use planner::PlannerNode;
use serde::Serialize;
use sim::lockstep::Simulator;

use crate::config_cmd::StackConfig;
use crate::run_eval::Evaluator;
use crate::run_lockstep::{self, End, Pipeline, RunStats};
use crate::run_processes;
use crate::stats::percentile;

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
    /// Print the summary as one JSON object on stdout.
    #[arg(long)]
    json: bool,
    /// Start every stage as its own OS process (sim, camera-ingest, aruco-pnp,
    /// depth-map, planner, fsm, px4-link) over iceoryx2 and MAVLink/UDP on the wall
    /// clock, as systemd does on the vehicle, instead of the one-process lockstep.
    #[arg(long)]
    processes: bool,
    /// --processes: where each process's log goes (default: a new directory under the
    /// system's temporary directory).
    #[arg(long, value_name = "DIR")]
    log_dir: Option<PathBuf>,
}

/// The end-of-run summary (the JSON fields).
#[derive(Debug, Clone, Serialize)]
pub struct RunSummary {
    scenario: String,
    seed: u64,
    outcome: &'static str,
    touchdown_error_m: Option<f64>,
    touchdown_rel_speed_mps: Option<f64>,
    flight_time_s: f64,
    distance_m: f64,
    target_speed_kmh: f64,
    uav_max_speed_kmh: f64,
    uav_avg_speed_kmh: f64,
    planning_time_ms_p50: Option<f64>,
    planning_time_ms_max: Option<f64>,
    replans: u64,
    collisions: u32,
}

fn summarize(name: &str, seed: u64, end: End, eval: &Evaluator, stats: &RunStats) -> RunSummary {
    let outcome = match end {
        End::Landed if eval.final_touchdown().is_some_and(|t| t.on_pad) => "landed",
        End::Landed | End::SafeLanded => "safe_landed",
        End::Crashed => "crashed",
        End::Timeout => "timeout",
    };
    let td = eval.final_touchdown();
    let airborne: Vec<_> = eval
        .samples
        .iter()
        .filter(|s| s.phase != MissionState::Idle)
        .collect();
    let t_end = td.map(|t| t.t_s).unwrap_or(f64::INFINITY);
    let flying: Vec<_> = airborne.iter().filter(|s| s.t_s <= t_end).collect();
    let flight_time_s = match (flying.first(), flying.last()) {
        (Some(a), Some(b)) => b.t_s - a.t_s,
        _ => 0.0,
    };
    let distance_m: f64 = flying
        .windows(2)
        .map(|w| {
            let (a, b) = (w[0].uav, w[1].uav);
            ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
        })
        .sum();
    let speed = |v: [f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    let uav_max = flying
        .iter()
        .map(|s| speed(s.uav_velocity))
        .fold(0.0, f64::max);
    let moving: Vec<f64> = eval
        .samples
        .iter()
        .filter_map(|s| s.pad_velocity.map(speed))
        .filter(|v| *v > 0.01)
        .collect();
    let target = if moving.is_empty() {
        0.0
    } else {
        moving.iter().sum::<f64>() / moving.len() as f64
    };
    let mut ms = stats.planning_ms.clone();
    ms.sort_by(f64::total_cmp);
    RunSummary {
        scenario: name.to_string(),
        seed,
        outcome,
        touchdown_error_m: td.map(|t| t.error_m),
        touchdown_rel_speed_mps: td.map(|t| t.rel_speed_mps),
        flight_time_s,
        distance_m,
        target_speed_kmh: target * 3.6,
        uav_max_speed_kmh: uav_max * 3.6,
        uav_avg_speed_kmh: if flight_time_s > 0.0 {
            distance_m / flight_time_s * 3.6
        } else {
            0.0
        },
        planning_time_ms_p50: (!ms.is_empty()).then(|| percentile(&ms, 50.0)),
        planning_time_ms_max: ms.last().copied(),
        replans: stats.plans.saturating_sub(1),
        collisions: eval.collisions,
    }
}

/// Runs the mission and reports; exit code 1 when it did not land on the pad.
pub fn run(args: &RunArgs) -> Result<bool> {
    let deploy = args.deploy_dir.clone().unwrap_or_else(deploy_dir);
    let cfg_path = args
        .config
        .clone()
        .unwrap_or_else(|| deploy.join("config").join("landing.toml"));
    let cfg: StackConfig = cfgload::load(&cfg_path)?;
    let scn = sim::scenario::load(&args.scenario, &deploy)?;
    let seed = args.seed.unwrap_or(scn.scenario.seed);
    let mut fsm_cfg = cfg.fsm.clone();
    fsm_cfg.preset_m = scn.scenario.mission.preset_m;
    fsm_cfg.commit_height_m = scn.scenario.mission.commit_height_m;
    if let Err(e) = fsm_cfg.validate() {
        bail!(
            "scenario {} gives the mission fsm.{}: {}",
            scn.scenario.name,
            e.key,
            e.message
        );
    }
    let mut eval = Evaluator::default();
    let tty = std::io::stderr().is_terminal();
    eprintln!(
        "run: {} (seed {seed}, {}): {}",
        scn.scenario.name,
        if args.processes { "processes" } else { "lockstep" },
        scn.scenario.description
    );
    let progress = |t: f64, state: MissionState, d: Option<f64>| {
        let d = d.map_or("-".to_string(), |d| format!("{d:.2} m"));
        let line = format!("[{t:6.1} s] {:<13} to pad {d}", state_name(state));
        if tty {
            eprint!("\r{line}   ");
            let _ = std::io::stderr().flush();
        } else if (t as u64) % 10 == 0 {
            eprintln!("{line}");
        }
    };
    let (end, stats, transitions) = if args.processes {
        let log_dir = args.log_dir.clone().unwrap_or_else(|| {
            std::env::temp_dir().join(format!("landing-run-{}", std::process::id()))
        });
        let launch = run_processes::Launch {
            scenario: &scn,
            seed,
            config: &cfg_path,
            deploy: &deploy,
            log_dir: &log_dir,
        };
        let r = run_processes::run(&launch, &mut eval, progress)?;
        if tty {
            eprintln!();
        }
        eprintln!("  process logs: {}", log_dir.display());
        r
    } else {
        let mut sim = Simulator::new(&scn, seed).context("building the simulator")?;
        let calibration = CameraCalibration::load(&scn.calibration_path())?;
        let pad = PadModel::load(&scn.pad_path())?;
        let estimator = PadEstimator::new(
            calibration,
            pad,
            down_camera_from_body(cfg.aruco_pnp.camera_position_in_body_m),
            cfg.aruco_pnp.settings(),
        )?;
        let mut pipe = Pipeline {
            estimator,
            mapper: DepthMapper::from_config(&cfg.depth_map)?,
            planner: PlannerNode::new(cfg.planner.clone()),
            fsm: Fsm::new(fsm_cfg),
            link: run_lockstep::link(),
        };
        let (end, stats) =
            run_lockstep::run(&mut sim, &mut pipe, scn.scenario.duration_s, &mut eval, progress)?;
        if tty {
            eprintln!();
        }
        (end, stats, pipe.fsm.transitions().to_vec())
    };
    for t in &transitions {
        eprintln!(
            "  {:7.2} s  {:>13} -> {:<13} {}",
            t.at_ns as f64 * 1e-9,
            state_name(t.from),
            state_name(t.to),
            t.reason
        );
    }
    for t in &eval.touchdowns {
        eprintln!(
            "  {:7.2} s  touchdown on the {} {:.3} m from the pad centre at {:.2} m/s ({}; pad estimate {} off)",
            t.t_s,
            if t.on_pad { "pad" } else { "ground" },
            t.error_m,
            t.rel_speed_mps,
            state_name(t.phase),
            t.estimate_error_m.map_or("-".into(), |e| format!("{e:.3} m"))
        );
    }
    for c in &eval.crashes {
        eprintln!("  crash: {c}");
    }
    let summary = summarize(&scn.scenario.name, seed, end, &eval, &stats);
    if args.json {
        println!("{}", serde_json::to_string(&summary)?);
    } else {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    }
    Ok(summary.outcome == "landed")
}
