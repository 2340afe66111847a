//! Replay: one stage of a recorded flight run again on the lockstep driver, fed from the
//! recording, its outputs compared with the flight's.
//!
//! The stage is built as `landing run` builds it ([`crate::lockstep::stage_for`], from
//! the flight's config in the recording's metadata or another one), and runs alone on
//! [`Lockstep`]: every recorded input is delivered with [`Lockstep::inject_at`] at the
//! time the flight's stage took it, and the stage steps with [`Lockstep::tick_at`] at
//! exactly the times the flight's stage stepped. When that was is read from the stamps
//! on what it read and published ([`plan`]: one short rule per stage); the driver, the
//! delivery and the comparison are the same for every stage. The stage runs without
//! its own clock and without the step it may take when its inputs are done (the
//! recorded steps are those steps): only the flight's schedule moves it.
//!
//! Outputs are compared by the flight's key (a capture time, a transition number, the
//! order of publishing), every field except the stage stamps, which are times on the
//! machine that ran it, not results; maps cell for cell.

mod plan;

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use foxglove::Decode;
use foxglove::schemas::RawImage;
use ipc_types::msg::{CameraFrameHeader, DepthFrameHeader, Header};
use ipc_types::topics;
use recorder::{Decoded, RecordedMaps, RecordedMessage};
use serde::Serialize;
use serde_json::Value;
use stage::lockstep::{InputSpec, Lockstep, NodeSpec};
use stage::{Input, Outbox, OwnedMessage, SliceHeader, Stage, StageError};

use crate::StackConfig;

/// The stages a recording can replay.
pub const STAGES: &[&str] = &["aruco-pnp", "depth-map", "planner", "fsm"];

/// What to replay.
#[derive(Debug, Clone)]
pub struct Request {
    /// The recording.
    pub file: PathBuf,
    /// The graph node whose stage runs again (one of [`STAGES`]).
    pub stage: String,
    /// The deploy directory (scenarios, calibrations, the graph).
    pub deploy: PathBuf,
    /// Another stack configuration than the flight's: what a change would have done.
    pub config: Option<PathBuf>,
}

/// How a replay compared with the flight.
#[derive(Debug, Clone, Serialize)]
pub struct ReplayReport {
    /// The stage.
    pub stage: String,
    /// Inputs delivered.
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
    /// Outputs the flight published that the recording lost (the recorder fell behind:
    /// gaps in the publisher's sequence numbers).
    pub lost: u64,
    /// Recorded outputs after the first lost one, not compared: what the lost one was
    /// made from is not in the recording, and a stage with memory (a map) carries it.
    pub not_compared: u64,
    /// The flight's outputs compared, for people (the fsm: its transitions; empty for
    /// stages with many outputs).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub flown: Vec<String>,
}

impl ReplayReport {
    /// What one output of the stage is called: map, trajectory, capture, transition.
    pub fn unit(&self) -> &'static str {
        plan::unit(&self.stage)
    }

    /// True when the replay made every recorded output, identical, and nothing else.
    pub fn reproduced(&self) -> bool {
        self.different == 0 && self.missing.is_empty() && self.extra == 0
    }
}

/// One recorded message of a stack topic.
struct Recorded {
    topic: &'static str,
    /// When the recorder took it, ns.
    log_time: u64,
    header: Header,
    msg: OwnedMessage,
}

/// What a recording holds for a replay: its stack messages (frames and maps with their
/// pixels and cells), in file order per kind.
#[derive(Default)]
struct Recording {
    messages: Vec<Recorded>,
    cameras: Vec<OwnedMessage>,
    /// Camera frames recorded as JPEG (not the frames the stage saw).
    jpeg: bool,
    depths: Vec<OwnedMessage>,
    maps: RecordedMaps,
}

/// Nanoseconds of a Foxglove timestamp.
fn ns_of(img: &RawImage) -> u64 {
    img.timestamp.map_or(0, |t| {
        u64::from(t.sec()) * 1_000_000_000 + u64::from(t.nsec())
    })
}

impl Recording {
    /// Reads `path`: the topics in `wanted` (short names), and the flight's metadata.
    fn read(path: &Path, wanted: &[&str]) -> Result<(Self, recorder::ReadSummary)> {
        let mut rec = Self::default();
        let (mut cam_headers, mut depth_headers) = (BTreeMap::new(), BTreeMap::new());
        let (mut cam_images, mut depth_images) = (Vec::new(), Vec::new());
        let want = |t: &str| wanted.contains(&t);
        let summary = recorder::read_recording(path, |m: &RecordedMessage<'_>| {
            let short = m.topic.trim_start_matches('/');
            if want(topics::MAP_OCCUPANCY) && rec.maps.take(m)? {
                return Ok(());
            }
            if m.schema == "foxglove.RawImage" && want(short) {
                let img = RawImage::decode(m.data)?;
                if short == topics::CAMERA_FRAME {
                    cam_images.push((ns_of(&img), img.data.to_vec()));
                } else if short == topics::SIM_DEPTH {
                    let depths: Vec<u16> = img
                        .data
                        .chunks_exact(2)
                        .map(|b| u16::from_le_bytes([b[0], b[1]]))
                        .collect();
                    depth_images.push((ns_of(&img), depths));
                }
                return Ok(());
            }
            if short == topics::CAMERA_FRAME
                && want(short)
                && m.schema == "foxglove.CompressedImage"
            {
                rec.jpeg = true;
            }
            if !m.stack_topic().is_some_and(|(info, _)| want(info.name)) {
                return Ok(());
            }
            let Some((topic, decoded)) = m.stack()? else {
                return Ok(());
            };
            match decoded {
                Decoded::Message(msg) => {
                    let header = msg_header(&msg);
                    rec.messages.push(Recorded {
                        topic,
                        log_time: m.log_time,
                        header,
                        msg,
                    });
                }
                Decoded::Header(SliceHeader::CameraFrame(h)) => {
                    cam_headers.insert(h.msg.capture_ns, h);
                }
                Decoded::Header(SliceHeader::DepthFrame(h)) => {
                    depth_headers.insert(h.msg.capture_ns, h);
                }
                Decoded::Header(_) => {}
            }
            Ok(())
        })?;
        rec.cameras = pair(cam_images, &cam_headers, |h: &CameraFrameHeader, px| {
            OwnedMessage::CameraFrame(*h, px)
        });
        rec.depths = pair(depth_images, &depth_headers, |h: &DepthFrameHeader, d| {
            OwnedMessage::DepthFrame(*h, d)
        });
        Ok((rec, summary))
    }

    /// The recorded messages on `topic`.
    fn on<'a>(&'a self, topic: &'a str) -> impl Iterator<Item = &'a Recorded> + 'a {
        self.messages.iter().filter(move |m| m.topic == topic)
    }
}

/// Pixels paired with the header of the same capture time.
fn pair<H, P>(
    images: Vec<(u64, Vec<P>)>,
    headers: &BTreeMap<u64, H>,
    make: impl Fn(&H, Vec<P>) -> OwnedMessage,
) -> Vec<OwnedMessage> {
    images
        .into_iter()
        .filter_map(|(ns, px)| headers.get(&ns).map(|h| make(h, px)))
        .collect()
}

/// The header of a message (MAVLink bytes have none: a default one).
fn msg_header(msg: &OwnedMessage) -> Header {
    msg.as_message().header().copied().unwrap_or_default()
}

/// When a publisher let a message out: its last stamp's exit. A message with no stamp
/// (px4-link's outcomes before they were stamped) counts from its capture time, when it
/// was made: the recorder's log time is when the recorder's round began, which can be
/// before a message taken in that round was published.
fn sent_at(h: &Header, log_time: u64) -> u64 {
    match h.stages().last() {
        Some(s) => s.exit_ns,
        None if h.capture_ns > 0 => h.capture_ns,
        None => log_time,
    }
}

/// The last stamp of `stage` in `h`: (enter, exit).
fn stamp_of(h: &Header, stage: ipc_types::msg::Stage) -> Option<(u64, u64)> {
    h.stages()
        .iter()
        .rev()
        .find(|s| s.stage == stage as u32)
        .map(|s| (s.enter_ns, s.exit_ns))
}

/// One output as compared: its key (what pairs it with the flight's), the capture time
/// it is reported by when missing, its results as JSON (stage stamps left out) and its
/// cells (maps).
#[derive(Debug, Clone, PartialEq)]
struct Output {
    key: u64,
    capture: u64,
    value: Value,
    cells: Option<Vec<u8>>,
}

/// A message's JSON without its header's stage stamps (times on the machine that ran
/// it), with its capture time kept.
fn results<T: Serialize>(m: &T, capture: u64) -> Result<Value> {
    let mut v = serde_json::to_value(m)?;
    if let Some(o) = v.as_object_mut() {
        o.remove("msg");
    }
    v["capture_ns"] = capture.into();
    Ok(v)
}

/// The first field where two JSON values differ.
fn first_difference(a: &Value, b: &Value, at: &str) -> Option<String> {
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => x.iter().find_map(|(k, va)| {
            first_difference(va, y.get(k).unwrap_or(&Value::Null), &format!("{at}.{k}"))
        }),
        (Value::Array(x), Value::Array(y)) => x
            .iter()
            .zip(y)
            .enumerate()
            .find_map(|(i, (va, vb))| first_difference(va, vb, &format!("{at}[{i}]")))
            .or_else(|| {
                (x.len() != y.len()).then(|| format!("{at}: {} against {} items", x.len(), y.len()))
            }),
        _ => (a != b).then(|| format!("{at}: {a} replayed, {b} in flight")),
    }
}

/// The stage of a replay: the flight's stage without a clock of its own and without the
/// step it takes when its inputs are done; the recorded schedule ticks it.
struct Scheduled(Box<dyn Stage>);

impl Stage for Scheduled {
    fn name(&self) -> &'static str {
        self.0.name()
    }

    fn on_input(
        &mut self,
        now_ns: u64,
        input: Input<'_>,
        out: &mut dyn Outbox,
    ) -> Result<(), StageError> {
        self.0.on_input(now_ns, input, out)
    }

    fn on_tick(&mut self, now_ns: u64, out: &mut dyn Outbox) -> Result<(), StageError> {
        self.0.on_tick(now_ns, out)
    }

    fn max_slice_len(&self, topic: &str) -> usize {
        self.0.max_slice_len(topic)
    }

    fn counters(&self) -> Vec<stage::Counter> {
        self.0.counters()
    }
}

/// What the flight's stage met, when, and what it made: the schedule a replay runs.
/// Inputs borrow the recording's messages (the driver copies each once, as it queues it).
#[derive(Default)]
struct Plan<'a> {
    /// (time, topic, message), in time order per topic.
    deliveries: Vec<(u64, &'static str, Cow<'a, OwnedMessage>)>,
    /// The flight's steps, ascending.
    ticks: Vec<u64>,
    /// The outputs the flight recorded.
    recorded: Vec<Output>,
    /// The flight's outputs for people.
    flown: Vec<String>,
    /// Outputs the recording lost (gaps in their publisher's sequence numbers).
    lost: u64,
    /// Recorded outputs after the first loss: their inputs are not all known.
    not_compared: u64,
}

/// The flight's config, scenario and seed, from the recording's metadata.
fn flight_setup(
    req: &Request,
    summary: &recorder::ReadSummary,
) -> Result<(StackConfig, sim::scenario::LoadedScenario, u64)> {
    if let Some(b) = &summary.broken {
        bail!("{}: {b}", req.file.display());
    }
    let meta = summary.metadata.get("landing").cloned().unwrap_or_default();
    let config: StackConfig = match (&req.config, meta.get("config")) {
        (Some(path), _) => stack_config::load(path)?,
        (None, Some(text)) => {
            stack_config::parse(text, &req.file).context("the recording's config (metadata)")?
        }
        (None, None) => bail!(
            "{}: no config in its metadata (give one with --config)",
            req.file.display()
        ),
    };
    let name = meta.get("scenario").map_or("paper-sim", String::as_str);
    let scenario = sim::scenario::load(name, &req.deploy)?;
    let seed = meta.get("seed").and_then(|s| s.parse().ok()).unwrap_or(1);
    Ok((config, scenario, seed))
}

/// Runs `req.stage` again on the recording and compares.
pub fn replay(req: &Request) -> Result<ReplayReport> {
    if !STAGES.contains(&req.stage.as_str()) {
        bail!("--stage {}: allowed: {}", req.stage, STAGES.join(", "));
    }
    let graph = graph::Graph::load(&graph::default_path(&req.deploy))?;
    let Some(node) = graph.node(&req.stage) else {
        bail!("the graph has no {} node", req.stage);
    };
    let spec = node.spec();
    let wanted: Vec<&str> = spec
        .inputs
        .iter()
        .map(|i| i.topic.as_str())
        .chain(spec.outputs.iter().map(String::as_str))
        .collect();
    let (recording, summary) = Recording::read(&req.file, &wanted)?;
    let (config, scenario, seed) = flight_setup(req, &summary)?;
    let plan = plan::plan(&req.stage, &recording, &req.file)?;
    let setup = crate::lockstep::Setup {
        scenario: &scenario,
        seed,
        config: &config,
        fsm: crate::lockstep::mission(&config, &scenario)?,
    };
    let Some(stage) = crate::lockstep::stage_for(node, &setup)? else {
        bail!("no stage for {}", req.stage);
    };
    // The node alone: every input delivered (none skipped for a newer one), no delay,
    // no modelled latency.
    let alone = NodeSpec {
        inputs: spec
            .inputs
            .iter()
            .map(|i| InputSpec {
                topic: i.topic.clone(),
                newest: false,
                delay: false,
                depth: None,
            })
            .collect(),
        latency_ns: 0,
        ..spec.clone()
    };
    let mut driver = Lockstep::new(vec![(alone, Box::new(Scheduled(stage)) as Box<dyn Stage>)])?;
    let mut deliveries = plan.deliveries;
    deliveries.sort_by_key(|(at, _, _)| *at);
    let inputs = deliveries.len() as u64;
    for (at, topic, msg) in &deliveries {
        driver.inject_at(*at, topic, msg.as_message());
    }
    for t in &plan.ticks {
        driver.tick_at(&req.stage, *t);
    }
    let mut made: Vec<(String, OwnedMessage)> = Vec::new();
    while driver
        .step(&mut |p| made.push((p.topic.to_string(), p.msg.to_owned())))?
        .is_some()
    {}
    let replayed = plan::outputs(&req.stage, made.iter().map(|(t, m)| (t.as_str(), m)))?;
    let mut report = compare(&req.stage, inputs, &plan.recorded, &replayed, plan.flown);
    report.lost = plan.lost;
    report.not_compared = plan.not_compared;
    report.recorded += plan.not_compared;
    Ok(report)
}

/// Pairs the replay's outputs with the flight's by key and compares them.
fn compare(
    stage: &str,
    inputs: u64,
    recorded: &[Output],
    replayed: &[Output],
    flown: Vec<String>,
) -> ReplayReport {
    let mut by_key: BTreeMap<u64, &Output> = replayed.iter().map(|o| (o.key, o)).collect();
    let mut report = ReplayReport {
        stage: stage.to_string(),
        inputs,
        recorded: recorded.len() as u64,
        replayed: replayed.len() as u64,
        identical: 0,
        different: 0,
        differences: vec![],
        missing: vec![],
        extra: 0,
        lost: 0,
        not_compared: 0,
        flown,
    };
    for f in recorded {
        let Some(r) = by_key.remove(&f.key) else {
            report.missing.push(f.capture);
            continue;
        };
        let diff =
            first_difference(&r.value, &f.value, "").or_else(|| match (&r.cells, &f.cells) {
                (Some(a), Some(b)) if a != b => {
                    let n = a.iter().zip(b).filter(|(x, y)| x != y).count();
                    Some(format!(": {n} of {} cells differ", b.len()))
                }
                (None, Some(_)) | (Some(_), None) => Some(": cells on one side only".into()),
                _ => None,
            });
        match diff {
            None => report.identical += 1,
            Some(d) => {
                report.different += 1;
                if report.differences.len() < 10 {
                    report
                        .differences
                        .push(format!("{} {}{d}", plan::unit(stage), f.key));
                }
            }
        }
    }
    report.extra = by_key.len() as u64;
    report
}
