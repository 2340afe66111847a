//! Misbehaving stages for fault tests, as dora-rs keeps in its own: a stage that panics,
//! one that hangs, one that fails with an error, one that publishes NaN, one that
//! publishes in bursts. Each stands in for a node of the shipped graph (aruco-pnp: its
//! inputs and its one output), so the runtime serves it and the watchdog watches it as
//! the real one; the tests check what the runtime and the watchdog make of it
//! (`tests/misbehaving.rs`).

use ipc_types::msg::{Header, PadObservation, Pose};
use ipc_types::topics;
use stage::{Counter, Input, Message, Outbox, Stage, StageError};

/// What goes wrong, after `after` ticks of 20 ms.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Misbehaviour {
    /// The stage panics.
    Panic,
    /// The stage never returns (a deadlock, an endless loop).
    Hang,
    /// The stage returns an error.
    Fail,
    /// Every tick publishes a pad observation full of NaN.
    Nan,
    /// Every tick publishes three good observations at once (with a delay fault on its
    /// output, one round waits three delays).
    Burst,
}

impl std::str::FromStr for Misbehaviour {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Ok(match s {
            "panic" => Self::Panic,
            "hang" => Self::Hang,
            "fail" => Self::Fail,
            "nan" => Self::Nan,
            "burst" => Self::Burst,
            _ => return Err(format!("`{s}` (allowed: panic, hang, fail, nan, burst)")),
        })
    }
}

/// The stage: ticks every 20 ms, then misbehaves.
#[derive(Debug)]
pub struct Misbehaving {
    what: Misbehaviour,
    after: u64,
    ticks: u64,
}

impl Misbehaving {
    /// Misbehaves by `what` from tick `after` on.
    pub fn new(what: Misbehaviour, after: u64) -> Self {
        Self {
            what,
            after,
            ticks: 0,
        }
    }
}

impl Stage for Misbehaving {
    fn name(&self) -> &'static str {
        "aruco-pnp"
    }

    fn tick_period_ns(&self) -> Option<u64> {
        Some(20_000_000)
    }

    fn on_input(
        &mut self,
        _now_ns: u64,
        _input: Input<'_>,
        _out: &mut dyn Outbox,
    ) -> Result<(), StageError> {
        Ok(())
    }

    #[allow(clippy::panic)] // the misbehaviour under test
    fn on_tick(&mut self, now_ns: u64, out: &mut dyn Outbox) -> Result<(), StageError> {
        self.ticks += 1;
        if self.ticks < self.after {
            return Ok(());
        }
        match self.what {
            Misbehaviour::Panic => panic!("misbehaving stage: panic at tick {}", self.ticks),
            Misbehaviour::Hang => loop {
                std::thread::sleep(std::time::Duration::from_secs(3600));
            },
            Misbehaviour::Fail => Err(StageError::Failed(format!(
                "misbehaving stage: error at tick {}",
                self.ticks
            ))),
            Misbehaviour::Nan => {
                let nan = Pose {
                    translation: [f64::NAN; 3],
                    rotation_xyzw: [f64::NAN; 4],
                };
                let obs = PadObservation {
                    msg: Header::captured_at(now_ns),
                    camera_from_pad: nan,
                    world_from_pad: nan,
                    world_valid: 1,
                    marker_count: 1,
                    ..PadObservation::default()
                };
                out.publish(topics::PAD_OBSERVATION, Message::PadObservation(&obs))
            }
            Misbehaviour::Burst => {
                let obs = PadObservation {
                    msg: Header::captured_at(now_ns),
                    marker_count: 1,
                    ..PadObservation::default()
                };
                for _ in 0..3 {
                    out.publish(topics::PAD_OBSERVATION, Message::PadObservation(&obs))?;
                }
                Ok(())
            }
        }
    }

    fn counters(&self) -> Vec<Counter> {
        vec![("ticks", self.ticks)]
    }
}
