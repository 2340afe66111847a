//! The landing mission: a pad motion filter and the state machine that takes off,
//! finds the pad, tracks it, descends and lands on it while it moves.
//!
//! Pure library: time and messages in, setpoints, goals, requests and status out. The
//! `fsm` binary binds it to iceoryx2; `landing run` steps it in lockstep with the
//! simulator.

pub mod config;
pub mod mission;
pub mod odometry;
pub mod pad_filter;
pub mod relative;
pub mod stage;

pub use config::{FsmConfig, PadFilterConfig, SurveyConfig};
pub use mission::{Fsm, Outputs, Transition};
pub use pad_filter::{PadEstimate, PadFilter, Update};
pub use stage::FsmStage;
