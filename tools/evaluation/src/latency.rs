//! `landing latency run.mcap`: per-stage and end-to-end latency from a recording's stage
//! stamps, message rates, and drops by sequence gaps.
//!
//! Every message header carries the capture time of the sensor data it derives from and
//! one stamp per stage it went through (`Header::stages`: enter and exit, exit closed by
//! the driver when the message left). px4-link publishes each new setpoint once more on
//! `px4/setpoint_sent` when its bytes went out, with its own stamp: the whole chain
//! camera -> camera-ingest -> aruco-pnp -> fsm -> px4-link (the wire) in one header.
//!
//! - end to end: for each camera frame (one capture time), the first setpoint on the
//!   wire that derives from it: wire time minus the time the camera delivered the frame
//!   (the sensor stamp's exit). The camera's own exposure, readout and transfer (the
//!   simulator models 30 ms) are the camera's, not the stack's; they are in
//!   `capture_to_wire_ms`, from the capture timestamp.
//! - stages: on that same chain, each stage's exit minus the previous stage's exit
//!   (transport, waiting for the stage's turn, and its work); and for every other topic,
//!   its publisher's exit minus the previous exit (or the capture time).

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use anyhow::Result;
use ipc_types::msg::Stage;
use ipc_types::topics;
use serde::Serialize;
use serde_json::Value;

use crate::stats::percentile;

/// Percentiles of a set of latencies, ms.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct Percentiles {
    /// Samples.
    pub count: usize,
    /// Median.
    pub p50: f64,
    /// 90th percentile.
    pub p90: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Largest.
    pub max: f64,
}

impl Percentiles {
    /// Of `v` (ms); `None` when empty.
    pub fn of(v: &[f64]) -> Option<Self> {
        if v.is_empty() {
            return None;
        }
        Some(Self {
            count: v.len(),
            p50: percentile(v, 50.0),
            p90: percentile(v, 90.0),
            p99: percentile(v, 99.0),
            max: v.iter().copied().fold(f64::MIN, f64::max),
        })
    }
}

/// What `landing latency` reports.
#[derive(Debug, Clone, Serialize)]
pub struct LatencyReport {
    /// Camera frame delivered -> first setpoint from it on the MAVLink wire, ms.
    pub end_to_end_ms: Option<Percentiles>,
    /// Capture timestamp -> the same setpoint on the wire (the camera's own latency
    /// included), ms.
    pub capture_to_wire_ms: Option<Percentiles>,
    /// Each stage's share of the end-to-end chain, ms, by stage.
    pub stages: BTreeMap<String, Percentiles>,
    /// Each publisher's latency on each topic (exit minus the previous stage's exit, or
    /// the capture time), ms, by `stage -> topic`.
    pub topics: BTreeMap<String, Percentiles>,
    /// Messages missing by sequence gaps, by topic.
    pub drops: BTreeMap<String, u64>,
    /// Messages per second, by topic.
    pub rates_hz: BTreeMap<String, f64>,
    /// Each supervised process's CPU use, percent of one core, from the watchdog's view
    /// (measured every second from /proc; none in lockstep, one process).
    pub cpu_percent: BTreeMap<String, CpuUse>,
    /// Where the recording broke, when it did (what came before is in the report).
    pub broken: Option<String>,
    /// The end-to-end samples, ms (the histogram's).
    #[serde(skip)]
    pub end_to_end_samples_ms: Vec<f64>,
}

/// A process's CPU use over a recording, percent of one core.
#[derive(Debug, Clone, Serialize)]
pub struct CpuUse {
    /// Over the whole recording: CPU time used / wall time between the first and the last
    /// measurement.
    pub mean: f64,
    /// The largest one-second measurement.
    pub max: f64,
    /// One-second measurements that found CPU time used (an idle second repeats the
    /// last one and is not counted).
    pub samples: usize,
}

/// The CPU measurements of one process: (view time, CPU time, percent) when it changed.
#[derive(Default)]
struct CpuTrack {
    samples: Vec<(u64, u64, f64)>,
}

impl CpuTrack {
    fn usage(&self) -> Option<CpuUse> {
        let (first, last) = (self.samples.first()?, self.samples.last()?);
        let wall = last.0.checked_sub(first.0).filter(|w| *w > 0)?;
        // A restart (less CPU time than before) leaves the mean to the measurements.
        let mean = match last.1.checked_sub(first.1) {
            Some(cpu) => cpu as f64 / wall as f64 * 100.0,
            None => self.samples.iter().map(|s| s.2).sum::<f64>() / self.samples.len() as f64,
        };
        Some(CpuUse {
            mean,
            max: self.samples.iter().skip(1).map(|s| s.2).fold(0.0, f64::max),
            samples: self.samples.len() - 1,
        })
    }
}

/// One stamp of a header, from JSON.
#[derive(Debug, Clone, Copy)]
struct Stamp {
    stage: u32,
    exit_ns: u64,
}

/// Capture time and stamps of a recorded message's header.
fn header(v: &Value) -> Option<(u64, u64, Vec<Stamp>)> {
    let h = &v["msg"];
    let capture = h["capture_ns"].as_u64()?;
    let seq = h["seq"].as_u64()?;
    let n = h["stage_count"].as_u64()? as usize;
    let stamps = h["stages"]
        .as_array()?
        .iter()
        .take(n)
        .filter_map(|s| {
            Some(Stamp {
                stage: u32::try_from(s["stage"].as_u64()?).ok()?,
                exit_ns: s["exit_ns"].as_u64()?,
            })
        })
        .collect();
    Some((seq, capture, stamps))
}

fn stage_name(raw: u32) -> String {
    Stage::from_raw(raw).map_or_else(|| format!("stage-{raw}"), |s| s.name().to_string())
}

fn ms(a: u64, b: u64) -> f64 {
    (b as f64 - a as f64) * 1e-6
}

/// The latency analysis of a stream of recorded messages (a file's, or the live bus's):
/// each message as the recorder writes its JSON, on its recorded channel name
/// (`/vehicle/state`, `/camera/frame/header`), at its log time.
#[derive(Default)]
pub struct Analysis {
    /// First wire time per capture: (wire, chain of stamps).
    chains: HashMap<u64, (u64, Vec<Stamp>)>,
    per_topic: BTreeMap<String, Vec<f64>>,
    last_seq: HashMap<String, u64>,
    drops: BTreeMap<String, u64>,
    counts: BTreeMap<String, u64>,
    span: HashMap<String, (u64, u64)>,
    cpu: BTreeMap<String, CpuTrack>,
}

impl Analysis {
    /// Takes in one message: `channel` as recorded (`/px4/setpoint_sent`), its JSON.
    pub fn add(&mut self, channel: &str, log_time: u64, v: &Value) {
        if channel.strip_prefix('/') == Some(topics::WATCHDOG_VIEW) {
            let n = v["count"].as_u64().unwrap_or(0) as usize;
            for p in v["processes"].as_array().into_iter().flatten().take(n) {
                let (Some(name), Some(ns)) = (p["name"].as_str(), p["cpu_ns"].as_u64()) else {
                    continue;
                };
                let track = self.cpu.entry(name.to_string()).or_default();
                let changed = track.samples.last().is_none_or(|l| l.1 != ns);
                if ns > 0 && changed {
                    let percent = p["cpu_percent"].as_f64().unwrap_or(0.0);
                    track.samples.push((log_time, ns, percent));
                }
            }
        }
        let Some((seq, capture, stamps)) = header(v) else {
            return;
        };
        let topic = channel.to_string();
        *self.counts.entry(topic.clone()).or_insert(0) += 1;
        let s = self
            .span
            .entry(topic.clone())
            .or_insert((log_time, log_time));
        s.1 = log_time;
        // Drops: a sequence that jumps (repeats, as the fsm's periodic status, are not).
        if let Some(prev) = self.last_seq.insert(topic.clone(), seq)
            && seq > prev + 1
        {
            *self.drops.entry(topic.clone()).or_insert(0) += seq - prev - 1;
        } else {
            self.drops.entry(topic.clone()).or_insert(0);
        }
        if let Some(last) = stamps.last() {
            let from = match stamps.len() {
                1 => capture,
                n => stamps[n - 2].exit_ns,
            };
            if capture > 0 && last.exit_ns >= from {
                let name = topic.get(1..).unwrap_or(&topic);
                self.per_topic
                    .entry(format!("{} -> {name}", stage_name(last.stage)))
                    .or_default()
                    .push(ms(from, last.exit_ns));
            }
        }
        if channel.strip_prefix('/') == Some(topics::PX4_SETPOINT_SENT)
            && capture > 0
            && stamps
                .first()
                .is_some_and(|s| s.stage == Stage::Sensor as u32)
            && stamps
                .last()
                .is_some_and(|s| s.stage == Stage::Px4Link as u32)
        {
            let wire = stamps.last().map_or(0, |s| s.exit_ns);
            match self.chains.get(&capture) {
                Some((w, _)) if *w <= wire => {}
                _ => {
                    self.chains.insert(capture, (wire, stamps));
                }
            }
        }
    }

    /// The report of everything taken in so far.
    pub fn report(&self) -> LatencyReport {
        let mut e2e = vec![];
        let mut c2w = vec![];
        let mut by_stage: BTreeMap<String, Vec<f64>> = BTreeMap::new();
        for (capture, (wire, stamps)) in &self.chains {
            let delivered = stamps[0].exit_ns;
            e2e.push(ms(delivered, *wire));
            c2w.push(ms(*capture, *wire));
            for w in stamps.windows(2) {
                by_stage
                    .entry(stage_name(w[1].stage))
                    .or_default()
                    .push(ms(w[0].exit_ns, w[1].exit_ns));
            }
        }
        let short = |t: &str| t.get(1..).unwrap_or(t).to_string();
        let rates_hz = self
            .counts
            .iter()
            .map(|(t, n)| {
                let (a, b) = self.span.get(t).copied().unwrap_or((0, 0));
                let secs = (b.saturating_sub(a)) as f64 * 1e-9;
                let rate = if secs > 0.0 && *n > 1 {
                    (*n - 1) as f64 / secs
                } else {
                    0.0
                };
                (short(t), rate)
            })
            .collect();
        LatencyReport {
            end_to_end_ms: Percentiles::of(&e2e),
            capture_to_wire_ms: Percentiles::of(&c2w),
            stages: by_stage
                .iter()
                .filter_map(|(k, v)| Some((k.clone(), Percentiles::of(v)?)))
                .collect(),
            topics: self
                .per_topic
                .iter()
                .filter_map(|(k, v)| Some((k.clone(), Percentiles::of(v)?)))
                .collect(),
            drops: self.drops.iter().map(|(t, n)| (short(t), *n)).collect(),
            rates_hz,
            cpu_percent: self
                .cpu
                .iter()
                .filter_map(|(k, t)| Some((k.clone(), t.usage()?)))
                .collect(),
            broken: None,
            end_to_end_samples_ms: e2e,
        }
    }
}

/// Reads `file` and computes the report.
pub fn analyse(file: &Path) -> Result<LatencyReport> {
    let mut analysis = Analysis::default();
    let summary = recorder::read_messages(file, &mut |m| {
        if m.encoding != "json" {
            return;
        }
        if let Ok(v) = serde_json::from_slice::<Value>(m.data) {
            analysis.add(m.topic, m.log_time, &v);
        }
    })?;
    let mut report = analysis.report();
    report.broken = summary.broken.map(|b| b.to_string());
    Ok(report)
}
