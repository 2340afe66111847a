//! `landing run` in one process: the graph's stages (the simulator, px4-link,
//! camera-ingest, aruco-pnp, depth-map, planner, fsm) on the lockstep driver, on
//! simulated time. Each gets its inputs when the graph says, and its outputs reach their
//! readers after the node's modelled processing time (`latency_ms`; the time a call
//! really took is measured and reported, not simulated: a seed flies the same on every
//! machine). MAVLink goes through its wire encoding both ways, as on a socket. The
//! pipeline sees only telemetry and sensor data; the ground truth goes to the referee.

use anyhow::{Context, Result, bail};
use aruco_pnp::ArucoStage;
use camera_ingest::IngestStage;
use depth_map::DepthStage;
use fsm::{FsmConfig, FsmStage};
use graph::{Graph, Node};
use ipc_types::msg::MissionState;
use ipc_types::topics;
use optics::{CameraCalibration, PadModel};
use planner::PlannerStage;
use px4_link::{Framing, LinkStage};
use sim::scenario::LoadedScenario;
use sim::stage::{Pace, SimStage};
use stage::lockstep::{Lockstep, Published};
use stage::{Message, Stage};

use crate::config::StackConfig;
use evaluation::{End, Referee};
use recorder::Recorder;

/// The Unix time at a lockstep run's time 0 (2026-09-15T00:00:00Z): signing timestamps
/// without a wall clock, the same on every run.
pub const LOCKSTEP_UNIX_NS_AT_ZERO: u64 = 1_789_430_400_000_000_000;

/// What the lockstep run needs to build its stages.
pub struct Setup<'a> {
    /// The scenario.
    pub scenario: &'a LoadedScenario,
    /// Seed of the simulator.
    pub seed: u64,
    /// The stack configuration.
    pub config: &'a StackConfig,
    /// The mission (the scenario's preset and commit height applied).
    pub fsm: FsmConfig,
}

/// The mission of `scenario` under `config`: the fsm section with the scenario's preset
/// point and commit height, checked.
pub fn mission(config: &StackConfig, scenario: &LoadedScenario) -> Result<FsmConfig> {
    let mut fsm = config.fsm.clone();
    fsm.preset_m = scenario.scenario.mission.preset_m;
    fsm.commit_height_m = scenario.scenario.mission.commit_height_m;
    // The lower of the configured ceiling and the camera's, as `fsm --search-height-max`.
    fsm.lower_search_ceiling(search_height_max_m(scenario)?);
    if let Err(e) = stack_config::Validate::validate(&fsm) {
        bail!(
            "scenario {} gives the mission fsm.{}: {}",
            scenario.scenario.name,
            e.key,
            e.message
        );
    }
    Ok(fsm)
}

/// The highest the mission of `scenario` may search from: where the camera it flies
/// still reads the pad's largest marker.
pub fn search_height_max_m(scenario: &LoadedScenario) -> Result<f64> {
    let camera = CameraCalibration::load(scenario.calibration_path())?;
    let pad = PadModel::load(scenario.pad_path())?;
    Ok(pad.detection_depth_m(camera.fx.min(camera.fy)))
}

/// The stage of one graph node, built from the stack configuration and the scenario
/// through the stage's one constructor (`from_config`, as its binary builds it); `None`
/// for a node the stack has no stage for. Where the deployment reads a file the config
/// names (the camera's calibration, the pad), lockstep reads the scenario's: the camera
/// the simulator renders.
pub fn stage_for(node: &Node, setup: &Setup<'_>) -> Result<Option<Box<dyn Stage>>> {
    let cfg = setup.config;
    let scn = setup.scenario;
    let camera = || CameraCalibration::load(scn.calibration_path());
    Ok(Some(match node.name.as_str() {
        "sim" => Box::new(
            SimStage::from_config(scn, setup.seed, Pace::Lockstep, None)
                .context("building the simulator")?
                .with_signing(cfg.signing_key()?, LOCKSTEP_UNIX_NS_AT_ZERO),
        ),
        "px4-link" => Box::new(LinkStage::from_config(
            &cfg.px4_link,
            Framing::Datagram,
            cfg.signing_key()?,
            LOCKSTEP_UNIX_NS_AT_ZERO,
        )),
        "camera-ingest" => {
            let section = cfg.camera_ingest.clone().unwrap_or_default();
            Box::new(IngestStage::from_config(&section, camera()?).context("undistortion maps")?)
        }
        "aruco-pnp" => Box::new(ArucoStage::from_config(
            &cfg.aruco_pnp,
            camera()?,
            PadModel::load(scn.pad_path())?,
        )?),
        "depth-map" => Box::new(DepthStage::from_config(&cfg.depth_map)?),
        "planner" => Box::new(PlannerStage::from_config(&cfg.planner)),
        "fsm" => Box::new(FsmStage::from_config(&setup.fsm)),
        // In lockstep no process can die or hang: it watches the data paths only.
        "watchdog" => Box::new(watchdog::WatchdogStage::from_config(&cfg.watchdog, &[])?),
        _ => return Ok(None),
    }))
}

/// The lockstep driver over every node of `graph`, in its same-instant order; `extra`
/// builds stages for nodes the stack does not know (a new stage, a test's stage).
pub fn driver(
    graph: &Graph,
    setup: &Setup<'_>,
    mut extra: impl FnMut(&Node) -> Option<Box<dyn Stage>>,
) -> Result<Lockstep> {
    let mut stages = Vec::new();
    for node in graph.step_order() {
        let stage = match stage_for(node, setup)? {
            Some(s) => s,
            None => match extra(node) {
                Some(s) => s,
                None => bail!(
                    "graph node `{}` has no stage to run in lockstep (known: sim, px4-link, camera-ingest, aruco-pnp, depth-map, planner, fsm, watchdog)",
                    node.name
                ),
            },
        };
        stages.push((node.spec(), stage));
    }
    Ok(Lockstep::new(stages)?)
}

/// Runs the mission on `driver` to its end or `duration_s`; `progress` is called about
/// once per simulated second. `paced`: simulated time never runs ahead of the wall clock
/// (a live view watches it as it would a flight).
pub fn run(
    driver: &mut Lockstep,
    duration_s: f64,
    referee: &mut Referee,
    rec: &mut Recording,
    paced: bool,
    mut progress: impl FnMut(f64, MissionState, Option<f64>),
) -> Result<End> {
    let end_ns = (duration_s * 1e9) as u64;
    let started = std::time::Instant::now();
    let mut next_progress = 0u64;
    let mut failure: Option<anyhow::Error> = None;
    loop {
        let step = driver.step(&mut |p: &Published<'_>| {
            if failure.is_none()
                && let Err(e) = observe(p, referee, rec)
            {
                failure = Some(e);
            }
        })?;
        if let Some(e) = failure {
            return Err(e);
        }
        let Some(now) = step else {
            bail!("the lockstep driver ran out of work (no stage ticks)");
        };
        if paced {
            let ahead = std::time::Duration::from_nanos(now).saturating_sub(started.elapsed());
            if !ahead.is_zero() {
                std::thread::sleep(ahead);
            }
        }
        if let Some(end) = referee.finished() {
            return Ok(end);
        }
        if now >= end_ns {
            return Ok(End::Timeout);
        }
        if runtime::shutdown::requested() {
            return Ok(End::Interrupted);
        }
        if now >= next_progress {
            next_progress = now + 1_000_000_000;
            progress(now as f64 * 1e-9, referee.phase, referee.distance_to_pad());
        }
    }
}

/// One published message: to the recording and, for the topics it reads, the referee.
fn observe(p: &Published<'_>, referee: &mut Referee, rec: &mut Recording) -> Result<()> {
    match p.msg {
        Message::FsmStatus(s) => referee.on_status(s),
        // The compute time this machine took, not the modelled latency.
        Message::PlannerStats(s) => referee.on_planner_stats(s, p.wall_ns as f64 * 1e-6),
        Message::TruthEvent(t) => referee.on_truth(t),
        Message::TruthState(s) => referee.on_truth_state(s),
        _ => {}
    }
    rec.record(p.topic, p.now_ns, &p.msg)
}

/// The recordings of a run (simulated time): the pipeline's, as the `recorder` process
/// writes it (every topic but ground truth and `[recorder] skip`, with the same code),
/// and the evaluator's truth in a file of its own.
#[derive(Default)]
pub struct Recording {
    /// The pipeline's recording.
    pub pipeline: Option<Recorder>,
    /// Ground truth (the simulator's evaluator-only topics).
    pub truth: Option<Recorder>,
    /// Topics the pipeline's recording leaves out.
    pub skip: Vec<String>,
}

impl Recording {
    /// Records `msg` (published on `topic`) in the recording it belongs to.
    pub fn record(&mut self, topic: &str, now_ns: u64, msg: &Message<'_>) -> Result<()> {
        let evaluator = topics::find(topic).is_some_and(|t| t.evaluator_only);
        let to = if evaluator {
            self.truth.as_mut()
        } else if self.skip.iter().any(|s| s == topic) {
            None
        } else {
            self.pipeline.as_mut()
        };
        if let Some(r) = to {
            r.record(topic, now_ns, msg)?;
        }
        Ok(())
    }
}
