//! What every `landing` CLI test needs: the built binary, run to completion.
#![allow(dead_code)] // each test file uses a part

use std::process::{Command, Output};

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
