//! What every `landing` CLI test needs: the built binary, run to completion.
#![allow(dead_code)] // each test file uses a part

use std::process::{Command, Output};
use std::sync::{PoisonError, RwLock, RwLockReadGuard, RwLockWriteGuard};

use serde_json::Value;

/// The machine's two cores, shared by the real-time stacks of a test file. Each takes
/// about a core; the harness runs two tests at a time on CI's two cores, and two stacks
/// beside each other starved both (measured: aruco-pnp lost 22-25 states held off the
/// CPU, and paper-sim touched down at 1.03 m/s; a restarted planner's flight 10.2 cm off,
/// where 8 alone landed 1.8-4.7 cm off). A vehicle's computer runs one stack: a flight
/// judged by how it lands has the machine to itself ([`one_stack`], a write lock that
/// waits for the others and holds the next ones off), and so has a flight judged by which
/// fault the watchdog found: starved beside another stack, a process misses its 250 ms
/// heartbeat deadline with nothing injected (a `make test` run: aruco-pnp "hung" in
/// goto-preset before the planner hang the test injected). Flights judged only by how they
/// end share it ([`beside_others`]), and so do lockstep flights in a file with a
/// judged real-time one (run.rs: a lockstep flight takes a core of the two).
static MACHINE: RwLock<()> = RwLock::new(());

/// Holds the machine for one real-time stack, alone, until dropped.
pub fn one_stack() -> RwLockWriteGuard<'static, ()> {
    MACHINE.write().unwrap_or_else(PoisonError::into_inner)
}

/// Holds a share of the machine for a stack judged only by how its run ends.
pub fn beside_others() -> RwLockReadGuard<'static, ()> {
    MACHINE.read().unwrap_or_else(PoisonError::into_inner)
}

/// Touchdown error within which a fault that costs nothing lands, m.
pub const ON_THE_PAD_M: f64 = 0.10;

/// Whether a run summary (or a `landing bench faults` row) came down on the pad: `landed`
/// within [`ON_THE_PAD_M`], or `safe_landed` by the referee's down-after-fault line within
/// it. The referee ends a faulted run as soon as the vehicle is down and disarmed, which on
/// the pad can come a moment before the fsm's own `landed` reaches it (the disarm shows in
/// the 20 Hz truth first): a touchdown its limits passed. The referee is not the stack's to
/// change; the touchdown error decides here.
pub fn landed_on_the_pad(s: &Value) -> bool {
    let down_after_fault = s["outcome"] == "safe_landed"
        && s["referee"] == "down and disarmed after a fault to a process";
    let on_pad = s["touchdown_error_m"]
        .as_f64()
        .is_some_and(|e| e <= ON_THE_PAD_M);
    on_pad && (s["outcome"] == "landed" || down_after_fault)
}

/// Runs the `landing` binary with `args` and waits for it.
pub fn landing(args: &[&str]) -> Output {
    landing_env(args, &[])
}

/// The same with extra environment variables.
pub fn landing_env(args: &[&str], env: &[(&str, &str)]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_landing"))
        .args(args)
        .envs(env.iter().copied())
        .output()
        .expect("run landing")
}

/// The shipped stack configuration's text.
pub fn shipped_config() -> String {
    std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../deploy/config/landing.toml"
    ))
    .expect("deploy/config/landing.toml")
}

/// Writes a stack configuration `text` as `dir/name` with the files it names beside
/// it (the calibrations and the pad layout, copied from deploy/config): a config's
/// files are found relative to it, wherever it is.
pub fn write_config(dir: &std::path::Path, name: &str, text: &str) -> std::path::PathBuf {
    let config = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../deploy/config"));
    std::fs::create_dir_all(dir).expect("config dir");
    for entry in std::fs::read_dir(config).expect("deploy/config").flatten() {
        let p = entry.path();
        let ext = p.extension().and_then(|e| e.to_str()).unwrap_or("");
        let is_pad = p.file_name().is_some_and(|n| n == "pad.toml");
        if ext == "yaml" || is_pad {
            std::fs::copy(&p, dir.join(entry.file_name())).expect("copy a config file");
        }
    }
    let path = dir.join(name);
    std::fs::write(&path, text).expect("write config");
    path
}
