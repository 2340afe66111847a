//! Tests of the graph's accessors and argument expansion.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test

use std::path::Path;

use super::*;

fn values() -> RunValues {
    RunValues {
        config: "/c/landing.toml".into(),
        link_addr: "127.0.0.1:9".into(),
        sim_remote: "127.0.0.1:9".into(),
        link_remote: "127.0.0.1:8".into(),
        preset: "-4,-2,4.5".into(),
        ..RunValues::default()
    }
}

#[test]
fn placeholders_are_replaced_by_the_run_values() {
    let v = values();
    assert_eq!(expand("{config}", &v), "/c/landing.toml");
    assert_eq!(expand("udp:{link_addr}", &v), "udp:127.0.0.1:9");
    assert_eq!(expand("--preset={preset}", &v), "--preset=-4,-2,4.5");
    assert_eq!(expand("sim", &v), "sim");
    assert_eq!(
        expand("{config}{link_addr}", &v),
        "/c/landing.toml127.0.0.1:9"
    );
}

#[test]
fn every_placeholder_has_a_run_value() {
    let v = RunValues::default();
    for p in PLACEHOLDERS {
        assert!(v.get(p).is_some(), "{p}");
    }
    assert!(v.get("nope").is_none());
}

const CHAIN: &str = r#"
[[topic]]
name = "a"
service = "landing/camera/frame"
type = "T"
[[topic]]
name = "b"
service = "landing/pad/observation"
type = "T"

[[node]]
name = "late"
binary = "sim"
start_last = true
on_vehicle = false
rate_hz = 1.0
trigger = "clock"
heartbeat_deadline_ms = 500
latency_ms = 0.0
outputs = ["a"]

[[node]]
name = "end"
binary = "fsm"
rate_hz = 1.0
trigger = "clock"
heartbeat_deadline_ms = 500
latency_ms = 0.0
inputs = [{ topic = "b", policy = "queue", depth = 4 }]

[[node]]
name = "middle"
binary = "aruco-pnp"
rate_hz = 1.0
trigger = "a"
heartbeat_deadline_ms = 500
latency_ms = 0.0
inputs = [{ topic = "a", policy = "newest", depth = 4 }]
outputs = ["b"]
"#;

fn names(nodes: Vec<&Node>) -> Vec<&str> {
    nodes.into_iter().map(|n| n.name.as_str()).collect()
}

#[test]
fn nodes_start_in_the_file_order_with_start_last_nodes_after_the_rest() {
    let g = Graph::parse(CHAIN, Path::new("g.toml")).unwrap();
    assert_eq!(names(g.start_order()), ["end", "middle", "late"]);
}

#[test]
fn the_step_order_puts_every_publisher_before_its_same_instant_readers() {
    let g = Graph::parse(CHAIN, Path::new("g.toml")).unwrap();
    assert_eq!(names(g.step_order()), ["late", "middle", "end"]);
}

#[test]
fn vehicle_nodes_leave_out_the_simulation_only_ones() {
    let g = Graph::parse(CHAIN, Path::new("g.toml")).unwrap();
    let v: Vec<&str> = g.vehicle_nodes().map(|n| n.name.as_str()).collect();
    assert_eq!(v, ["end", "middle"]);
}

#[test]
fn publishers_and_readers_are_found_by_topic() {
    let g = Graph::parse(CHAIN, Path::new("g.toml")).unwrap();
    assert_eq!(
        g.publishers("a")
            .map(|n| n.name.as_str())
            .collect::<Vec<_>>(),
        ["late"]
    );
    assert_eq!(
        g.readers("b").map(|n| n.name.as_str()).collect::<Vec<_>>(),
        ["end"]
    );
    assert!(
        g.node("middle")
            .is_some_and(|n| n.reads("a") && n.publishes("b"))
    );
    assert!(g.topic("c").is_none());
}

#[test]
fn entry_keys_are_split_into_kind_index_and_rest() {
    assert_eq!(
        split_entry_key("node[3].inputs[0].policy"),
        Some(("node", 3, Some("inputs[0].policy")))
    );
    assert_eq!(split_entry_key("topic[0]"), Some(("topic", 0, None)));
    assert_eq!(split_entry_key("nodes"), None);
}
