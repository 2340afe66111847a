//! `landing run --processes --inject FAULT:PROCESS@WHEN`: faults done to the stack's
//! processes in flight, and what became of them.
//!
//! Only the faults a signal can do are here (`kill`: SIGKILL, a crash; `stop`: SIGSTOP,
//! a hang). Faults inside the data paths (delay, drop, corrupt) belong in the runtime's
//! ports and are not built yet (issue 17).

use std::fmt;
use std::str::FromStr;

use ipc_types::msg::MissionState;
use serde::Serialize;
use thiserror::Error;

/// What is done to the process.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Fault {
    /// SIGKILL: the process is gone at once, as after a crash.
    Kill,
    /// SIGSTOP: the process hangs (never continued during the run).
    Stop,
}

impl Fault {
    /// Its name, as `--inject` and the summary write it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Kill => "kill",
            Self::Stop => "stop",
        }
    }

    /// The signal that does it.
    pub fn signal(self) -> libc::c_int {
        match self {
            Self::Kill => libc::SIGKILL,
            Self::Stop => libc::SIGSTOP,
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
    /// To which process (a node of the graph).
    pub process: String,
    /// When.
    pub when: When,
}

/// Why an `--inject` value was refused.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error(
    "--inject {value}: {why} (FAULT:PROCESS@WHEN, FAULT kill or stop, WHEN takeoff, track, descend, land or seconds, e.g. kill:fsm@track or stop:planner@12.5)"
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
        let (fault, rest) = s.split_once(':').ok_or_else(|| err("no ':'"))?;
        let (process, when) = rest.split_once('@').ok_or_else(|| err("no '@'"))?;
        let fault = match fault {
            "kill" => Fault::Kill,
            "stop" => Fault::Stop,
            _ => return Err(err("unknown fault")),
        };
        if process.is_empty() {
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
            when,
        })
    }
}

impl fmt::Display for Injection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let fault = self.fault.name();
        match self.when {
            When::At(t) => write!(f, "{fault}:{}@{t}", self.process),
            When::Phase(p) => write!(f, "{fault}:{}@{}", self.process, p.name()),
        }
    }
}

impl Injection {
    /// Due at simulated time `t_s` in mission state `phase`.
    pub fn due(&self, t_s: f64, phase: MissionState) -> bool {
        match self.when {
            When::At(at) => t_s >= at,
            When::Phase(p) => phase == p,
        }
    }
}

/// One fault in the run summary (`--json` `faults`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FaultRecord {
    /// `kill`, `stop`, or `exited` (a process that ended on its own).
    pub fault: String,
    /// The process.
    pub process: String,
    /// Simulated time of the fault, s.
    pub at_s: f64,
    /// How long until the watchdog found the process hung or dead, ms (its view's
    /// `fault_ns` against the monotonic time the signal was sent); `null`: it did not.
    pub detected_after_ms: Option<f64>,
    /// What the watchdog decided about it (its decision line: "fsm died: critical,
    /// land"); `null` when it decided nothing (on the ground, or not found).
    pub action: Option<String>,
    /// How long until the watchdog's safe-land (or hold) order went out, ms; `null` when
    /// none followed this fault.
    pub ordered_after_ms: Option<f64>,
    /// Monotonic time of the fault, ns (not in the summary).
    #[serde(skip)]
    pub at_ns: u64,
    /// The run's outcome.
    pub outcome: String,
}

#[cfg(test)]
#[path = "inject_test.rs"]
mod tests;
