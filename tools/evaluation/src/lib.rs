//! Evaluation: judging a flight from the simulator's ground truth and looking at
//! flights afterwards. The referee ([`referee`]) is the only code that reads the truth;
//! the flight log and its summary ([`flight_log`]) are what it writes; [`plot`] draws
//! them; [`latency`] turns a recording's stage stamps into per-stage and end-to-end
//! latency, and [`latency_live`] does the same on a running stack; [`touchdown`] takes a
//! recorded touchdown apart against the truth.
//!
//! It runs nothing: the stack's runners (`stack`) call the referee as a mission flies,
//! and campaigns, benchmarks and the `landing` command read what it keeps.

pub mod flight_log;
pub mod latency;
pub mod latency_live;
pub mod plot;
pub mod referee;
pub mod stats;
pub mod touchdown;

pub use flight_log::{FaultRecord, FlightLog, Outcome, RunSummary};
pub use referee::{End, Evaluator, Referee, Rules};
