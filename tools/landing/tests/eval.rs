#![allow(clippy::unwrap_used, clippy::expect_used)]
//! `landing eval`: a small campaign of two scenarios through the same code a 300-run one
//! takes: worker processes, shards, a resumed shard, a merge, and what it refuses.

mod common;

use std::path::{Path, PathBuf};

use serde_json::Value;

fn landing(args: &[&str]) -> std::process::Output {
    common::landing_env(args, &[("LANDING_LOG", "error")])
}

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("landing-eval-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn ok_json(args: &[&str]) -> Value {
    let o = landing(args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{args:?}: {err}");
    serde_json::from_slice(&o.stdout).unwrap_or_else(|e| panic!("{e}: {err}"))
}

/// The table without the planning times (wall-clock, different in every flight).
fn without_timing(mut table: Value) -> Value {
    for (_, s) in table.as_object_mut().unwrap() {
        let s = s.as_object_mut().unwrap();
        s.retain(|k, _| !k.starts_with("planning_time"));
    }
    table
}

/// Every run file under `d`, by its path below `d`, with its bytes.
fn run_files(d: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    for s in std::fs::read_dir(d).unwrap().flatten() {
        if !s.path().is_dir() {
            continue;
        }
        for f in std::fs::read_dir(s.path()).unwrap().flatten() {
            let p = f.path();
            let name = p.file_name().unwrap().to_str().unwrap().to_string();
            if name.starts_with("run-") && !name.ends_with(".timing.json") {
                out.push((
                    p.strip_prefix(d).unwrap().to_path_buf(),
                    std::fs::read(&p).unwrap(),
                ));
            }
        }
    }
    out.sort();
    out
}

const TWO: &str = "indoor-static,indoor-moving";

#[test]
fn three_shards_and_a_merge_give_the_unsharded_table_and_the_same_run_files() {
    // The whole campaign with two workers.
    let whole = dir("whole");
    let w = whole.to_str().unwrap();
    let table = ok_json(&[
        "eval",
        "--scenarios",
        TWO,
        "--runs",
        "2",
        "--jobs",
        "2",
        "--out",
        w,
        "--json",
        "--tracks",
        "0",
    ]);
    for name in ["indoor-static", "indoor-moving"] {
        assert_eq!(table[name]["runs"], 2, "{table}");
    }
    // Three shards with one worker each, into one directory, then merged.
    let shards = dir("shards");
    let s = shards.to_str().unwrap();
    for k in ["1/3", "2/3", "3/3"] {
        ok_json(&[
            "eval",
            "--scenarios",
            TWO,
            "--runs",
            "2",
            "--jobs",
            "1",
            "--out",
            s,
            "--shard",
            k,
            "--json",
            "--tracks",
            "0",
        ]);
    }
    let merged = ok_json(&["eval", "merge", s, "--expect", "2", "--json"]);
    assert_eq!(without_timing(merged), without_timing(table));
    // One worker or two, a shard or the whole: each run's file is the same, byte for byte.
    let (a, b) = (run_files(&whole), run_files(&shards));
    assert_eq!(a.len(), 4);
    assert_eq!(a, b);
    // The figures are there.
    for f in [
        "indoor-static-touchdowns.png",
        "indoor-moving-error-cdf.png",
    ] {
        assert!(whole.join("plots").join(f).is_file(), "{f}");
    }
}

#[test]
fn a_resumed_shard_flies_only_the_runs_that_are_missing() {
    let d = dir("resume");
    let p = d.to_str().unwrap();
    let args = |shard: Option<&str>| {
        let mut a = vec![
            "eval",
            "--scenarios",
            "indoor-static",
            "--runs",
            "2",
            "--jobs",
            "1",
            "--out",
            p,
            "--tracks",
            "0",
            "--json",
        ];
        if let Some(s) = shard {
            a.extend(["--shard", s]);
        }
        a.iter().map(|s| s.to_string()).collect::<Vec<_>>()
    };
    let first = args(Some("1/2"));
    let first: Vec<&str> = first.iter().map(String::as_str).collect();
    ok_json(&first);
    let before = run_files(&d);
    assert_eq!(before.len(), 1);
    let stamp = std::fs::metadata(d.join(&before[0].0))
        .unwrap()
        .modified()
        .unwrap();
    let whole = args(None);
    let whole: Vec<&str> = whole.iter().map(String::as_str).collect();
    let o = landing(&whole);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("1 to fly, 1 already in"), "{err}");
    assert_eq!(
        std::fs::metadata(d.join(&before[0].0))
            .unwrap()
            .modified()
            .unwrap(),
        stamp,
        "the run already there was flown again"
    );
    assert_eq!(run_files(&d).len(), 2);
}

fn refused(args: &[&str], says: &str) {
    let o = landing(args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
    assert_eq!(err.trim().lines().count(), 1, "{args:?}: {err}");
    assert!(err.contains(says), "{args:?}: {err}");
}

#[test]
fn bad_input_is_one_line_and_exit_2() {
    let d = dir("bad");
    let p = d.to_str().unwrap();
    refused(
        &["eval", "--scenarios", "no-such-scenario", "--out", p],
        "no-such-scenario",
    );
    refused(
        &["eval", "--runs", "0", "--out", p],
        "--runs 0 is not allowed",
    );
    refused(&["eval", "--shard", "0/3", "--out", p], "allowed: K/N");
    refused(&["eval", "--shard", "4/3", "--out", p], "allowed: K/N");
    refused(
        &["eval", "--jobs", "0", "--out", p],
        "--jobs 0 is not allowed",
    );
}

/// A run file as `landing eval` writes it, for the merge's refusals (no flight needed).
fn run_file(d: &Path, scenario: &str, index: u64, config_hash: &str) {
    let v = serde_json::json!({
        "format": "landing-eval-run/1", "scenario": scenario, "scenario_hash": "s",
        "index": index, "seed": 7 + index, "config_hash": config_hash, "revision": "r",
        "outcome": "landed", "referee": "at rest on the pad", "touchdown_error_m": 0.02,
        "touchdown_pad_m": [0.01, 0.0], "touchdown_rel_speed_mps": 0.1,
        "contact_vertical_mps": 0.7, "contact_horizontal_mps": 0.05, "contact_tilt_deg": 1.0,
        "flight_time_s": 10.0, "distance_m": 3.0, "target_speed_kmh": null,
        "collisions": null, "replans": 0
    });
    let p = d.join(scenario).join(format!("run-{index:06}.json"));
    std::fs::create_dir_all(p.parent().unwrap()).unwrap();
    std::fs::write(p, v.to_string()).unwrap();
}

#[test]
fn a_merge_refuses_two_configs_a_missing_or_twice_given_run_and_a_file_not_ours() {
    let (a, b) = (dir("merge-a"), dir("merge-b"));
    run_file(&a, "paper-sim", 0, "h1");
    run_file(&b, "paper-sim", 1, "h2");
    let (pa, pb) = (a.to_str().unwrap(), b.to_str().unwrap());
    refused(&["eval", "merge", pa, pb], "different stack configurations");
    run_file(&b, "paper-sim", 1, "h1");
    refused(
        &["eval", "merge", pa, pb, "--expect", "3"],
        "1 runs missing: 2",
    );
    // Both shards hold run 0.
    run_file(&b, "paper-sim", 0, "h1");
    refused(
        &["eval", "merge", pa, pb],
        "run 0 of paper-sim is there twice",
    );
    std::fs::write(b.join("paper-sim").join("run-000000.json"), "{\"x\": 1}").unwrap();
    refused(
        &["eval", "merge", pa, pb],
        "not a run file of `landing eval`",
    );
    // And the two good shards merge.
    run_file(&b, "paper-sim", 0, "h1");
    std::fs::remove_file(a.join("paper-sim").join("run-000000.json")).unwrap();
    let t = ok_json(&["eval", "merge", pa, pb, "--expect", "2", "--json"]);
    assert_eq!(t["paper-sim"]["landed"], 2, "{t}");
}
