#![allow(clippy::unwrap_used, clippy::expect_used)]
//! `landing run` however it is stopped: killed outright, interrupted, or losing a stage.
//! No stage process outlives it, nothing of its iceoryx2 prefix stays in /dev/shm or
//! /tmp/iceoryx2, and every end that lets it speak prints its summary.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

mod common;

/// The stage processes of deploy/graph.toml.
const STAGES: usize = 8;

fn prefix(tag: &str) -> String {
    format!("lt_{tag}{}_", std::process::id())
}

/// Process ids whose command line mentions `prefix` (the stages get `--ipc-prefix`).
fn processes_with(prefix: &str) -> Vec<u32> {
    let mut pids = Vec::new();
    for e in std::fs::read_dir("/proc").unwrap().flatten() {
        let Ok(pid) = e.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        if let Ok(cmd) = std::fs::read(e.path().join("cmdline"))
            && String::from_utf8_lossy(&cmd).contains(prefix)
        {
            pids.push(pid);
        }
    }
    pids
}

/// Files of `prefix` in /dev/shm and under /tmp/iceoryx2.
fn files_of(prefix: &str) -> Vec<String> {
    let mut found = Vec::new();
    let mut walk = vec![std::path::PathBuf::from("/dev/shm")];
    walk.push(std::path::PathBuf::from("/tmp/iceoryx2"));
    while let Some(dir) = walk.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                walk.push(p);
            } else if e.file_name().to_string_lossy().starts_with(prefix) {
                found.push(p.display().to_string());
            }
        }
    }
    found
}

fn start(args: &[&str], prefix: &str) -> Child {
    Command::new(env!("CARGO_BIN_EXE_landing"))
        .args(["--ipc-prefix", prefix, "run"])
        .args(args)
        .env("LANDING_LOG", "warn")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Waits until every stage of `prefix` runs (besides `landing` itself).
fn wait_for_stages(prefix: &str, landing: u32) {
    let end = Instant::now() + Duration::from_secs(30);
    loop {
        let stages = processes_with(prefix)
            .into_iter()
            .filter(|p| *p != landing)
            .count();
        if stages >= STAGES {
            // Let them open their ports and the simulator's clock start.
            std::thread::sleep(Duration::from_secs(2));
            return;
        }
        assert!(Instant::now() < end, "{stages} of {STAGES} stages started");
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Waits up to 10 s for `prefix` to leave no process and no file behind.
fn assert_nothing_left(prefix: &str) {
    let end = Instant::now() + Duration::from_secs(10);
    loop {
        let (procs, files) = (processes_with(prefix), files_of(prefix));
        if procs.is_empty() && files.is_empty() {
            return;
        }
        assert!(
            Instant::now() < end,
            "left behind: processes {procs:?}, files {files:?}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

fn signal(pid: u32, sig: libc::c_int) {
    // SAFETY: signalling a process this test started.
    assert_eq!(unsafe { libc::kill(pid as i32, sig) }, 0);
}

fn summary(child: Child) -> (Option<i32>, Value, String) {
    let out = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    let json = serde_json::from_str(stdout.trim())
        .unwrap_or_else(|e| panic!("no summary ({e}): {stdout}\n{stderr}"));
    (out.status.code(), json, stderr)
}

#[test]
fn killing_landing_outright_leaves_no_stage_and_no_shared_memory_behind() {
    let _machine = common::beside_others();
    let p = prefix("kill");
    let mut landing = start(&["--processes", "--json"], &p);
    wait_for_stages(&p, landing.id());
    signal(landing.id(), libc::SIGKILL);
    let _ = landing.wait();
    assert_nothing_left(&p);
}

#[test]
fn ctrl_c_ends_a_processes_run_as_interrupted_with_its_summary() {
    let _machine = common::beside_others();
    let p = prefix("int");
    let landing = start(&["--processes", "--json"], &p);
    wait_for_stages(&p, landing.id());
    signal(landing.id(), libc::SIGINT);
    let (code, s, log) = summary(landing);
    assert_eq!(s["outcome"], "interrupted", "{s}\n{log}");
    assert_eq!(code, Some(1), "{log}");
    assert_nothing_left(&p);
}

#[test]
fn the_simulator_dying_ends_the_run_with_a_summary_naming_it() {
    let _machine = common::beside_others();
    let p = prefix("die");
    let landing = start(&["--processes", "--json"], &p);
    wait_for_stages(&p, landing.id());
    let sim = processes_with(&p)
        .into_iter()
        .find(|pid| {
            let exe = std::fs::read_link(format!("/proc/{pid}/exe")).unwrap_or_default();
            exe.file_name().is_some_and(|n| n == "sim")
        })
        .expect("a sim process");
    signal(sim, libc::SIGKILL);
    let (code, s, log) = summary(landing);
    assert_eq!(s["outcome"], "process_died", "{s}\n{log}");
    let why = s["referee"].as_str().unwrap();
    assert!(why.starts_with("sim exited"), "{why}");
    assert_eq!(code, Some(1), "{log}");
    // The survivors clean up after the killed simulator.
    assert_nothing_left(&p);
}

#[test]
fn an_fsm_killed_while_tracking_is_found_by_the_watchdog_which_orders_a_landing() {
    let _machine = common::one_stack();
    // The watchdog finds the fsm's node dead and orders px4-link to land (AUTO.LAND);
    // had px4-link died too, PX4's offboard-loss failsafe (COM_OBL_RC_ACT = 4 in the
    // airframe, deploy/README.md) would land after COM_OF_LOSS_T. The vehicle must end on
    // the ground, disarmed, without a crash or a hard landing.
    let p = prefix("fsm");
    let landing = start(&["--processes", "--json", "--inject", "kill:fsm@track"], &p);
    let (code, s, log) = summary(landing);
    assert_eq!(s["outcome"], "safe_landed", "{s}\n{log}");
    assert_eq!(code, Some(1), "{log}");
    let faults = s["faults"].as_array().unwrap();
    assert_eq!(faults.len(), 1, "{s}");
    assert_eq!(faults[0]["fault"], "kill");
    assert_eq!(faults[0]["process"], "fsm");
    assert_eq!(faults[0]["outcome"], "safe_landed");
    assert!(faults[0]["at_s"].as_f64().unwrap() > 1.0, "{s}");
    assert_eq!(faults[0]["action"], "fsm died: land (critical)", "{s}");
    assert!(faults[0]["detected_after_ms"].as_f64().is_some(), "{s}");
    assert!(faults[0]["ordered_after_ms"].as_f64().is_some(), "{s}");
    assert_nothing_left(&p);
}

#[test]
fn a_planner_restarted_while_tracking_is_found_dead_and_rejoins_without_a_landing() {
    let _machine = common::one_stack();
    // SIGKILL and the same command again at once, as systemd's Restart=on-failure: the
    // node list never shows the name missing, only under another node id. The death is
    // found; the new planner is back within the watchdog's restart budget, so nothing is
    // ordered and the mission lands on the pad.
    let p = prefix("restart");
    let landing = start(
        &["--processes", "--json", "--inject", "restart:planner@track"],
        &p,
    );
    let (_, s, log) = summary(landing);
    // On the pad: `landed`, or the referee's down-after-fault line when it saw the disarm
    // before the fsm's `landed` (as the fault matrix judges it, tests/faults.rs). Asserting
    // `landed` alone failed once in three runs of this binary (its summary not kept); the
    // matrix saw that line on the pad in 4 of 18 restarts.
    assert!(common::landed_on_the_pad(&s), "{s}\n{log}");
    let f = &s["faults"][0];
    assert_eq!(f["fault"], "restart", "{s}");
    assert!(f["detected_after_ms"].as_f64().is_some(), "found dead: {s}");
    assert!(
        f["rejoined_after_ms"].as_f64().is_some(),
        "back in the graph: {s}"
    );
    assert!(f["ordered_after_ms"].is_null(), "no landing order: {s}");
    assert!(f["action"].is_null(), "nothing decided: {s}");
    // The second planner stopped with the stack, and cleaned up.
    assert_nothing_left(&p);
}

/// `landing run --processes --inject VALUE` refused: exit code 2, one line on stderr.
fn refused_injection(value: &str) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_landing"))
        .args(["run", "--processes", "--inject", value])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    err
}

#[test]
fn a_malformed_injection_is_one_line_naming_what_is_allowed() {
    let err = refused_injection("explode:fsm@track");
    assert!(
        err.contains("unknown fault") && err.contains("kill, stop or restart"),
        "{err}"
    );
}

#[test]
fn an_injection_into_a_process_the_graph_does_not_have_is_refused_before_the_flight() {
    let err = refused_injection("kill:fms@track");
    assert!(
        err.contains("no process fms in the graph") && err.contains("px4-link"),
        "{err}"
    );
}

#[test]
fn blanking_a_topic_that_carries_no_images_is_refused_before_the_flight() {
    let err = refused_injection("blank:2:vehicle/state@track");
    assert!(
        err.contains("vehicle/state carries none") && err.contains("sim/camera"),
        "{err}"
    );
}

#[test]
fn ctrl_c_ends_a_lockstep_run_as_interrupted_with_its_summary() {
    let _machine = common::beside_others();
    // Stopped at its first progress line (the flight takes a few seconds here).
    let mut landing = start(&["--scenario", "obstacle-demo", "--json"], &prefix("lock"));
    let mut err = BufReader::new(landing.stderr.take().unwrap());
    let mut line = String::new();
    while !line.contains("[   0.0 s]") {
        line.clear();
        assert!(err.read_line(&mut line).unwrap() > 0, "no progress line");
    }
    signal(landing.id(), libc::SIGINT);
    let out = landing.wait_with_output().unwrap();
    let s: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(s["outcome"], "interrupted", "{s}");
    assert_eq!(out.status.code(), Some(1));
}

#[test]
fn landing_clean_removes_what_a_stack_killed_outright_left_behind() {
    let _machine = common::beside_others();
    // Every process SIGKILLed at once (a power cut, `systemctl kill -s KILL`): nobody is
    // left to clean up, so `landing clean` (landing-clean.service, before the stack
    // starts again) must.
    let p = prefix("clean");
    let mut landing = start(&["--processes", "--json"], &p);
    wait_for_stages(&p, landing.id());
    for pid in processes_with(&p) {
        signal(pid, libc::SIGKILL);
    }
    let _ = landing.wait();
    let end = Instant::now() + Duration::from_secs(5);
    while !processes_with(&p).is_empty() {
        assert!(
            Instant::now() < end,
            "still running: {:?}",
            processes_with(&p)
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(!files_of(&p).is_empty(), "a SIGKILL leaves files behind");
    let out = Command::new(env!("CARGO_BIN_EXE_landing"))
        .args(["--ipc-prefix", &p, "clean"])
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{said}");
    // Every stage, `landing run`'s own node and the watchdog's supervision node.
    assert!(said.contains(&format!("{} dead", STAGES + 2)), "{said}");
    assert!(files_of(&p).is_empty(), "left: {:?}", files_of(&p));
}

#[test]
fn landing_status_shows_a_process_hung_in_flight_and_the_watchdogs_order() {
    let _machine = common::one_stack();
    let p = prefix("status");
    let landing = start(
        &["--processes", "--json", "--inject", "stop:planner@track"],
        &p,
    );
    let end = Instant::now() + Duration::from_secs(60);
    let mut last = Value::Null;
    while Instant::now() < end {
        let out = Command::new(env!("CARGO_BIN_EXE_landing"))
            .args(["--ipc-prefix", &p, "status", "--json", "--wait-s", "2"])
            .output()
            .unwrap();
        if out.status.success() {
            last = serde_json::from_slice(&out.stdout).unwrap();
            let planner = last["processes"]
                .as_array()
                .unwrap()
                .iter()
                .find(|x| x["name"] == "planner")
                .cloned()
                .unwrap();
            if planner["state"] == "hung" {
                assert_eq!(planner["missed_deadlines"], 1, "{last}");
                assert_eq!(last["last_fault"], "planner hung", "{last}");
                assert_eq!(last["decision"], "planner hung in track: land", "{last}");
                // Ordered in this flight (`safe_land_ordered` is over once it is down).
                assert!(last["order_ns"].as_u64().unwrap() > 0, "{last}");
                break;
            }
        }
        std::thread::sleep(Duration::from_millis(200));
    }
    assert_eq!(last["last_fault"], "planner hung", "never saw it: {last}");
    let (_, s, log) = summary(landing);
    assert_eq!(s["outcome"], "safe_landed", "{s}\n{log}");
    assert_nothing_left(&p);
}

#[test]
fn landing_status_without_a_running_stack_is_one_line_and_exit_2() {
    let out = Command::new(env!("CARGO_BIN_EXE_landing"))
        .args([
            "--ipc-prefix",
            &prefix("nostack"),
            "status",
            "--wait-s",
            "0.3",
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("no watchdog view under prefix"), "{err}");
}

#[test]
fn landing_inject_corrupts_a_running_stacks_pad_observations_and_stops_its_planner() {
    let _machine = common::beside_others();
    let p = prefix("inject");
    let logs = std::env::temp_dir().join(format!("lt-inject-{}", std::process::id()));
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_landing"));
    cmd.args([
        "--ipc-prefix",
        &p,
        "run",
        "--processes",
        "--json",
        "--log-dir",
    ])
    .arg(&logs)
    .env("LANDING_LOG", "warn")
    .env("LANDING_FAULT_INJECTION", "1")
    .stdout(Stdio::piped())
    .stderr(Stdio::piped());
    let landing = cmd.spawn().unwrap();
    wait_for_stages(&p, landing.id());
    let inject = |what: &str| {
        Command::new(env!("CARGO_BIN_EXE_landing"))
            .args(["--ipc-prefix", &p, "inject", what])
            .output()
            .unwrap()
    };
    // Wait for the pad to be tracked: observations flow.
    let end = Instant::now() + Duration::from_secs(60);
    loop {
        assert!(Instant::now() < end, "never tracked");
        let out = Command::new(env!("CARGO_BIN_EXE_landing"))
            .args(["--ipc-prefix", &p, "status", "--json", "--wait-s", "2"])
            .output()
            .unwrap();
        let v: Value = serde_json::from_slice(&out.stdout).unwrap_or(Value::Null);
        if v["phase"] == "track" {
            break;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let bad = inject("explode:planner");
    assert_eq!(bad.status.code(), Some(2));
    assert_eq!(
        String::from_utf8_lossy(&bad.stderr).trim().lines().count(),
        1
    );
    assert!(inject("corrupt:aruco-pnp").status.success());
    assert!(inject("stop:planner").status.success());
    let (_, s, log) = summary(landing);
    // Garbage or a hung planner before the descent: the watchdog lands where it is.
    assert_eq!(s["outcome"], "safe_landed", "{s}\n{log}");
    let aruco = std::fs::read_to_string(logs.join("aruco-pnp.log")).unwrap();
    let stop = aruco
        .lines()
        .find(|l| l.contains("aruco-pnp stopped"))
        .unwrap();
    assert!(!stop.contains("injected_corrupted=0 "), "{stop}");
    let dog = std::fs::read_to_string(logs.join("watchdog.log")).unwrap();
    assert!(dog.contains("planner hung"), "{dog}");
    assert_nothing_left(&p);
    let _ = std::fs::remove_dir_all(&logs);
}
