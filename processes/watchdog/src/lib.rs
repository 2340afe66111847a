//! The watchdog's logic, a pure library: heartbeats, dead processes, data-path arrivals
//! and the mission's phase go in with their times; the supervisor's view of the stack,
//! the faults it found and a safe-land order when the policy asks for one come out. No
//! IPC, no clock, no sleep: a driver (iceoryx2 on the vehicle, lockstep in tests) feeds
//! it. Which processes and paths to watch comes from the dataflow graph.

use ipc_types::msg::{
    Liveness, MAX_WATCHED, MissionState, ProcessHealth, SafetyAction, Text, WatchdogView,
};

pub mod stage;

pub use stage::{
    PhaseBudget, RideThroughConfig, WatchdogStage, WatchdogStageConfig, watched_processes,
};
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
    /// A death waits this long for the process to come back (systemd restarts it) before
    /// it counts as a loss, ms; 0: a death is a loss at once.
    pub restart_ms: f64,
}

/// A value per mission phase: the phases named, and one for every other phase. The
/// policy ([`Policy`]) and the ride-through budgets ([`Budget`]) are both this.
#[derive(Debug, Clone, PartialEq)]
pub struct ByPhase<T> {
    /// The phases with their own value.
    pub by_phase: Vec<(MissionState, T)>,
    /// Every other phase.
    pub otherwise: T,
}

impl<T: Copy> ByPhase<T> {
    /// The same value in every phase.
    pub fn flat(value: T) -> Self {
        Self {
            by_phase: Vec::new(),
            otherwise: value,
        }
    }

    /// The value in `phase`.
    pub fn get(&self, phase: MissionState) -> T {
        self.by_phase
            .iter()
            .find(|(p, _)| *p == phase)
            .map_or(self.otherwise, |(_, v)| *v)
    }

    fn values(&self) -> impl Iterator<Item = T> + '_ {
        self.by_phase
            .iter()
            .map(|(_, v)| *v)
            .chain(std::iter::once(self.otherwise))
    }
}

/// How long something may be gone in each mission phase before it is a loss, ms: within
/// it the mission flies on (the pad filter predicts, setpoints keep flowing), past it the
/// policy applies.
pub type Budget = ByPhase<f64>;

/// One data path that must keep flowing while the mission is in one of `phases`.
#[derive(Debug, Clone, PartialEq)]
pub struct PathRule {
    /// The topic.
    pub topic: String,
    /// The mission states in which it must flow (empty: always, once it has started).
    pub phases: Vec<MissionState>,
    /// Silent for longer than this in the phase it is silent in is a fault, ms; infinite
    /// for a path that may rightly stop (pad observations: the pad out of view), watched
    /// for garbage only.
    pub silence: Budget,
    /// Carrying only garbage for longer than this is a loss, ms (garbage is reported at
    /// once; a moment of it, dropped by its readers, is flown through).
    pub garbage: Budget,
    /// Its silence in the air orders a safe landing.
    pub critical: bool,
}

/// What to do when a process or path that is not critical is lost in the air.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Action {
    /// Land where the vehicle is (PX4 AUTO.LAND).
    Land,
    /// Hold where it is (PX4 AUTO.LOITER) for an operator.
    Hold,
    /// Order nothing: the fsm keeps landing on the pad, on its estimate. Only while the
    /// estimate is fresh; otherwise the watchdog lands.
    Continue,
}

impl Action {
    /// Its name in config and logs.
    pub fn name(self) -> &'static str {
        match self {
            Self::Land => "land",
            Self::Hold => "hold",
            Self::Continue => "continue",
        }
    }
}

/// What to do per mission phase when something not critical is lost in the air. A
/// critical loss (the fsm, px4-link, the autopilot's telemetry, the setpoints) always
/// lands; on the ground nothing is ordered (systemd restarts what died).
pub type Policy = ByPhase<Action>;

impl Default for Policy {
    /// Close over the pad the fsm goes on landing on its estimate (stopping to land in
    /// place over a moving pad is what ends in a hard landing); anywhere else, land.
    fn default() -> Self {
        Self {
            by_phase: vec![
                (MissionState::Descend, Action::Continue),
                (MissionState::Land, Action::Continue),
            ],
            otherwise: Action::Land,
        }
    }
}

/// What to watch.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct WatchdogConfig {
    /// The processes.
    pub processes: Vec<WatchedProcess>,
    /// The data paths.
    pub paths: Vec<PathRule>,
    /// What to do about a non-critical loss in the air.
    pub policy: Policy,
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
    /// A restart budget outside 0 to 60000 ms.
    #[error("restart budget of {name}: {value} ms is out of range (allowed: 0 to 60000)")]
    BadRestart {
        /// The process.
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
            Self::Hung(p) => format!("{p} hung"),
            Self::Silent(t) => format!("{t} silent"),
            Self::Garbage(t) => format!("garbage on {t}"),
        }
    }
}

/// What the watchdog decided about one fault in the air.
#[derive(Debug, Clone, PartialEq)]
pub struct Decision {
    /// The fault.
    pub fault: Fault,
    /// What it does about it.
    pub action: Action,
    /// Why, in a line.
    pub why: String,
}

/// What one [`Watchdog::tick`] decided.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Outputs {
    /// Faults found since the last tick (each reported once, until it clears).
    pub faults: Vec<(u64, Fault)>,
    /// What was decided about the faults standing in the air (each decided once).
    pub decisions: Vec<Decision>,
    /// The order to give: a safe landing or a hold, with its reason. Given once; a hold
    /// may later become a landing.
    pub order: Option<(SafetyAction, String)>,
    /// Processes back since the last tick after a death: name and milliseconds from the
    /// death being found to the first heartbeat of the new process.
    pub rejoins: Vec<(String, f64)>,
}

#[derive(Debug, Clone)]
struct ProcessState {
    liveness: Liveness,
    last_beat_ns: Option<u64>,
    fault_ns: Option<u64>,
    missed: u32,
    decided: bool,
    /// The last CPU measurement: when, and the CPU time then, ns.
    cpu: Option<(u64, u64)>,
    /// CPU use between the last two measurements, percent of one core.
    cpu_percent: f64,
    /// Times it came back after a death.
    restarts: u32,
    /// When it first beat after its last death.
    rejoined_ns: u64,
}

#[derive(Debug, Clone)]
struct PathState {
    last_ns: Option<u64>,
    silent: bool,
    /// Since when it has carried only garbage.
    garbage_since: Option<u64>,
    decided: bool,
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
    pad_fresh: bool,
    pending: Vec<(u64, Fault)>,
    rejoins: Vec<(String, f64)>,
    order: Option<SafetyAction>,
    order_ns: u64,
    faults: u32,
    last_fault: Option<(u64, String)>,
    action: String,
}

impl Watchdog {
    /// A watchdog for `cfg`, checked.
    pub fn new(cfg: WatchdogConfig) -> Result<Self, ConfigError> {
        if cfg.processes.len() > MAX_WATCHED {
            return Err(ConfigError::TooMany(cfg.processes.len()));
        }
        let mut names: Vec<&str> = Vec::new();
        let named = cfg
            .processes
            .iter()
            .map(|p| &p.name)
            .chain(cfg.paths.iter().map(|r| &r.topic));
        for name in named {
            if names.contains(&name.as_str()) {
                return Err(ConfigError::Duplicate(name.clone()));
            }
            names.push(name);
        }
        let limits = cfg
            .processes
            .iter()
            .map(|p| ("heartbeat deadline", &p.name, p.deadline_ms))
            .chain(cfg.paths.iter().flat_map(|r| {
                let silence = r
                    .silence
                    .values()
                    .map(move |ms| ("silence limit", &r.topic, ms));
                let garbage = r
                    .garbage
                    .values()
                    .map(move |ms| ("garbage limit", &r.topic, ms));
                silence.chain(garbage)
            }));
        for (what, name, value) in limits {
            if value <= 0.0 || value.is_nan() {
                return Err(ConfigError::BadLimit {
                    what,
                    name: name.clone(),
                    value,
                });
            }
        }
        if let Some(p) = cfg
            .processes
            .iter()
            .find(|p| !(0.0..=60_000.0).contains(&p.restart_ms))
        {
            return Err(ConfigError::BadRestart {
                name: p.name.clone(),
                value: p.restart_ms,
            });
        }
        Ok(Self {
            processes: vec![
                ProcessState {
                    liveness: Liveness::Starting,
                    last_beat_ns: None,
                    fault_ns: None,
                    missed: 0,
                    decided: false,
                    cpu: None,
                    cpu_percent: 0.0,
                    restarts: 0,
                    rejoined_ns: 0,
                };
                cfg.processes.len()
            ],
            paths: vec![
                PathState {
                    last_ns: None,
                    silent: false,
                    garbage_since: None,
                    decided: false,
                };
                cfg.paths.len()
            ],
            cfg,
            phase: MissionState::Idle,
            phase_since_ns: 0,
            airborne: false,
            pad_fresh: false,
            pending: Vec::new(),
            rejoins: Vec::new(),
            order: None,
            order_ns: 0,
            faults: 0,
            last_fault: None,
            action: String::new(),
        })
    }

    /// A heartbeat of `process` at `now_ns`. A process that beats again after a hang
    /// is alive again; a dead one that beats was restarted (within its restart budget,
    /// its death was never a loss).
    pub fn beat(&mut self, process: &str, now_ns: u64) {
        if let Some(k) = self.process_index(process) {
            let p = &mut self.processes[k];
            if p.liveness == Liveness::Dead {
                p.restarts = p.restarts.saturating_add(1);
                p.rejoined_ns = now_ns;
                let after_ms = now_ns.saturating_sub(p.fault_ns.unwrap_or(now_ns)) as f64 * 1e-6;
                self.rejoins.push((process.to_string(), after_ms));
            }
            p.last_beat_ns = Some(now_ns);
            p.liveness = Liveness::Alive;
            p.decided = false;
        }
    }

    /// `process` had used `cpu_ns` of CPU time at `now_ns`: its CPU use since the last
    /// measurement goes into the view. A restarted process (less CPU time than before)
    /// starts over.
    pub fn cpu(&mut self, process: &str, now_ns: u64, cpu_ns: u64) {
        if let Some(k) = self.process_index(process) {
            let p = &mut self.processes[k];
            if let Some((t0, c0)) = p.cpu
                && now_ns > t0
                && cpu_ns >= c0
            {
                p.cpu_percent = (cpu_ns - c0) as f64 / (now_ns - t0) as f64 * 100.0;
            } else {
                p.cpu_percent = 0.0;
            }
            p.cpu = Some((now_ns, cpu_ns));
        }
    }

    /// `process` is gone (its iceoryx2 node is dead, or no longer listed).
    pub fn died(&mut self, process: &str, now_ns: u64) {
        if let Some(k) = self.process_index(process)
            && self.processes[k].liveness != Liveness::Dead
        {
            self.processes[k].liveness = Liveness::Dead;
            self.processes[k].fault_ns = Some(now_ns);
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
            if path.garbage_since.is_none() {
                path.garbage_since = Some(now_ns);
                self.pending
                    .push((now_ns, Fault::Garbage(topic.to_string())));
            }
            return;
        }
        if path.garbage_since.is_some() || path.silent {
            path.decided = false;
        }
        path.garbage_since = None;
        path.last_ns = Some(now_ns);
        path.silent = false;
    }

    /// The mission's state (from the fsm's status), whether the vehicle is in the air
    /// (from the autopilot's landed state) and whether the fsm's pad estimate is fresh,
    /// at `now_ns`.
    pub fn mission(&mut self, phase: MissionState, airborne: bool, pad_fresh: bool, now_ns: u64) {
        if phase != self.phase {
            self.phase = phase;
            self.phase_since_ns = now_ns;
        }
        // Down again: an order was for that flight; the next one starts without it (the
        // view keeps when it was given).
        if self.airborne && !airborne {
            self.order = None;
        }
        self.airborne = airborne;
        self.pad_fresh = pad_fresh;
    }

    /// Looks at every deadline at `now_ns`: new faults, what is done about those standing
    /// in the air, and the order when one is due.
    pub fn tick(&mut self, now_ns: u64) -> Outputs {
        for (k, w) in self.cfg.processes.iter().enumerate() {
            let p = &mut self.processes[k];
            let late = p
                .last_beat_ns
                .is_some_and(|t| now_ns.saturating_sub(t) as f64 * 1e-6 > w.deadline_ms);
            if p.liveness == Liveness::Alive && late {
                p.liveness = Liveness::Hung;
                p.fault_ns = Some(now_ns);
                p.missed = p.missed.saturating_add(1);
                self.pending.push((now_ns, Fault::Hung(w.name.clone())));
            }
        }
        for (k, r) in self.cfg.paths.iter().enumerate() {
            let needed = r.phases.is_empty() || r.phases.contains(&self.phase);
            let path = &mut self.paths[k];
            // A path needed only in some phases is counted from the later of its last
            // message and the phase's start (it has until its limit after the descent
            // begins); one needed always, from its last message (a phase change, the fsm
            // reacting to the very silence, must not restart the count).
            let since = if r.phases.is_empty() {
                path.last_ns.unwrap_or(0)
            } else {
                path.last_ns.unwrap_or(0).max(self.phase_since_ns)
            };
            let started = path.last_ns.is_some() || !r.phases.is_empty();
            let silent = needed
                && started
                && now_ns.saturating_sub(since) as f64 * 1e-6 > r.silence.get(self.phase);
            if silent && !path.silent {
                self.pending.push((now_ns, Fault::Silent(r.topic.clone())));
            }
            path.silent = silent;
        }
        let faults = std::mem::take(&mut self.pending);
        if let Some((at, f)) = faults.last() {
            self.last_fault = Some((*at, f.describe()));
        }
        self.faults = self.faults.saturating_add(faults.len() as u32);
        let mut out = Outputs {
            faults,
            rejoins: std::mem::take(&mut self.rejoins),
            ..Outputs::default()
        };
        if !self.airborne {
            return out;
        }
        for (fault, critical) in self.undecided(now_ns) {
            let action = match (critical, self.cfg.policy.get(self.phase)) {
                (true, _) => Action::Land,
                (false, Action::Continue) if !self.pad_fresh => Action::Land,
                (false, a) => a,
            };
            // Short: the view keeps 48 bytes of it (the log the whole line).
            let why = match (critical, action) {
                (true, _) => format!("{}: land (critical)", fault.describe()),
                (false, a)
                    if a != Action::Continue
                        && !self.pad_fresh
                        && self.cfg.policy.get(self.phase) == Action::Continue =>
                {
                    format!(
                        "{} in {}: land, no pad",
                        fault.describe(),
                        self.phase.name()
                    )
                }
                (false, a) => format!(
                    "{} in {}: {}",
                    fault.describe(),
                    self.phase.name(),
                    a.name()
                ),
            };
            let wanted = match action {
                Action::Land => Some(SafetyAction::SafeLand),
                Action::Hold => Some(SafetyAction::Hold),
                Action::Continue => None,
            };
            if let Some(w) = wanted
                && self.order != Some(SafetyAction::SafeLand)
                && self.order != Some(w)
            {
                self.order = Some(w);
                self.order_ns = now_ns;
                out.order = Some((w, fault.describe()));
            }
            self.action.clone_from(&why);
            out.decisions.push(Decision { fault, action, why });
        }
        out
    }

    /// The standing faults not decided yet, each with whether it is critical; marked
    /// decided. A dead process is decided only once its restart budget has passed.
    fn undecided(&mut self, now_ns: u64) -> Vec<(Fault, bool)> {
        let mut v = Vec::new();
        for (w, p) in self.cfg.processes.iter().zip(self.processes.iter_mut()) {
            let fault = match p.liveness {
                Liveness::Dead
                    if now_ns.saturating_sub(p.fault_ns.unwrap_or(0)) as f64 * 1e-6
                        < w.restart_ms =>
                {
                    continue;
                }
                Liveness::Dead => Fault::Dead(w.name.clone()),
                Liveness::Hung => Fault::Hung(w.name.clone()),
                Liveness::Starting | Liveness::Alive => continue,
            };
            if !p.decided {
                p.decided = true;
                v.push((fault, w.critical));
            }
        }
        let phase = self.phase;
        for (r, s) in self.cfg.paths.iter().zip(self.paths.iter_mut()) {
            let garbage_lost = s
                .garbage_since
                .is_some_and(|t| now_ns.saturating_sub(t) as f64 * 1e-6 > r.garbage.get(phase));
            // While garbage flows, its own budget decides (its silence is the garbage).
            let fault = if garbage_lost {
                Fault::Garbage(r.topic.clone())
            } else if s.silent && s.garbage_since.is_none() {
                Fault::Silent(r.topic.clone())
            } else {
                continue;
            };
            if !s.decided {
                s.decided = true;
                v.push((fault, r.critical));
            }
        }
        v
    }

    /// True while a safe landing ordered in this flight stands.
    pub fn ordered(&self) -> bool {
        self.order == Some(SafetyAction::SafeLand)
    }

    /// The view of the stack for the recorder and `landing status`.
    pub fn view(&self) -> WatchdogView {
        let mut v = WatchdogView {
            count: self.cfg.processes.len().min(MAX_WATCHED) as u32,
            safe_land_ordered: u32::from(self.ordered()),
            faults: self.faults,
            phase: self.phase as u32,
            last_fault_ns: self.last_fault.as_ref().map_or(0, |(t, _)| *t),
            order_ns: self.order_ns,
            last_fault: Text::new(self.last_fault.as_ref().map_or("", |(_, f)| f)),
            action: Text::new(&self.action),
            ..WatchdogView::default()
        };
        for (slot, (w, p)) in v
            .processes
            .iter_mut()
            .zip(self.cfg.processes.iter().zip(&self.processes))
        {
            *slot = ProcessHealth {
                name: Text::new(&w.name),
                liveness: p.liveness as u32,
                missed_deadlines: p.missed,
                restarts: p.restarts,
                last_heartbeat_ns: p.last_beat_ns.unwrap_or(0),
                fault_ns: p.fault_ns.unwrap_or(0),
                cpu_ns: p.cpu.map_or(0, |(_, c)| c),
                cpu_percent: p.cpu_percent,
                rejoined_ns: p.rejoined_ns,
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
