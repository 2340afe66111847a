//! `landing run --processes --inject FAULT:PROCESS@WHEN`: faults done to the stack's
//! processes in flight, and what became of them.
//!
//! A signal does `kill` (SIGKILL, a crash), `stop` (SIGSTOP, a hang) and `restart` (SIGKILL,
//! then the same command again, as systemd restarts a unit); the runtime's
//! output ports do `delay:MS`, `drop:FRACTION` and `corrupt`, ordered through
//! `landing/fault/inject` (`runtime::port_faults`), which the stage processes listen to
//! because `landing run` starts them with `LANDING_FAULT_INJECTION=1`.

use std::fmt;
use std::str::FromStr;

use ipc_types::msg::{MissionState, PortFault};
use ipc_types::topics::{self, Payload};
use thiserror::Error;

/// What is done to the process.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fault {
    /// SIGKILL: the process is gone at once, as after a crash.
    Kill,
    /// SIGSTOP: the process hangs (never continued during the run).
    Stop,
    /// SIGKILL, then the same command started again at once: a crash that systemd's
    /// `Restart=on-failure` answers.
    Restart,
    /// Each of its outputs waits this many ms before it is sent.
    Delay(f64),
    /// Each of its outputs is dropped with this probability.
    Drop(f64),
    /// Its outputs' payloads are overwritten: NaN and out-of-range values; for this many
    /// seconds (`corrupt:0.5:P`), else to the end of the run (`corrupt:P`).
    Corrupt(Option<f64>),
    /// A world fault: one topic stops for this many seconds, then comes back (the
    /// simulator's camera unplugged and plugged in again, the autopilot's telemetry
    /// lost). The injection names the topic; its publisher does it.
    Cut(f64),
    /// A world fault: the images of one topic show nothing for this many seconds while
    /// they keep coming (`sim/camera`: the pad hidden, the view blocked). Its publisher
    /// paints them one grey.
    Blank(f64),
    /// A world fault: this many datagrams of random bytes at the process's MAVLink UDP
    /// port, from another port, as fast as they go.
    Garbage(u32),
    /// A world fault: datagrams of this kind at the process's MAVLink UDP port, from
    /// another port, this many per second, from the injection to the end of the run.
    Flood(FloodKind, f64),
}

/// What a flood sends.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FloodKind {
    /// Random bytes, 1 to 280 of them.
    Random,
    /// Valid autopilot frames with bytes flipped, cut short or glued together.
    Mutated,
    /// Valid autopilot heartbeats and positions (system 1, component 1, good
    /// checksums) saying something else than the autopilot: spoofing from another port.
    Spoofed,
}

impl FloodKind {
    /// Its name in `--inject`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Random => "random",
            Self::Mutated => "mutated",
            Self::Spoofed => "spoofed",
        }
    }
}

impl Fault {
    /// Its name, as `--inject` and the summary write it (`delay:50`).
    pub fn name(self) -> String {
        match self {
            Self::Kill => "kill".into(),
            Self::Stop => "stop".into(),
            Self::Restart => "restart".into(),
            Self::Delay(ms) => format!("delay:{ms}"),
            Self::Drop(f) => format!("drop:{f}"),
            Self::Corrupt(None) => "corrupt".into(),
            Self::Corrupt(Some(s)) => format!("corrupt:{s}"),
            Self::Cut(s) => format!("cut:{s}"),
            Self::Blank(s) => format!("blank:{s}"),
            Self::Garbage(n) => format!("garbage:{n}"),
            Self::Flood(kind, rate) => format!("flood:{}:{rate}", kind.name()),
        }
    }

    /// The signal that does it, for a fault to the whole process.
    pub fn signal(self) -> Option<libc::c_int> {
        match self {
            Self::Kill | Self::Restart => Some(libc::SIGKILL),
            Self::Stop => Some(libc::SIGSTOP),
            _ => None,
        }
    }

    /// How long a port fault lasts, s (0: to the end of the run, or until cleared).
    pub fn duration_s(self) -> f64 {
        match self {
            Self::Cut(s) | Self::Blank(s) | Self::Corrupt(Some(s)) => s,
            _ => 0.0,
        }
    }

    /// The order to its output ports, for a fault in its data paths.
    pub fn order(self) -> Option<(PortFault, f64)> {
        match self {
            Self::Delay(ms) => Some((PortFault::Delay, ms)),
            Self::Drop(f) => Some((PortFault::Drop, f)),
            Self::Corrupt(_) => Some((PortFault::Corrupt, 0.0)),
            Self::Cut(_) => Some((PortFault::Drop, 1.0)),
            Self::Blank(_) => Some((PortFault::Blank, 0.0)),
            _ => None,
        }
    }
}

/// When it is done.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum When {
    /// Seconds of simulated time after the start.
    At(f64),
    /// As the mission enters this state.
    Phase(MissionState),
}

/// One `--inject` flag.
#[derive(Debug, Clone, PartialEq)]
pub struct Injection {
    /// What.
    pub fault: Fault,
    /// To which process (a node of the graph; for a cut, the topic's publisher, filled
    /// in from the graph by [`Injection::resolve`]).
    pub process: String,
    /// The one topic it concerns (a cut), else every output.
    pub topic: Option<String>,
    /// When.
    pub when: When,
}

/// Why an `--inject` value was refused.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error(
    "--inject {value}: {why} (FAULT:PROCESS@WHEN, FAULT kill, stop or restart, delay:MS (0-10000), drop:FRACTION (0-1), corrupt or corrupt:SECONDS (0-600), or a world fault cut:SECONDS:TOPIC (0-600), blank:SECONDS:TOPIC (0-600, images) garbage:DATAGRAMS:px4-link (1-1000000) or flood:random|mutated|spoofed:PER_SECOND:px4-link (1-100000, until the end), WHEN takeoff, track, descend, land or seconds, e.g. kill:fsm@track, stop:planner@12.5, drop:0.5:aruco-pnp@descend, cut:2:sim/camera@track)"
)]
pub struct InjectionError {
    value: String,
    why: &'static str,
}

impl FromStr for Injection {
    type Err = InjectionError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let err = |why| InjectionError {
            value: s.to_string(),
            why,
        };
        if !s.contains(':') {
            return Err(err("no ':'"));
        }
        let (left, when) = s.rsplit_once('@').ok_or_else(|| err("no '@'"))?;
        let parts: Vec<&str> = left.split(':').collect();
        let number = |v: &str, hi: f64| match v.parse::<f64>() {
            Ok(x) if x.is_finite() && x > 0.0 && x <= hi => Ok(x),
            _ => Err(err("value out of range")),
        };
        let mut topic = None;
        let (fault, process) = match parts[..] {
            ["kill", p] => (Fault::Kill, p),
            ["stop", p] => (Fault::Stop, p),
            ["restart", p] => (Fault::Restart, p),
            ["corrupt", p] => (Fault::Corrupt(None), p),
            ["corrupt", secs, p] => (Fault::Corrupt(Some(number(secs, 600.0)?)), p),
            ["delay", ms, p] => (Fault::Delay(number(ms, 10_000.0)?), p),
            ["drop", f, p] => (Fault::Drop(number(f, 1.0)?), p),
            ["cut", secs, t] if t.contains('/') => {
                topic = Some(t.to_string());
                (Fault::Cut(number(secs, 600.0)?), "")
            }
            ["blank", secs, t] if t.contains('/') => {
                topic = Some(t.to_string());
                (Fault::Blank(number(secs, 600.0)?), "")
            }
            ["garbage", n, p] => {
                let n = number(n, 1_000_000.0)?;
                if n.fract() != 0.0 {
                    return Err(err("value out of range"));
                }
                (Fault::Garbage(n as u32), p)
            }
            ["flood", kind, rate, p] => {
                let kind = match kind {
                    "random" => FloodKind::Random,
                    "mutated" => FloodKind::Mutated,
                    "spoofed" => FloodKind::Spoofed,
                    _ => return Err(err("unknown flood (random, mutated or spoofed)")),
                };
                (Fault::Flood(kind, number(rate, 100_000.0)?), p)
            }
            _ => return Err(err("unknown fault")),
        };
        if process.is_empty() && topic.is_none() {
            return Err(err("no process"));
        }
        let when = match when {
            "takeoff" => When::Phase(MissionState::Takeoff),
            "track" => When::Phase(MissionState::Track),
            "descend" => When::Phase(MissionState::Descend),
            "land" => When::Phase(MissionState::Land),
            t => match t.trim_end_matches('s').parse::<f64>() {
                Ok(v) if v.is_finite() && v >= 0.0 => When::At(v),
                _ => return Err(err("unknown time")),
            },
        };
        Ok(Self {
            fault,
            process: process.to_string(),
            topic,
            when,
        })
    }
}

impl fmt::Display for Injection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let fault = self.fault.name();
        let target = self.topic.as_deref().unwrap_or(&self.process);
        match self.when {
            When::At(t) => write!(f, "{fault}:{target}@{t}"),
            When::Phase(p) => write!(f, "{fault}:{target}@{}", p.name()),
        }
    }
}

impl Injection {
    /// The process it is done to, from `graph`: its own, or the publisher of its topic;
    /// the error names what the graph has.
    pub fn resolve(&mut self, graph: &graph::Graph) -> Result<(), String> {
        if let Some(t) = &self.topic {
            let Some(n) = graph.publishers(t).next() else {
                let topics: Vec<&str> = graph.topics.iter().map(|t| t.name.as_str()).collect();
                return Err(format!(
                    "--inject {self}: no node publishes {t} (topics: {})",
                    topics.join(", ")
                ));
            };
            self.process = n.name.clone();
        }
        if !graph.nodes.iter().any(|n| n.name == self.process) {
            let names: Vec<&str> = graph.nodes.iter().map(|n| n.name.as_str()).collect();
            return Err(format!(
                "--inject {self}: no process {} in the graph (its processes: {})",
                self.process,
                names.join(", ")
            ));
        }
        if let (Fault::Blank(_), Some(t)) = (self.fault, &self.topic)
            && !topics::find(t).is_some_and(|t| t.payload == Payload::CameraFrame)
        {
            return Err(format!(
                "--inject {self}: blank paints images; {t} carries none (allowed: sim/camera, camera/frame)"
            ));
        }
        if matches!(self.fault, Fault::Garbage(_) | Fault::Flood(..)) && self.process != "px4-link"
        {
            return Err(format!(
                "--inject {self}: garbage and floods go to px4-link's MAVLink port (allowed: garbage:N:px4-link, flood:KIND:RATE:px4-link)"
            ));
        }
        Ok(())
    }

    /// Due at simulated time `t_s` in mission state `phase`.
    pub fn due(&self, t_s: f64, phase: MissionState) -> bool {
        match self.when {
            When::At(at) => t_s >= at,
            When::Phase(p) => phase == p,
        }
    }
}

pub use evaluation::flight_log::FaultRecord;

#[cfg(test)]
#[path = "inject_test.rs"]
mod tests;
