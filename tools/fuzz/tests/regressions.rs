//! `landing-fuzz` as CI runs it, briefly: every target over its seeds, the inputs that
//! once failed (tools/fuzz/regressions/) and a short run of mutations, with the bounded
//! allocator and the hang watchdog on. Zero failures; the exec counts are reported.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::process::Command;

use serde_json::Value;

fn fuzz(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_landing-fuzz"))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn every_target_runs_its_seeds_and_regressions_without_a_failure() {
    let dir = std::env::temp_dir().join(format!("landing-fuzz-test-{}", std::process::id()));
    let o = fuzz(&[
        "--seconds",
        "0.3",
        "--seed",
        "1",
        "--json",
        "--crash-dir",
        dir.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let rows: Vec<Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let names: Vec<&str> = fuzz::TARGETS.iter().map(|t| t.name).collect();
    assert_eq!(
        rows.iter()
            .map(|r| r["target"].as_str().unwrap())
            .collect::<Vec<_>>(),
        names
    );
    for r in &rows {
        assert_eq!(r["failures"], 0, "{r}");
        assert!(r["execs"].as_u64().unwrap() > 0, "{r}");
    }
    // The MCAP inputs that made `landing mcap info` abort on an exabyte allocation.
    let mcap = rows.iter().find(|r| r["target"] == "mcap").unwrap();
    assert!(mcap["regressions"].as_u64().unwrap() >= 6, "{mcap}");
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

#[test]
fn a_target_that_does_not_exist_is_one_line_naming_the_targets() {
    let o = fuzz(&["--target", "nope"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        err.contains("mavlink-stream") && err.contains("depth-frame"),
        "{err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(fuzz(&["--help"]).status.success());
}

#[test]
fn an_input_that_allocates_without_bound_fails_the_run_and_is_saved() {
    // With a bound of 1 MB, depth-map's own map (a few MB of log-odds) is over it: the
    // fuzzer must report that, not pass.
    let dir = std::env::temp_dir().join(format!("landing-fuzz-bound-{}", std::process::id()));
    let o = fuzz(&[
        "--target",
        "depth-frame",
        "--seconds",
        "0.1",
        "--max-alloc-mb",
        "1",
        "--crash-dir",
        dir.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(dir.join("depth-frame-oversize").is_file());
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}
