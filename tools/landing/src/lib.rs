//! The `landing` command's library: the mission runners (lockstep and processes), the
//! referee, benchmarks, plots, recordings and tools, so that tests and other tools can
//! run a mission with stages of their own (`run_lockstep::driver`'s `extra`) rather than
//! only through the command line.

pub mod bench_aruco;
pub mod bench_depth;
pub mod bench_faults;
pub mod bench_ipc;
pub mod bench_latency;
pub mod bench_perception;
pub mod bench_planner;
pub mod bench_recorder;
pub mod bench_sim;
pub mod config_cmd;
pub mod flight_log;
pub mod flood;
pub mod graph_cmd;
pub mod inject;
pub mod inject_cmd;
pub mod latency_cmd;
pub mod latency_live;
pub mod link_cmd;
pub mod map_cmd;
pub mod map_pilot;
pub mod pad_detect;
pub mod pad_print;
pub mod plan_cmd;
pub mod plot;
pub mod plot_cmd;
pub mod procs;
pub mod replay_cmd;
pub mod replay_depth;
pub mod replay_fsm;
pub mod replay_planner;
pub mod run_cmd;
pub mod run_eval;
pub mod run_lockstep;
pub mod run_processes;
pub mod stats;
pub mod status_cmd;
