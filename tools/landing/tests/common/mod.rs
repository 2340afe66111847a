//! What every `landing` CLI test needs: the built binary, run to completion.
#![allow(dead_code)] // each test file uses a part

use std::process::{Command, Output};
use std::sync::{Mutex, MutexGuard, PoisonError};

/// One stack of OS processes flying in real time at once within a test file. Each takes
/// about a core; the harness runs two tests at a time on CI's two cores, and two stacks
/// beside each other starved both (measured: aruco-pnp lost 22-25 states held off the
/// CPU, and paper-sim touched down at 1.03 m/s). A vehicle's computer runs one stack; a
/// lockstep flight beside it stays as the load.
static ONE_STACK: Mutex<()> = Mutex::new(());

/// Holds the machine for one real-time stack until dropped.
pub fn one_stack() -> MutexGuard<'static, ()> {
    ONE_STACK.lock().unwrap_or_else(PoisonError::into_inner)
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
