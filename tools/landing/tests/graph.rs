//! `landing graph` as a user meets it: the shipped graph as text, one JSON object and
//! Graphviz DOT; a broken graph is one line naming the file and the node, exit code 2.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test

mod common;
use std::process::Output;

use common::landing;
use serde_json::Value;

const NODES: [&str; 8] = [
    "sim",
    "camera-ingest",
    "aruco-pnp",
    "depth-map",
    "planner",
    "fsm",
    "px4-link",
    "watchdog",
];

fn shipped() -> String {
    concat!(env!("CARGO_MANIFEST_DIR"), "/../../deploy/graph.toml").to_string()
}

fn stdout(o: &Output) -> String {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).to_string()
}

#[test]
fn the_text_lists_every_node_with_its_inputs_outputs_and_rate() {
    let out = stdout(&landing(&["graph", "--graph", &shipped()]));
    for n in NODES {
        assert!(
            out.lines()
                .any(|l| l.starts_with(&format!("{n}  (binary {n};"))),
            "{n}: {out}"
        );
    }
    assert!(
        out.contains("sim  (binary sim; 500 Hz on its clock;"),
        "{out}"
    );
    assert!(out.contains("  in   planner/trajectory"), "{out}");
    assert!(out.contains("  out  vehicle/state"), "{out}");
}

#[test]
fn the_default_graph_is_the_deploy_directorys() {
    let deploy = concat!(env!("CARGO_MANIFEST_DIR"), "/../../deploy");
    let out = stdout(&landing(&["graph", "--deploy-dir", deploy]));
    assert!(out.lines().next().unwrap().ends_with("graph.toml"), "{out}");
    assert!(out.contains("fsm  (binary fsm;"), "{out}");
}

#[test]
fn json_is_one_object_with_every_node_and_topic() {
    let out = stdout(&landing(&["graph", "--graph", &shipped(), "--json"]));
    assert_eq!(out.trim().lines().count(), 1, "{out}");
    let v: Value = serde_json::from_str(out.trim()).unwrap();
    let nodes = v["nodes"].as_array().unwrap();
    assert_eq!(nodes.len(), 8);
    for n in nodes {
        for key in ["name", "inputs", "outputs", "rate_hz"] {
            assert!(!n[key].is_null(), "{key}: {n}");
        }
        assert!(n["inputs"].is_array() && n["outputs"].is_array(), "{n}");
        assert!(n["rate_hz"].as_f64().unwrap() > 0.0, "{n}");
    }
    let mut names: Vec<&str> = nodes.iter().map(|n| n["name"].as_str().unwrap()).collect();
    names.sort_unstable();
    let mut expected = NODES.to_vec();
    expected.sort_unstable();
    assert_eq!(names, expected);
    let topics = v["topics"].as_array().unwrap();
    assert!(topics.iter().any(|t| t["name"] == "camera/frame"
        && t["service"] == "landing/camera/frame"
        && t["type"] == "landing::CameraFrameHeader/v1"));
}

#[test]
fn dot_is_a_graphviz_digraph() {
    let out = stdout(&landing(&["graph", "--graph", &shipped(), "--dot"]));
    assert!(out.starts_with("digraph"), "{out}");
    assert!(out.trim_end().ends_with('}'), "{out}");
    for n in NODES {
        assert!(out.contains(&format!("\"n:{n}\"")), "{n}");
    }
}

/// The shipped graph with `old` replaced by `new`, written to a file of its own.
fn broken(name: &str, old: &str, new: &str) -> String {
    let text = std::fs::read_to_string(shipped()).unwrap();
    assert!(text.contains(old), "{old} is not in deploy/graph.toml");
    let dir = std::env::temp_dir().join(format!("landing-graph-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, text.replacen(old, new, 1)).unwrap();
    path.to_str().unwrap().to_string()
}

/// Exit code 2 and one line on stderr naming the file and the node; returns the line.
fn refused(path: &str, node: &str) -> String {
    let o = landing(&["graph", "--graph", path]);
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(o.stdout.is_empty(), "nothing printed on stdout");
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    assert!(err.contains(path), "names the file: {err}");
    assert!(
        err.contains(&format!("node {node}:")),
        "names the node: {err}"
    );
    err
}

#[test]
fn an_unknown_topic_is_one_line_naming_the_node_the_topic_and_the_declared_topics() {
    let path = broken(
        "unknown_topic.toml",
        "{ topic = \"planner/trajectory\", policy",
        "{ topic = \"planner/trajectroy\", policy",
    );
    let err = refused(&path, "fsm");
    assert!(
        err.contains("input topic planner/trajectroy is not declared (allowed: sim/camera, "),
        "{err}"
    );
}

#[test]
fn a_cycle_without_a_delayed_input_is_one_line_naming_the_cycle() {
    let path = broken(
        "cycle.toml",
        "{ topic = \"planner/trajectory\", policy = \"queue\", depth = 4, delay = true }",
        "{ topic = \"planner/trajectory\", policy = \"queue\", depth = 4 }",
    );
    let err = refused(&path, "planner");
    assert!(
        err.contains("cycle planner -> planner/trajectory -> fsm -> planner/goal -> planner has no delayed input"),
        "{err}"
    );
}

#[test]
fn a_node_without_a_binary_is_one_line_naming_the_allowed_binaries() {
    let path = broken("no_binary.toml", "binary = \"planner\"\n", "");
    let err = refused(&path, "planner");
    assert!(
        err.contains("no binary (allowed: a command name of lowercase letters, digits and -: one of the stack's (sim, camera-ingest, aruco-pnp, depth-map, planner, fsm, px4-link, watchdog) or your own)"),
        "{err}"
    );
}

#[test]
fn a_rate_of_zero_is_one_line_naming_the_allowed_rates() {
    let path = broken(
        "rate_zero.toml",
        "binary = \"depth-map\"\nrate_hz = 30.0",
        "binary = \"depth-map\"\nrate_hz = 0.0",
    );
    let err = refused(&path, "depth-map");
    assert!(
        err.contains("rate_hz 0 is not allowed (allowed: above 0 and at most 10000 Hz)"),
        "{err}"
    );
}
