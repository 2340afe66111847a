//! The evaluator of `landing run`: the only part that reads the simulator's ground
//! truth (where the vehicle and the pad really are, touchdowns, collisions, crashes).

use ipc_types::msg::{MissionState, TruthEvent, TruthKind, TruthState};
use sim::lockstep::Simulator;

/// The world at one instant, for the flight log and the plots.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Simulated time, s.
    pub t_s: f64,
    /// True vehicle position, world ENU, m.
    pub uav: [f64; 3],
    /// True vehicle velocity, m/s.
    pub uav_velocity: [f64; 3],
    /// True pad centre, m (None without a ground vehicle).
    pub pad: Option<[f64; 3]>,
    /// True pad velocity, m/s.
    pub pad_velocity: Option<[f64; 3]>,
    /// The fsm's state.
    pub phase: MissionState,
}

impl Sample {
    /// The truth now, from the simulator in this process.
    pub fn of(sim: &Simulator, phase: MissionState) -> Self {
        Self::from_truth(&sim::lockstep::truth_state(sim, sim.time_ns()), phase)
    }

    /// The truth the `sim` process published (`landing/sim/truth_state`).
    pub fn from_truth(s: &TruthState, phase: MissionState) -> Self {
        let pad = s.pad_valid != 0;
        Self {
            t_s: s.sim_time_ns as f64 * 1e-9,
            uav: s.vehicle_position,
            uav_velocity: s.vehicle_velocity,
            pad: pad.then_some(s.pad_position),
            pad_velocity: pad.then_some(s.pad_velocity),
            phase,
        }
    }
}

/// Horizontal distance from the vehicle to the pad, m (`None` without a pad).
pub fn distance_to_pad(s: &TruthState) -> Option<f64> {
    (s.pad_valid != 0).then(|| {
        let (u, p) = (s.vehicle_position, s.pad_position);
        (u[0] - p[0]).hypot(u[1] - p[1])
    })
}

/// True for the simulator's crash event.
pub fn is_crash(t: &TruthEvent) -> bool {
    t.kind == TruthKind::Crash as u32
}

/// A touchdown as the simulator saw it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Touchdown {
    /// When, s.
    pub t_s: f64,
    /// On the pad (not the ground).
    pub on_pad: bool,
    /// Horizontal distance from the pad centre, m.
    pub error_m: f64,
    /// Speed relative to the surface, m/s.
    pub rel_speed_mps: f64,
    /// The fsm's state at that moment.
    pub phase: MissionState,
}

/// Collects the truth during a run.
#[derive(Debug, Clone, Default)]
pub struct Evaluator {
    /// Samples at 20 Hz.
    pub samples: Vec<Sample>,
    /// Every touchdown.
    pub touchdowns: Vec<Touchdown>,
    /// Obstacle collisions.
    pub collisions: u32,
    /// Crash reasons.
    pub crashes: Vec<String>,
}

impl Evaluator {
    /// Takes in one truth event, with the fsm's state at that moment.
    pub fn on_truth(&mut self, t: &TruthEvent, phase: MissionState) {
        match TruthKind::from_raw(t.kind) {
            Some(TruthKind::Touchdown) => {
                let [x, y] = t.rel_position_pad;
                let v = t.rel_velocity;
                self.touchdowns.push(Touchdown {
                    t_s: t.msg.capture_ns as f64 * 1e-9,
                    on_pad: t.on_pad != 0,
                    error_m: x.hypot(y),
                    rel_speed_mps: (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt(),
                    phase,
                });
            }
            Some(TruthKind::Collision) => self.collisions += 1,
            Some(TruthKind::Crash) => self.crashes.push(t.reason.as_str().to_string()),
            _ => {}
        }
    }

    /// Keeps one sample.
    pub fn sample(&mut self, s: Sample) {
        self.samples.push(s);
    }

    /// The touchdown that ended the mission: the last one on the pad, else the last one
    /// after take-off.
    pub fn final_touchdown(&self) -> Option<&Touchdown> {
        let flown = |t: &&Touchdown| t.phase != MissionState::Idle;
        self.touchdowns
            .iter()
            .rfind(|t| flown(t) && t.on_pad)
            .or_else(|| self.touchdowns.iter().rfind(flown))
    }
}
