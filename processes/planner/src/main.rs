//! `planner` binary (placeholder until the IPC binding lands).
fn main() {}
