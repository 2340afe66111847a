//! The evaluator's record of one flight, and the summary of it a user reads.
//!
//! A [`FlightLog`] holds ground truth (where the vehicle and the pad really were): only the
//! evaluator (`landing run`) sees it, never a pipeline process. [`RunSummary`] condenses it
//! into the numbers the paper reports (touchdown error, distance, speeds, planning time),
//! printed at the end of a run and written as JSON with `--json`.

use std::fmt;

use serde::Serialize;

use crate::stats::percentile;

/// UAV height above its starting height that counts as airborne, m: take-off is the
/// last sample before the vehicle first rises this far (ground contact jitter stays below).
pub const TAKEOFF_RISE_M: f64 = 0.1;
/// Pad vehicle speed above which it counts as moving, m/s (for the target speed).
pub const MOVING_SPEED_MPS: f64 = 0.05;
/// Metres per second to kilometres per hour.
const KMH_PER_MPS: f64 = 3.6;

/// The true state of the flight at one instant (world ENU, metres, seconds).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FlightSample {
    /// Simulated time since the start of the run, s.
    pub t_s: f64,
    /// UAV position (body origin), world ENU, m.
    pub uav: [f64; 3],
    /// Landing point (pad centre) on the ground vehicle, world ENU, m; `None` when the
    /// scenario has no pad vehicle.
    pub ugv_pad: Option<[f64; 3]>,
    /// The mission state machine's state name at this instant (colours the plots).
    pub phase: String,
    /// UAV velocity, world, m/s.
    pub uav_velocity: [f64; 3],
    /// Pad vehicle velocity, world, m/s; `None` when there is none (then the target speed is
    /// taken from successive `ugv_pad` positions).
    pub ugv_velocity: Option<[f64; 3]>,
}

/// Where and how the vehicle touched down, from the simulator's truth.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Touchdown {
    /// When, s since the start of the run.
    pub t_s: f64,
    /// UAV position at touchdown, world, m.
    pub uav: [f64; 3],
    /// Pad centre at touchdown, world, m.
    pub pad: [f64; 3],
    /// Horizontal distance from the UAV to the pad centre, m.
    pub error_m: f64,
    /// Speed of the UAV relative to the surface it touched, m/s.
    pub rel_speed_mps: f64,
    /// True when it came down on the pad (not the ground).
    pub on_pad: bool,
}

/// The whole flight as the evaluator saw it: what the plots and the summary are made of.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct FlightLog {
    /// Scenario name.
    pub scenario: String,
    /// Seed of every random process of the run.
    pub seed: u64,
    /// Truth samples, in time order.
    pub samples: Vec<FlightSample>,
    /// Obstacles as axis-aligned boxes (min corner, max corner), world, m.
    pub obstacles: Vec<([f64; 3], [f64; 3])>,
    /// The touchdown, when there was one.
    pub touchdown: Option<Touchdown>,
    /// The first contact of the final landing (speeds and tilt the referee judged).
    pub contact: Option<TouchdownContact>,
}

/// How the final landing first met its surface, relative to it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TouchdownContact {
    /// Speed along the surface normal, m/s.
    pub vertical_speed_mps: f64,
    /// Speed along the surface, m/s.
    pub horizontal_speed_mps: f64,
    /// Angle between body up and the surface normal, deg.
    pub tilt_deg: f64,
}

/// How a run ended, as the summary names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    /// At rest on the pad at the end, disarmed, every foot on the board.
    Landed,
    /// A touchdown beyond the referee's speed or tilt limits.
    HardLanding,
    /// The fsm said Landed but the vehicle ended elsewhere (beside the pad, over the
    /// board's edge, sliding, still armed).
    OffPad,
    /// Landed in place (off the pad) after a failure: vehicle safe, mission not done.
    SafeLanded,
    /// Hit something or came down hard.
    Crashed,
    /// Neither landed nor crashed within the time limit.
    Timeout,
    /// Stopped by SIGINT (Ctrl-C) or SIGTERM before it ended.
    Interrupted,
    /// The simulator's process exited during the mission (`--processes`).
    ProcessDied,
}

impl Outcome {
    /// The name used in JSON and in the terminal.
    pub fn name(self) -> &'static str {
        match self {
            Self::Landed => "landed",
            Self::HardLanding => "hard_landing",
            Self::OffPad => "off_pad",
            Self::SafeLanded => "safe_landed",
            Self::Crashed => "crashed",
            Self::Timeout => "timeout",
            Self::Interrupted => "interrupted",
            Self::ProcessDied => "process_died",
        }
    }
}

impl fmt::Display for Outcome {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The end-of-run numbers (the paper's "key flight data"), printed and written as JSON.
///
/// Fields that do not apply are `None` (JSON `null`): no touchdown, no pad vehicle, no
/// planning call, no obstacles to collide with.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunSummary {
    /// Scenario name.
    pub scenario: String,
    /// Seed of the run.
    pub seed: u64,
    /// How it ended.
    pub outcome: Outcome,
    /// Horizontal distance from the UAV to the pad centre at touchdown, m.
    pub touchdown_error_m: Option<f64>,
    /// UAV speed relative to the surface at touchdown, m/s.
    pub touchdown_rel_speed_mps: Option<f64>,
    /// Speed along the surface normal at the final landing's first contact, m/s.
    pub touchdown_vertical_speed_mps: Option<f64>,
    /// Speed along the surface there, m/s.
    pub touchdown_horizontal_speed_mps: Option<f64>,
    /// Tilt from the surface normal there, deg.
    pub touchdown_tilt_deg: Option<f64>,
    /// The referee's reason for the outcome, one line.
    pub referee: String,
    /// Take-off to touchdown (or to the end of the log), s.
    pub flight_time_s: f64,
    /// UAV path length from take-off to touchdown, m.
    pub distance_m: f64,
    /// Mean pad vehicle speed while it moves, km/h (0 when it never moves).
    pub target_speed_kmh: Option<f64>,
    /// Highest UAV speed in flight, km/h.
    pub uav_max_speed_kmh: f64,
    /// distance / flight time, km/h (the paper's "average speed").
    pub uav_avg_speed_kmh: f64,
    /// Median planning call, ms.
    pub planning_time_ms_p50: Option<f64>,
    /// Slowest planning call, ms.
    pub planning_time_ms_max: Option<f64>,
    /// Plans after the first.
    pub replans: u32,
    /// Obstacle contacts; `None` when not counted (no obstacles).
    pub collisions: Option<u32>,
    /// Faults done to the stack's processes (`--inject`) or processes that exited on
    /// their own during the run (`--processes`).
    pub faults: Vec<FaultRecord>,
    /// `--router`: the datagrams through the MAVLink router, per endpoint, and what the
    /// second ground station sent and heard.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub router: Option<serde_json::Value>,
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    norm([a[0] - b[0], a[1] - b[1], a[2] - b[2]])
}

impl FlightLog {
    /// Index of the take-off sample: the last one before the UAV first rises
    /// [`TAKEOFF_RISE_M`] above its starting height; `None` when it never does.
    pub fn takeoff_index(&self) -> Option<usize> {
        let z0 = self.samples.first()?.uav[2];
        let i = self
            .samples
            .iter()
            .position(|s| s.uav[2] > z0 + TAKEOFF_RISE_M)?;
        Some(i.saturating_sub(1))
    }

    /// The samples of the flight proper: take-off to touchdown (or to the end of the log).
    pub fn flight_samples(&self) -> &[FlightSample] {
        let Some(start) = self.takeoff_index() else {
            return &[];
        };
        let end = match &self.touchdown {
            Some(td) => self.samples.partition_point(|s| s.t_s <= td.t_s),
            None => self.samples.len(),
        };
        self.samples.get(start..end.max(start)).unwrap_or(&[])
    }

    /// Mean speed of the pad vehicle over the samples where it moves, m/s; `None` without
    /// a pad vehicle, 0 when it never moves.
    pub fn target_speed_mps(&self) -> Option<f64> {
        let mut speeds = Vec::new();
        let mut prev: Option<(f64, [f64; 3])> = None;
        for s in &self.samples {
            let Some(pad) = s.ugv_pad else {
                prev = None;
                continue;
            };
            let v = match (s.ugv_velocity, prev) {
                (Some(v), _) => Some(norm(v)),
                (None, Some((t0, p0))) if s.t_s > t0 => Some(dist(pad, p0) / (s.t_s - t0)),
                _ => None,
            };
            speeds.extend(v);
            prev = Some((s.t_s, pad));
        }
        if speeds.is_empty() {
            // A pad seen in only one sample and no velocity: it is there, not moving.
            return self
                .samples
                .iter()
                .any(|s| s.ugv_pad.is_some())
                .then_some(0.0);
        }
        let moving: Vec<f64> = speeds
            .into_iter()
            .filter(|v| *v > MOVING_SPEED_MPS)
            .collect();
        if moving.is_empty() {
            return Some(0.0);
        }
        Some(moving.iter().sum::<f64>() / moving.len() as f64)
    }
}

impl RunSummary {
    /// Condenses a flight: distance and flight time from take-off to touchdown, speeds
    /// from the truth velocities, planning time percentiles from `planning_times_ms`
    /// (one entry per planning call; non-finite entries are ignored).
    pub fn from_log(
        log: &FlightLog,
        outcome: Outcome,
        planning_times_ms: &[f64],
        replans: u32,
        collisions: Option<u32>,
    ) -> Self {
        let flight = log.flight_samples();
        let distance_m: f64 = flight.windows(2).map(|w| dist(w[0].uav, w[1].uav)).sum();
        let flight_time_s = match (flight.first(), &log.touchdown, flight.last()) {
            (Some(first), Some(td), _) => (td.t_s - first.t_s).max(0.0),
            (Some(first), None, Some(last)) => last.t_s - first.t_s,
            _ => 0.0,
        };
        let max_mps = flight
            .iter()
            .map(|s| norm(s.uav_velocity))
            .filter(|v| v.is_finite())
            .fold(0.0, f64::max);
        let avg_mps = if flight_time_s > 0.0 {
            distance_m / flight_time_s
        } else {
            0.0
        };
        let plans: Vec<f64> = planning_times_ms
            .iter()
            .copied()
            .filter(|v| v.is_finite())
            .collect();
        let (p50, pmax) = if plans.is_empty() {
            (None, None)
        } else {
            (
                Some(percentile(&plans, 50.0)),
                Some(plans.iter().copied().fold(f64::MIN, f64::max)),
            )
        };
        Self {
            scenario: log.scenario.clone(),
            seed: log.seed,
            outcome,
            touchdown_error_m: log.touchdown.as_ref().map(|t| t.error_m),
            touchdown_rel_speed_mps: log.touchdown.as_ref().map(|t| t.rel_speed_mps),
            touchdown_vertical_speed_mps: log.contact.map(|c| c.vertical_speed_mps),
            touchdown_horizontal_speed_mps: log.contact.map(|c| c.horizontal_speed_mps),
            touchdown_tilt_deg: log.contact.map(|c| c.tilt_deg),
            referee: String::new(),
            flight_time_s,
            distance_m,
            target_speed_kmh: log.target_speed_mps().map(|v| v * KMH_PER_MPS),
            uav_max_speed_kmh: max_mps * KMH_PER_MPS,
            uav_avg_speed_kmh: avg_mps * KMH_PER_MPS,
            planning_time_ms_p50: p50,
            planning_time_ms_max: pmax,
            replans,
            collisions,
            faults: Vec::new(),
            router: None,
        }
    }
}

/// `value unit` with `decimals`, or "n/a".
fn opt(v: Option<f64>, decimals: usize, unit: &str) -> String {
    match v {
        Some(v) => format!("{v:.decimals$} {unit}"),
        None => "n/a".to_string(),
    }
}

impl fmt::Display for RunSummary {
    /// The end-of-run summary for the terminal, one fact per line.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let verdict = match self.outcome {
            Outcome::Landed => "LANDED on the pad",
            Outcome::HardLanding => "HARD LANDING",
            Outcome::OffPad => "OFF THE PAD",
            Outcome::SafeLanded => "SAFE LANDING (not on the pad)",
            Outcome::Crashed => "CRASHED",
            Outcome::Timeout => "TIMEOUT (no landing)",
            Outcome::Interrupted => "INTERRUPTED",
            Outcome::ProcessDied => "A PROCESS DIED",
        };
        writeln!(f, "scenario    {} (seed {})", self.scenario, self.seed)?;
        writeln!(f, "outcome     {verdict}: {}", self.referee)?;
        writeln!(
            f,
            "touchdown   error {}, relative speed {}; first contact {} down, {} sideways, tilt {}",
            opt(self.touchdown_error_m, 3, "m"),
            opt(self.touchdown_rel_speed_mps, 2, "m/s"),
            opt(self.touchdown_vertical_speed_mps, 2, "m/s"),
            opt(self.touchdown_horizontal_speed_mps, 2, "m/s"),
            opt(self.touchdown_tilt_deg, 1, "deg")
        )?;
        writeln!(
            f,
            "flight      {:.1} s, {:.1} m",
            self.flight_time_s, self.distance_m
        )?;
        writeln!(
            f,
            "speed       UAV max {:.1} km/h, avg {:.1} km/h; target {}",
            self.uav_max_speed_kmh,
            self.uav_avg_speed_kmh,
            opt(self.target_speed_kmh, 1, "km/h")
        )?;
        writeln!(
            f,
            "planning    p50 {}, max {}, {} replans",
            opt(self.planning_time_ms_p50, 2, "ms"),
            opt(self.planning_time_ms_max, 2, "ms"),
            self.replans
        )?;
        match self.collisions {
            Some(n) => write!(f, "collisions  {n}"),
            None => write!(f, "collisions  n/a (no obstacles)"),
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
    /// A `restart`: how long from the kill until the new process's first heartbeat
    /// reached the watchdog (back in the graph), ms; else `null`.
    pub rejoined_after_ms: Option<f64>,
    /// Datagrams sent at px4-link's port (`garbage`, `flood`), else `null`.
    pub datagrams_sent: Option<u64>,
    /// Monotonic time of the fault, ns (not in the summary).
    #[serde(skip)]
    pub at_ns: u64,
    /// The run's outcome.
    pub outcome: String,
}

#[cfg(test)]
#[path = "flight_log_test.rs"]
mod tests;
