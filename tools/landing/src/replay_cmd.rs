//! `landing replay run.mcap --stage aruco-pnp`: runs one stage again on the inputs a
//! recording holds, through the stage's own library, and compares what it publishes with
//! what it published in flight.
//!
//! aruco-pnp: every recorded vehicle state and every raw camera frame (`--raw-images`
//! recordings: a JPEG frame is not the frame the stage saw) is handed to a new
//! `ArucoStage`, built as `landing run` builds it (`run_lockstep::stage_for`) from the
//! flight's config (the recording's metadata) and the scenario's calibration and pad, in the order the flight's stage saw them: each frame
//! at the time the flight's aruco-pnp took it (its stamp on the observation), after every
//! state px4-link had published by then. Each observation is compared, field by field and
//! bit for bit, with the recorded one of the same capture time; the stage stamps (times
//! on this machine, not results) are left out.

use std::collections::{BTreeMap, HashMap};
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;
use foxglove::Decode;
use foxglove::schemas::RawImage;
use ipc_types::msg::{CameraFrameHeader, Header, PadObservation, Stage as StageId, VehicleState};
use serde::Serialize;
use serde_json::Value;
use stage::{Input, Message, Outbox, SliceHeader, SliceMut, StageError};

use crate::config_cmd::StackConfig;

/// Arguments of `landing replay`.
#[derive(Debug, Args)]
pub struct ReplayArgs {
    /// The recording (made with --raw-images for aruco-pnp).
    #[arg(value_name = "FILE.mcap")]
    pub(crate) file: PathBuf,
    /// The stage to run again: aruco-pnp (a --raw-images recording), depth-map, planner
    /// or fsm.
    #[arg(long)]
    pub(crate) stage: String,
    /// The deploy directory (scenarios, calibrations; default: found as `landing run`
    /// finds it).
    #[arg(long)]
    pub(crate) deploy_dir: Option<PathBuf>,
    /// Run the stage with this stack configuration instead of the flight's (its
    /// metadata): what the change would have done to the flight's outputs, on the same
    /// inputs.
    #[arg(long, value_name = "FILE.toml")]
    pub(crate) config: Option<PathBuf>,
    /// Print the result as JSON.
    #[arg(long)]
    pub(crate) json: bool,
}

/// How a replay compared with the flight.
#[derive(Debug, Clone, Serialize)]
pub struct ReplayReport {
    /// The stage.
    pub stage: String,
    /// Inputs handed over.
    pub inputs: u64,
    /// Outputs the flight recorded.
    pub recorded: u64,
    /// Outputs the replay made.
    pub replayed: u64,
    /// Recorded outputs the replay made bit for bit.
    pub identical: u64,
    /// Recorded outputs the replay made differently.
    pub different: u64,
    /// The first few of them, with the first field that differs.
    pub differences: Vec<String>,
    /// Recorded outputs the replay did not make (capture times).
    pub missing: Vec<u64>,
    /// Outputs the replay made that the flight did not record.
    pub extra: u64,
    /// The flight's outputs compared, for people (the fsm: its transitions; empty for
    /// stages with many outputs).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub flown: Vec<String>,
}

/// The exit of `stage`'s stamp in `h`.
pub(crate) fn exit_of(h: &Header, stage: StageId) -> Option<u64> {
    h.stages()
        .iter()
        .find(|s| s.stage == stage as u32)
        .map(|s| s.exit_ns)
}

/// The enter of `stage`'s stamp in `h`.
pub(crate) fn enter_of(h: &Header, stage: StageId) -> Option<u64> {
    h.stages()
        .iter()
        .find(|s| s.stage == stage as u32)
        .map(|s| s.enter_ns)
}

/// Collects the observations the replayed stage publishes.
#[derive(Default)]
struct Collect {
    observations: Vec<PadObservation>,
}

impl Outbox for Collect {
    fn publish(&mut self, _topic: &str, msg: Message<'_>) -> Result<(), StageError> {
        if let Message::PadObservation(o) = msg {
            self.observations.push(*o);
        }
        Ok(())
    }

    fn publish_slice(
        &mut self,
        _topic: &str,
        _len: usize,
        _fill: &mut dyn FnMut(SliceMut<'_>) -> Option<SliceHeader>,
    ) -> Result<bool, StageError> {
        Ok(false)
    }
}

/// An observation's results as JSON, without its stage stamps.
fn results(o: &PadObservation) -> Result<Value> {
    let mut v = serde_json::to_value(o)?;
    if let Some(m) = v.as_object_mut() {
        m.remove("msg");
    }
    v["capture_ns"] = o.msg.capture_ns.into();
    Ok(v)
}

/// The first field where two JSON values differ.
pub(crate) fn first_difference(a: &Value, b: &Value, at: &str) -> Option<String> {
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => {
            for (k, va) in x {
                let d =
                    first_difference(va, y.get(k).unwrap_or(&Value::Null), &format!("{at}.{k}"));
                if d.is_some() {
                    return d;
                }
            }
            None
        }
        (Value::Array(x), Value::Array(y)) => {
            for (i, (va, vb)) in x.iter().zip(y).enumerate() {
                let d = first_difference(va, vb, &format!("{at}[{i}]"));
                if d.is_some() {
                    return d;
                }
            }
            (x.len() != y.len()).then(|| format!("{at}: {} against {} items", x.len(), y.len()))
        }
        _ => (a != b).then(|| format!("{at}: {a} replayed, {b} in flight")),
    }
}

/// The flight a recording holds, as its metadata tells: the config, the scenario and the
/// seed it flew with, to build a stage as `landing run` built it.
pub(crate) struct Flight {
    deploy: PathBuf,
    config: StackConfig,
    scenario: sim::scenario::LoadedScenario,
    seed: u64,
}

impl Flight {
    /// The flight of the recording `args.file`, whose reading gave `summary`.
    pub(crate) fn of(args: &ReplayArgs, summary: &recorder::ReadSummary) -> Result<Self> {
        if let Some(b) = &summary.broken {
            bail!("{}: {b}", args.file.display());
        }
        let deploy = args
            .deploy_dir
            .clone()
            .unwrap_or_else(stack_config::deploy_dir);
        let meta = summary.metadata.get("landing").cloned().unwrap_or_default();
        let config: StackConfig = match (&args.config, meta.get("config")) {
            (Some(path), _) => stack_config::load(path)?,
            (None, Some(text)) => stack_config::parse(text, &args.file)
                .context("the recording's config (metadata)")?,
            (None, None) => bail!(
                "{}: no config in its metadata (give one with --config)",
                args.file.display()
            ),
        };
        let name = meta.get("scenario").map_or("paper-sim", String::as_str);
        let scenario = sim::scenario::load(name, &deploy)?;
        let seed = meta.get("seed").and_then(|s| s.parse().ok()).unwrap_or(1);
        Ok(Self {
            deploy,
            config,
            scenario,
            seed,
        })
    }

    /// The graph node `name`'s stage, built as `landing run` builds it
    /// (`run_lockstep::stage_for`).
    pub(crate) fn stage(&self, name: &str) -> Result<Option<Box<dyn stage::Stage>>> {
        let graph = graph::Graph::load(&graph::default_path(&self.deploy))?;
        let Some(node) = graph.node(name) else {
            bail!("the graph has no {name} node");
        };
        let setup = crate::run_lockstep::Setup {
            scenario: &self.scenario,
            seed: self.seed,
            config: &self.config,
            fsm: crate::run_lockstep::mission(&self.config, &self.scenario)?,
        };
        crate::run_lockstep::stage_for(node, &setup)
    }
}

/// One input event of the replay, in the order the flight's stage met them.
enum Event {
    State(VehicleState),
    Frame(CameraFrameHeader, Vec<u8>),
}

/// Replays aruco-pnp.
fn replay_aruco(args: &ReplayArgs) -> Result<ReplayReport> {
    let mut states: Vec<(u64, VehicleState)> = vec![];
    let mut headers: HashMap<u64, CameraFrameHeader> = HashMap::new();
    let mut images: Vec<RawImage> = vec![];
    // The recorded observations, by capture time: their JSON and the flight's header.
    let mut recorded: BTreeMap<u64, (Value, Header)> = BTreeMap::new();
    let mut jpeg = false;
    let summary = recorder::read_recording(&args.file, |m| {
        match (m.topic, m.schema) {
            ("/vehicle/state", _) => {
                let s: VehicleState = m.decode()?;
                // When px4-link published it.
                let at = exit_of(&s.msg, StageId::Px4Link).unwrap_or(m.log_time);
                states.push((at, s));
            }
            ("/camera/frame/header", _) => {
                let h: CameraFrameHeader = m.decode()?;
                headers.insert(h.msg.capture_ns, h);
            }
            ("/camera/frame", "foxglove.RawImage") => images.push(RawImage::decode(m.data)?),
            ("/camera/frame", _) => jpeg = true,
            ("/pad/observation", _) => {
                let v: Value = serde_json::from_slice(m.data)?;
                let h = m.header()?;
                recorded.insert(h.capture_ns, (v, h));
            }
            _ => {}
        }
        Ok(())
    })?;
    let flight = Flight::of(args, &summary)?;
    if images.is_empty() {
        if jpeg {
            bail!(
                "{}: its camera frames are JPEG, not the frames aruco-pnp saw: record with --raw-images to replay aruco-pnp",
                args.file.display()
            );
        }
        bail!("{}: no camera frames (/camera/frame)", args.file.display());
    }
    let Some(mut stage) = flight.stage("aruco-pnp")? else {
        bail!("no stage for aruco-pnp");
    };

    // Frames at the time the flight's stage took them: its stamp on the observation, else
    // (no observation came of it) when camera-ingest published it.
    let mut events: Vec<(u64, u8, Event)> = vec![];
    for img in images {
        let ns = img.timestamp.map_or(0, |t| {
            u64::from(t.sec()) * 1_000_000_000 + u64::from(t.nsec())
        });
        let Some(h) = headers.get(&ns).copied() else {
            continue;
        };
        let at = recorded
            .get(&ns)
            .and_then(|(_, h)| enter_of(h, StageId::ArucoPnp))
            .or_else(|| exit_of(&h.msg, StageId::CameraIngest))
            .unwrap_or(ns);
        events.push((at, 1, Event::Frame(h, img.data.to_vec())));
    }
    for (at, s) in states {
        events.push((at, 0, Event::State(s)));
    }
    // States first at a tie: the stage reads them first (deploy/graph.toml).
    events.sort_by_key(|(at, kind, _)| (*at, *kind));
    let mut out = Collect::default();
    let mut inputs = 0;
    for (at, _, e) in &events {
        inputs += 1;
        let msg = match e {
            Event::State(s) => Message::VehicleState(s),
            Event::Frame(h, px) => Message::CameraFrame(h, px),
        };
        let topic = match e {
            Event::State(_) => ipc_types::topics::VEHICLE_STATE,
            Event::Frame(..) => ipc_types::topics::CAMERA_FRAME,
        };
        stage.on_input(*at, Input { topic, msg }, &mut out)?;
        stage.on_inputs_done(*at, &mut out)?;
    }
    let mut report = ReplayReport {
        stage: args.stage.clone(),
        inputs,
        recorded: recorded.len() as u64,
        replayed: out.observations.len() as u64,
        identical: 0,
        different: 0,
        differences: vec![],
        missing: vec![],
        extra: 0,
        flown: vec![],
    };
    let mut replayed: HashMap<u64, Value> = HashMap::new();
    for o in &out.observations {
        replayed.insert(o.msg.capture_ns, results(o)?);
    }
    for (capture, (v, _)) in &recorded {
        let mut flight = v.clone();
        if let Some(m) = flight.as_object_mut() {
            m.remove("msg");
        }
        flight["capture_ns"] = (*capture).into();
        match replayed.remove(capture) {
            None => report.missing.push(*capture),
            Some(r) => match first_difference(&r, &flight, "") {
                None => report.identical += 1,
                Some(d) => {
                    report.different += 1;
                    if report.differences.len() < 10 {
                        report.differences.push(format!("capture {capture}: {d}"));
                    }
                }
            },
        }
    }
    report.extra = replayed.len() as u64;
    Ok(report)
}

/// Runs `landing replay`; fails when the replay did not reproduce the flight.
pub fn run(args: &ReplayArgs) -> Result<bool> {
    let report = match args.stage.as_str() {
        "aruco-pnp" => replay_aruco(args)?,
        "fsm" => crate::replay_fsm::replay(args)?,
        "depth-map" => crate::replay_depth::replay(args)?,
        "planner" => crate::replay_planner::replay(args)?,
        other => bail!("--stage {other}: allowed: aruco-pnp, depth-map, planner, fsm"),
    };
    let differing = report.different;
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!(
            "replay {}: {} inputs; {} outputs in flight, {} replayed: {} identical, {differing} different, {} missing, {} extra",
            report.stage,
            report.inputs,
            report.recorded,
            report.replayed,
            report.identical,
            report.missing.len(),
            report.extra
        );
        for f in &report.flown {
            println!("  in flight: {f}");
        }
        for d in &report.differences {
            println!("  {d}");
        }
    }
    Ok(differing == 0 && report.missing.is_empty() && report.extra == 0)
}
