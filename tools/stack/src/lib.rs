//! The stack as one thing to build and run: its configuration ([`config`]), the stage of
//! every graph node built from it ([`lockstep`]'s registry), the lockstep runner (every
//! stage and the simulator in one process on simulated time) and the process runner
//! ([`processes`]: every stage its own OS process, as systemd starts them), and the
//! faults done to a running stack ([`inject`], [`flood`]), and one stage of a recorded
//! flight run again on the lockstep driver ([`replay`]).
//!
//! The referee (`evaluation`) judges the flights these runners fly; the `landing`
//! command, the benchmarks, the campaigns and the tests all run missions through here.

pub mod config;
pub mod doctor;
pub mod flood;
pub mod inject;
pub mod lockstep;
pub mod map_pilot;
pub mod mapping;
pub mod mission;
pub mod processes;
pub mod procs;
pub mod px4_sitl;
pub mod replay;
pub mod router;

pub use config::StackConfig;
