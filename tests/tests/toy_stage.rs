//! A stage added through the graph and the stage interface alone runs in both modes.
//!
//! `altitude-guard` (`landing_tests::toy`) is a library implementing `stage::Stage` and a
//! binary that hands it to `runtime::serve`; a copy of the shipped graph with one more
//! `[[node]]` wires it in. No driver, no runner and no other stage is edited: the
//! lockstep run builds it through `run_lockstep::driver`'s `extra`, and `landing run
//! --processes --graph` starts its binary with the others. In both, the guard sees the
//! vehicle climb through its ceiling during take-off and orders a safe landing, and the
//! fsm obeys it.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test

use std::path::PathBuf;
use std::process::Command;

use evaluation::{End, Referee};
use graph::Graph;
use ipc_types::msg::MissionState;
use landing_tests::stack::{deploy_dir, stack_binary};
use landing_tests::stop::{count_in, last_line_with};
use landing_tests::toy::{AltitudeGuard, graph_node};
use stack::StackConfig;
use stack::lockstep::{self as run_lockstep, Recording, Setup};
use stage::Stage;

/// Below the preset height of paper-sim: crossed during take-off.
const CEILING_M: f64 = 1.0;

/// The shipped graph with the guard added, written to a file of its own.
fn toy_graph(dir: &std::path::Path) -> PathBuf {
    let shipped = std::fs::read_to_string(deploy_dir().join("graph.toml")).unwrap();
    let path = dir.join("graph-with-guard.toml");
    std::fs::write(&path, shipped + &graph_node(CEILING_M)).unwrap();
    path
}

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("toy-stage-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn a_stage_added_through_the_graph_runs_in_lockstep() {
    let dir = temp_dir("lockstep");
    let graph = Graph::load(&toy_graph(&dir)).unwrap();
    let deploy = deploy_dir();
    let cfg: StackConfig = stack_config::load(&deploy.join("config/landing.toml")).unwrap();
    let scn = sim::scenario::load("paper-sim", &deploy).unwrap();
    let setup = Setup {
        scenario: &scn,
        seed: 1,
        config: &cfg,
        fsm: run_lockstep::mission(&cfg, &scn).unwrap(),
    };
    let mut driver = run_lockstep::driver(&graph, &setup, |node| {
        (node.name == "altitude-guard")
            .then(|| Box::new(AltitudeGuard::new(CEILING_M)) as Box<dyn Stage>)
    })
    .unwrap();
    let mut referee = Referee::new(0);
    let end = run_lockstep::run(
        &mut driver,
        scn.scenario.duration_s,
        &mut referee,
        &mut Recording::default(),
        false,
        |_, _, _| {},
    )
    .unwrap();

    let guard = driver.stage("altitude-guard").unwrap().counters();
    assert!(guard.contains(&("orders", 1)), "{guard:?}");
    assert!(
        guard.iter().any(|&(k, v)| k == "states" && v > 10),
        "{guard:?}"
    );
    let safe_land = referee
        .transitions
        .iter()
        .find(|t| t.to == MissionState::SafeLand)
        .unwrap_or_else(|| panic!("no SafeLand: {:?}", referee.transitions));
    assert!(
        safe_land
            .reason
            .contains("altitude-guard: above the ceiling"),
        "{}",
        safe_land.reason
    );
    assert_eq!(end, End::SafeLanded);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_stage_added_through_the_graph_runs_as_its_own_process() {
    let dir = temp_dir("processes");
    let graph = toy_graph(&dir);
    let logs = dir.join("logs");
    let out = Command::new(stack_binary("landing"))
        .args(["run", "--scenario", "paper-sim", "--processes", "--json"])
        .arg("--graph")
        .arg(&graph)
        .arg("--log-dir")
        .arg(&logs)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        out.status.code(),
        Some(1),
        "not landed on the pad:\n{stderr}"
    );
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(summary["outcome"], "safe_landed", "{stderr}");
    assert!(
        stderr.contains("altitude-guard: above the ceiling"),
        "the fsm's transition names the order:\n{stderr}"
    );
    let log = std::fs::read_to_string(logs.join("altitude-guard.log")).unwrap();
    let line = last_line_with(&log, "altitude-guard stopped").unwrap_or_else(|| panic!("{log}"));
    assert_eq!(count_in(line, "orders"), Some(1), "{line}");
    assert!(count_in(line, "states").unwrap() > 10, "{line}");
    std::fs::remove_dir_all(&dir).unwrap();
}
