#![allow(clippy::unwrap_used, clippy::expect_used)]
//! The `fsm` binary: a user mistake is one line naming what is wrong and what is
//! allowed, exit code 2. (The binary flying a mission with the rest of the stack is
//! `landing run --processes`, tested in tools/landing/tests/run.rs.)

use std::process::Command;

fn fsm(args: &[&str]) -> (Option<i32>, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_fsm"))
        .args(args)
        .args(["--ipc-prefix", &format!("fsmtest{}_", std::process::id())])
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).to_string(),
    )
}

#[test]
fn a_preset_that_is_not_three_numbers_is_one_line_and_exit_2() {
    let (code, err) = fsm(&["--preset=1,2"]);
    assert_eq!(code, Some(2), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("--preset") && err.contains("allowed"), "{err}");
}

#[test]
fn a_preset_below_the_minimum_height_is_refused_by_name() {
    let (code, err) = fsm(&["--preset=0,0,0.1"]);
    assert_eq!(code, Some(2), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("preset_m[2]"), "{err}");
}

#[test]
fn a_bad_config_value_is_one_line_naming_the_key() {
    let dir = std::env::temp_dir().join(format!("fsm-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("bad.toml");
    std::fs::write(&p, "[ipc]\nprefix = \"landing_\"\nheartbeat_period_ms = 100\nheartbeat_deadline_ms = 500\n[fsm]\ncommit_height_m = -1.0\n").unwrap();
    let (code, err) = fsm(&["--config", p.to_str().unwrap()]);
    assert_eq!(code, Some(2), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("commit_height_m"), "{err}");
}
