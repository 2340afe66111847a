//! The watchdog's logic, a pure library: heartbeats, dead processes, data-path arrivals
//! and the mission's phase go in with their times; the supervisor's view of the stack,
//! the faults it found and a safe-land order when the policy asks for one come out. No
//! IPC, no clock, no sleep: a driver (iceoryx2 on the vehicle, lockstep in tests) feeds
//! it. Which processes and paths to watch comes from the dataflow graph.

use ipc_types::msg::{MAX_WATCHED, MissionState, ProcessHealth, SafetyAction, Text, WatchdogView};
use thiserror::Error;

/// One supervised process.
#[derive(Debug, Clone, PartialEq)]
pub struct WatchedProcess {
    /// Its name (graph node, heartbeat service).
    pub name: String,
    /// Hung after this long without a heartbeat, ms (the graph's `heartbeat_deadline_ms`).
    pub deadline_ms: f64,
    /// Its loss in the air orders a safe landing (the fsm and px4-link: without them
    /// nothing flies the vehicle).
    pub critical: bool,
}

/// One data path that must keep flowing while the mission is in one of `phases`.
#[derive(Debug, Clone, PartialEq)]
pub struct PathRule {
    /// The topic.
    pub topic: String,
    /// The mission states in which it must flow (empty: always, once it has started).
    pub phases: Vec<MissionState>,
    /// Silent for longer than this is a fault, ms.
    pub max_silence_ms: f64,
    /// Its silence in the air orders a safe landing.
    pub critical: bool,
}

/// What to watch.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct WatchdogConfig {
    /// The processes.
    pub processes: Vec<WatchedProcess>,
    /// The data paths.
    pub paths: Vec<PathRule>,
}

/// Why a configuration was refused.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ConfigError {
    /// More processes than a [`WatchdogView`] holds.
    #[error("{0} processes to watch: at most {MAX_WATCHED}")]
    TooMany(usize),
    /// A deadline or silence limit that is not a positive number.
    #[error("{what} of {name}: {value} ms is not a positive number of milliseconds")]
    BadLimit {
        /// Which limit.
        what: &'static str,
        /// Of which process or topic.
        name: String,
        /// The value given.
        value: f64,
    },
    /// A process or topic named twice.
    #[error("{0} is watched twice")]
    Duplicate(String),
}

/// A fault the watchdog found.
#[derive(Debug, Clone, PartialEq)]
pub enum Fault {
    /// The process is gone (its node died, or its notifier).
    Dead(String),
    /// No heartbeat within its deadline.
    Hung(String),
    /// No message on the path within its limit, in a phase that needs it.
    Silent(String),
    /// A message with non-finite or out-of-range values on the path.
    Garbage(String),
}

impl Fault {
    /// One line for logs and the recorder.
    pub fn describe(&self) -> String {
        match self {
            Self::Dead(p) => format!("{p} died"),
            Self::Hung(p) => format!("{p} hung (no heartbeat)"),
            Self::Silent(t) => format!("{t} fell silent"),
            Self::Garbage(t) => format!("garbage on {t}"),
        }
    }
}

/// What one [`Watchdog::tick`] decided.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Outputs {
    /// Faults found since the last tick (each reported once, until it clears).
    pub faults: Vec<(u64, Fault)>,
    /// The order to give, once: a safe landing, with its reason.
    pub order: Option<(SafetyAction, String)>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Health {
    /// No heartbeat yet.
    Starting,
    Alive,
    Hung,
    Dead,
}

#[derive(Debug, Clone)]
struct ProcessState {
    health: Health,
    last_beat_ns: Option<u64>,
    missed: u32,
}

#[derive(Debug, Clone)]
struct PathState {
    last_ns: Option<u64>,
    silent: bool,
    garbage: bool,
}

/// The supervisor.
#[derive(Debug, Clone)]
pub struct Watchdog {
    cfg: WatchdogConfig,
    processes: Vec<ProcessState>,
    paths: Vec<PathState>,
    phase: MissionState,
    phase_since_ns: u64,
    airborne: bool,
    pending: Vec<(u64, Fault)>,
    ordered: bool,
}

impl Watchdog {
    /// A watchdog for `cfg`, checked.
    pub fn new(cfg: WatchdogConfig) -> Result<Self, ConfigError> {
        if cfg.processes.len() > MAX_WATCHED {
            return Err(ConfigError::TooMany(cfg.processes.len()));
        }
        let mut names: Vec<&str> = Vec::new();
        let limits = cfg
            .processes
            .iter()
            .map(|p| ("heartbeat deadline", &p.name, p.deadline_ms))
            .chain(
                cfg.paths
                    .iter()
                    .map(|r| ("silence limit", &r.topic, r.max_silence_ms)),
            );
        for (what, name, value) in limits {
            if !(value.is_finite() && value > 0.0) {
                return Err(ConfigError::BadLimit {
                    what,
                    name: name.clone(),
                    value,
                });
            }
            if names.contains(&name.as_str()) {
                return Err(ConfigError::Duplicate(name.clone()));
            }
            names.push(name);
        }
        Ok(Self {
            processes: vec![
                ProcessState {
                    health: Health::Starting,
                    last_beat_ns: None,
                    missed: 0,
                };
                cfg.processes.len()
            ],
            paths: vec![
                PathState {
                    last_ns: None,
                    silent: false,
                    garbage: false,
                };
                cfg.paths.len()
            ],
            cfg,
            phase: MissionState::Idle,
            phase_since_ns: 0,
            airborne: false,
            pending: Vec::new(),
            ordered: false,
        })
    }

    /// A heartbeat of `process` at `now_ns`. A process that beats again after a hang
    /// is alive again; a dead one that beats was restarted.
    pub fn beat(&mut self, process: &str, now_ns: u64) {
        if let Some(k) = self.process_index(process) {
            let p = &mut self.processes[k];
            p.last_beat_ns = Some(now_ns);
            p.health = Health::Alive;
        }
    }

    /// `process` is gone (its iceoryx2 node is dead, or its heartbeat notifier).
    pub fn died(&mut self, process: &str, now_ns: u64) {
        if let Some(k) = self.process_index(process)
            && self.processes[k].health != Health::Dead
        {
            self.processes[k].health = Health::Dead;
            self.pending
                .push((now_ns, Fault::Dead(process.to_string())));
        }
    }

    /// A message on `topic` at `now_ns`; `sane` false when a value in it is non-finite
    /// or out of its range.
    pub fn message(&mut self, topic: &str, now_ns: u64, sane: bool) {
        let Some(k) = self.cfg.paths.iter().position(|r| r.topic == topic) else {
            return;
        };
        let path = &mut self.paths[k];
        if !sane {
            if !path.garbage {
                path.garbage = true;
                self.pending
                    .push((now_ns, Fault::Garbage(topic.to_string())));
            }
            return;
        }
        path.garbage = false;
        path.last_ns = Some(now_ns);
        path.silent = false;
    }

    /// The mission's state (from the fsm's status) and whether the vehicle is in the air
    /// (from the autopilot's landed state), at `now_ns`.
    pub fn mission(&mut self, phase: MissionState, airborne: bool, now_ns: u64) {
        if phase != self.phase {
            self.phase = phase;
            self.phase_since_ns = now_ns;
        }
        self.airborne = airborne;
    }

    /// Looks at every deadline at `now_ns`: new faults, and the order when the policy
    /// asks for one (at most once per run).
    pub fn tick(&mut self, now_ns: u64) -> Outputs {
        for (k, w) in self.cfg.processes.iter().enumerate() {
            let p = &mut self.processes[k];
            let late = p
                .last_beat_ns
                .is_some_and(|t| now_ns.saturating_sub(t) as f64 * 1e-6 > w.deadline_ms);
            if p.health == Health::Alive && late {
                p.health = Health::Hung;
                p.missed = p.missed.saturating_add(1);
                self.pending.push((now_ns, Fault::Hung(w.name.clone())));
            }
        }
        for (k, r) in self.cfg.paths.iter().enumerate() {
            let needed = r.phases.is_empty() || r.phases.contains(&self.phase);
            let path = &mut self.paths[k];
            // Counted from the later of its last message and the phase's start: a path
            // needed only while descending has until its limit after the descent begins.
            let since = path.last_ns.unwrap_or(0).max(self.phase_since_ns);
            let started = path.last_ns.is_some() || !r.phases.is_empty();
            let silent =
                needed && started && now_ns.saturating_sub(since) as f64 * 1e-6 > r.max_silence_ms;
            if silent && !path.silent {
                self.pending.push((now_ns, Fault::Silent(r.topic.clone())));
            }
            path.silent = silent;
        }
        let faults = std::mem::take(&mut self.pending);
        let mut order = None;
        if self.airborne
            && !self.ordered
            && let Some(why) = self.critical_fault()
        {
            self.ordered = true;
            order = Some((SafetyAction::SafeLand, why));
        }
        Outputs { faults, order }
    }

    /// The first standing fault the policy lands for, described.
    fn critical_fault(&self) -> Option<String> {
        let process = self
            .cfg
            .processes
            .iter()
            .zip(&self.processes)
            .find(|(w, p)| w.critical && matches!(p.health, Health::Hung | Health::Dead));
        if let Some((w, p)) = process {
            let f = if p.health == Health::Dead {
                Fault::Dead(w.name.clone())
            } else {
                Fault::Hung(w.name.clone())
            };
            return Some(f.describe());
        }
        self.cfg
            .paths
            .iter()
            .zip(&self.paths)
            .find(|(r, s)| r.critical && (s.silent || s.garbage))
            .map(|(r, s)| {
                if s.silent {
                    Fault::Silent(r.topic.clone()).describe()
                } else {
                    Fault::Garbage(r.topic.clone()).describe()
                }
            })
    }

    /// True once a safe landing was ordered.
    pub fn ordered(&self) -> bool {
        self.ordered
    }

    /// The view of the stack for the recorder and `landing status`.
    pub fn view(&self) -> WatchdogView {
        let mut v = WatchdogView {
            count: self.cfg.processes.len().min(MAX_WATCHED) as u32,
            safe_land_ordered: u32::from(self.ordered),
            ..WatchdogView::default()
        };
        for (slot, (w, p)) in v
            .processes
            .iter_mut()
            .zip(self.cfg.processes.iter().zip(&self.processes))
        {
            *slot = ProcessHealth {
                name: Text::new(&w.name),
                alive: u32::from(p.health == Health::Alive),
                missed_deadlines: p.missed,
                last_heartbeat_ns: p.last_beat_ns.unwrap_or(0),
                last_output_ns: 0,
            };
        }
        v
    }

    fn process_index(&self, name: &str) -> Option<usize> {
        self.cfg.processes.iter().position(|p| p.name == name)
    }
}

#[cfg(test)]
#[path = "lib_test.rs"]
mod tests;
