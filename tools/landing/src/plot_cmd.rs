//! `landing plot run.mcap --out DIR`: the plots `landing run --plot` draws, from a
//! recording.
//!
//! With the truth file `landing run` wrote beside the recording (`FILE.truth.mcap`), the
//! recorded fsm statuses and truth go through the same referee `landing run` uses, in the
//! order they were logged, so the plots are the run's. Without one (a real flight), the
//! plots show what the stack believed: the vehicle's estimated state from px4-link and
//! the pad as the fsm's filter estimated it, and no touchdown.

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use clap::Args;
use ipc_types::msg::{MissionState, Stage as StageId, VehicleState};
use ipc_types::topics;

use crate::flight_log::{FlightLog, FlightSample};
use crate::plot;
use crate::run_eval::{Referee, stage_ms};

/// Arguments of `landing plot`.
#[derive(Debug, Args)]
pub struct PlotArgs {
    /// The recording (`landing run --record FILE.mcap`, or the recorder's file of a
    /// flight).
    #[arg(value_name = "FILE.mcap")]
    file: PathBuf,
    /// Where the plots go (created if missing).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// The simulator's truth (default: FILE.truth.mcap beside the recording, when it is
    /// there). Without it the plots show the stack's estimates.
    #[arg(long, value_name = "FILE.truth.mcap")]
    truth: Option<PathBuf>,
    /// The deploy directory, for the scenario's obstacles (default: found as `landing
    /// run` finds it).
    #[arg(long)]
    deploy_dir: Option<PathBuf>,
}

/// One message that matters to the plots, at its log time.
enum Event {
    Status(ipc_types::msg::FsmStatus),
    State(VehicleState),
    Truth(ipc_types::msg::TruthEvent),
    TruthState(ipc_types::msg::TruthState),
}

/// What the files hold for the plots.
#[derive(Default)]
struct Read {
    events: Vec<(u64, Event)>,
    planning_ms: Vec<f64>,
    scenario: Option<String>,
    seed: u64,
    lockstep: bool,
}

/// Reads the messages of `path` the plots need into `read`.
fn read_file(path: &Path, read: &mut Read) -> Result<()> {
    let summary = recorder::read_recording(path, |m| {
        if m.encoding != "json" {
            return Ok(());
        }
        let topic = m.topic.trim_start_matches('/');
        let event = match topic {
            topics::FSM_STATUS => Event::Status(m.decode()?),
            topics::VEHICLE_STATE => Event::State(m.decode()?),
            topics::SIM_TRUTH => Event::Truth(m.decode()?),
            topics::SIM_TRUTH_STATE => Event::TruthState(m.decode()?),
            topics::PLANNER_STATS => {
                if let Some(ms) = stage_ms(&m.header()?, StageId::Planner) {
                    read.planning_ms.push(ms);
                }
                return Ok(());
            }
            _ => return Ok(()),
        };
        read.events.push((m.log_time, event));
        Ok(())
    })?;
    if let Some(b) = &summary.broken {
        // What was read is plotted; the damage is named.
        eprintln!("  {}: {b}", path.display());
    }
    if let Some(meta) = summary.metadata.get("landing") {
        if let Some(s) = meta.get("scenario") {
            read.scenario = Some(s.clone());
        }
        if let Some(s) = meta.get("seed").and_then(|s| s.parse().ok()) {
            read.seed = s;
        }
        if meta.get("mode").is_some_and(|m| m == "lockstep") {
            read.lockstep = true;
        }
    }
    Ok(())
}

/// The flight log of a recording with its truth: the referee of `landing run`.
fn from_truth(read: &Read, name: &str, obstacles: Vec<([f64; 3], [f64; 3])>) -> FlightLog {
    let mut referee = Referee::new(0);
    for (_, e) in &read.events {
        match e {
            Event::Status(s) => referee.on_status(s),
            Event::Truth(t) => referee.on_truth(t),
            Event::TruthState(s) => referee.on_truth_state(s),
            Event::State(_) => {}
        }
    }
    referee.eval.flight_log(name, read.seed, obstacles)
}

/// At most this often a sample of the estimates, s (the truth's 20 Hz).
const SAMPLE_PERIOD_S: f64 = 0.05;

/// The flight log of a recording without truth: the stack's estimates.
fn from_estimates(read: &Read, name: &str, obstacles: Vec<([f64; 3], [f64; 3])>) -> FlightLog {
    let mut log = FlightLog {
        scenario: name.to_string(),
        seed: read.seed,
        obstacles,
        ..FlightLog::default()
    };
    let Some(t0) = read.events.first().map(|(t, _)| *t) else {
        return log;
    };
    let mut phase = MissionState::Idle;
    let mut pad: Option<([f64; 3], [f64; 3])> = None;
    for (at, e) in &read.events {
        match e {
            Event::Status(s) => {
                phase = MissionState::from_raw(s.state).unwrap_or(phase);
                let finite = s
                    .pad_position
                    .iter()
                    .chain(&s.pad_velocity)
                    .all(|x| x.is_finite());
                if s.pad_valid != 0 && finite {
                    pad = Some((s.pad_position, s.pad_velocity));
                }
            }
            Event::State(s) => {
                let t_s = at.saturating_sub(t0) as f64 * 1e-9;
                let due = log
                    .samples
                    .last()
                    .is_none_or(|l| t_s - l.t_s >= SAMPLE_PERIOD_S);
                let finite =
                    s.world_from_body.is_finite() && s.velocity.iter().all(|x| x.is_finite());
                if due && finite {
                    log.samples.push(FlightSample {
                        t_s,
                        uav: s.world_from_body.translation,
                        ugv_pad: pad.map(|p| p.0),
                        phase: phase.name().to_string(),
                        uav_velocity: s.velocity,
                        ugv_velocity: pad.map(|p| p.1),
                    });
                }
            }
            Event::Truth(_) | Event::TruthState(_) => {}
        }
    }
    log
}

/// Runs `landing plot`.
pub fn run(args: &PlotArgs) -> Result<()> {
    let beside = args.file.with_extension("truth.mcap");
    let truth = match &args.truth {
        Some(t) => Some(t.clone()),
        None => beside.exists().then_some(beside),
    };
    let mut read = Read::default();
    if let Some(t) = &truth {
        read_file(t, &mut read)?;
    }
    read_file(&args.file, &mut read)?;
    // Both files log on one clock (lockstep: simulated; processes: monotonic). A stable
    // sort keeps each file's order at a tie, the truth first: the simulator steps first
    // at a lockstep instant.
    read.events.sort_by_key(|(t, _)| *t);
    let deploy = args
        .deploy_dir
        .clone()
        .unwrap_or_else(stack_config::deploy_dir);
    let obstacles = match &read.scenario {
        Some(name) => match sim::scenario::load(name, &deploy) {
            Ok(s) => s
                .obstacles(read.seed)
                .iter()
                .map(|b| (b.min_m, b.max_m))
                .collect(),
            Err(e) => {
                eprintln!("  no obstacles drawn: {e}");
                vec![]
            }
        },
        None => vec![],
    };
    let name = read.scenario.clone().unwrap_or_else(|| "flight".into());
    let log = if truth.is_some() {
        from_truth(&read, &name, obstacles)
    } else {
        let estimated = format!("{name}, the stack's estimates (no truth file)");
        from_estimates(&read, &estimated, obstacles)
    };
    if log.samples.is_empty() {
        bail!(
            "{}: nothing to plot (no {} messages)",
            args.file.display(),
            if truth.is_some() {
                "sim/truth_state"
            } else {
                "vehicle/state"
            }
        );
    }
    let mut written = plot::write_plots(&args.out, &log)?;
    // In lockstep the planner's stamp is its modelled latency, not its compute.
    if !read.planning_ms.is_empty() && !read.lockstep {
        let p = args.out.join("planning_ms.png");
        plot::write_histogram(&p, "planning time per call (ms)", &read.planning_ms)?;
        written.push(p);
    }
    if let Some(t) = &truth {
        eprintln!("  truth: {}", t.display());
    }
    for p in written {
        println!("{}", p.display());
    }
    Ok(())
}
