//! The benchmarks of `landing bench`: each measures one claim of the README on this
//! machine and prints it (a table, or one JSON object with `--json`). What each measures
//! and against what baseline is its module's doc; the figures and the commands that make
//! them are in the README.

pub mod aruco;
pub mod depth;
pub mod faults;
pub mod ipc;
pub mod latency;
pub mod perception;
pub mod planner;
pub mod recorder;
pub mod sim;
