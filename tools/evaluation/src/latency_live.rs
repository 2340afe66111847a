//! `landing latency --live`: the analysis of `landing latency` on the running stack's
//! topics instead of a recording: this process subscribes to every iceoryx2 topic of the
//! graph (ground truth aside), as the recorder does, through the iceoryx2 driver, turns
//! each message into the JSON the recorder would write, and prints a summary line every
//! period and the whole report at the end (`--seconds`, or Ctrl-C).

use std::time::Duration;

use anyhow::{Context, Result};
use graph::{Graph, Transport};
use runtime::driver::{self, Beat};
use runtime::{Ipc, IpcPrefix};
use serde_json::Value;
use stage::lockstep::{InputSpec, NodeSpec};
use stage::{Counter, Input, Message, Outbox, Stage, StageError};

use crate::latency::{Analysis, LatencyReport};

/// The node name this process takes on the bus.
const NODE: &str = "latency-live";

/// The JSON the recorder writes for `msg` on `topic`, and the channel it writes it on
/// (`/<topic>`, or `/<topic>/header` for frames and maps, whose pixels and cells are not
/// JSON); `None` for what the recorder does not record as JSON.
pub fn recorded_json(topic: &str, msg: &Message<'_>) -> Option<(String, Value)> {
    let header = |v: serde_json::Result<Value>| Some((format!("/{topic}/header"), v.ok()?));
    let whole = |v: serde_json::Result<Value>| Some((format!("/{topic}"), v.ok()?));
    match *msg {
        Message::CameraFrame(h, _) => header(serde_json::to_value(h)),
        Message::DepthFrame(h, _) => header(serde_json::to_value(h)),
        Message::OccupancyMap(h, _) => header(serde_json::to_value(h)),
        Message::VehicleState(m) => whole(serde_json::to_value(m)),
        Message::VioOdometry(m) => whole(serde_json::to_value(m)),
        Message::PadObservation(m) => whole(serde_json::to_value(m)),
        Message::Trajectory(m) => whole(serde_json::to_value(m)),
        Message::FsmStatus(m) => whole(serde_json::to_value(m)),
        Message::WatchdogView(m) => whole(serde_json::to_value(m)),
        Message::SafetyCommand(m) => whole(serde_json::to_value(m)),
        Message::PlannerGoal(m) => whole(serde_json::to_value(m)),
        Message::PlannerStats(m) => whole(serde_json::to_value(m)),
        Message::Setpoint(m) => whole(serde_json::to_value(m)),
        Message::LinkRequest(m) => whole(serde_json::to_value(m)),
        Message::LinkOutcome(m) => whole(serde_json::to_value(m)),
        Message::TruthEvent(_)
        | Message::TruthState(_)
        | Message::Mavlink(_)
        | Message::ProcessEvent(_) => None,
    }
}

/// The live analysis as a stage: messages in, a summary line every period.
pub struct LiveStage {
    analysis: Analysis,
    period_ns: u64,
    seconds: Option<f64>,
    started_ns: Option<u64>,
    done: bool,
    messages: u64,
    /// Summary lines, for the caller to print (the stage itself does no I/O).
    pub lines: Vec<String>,
}

impl LiveStage {
    /// Summaries every `period`; finished after `seconds` (None: until stopped).
    pub fn new(period: Duration, seconds: Option<f64>) -> Self {
        Self {
            analysis: Analysis::default(),
            period_ns: u64::try_from(period.as_nanos()).unwrap_or(u64::MAX).max(1),
            seconds,
            started_ns: None,
            done: false,
            messages: 0,
            lines: Vec::new(),
        }
    }

    /// The report of everything seen so far.
    pub fn report(&self) -> LatencyReport {
        self.analysis.report()
    }
}

/// One summary line of a report, `elapsed_s` into the run.
pub fn summary_line(elapsed_s: f64, r: &LatencyReport) -> String {
    let e2e = r.end_to_end_ms.as_ref().map_or_else(
        || "no setpoint from a camera frame yet".to_string(),
        |p| {
            format!(
                "end to end p50 {:.2} p90 {:.2} p99 {:.2} max {:.2} ms ({} frames)",
                p.p50, p.p90, p.p99, p.max, p.count
            )
        },
    );
    let drops: u64 = r.drops.values().sum();
    let cpu: Vec<String> = r
        .cpu_percent
        .iter()
        .map(|(k, c)| format!("{k} {:.1}", c.mean))
        .collect();
    let cpu = if cpu.is_empty() {
        String::new()
    } else {
        format!("; cpu % {}", cpu.join(", "))
    };
    format!("[{elapsed_s:6.1} s] {e2e}; drops {drops}{cpu}")
}

impl Stage for LiveStage {
    fn name(&self) -> &'static str {
        NODE
    }

    fn tick_period_ns(&self) -> Option<u64> {
        Some(self.period_ns)
    }

    fn on_input(
        &mut self,
        now_ns: u64,
        input: Input<'_>,
        _out: &mut dyn Outbox,
    ) -> Result<(), StageError> {
        self.started_ns.get_or_insert(now_ns);
        if let Some((channel, v)) = recorded_json(input.topic, &input.msg) {
            self.analysis.add(&channel, now_ns, &v);
            self.messages += 1;
        }
        Ok(())
    }

    fn on_tick(&mut self, now_ns: u64, _out: &mut dyn Outbox) -> Result<(), StageError> {
        let started = *self.started_ns.get_or_insert(now_ns);
        let elapsed = now_ns.saturating_sub(started) as f64 * 1e-9;
        self.lines
            .push(summary_line(elapsed, &self.analysis.report()));
        if self.seconds.is_some_and(|s| elapsed >= s) {
            self.done = true;
        }
        Ok(())
    }

    fn finished(&self) -> bool {
        self.done
    }

    fn counters(&self) -> Vec<Counter> {
        vec![("messages", self.messages)]
    }
}

/// Every iceoryx2 topic of `graph` but ground truth, taken in full.
fn spec(graph: &Graph) -> NodeSpec {
    NodeSpec {
        name: NODE.into(),
        inputs: graph
            .topics
            .iter()
            .filter(|t| t.transport == Transport::Iceoryx2 && !t.evaluator_only)
            .map(|t| InputSpec {
                topic: t.name.clone(),
                newest: false,
                delay: false,
                // Every message counts: the deepest buffer the topic allows.
                depth: Some(stage::max_depth(t.elements.as_deref())),
            })
            .collect(),
        outputs: vec![],
        latency_ns: 0,
        periodic: None,
    }
}

/// Watches the stack under `prefix` for `seconds` (None: until Ctrl-C), printing a
/// summary line every `period` on stderr; returns the whole report.
pub fn watch(
    prefix: Option<&str>,
    graph_path: &std::path::Path,
    period: Duration,
    seconds: Option<f64>,
) -> Result<LatencyReport> {
    let graph = Graph::load(graph_path)?;
    let prefix = IpcPrefix::from_flag_or_env(prefix)?;
    let ipc = Ipc::open(NODE, &prefix).context("joining the stack's shared memory")?;
    runtime::shutdown::install();
    eprintln!(
        "latency --live: watching the stack under prefix `{}` ({}; Ctrl-C ends)",
        prefix.as_str(),
        seconds.map_or_else(|| "until stopped".to_string(), |s| format!("{s} s"))
    );
    let mut stage = PrintingStage(LiveStage::new(period, seconds));
    let beat = Beat {
        period: Duration::from_millis(100),
        deadline: Duration::from_millis(1000),
    };
    driver::run(&ipc, &spec(&graph), &mut stage, None, beat)?;
    Ok(stage.0.report())
}

/// The live stage, its summary lines printed as they come (the binary's side).
struct PrintingStage(LiveStage);

impl Stage for PrintingStage {
    fn name(&self) -> &'static str {
        self.0.name()
    }

    fn tick_period_ns(&self) -> Option<u64> {
        self.0.tick_period_ns()
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
        self.0.on_tick(now_ns, out)?;
        for l in self.0.lines.drain(..) {
            eprintln!("{l}");
        }
        Ok(())
    }

    fn finished(&self) -> bool {
        self.0.finished()
    }

    fn counters(&self) -> Vec<Counter> {
        self.0.counters()
    }
}
