//! Tests of the graph's rules: each broken rule is one line naming the file, the node or
//! topic, and what is allowed.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test

use std::path::Path;

use crate::Graph;

/// Two nodes in a cycle closed by a delayed input, and an external topic.
pub(crate) const SMALL: &str = r#"
[[topic]]
name = "pad/observation"
service = "landing/pad/observation"
type = "landing::PadObservation/v1"

[[topic]]
name = "fsm/setpoint"
service = "landing/fsm/setpoint"
type = "landing::Setpoint/v1"

[[topic]]
name = "safety/command"
service = "landing/safety/command"
type = "landing::SafetyCommand/v1"
external = true

[[node]]
name = "aruco-pnp"
binary = "aruco-pnp"
rate_hz = 30.0
trigger = "clock"
heartbeat_deadline_ms = 500
latency_ms = 0.0
inputs = [{ topic = "fsm/setpoint", policy = "newest", depth = 4, delay = true }]
outputs = ["pad/observation"]

[[node]]
name = "fsm"
binary = "fsm"
rate_hz = 50.0
trigger = "clock"
heartbeat_deadline_ms = 500
latency_ms = 0.0
inputs = [
    { topic = "pad/observation", policy = "queue", depth = 4 },
    { topic = "safety/command", policy = "queue", depth = 4 },
]
outputs = ["fsm/setpoint"]
args = ["--config", "{config}"]
"#;

/// SMALL with `old` replaced by `new` (which must occur).
fn with(old: &str, new: &str) -> String {
    assert!(SMALL.contains(old), "{old} not in the test graph");
    SMALL.replacen(old, new, 1)
}

/// The error `text` gives: one line naming the file.
fn error(text: &str) -> String {
    let e = Graph::parse(text, Path::new("deploy/graph.toml"))
        .unwrap_err()
        .to_string();
    assert_eq!(e.lines().count(), 1, "one line: {e}");
    assert!(e.contains("deploy/graph.toml"), "names the file: {e}");
    e
}

#[test]
fn the_small_graph_is_valid() {
    let g = Graph::parse(SMALL, Path::new("g.toml")).unwrap();
    assert_eq!(g.nodes.len(), 2);
    assert_eq!(g.topics.len(), 3);
}

#[test]
fn an_undeclared_input_topic_names_the_node_the_topic_and_the_declared_topics() {
    let e = error(&with(
        r#"topic = "pad/observation", policy"#,
        r#"topic = "pad/observervation", policy"#,
    ));
    assert_eq!(
        e,
        "deploy/graph.toml: node fsm: input topic pad/observervation is not declared (allowed: pad/observation, fsm/setpoint, safety/command)"
    );
}

#[test]
fn an_undeclared_output_topic_is_refused() {
    let e = error(&with(
        r#"outputs = ["fsm/setpoint"]"#,
        r#"outputs = ["fsm/setpiont"]"#,
    ));
    assert!(
        e.contains("node fsm: output topic fsm/setpiont is not declared (allowed: "),
        "{e}"
    );
}

#[test]
fn a_cycle_without_a_delayed_input_names_the_cycle_and_the_fix() {
    let e = error(&with(", delay = true }", " }"));
    assert!(
        e.contains("node aruco-pnp: cycle aruco-pnp -> pad/observation -> fsm -> fsm/setpoint -> aruco-pnp has no delayed input"),
        "{e}"
    );
    assert!(
        e.contains("allowed: mark one input on the cycle `delay = true`"),
        "{e}"
    );
}

#[test]
fn a_node_that_reads_its_own_output_at_the_same_instant_is_a_cycle() {
    let e = error(&with(
        r#"outputs = ["fsm/setpoint"]"#,
        r#"outputs = ["fsm/setpoint", "safety/command"]"#,
    ));
    assert!(
        e.contains("node fsm: cycle fsm -> safety/command -> fsm has no delayed input"),
        "{e}"
    );
}

#[test]
fn a_node_without_a_binary_is_refused_with_the_stack_binaries() {
    let e = error(&with("binary = \"fsm\"\n", ""));
    assert_eq!(
        e,
        "deploy/graph.toml: node fsm: no binary (allowed: a command name of lowercase letters, digits and -: one of the stack's (sim, camera-ingest, aruco-pnp, depth-map, planner, fsm, px4-link, watchdog) or your own)"
    );
}

#[test]
fn a_binary_that_is_not_a_command_name_is_refused_and_one_of_your_own_is_not() {
    for bad in ["Fsm", "../fsm", "fsm --x", "-fsm", "/usr/bin/fsm"] {
        let e = error(&with("binary = \"fsm\"", &format!("binary = \"{bad}\"")));
        assert!(
            e.contains(&format!(
                "node fsm: binary {bad} is not allowed (allowed: a command name"
            )),
            "{e}"
        );
    }
    let own = with("binary = \"fsm\"", "binary = \"altitude-guard2\"");
    let g = Graph::parse(&own, Path::new("g.toml")).unwrap();
    assert_eq!(g.node("fsm").unwrap().binary, "altitude-guard2");
}

#[test]
fn a_rate_of_zero_negative_or_not_finite_is_refused() {
    for (bad, shown) in [
        ("0.0", "0"),
        ("-5.0", "-5"),
        ("nan", "NaN"),
        ("inf", "inf"),
        ("20000.0", "20000"),
    ] {
        let e = error(&with("rate_hz = 50.0", &format!("rate_hz = {bad}")));
        assert!(
            e.contains(&format!(
                "node fsm: rate_hz {shown} is not allowed (allowed: above 0 and at most 10000 Hz)"
            )),
            "{bad}: {e}"
        );
    }
    let e = error(&with("rate_hz = 50.0\n", ""));
    assert!(e.contains("node fsm: no rate_hz (allowed: above 0"), "{e}");
}

#[test]
fn a_rate_that_is_not_a_number_names_the_node_and_the_key() {
    let e = error(&with("rate_hz = 50.0", "rate_hz = \"fast\""));
    assert!(
        e.starts_with("deploy/graph.toml: node fsm: key `rate_hz`: invalid type"),
        "{e}"
    );
}

#[test]
fn a_wrong_policy_names_the_node_the_input_and_the_allowed_policies() {
    let e = error(&with(
        r#"policy = "queue", depth = 4 },
    { topic = "safety"#,
        r#"policy = "lifo", depth = 4 },
    { topic = "safety"#,
    ));
    assert!(
        e.contains(
            "node fsm: key `inputs[0].policy`: unknown variant `lifo`, expected `newest` or `queue`"
        ),
        "{e}"
    );
}

#[test]
fn an_unknown_key_in_a_node_names_the_node() {
    let e = error(&with(
        "latency_ms = 0.0\ninputs = [\n",
        "latency_ms = 0.0\nlatencee = 1\ninputs = [\n",
    ));
    assert!(
        e.contains("node fsm: key `latencee`") || e.contains("node fsm: unknown field `latencee`"),
        "{e}"
    );
}

#[test]
fn duplicate_nodes_and_topics_are_refused() {
    let e = error(&with("name = \"aruco-pnp\"", "name = \"fsm\""));
    assert!(
        e.contains("node fsm: is declared twice (allowed: each node name once)"),
        "{e}"
    );
    let e = error(&with(
        "name = \"fsm/setpoint\"",
        "name = \"pad/observation\"",
    ));
    assert!(
        e.contains("topic pad/observation: is declared twice (allowed: each topic name once)"),
        "{e}"
    );
}

#[test]
fn a_topic_that_no_node_publishes_is_refused_unless_external() {
    let e = error(&with("external = true\n", ""));
    assert!(
        e.contains("node fsm: input topic safety/command has no publisher (allowed: a topic some node lists in its outputs, or one marked external = true)"),
        "{e}"
    );
}

#[test]
fn a_topic_no_node_uses_is_refused() {
    let text = format!(
        "{SMALL}\n[[topic]]\nname = \"planner/goal\"\nservice = \"landing/planner/goal\"\ntype = \"landing::PlannerGoal/v1\"\n"
    );
    let e = error(&text);
    assert!(
        e.contains("topic planner/goal: no node reads or publishes it"),
        "{e}"
    );
}

#[test]
fn no_node_may_read_ground_truth() {
    let text = with(
        "name = \"safety/command\"\nservice = \"landing/safety/command\"\ntype = \"landing::SafetyCommand/v1\"\nexternal = true",
        "name = \"safety/command\"\nservice = \"landing/sim/truth\"\ntype = \"landing::TruthEvent/v2\"\nevaluator_only = true",
    );
    let e = error(&text);
    assert!(
        e.contains("node fsm: input topic safety/command is evaluator-only ground truth (allowed readers: the evaluator of landing run, never a node)"),
        "{e}"
    );
}

#[test]
fn a_truth_service_must_be_marked_evaluator_only() {
    let e = error(&with(
        "service = \"landing/safety/command\"",
        "service = \"landing/sim/truth_state\"",
    ));
    assert!(e.contains("topic safety/command: service landing/sim/truth_state is ground truth (allowed: evaluator_only = true on it)"), "{e}");
}

#[test]
fn a_service_the_stack_does_not_have_is_refused() {
    let e = error(&with(
        "service = \"landing/fsm/setpoint\"",
        "service = \"landing/fsm/setpoints\"",
    ));
    assert!(e.contains("topic fsm/setpoint: service landing/fsm/setpoints is not a service of the stack (allowed: one of landing/sim/camera, "), "{e}");
}

#[test]
fn two_topics_on_one_service_are_refused() {
    let e = error(&with(
        "service = \"landing/fsm/setpoint\"",
        "service = \"landing/pad/observation\"",
    ));
    assert!(
        e.contains(
            "topic fsm/setpoint: service landing/pad/observation is already another topic's"
        ),
        "{e}"
    );
}

#[test]
fn an_iceoryx2_input_needs_a_depth_and_a_mavlink_input_has_none() {
    let e = error(&with(
        "policy = \"newest\", depth = 4,",
        "policy = \"newest\",",
    ));
    assert!(
        e.contains(
            "node aruco-pnp: input topic fsm/setpoint has no depth (allowed: 1 to 16 messages"
        ),
        "{e}"
    );
    let e = error(&with(
        "policy = \"newest\", depth = 4,",
        "policy = \"newest\", depth = 0,",
    ));
    assert!(
        e.contains("input topic fsm/setpoint: depth 0 is out of range (allowed: 1 to 16)"),
        "{e}"
    );
    let mavlink = with(
        "name = \"fsm/setpoint\"\nservice = \"landing/fsm/setpoint\"\ntype = \"landing::Setpoint/v1\"",
        "name = \"fsm/setpoint\"\ntransport = \"mavlink\"\ntype = \"MAVLink 2\"",
    );
    let e = error(&mavlink);
    assert!(
        e.contains(
            "node aruco-pnp: input topic fsm/setpoint: depth does not apply to a MAVLink or runtime topic"
        ),
        "{e}"
    );
    let ok = mavlink.replace("policy = \"newest\", depth = 4,", "policy = \"newest\",");
    Graph::parse(&ok, Path::new("g.toml")).unwrap();
}

#[test]
fn a_trigger_is_the_clock_or_one_of_the_inputs() {
    let e = error(&with(
        "rate_hz = 50.0\ntrigger = \"clock\"",
        "rate_hz = 50.0\ntrigger = \"vehicle/state\"",
    ));
    assert!(
        e.contains("node fsm: trigger vehicle/state is not allowed (allowed: clock, pad/observation, safety/command: its clock or one of its inputs)"),
        "{e}"
    );
    let ok = with(
        "rate_hz = 50.0\ntrigger = \"clock\"",
        "rate_hz = 50.0\ntrigger = \"pad/observation\"",
    );
    Graph::parse(&ok, Path::new("g.toml")).unwrap();
}

#[test]
fn a_periodic_wake_needs_an_iceoryx2_trigger_and_is_handed_to_the_driver() {
    let clock = with(
        "rate_hz = 50.0\ntrigger = \"clock\"",
        "rate_hz = 50.0\ntrigger = \"clock\"\nwake = \"periodic\"",
    );
    let e = error(&clock);
    assert!(
        e.contains(
            "node fsm: wake = \"periodic\" needs an input over shared memory as the trigger, not clock"
        ),
        "{e}"
    );
    let e = error(&with(
        "rate_hz = 50.0\ntrigger = \"clock\"",
        "rate_hz = 50.0\ntrigger = \"clock\"\nwake = \"often\"",
    ));
    assert!(
        e.contains("node fsm: wake often is not allowed (allowed: event, periodic)"),
        "{e}"
    );
    let ok = with(
        "rate_hz = 50.0\ntrigger = \"clock\"",
        "rate_hz = 50.0\ntrigger = \"pad/observation\"\nwake = \"periodic\"",
    );
    let g = Graph::parse(&ok, Path::new("g.toml")).unwrap();
    let spec = g.node("fsm").unwrap().spec();
    assert_eq!(spec.periodic.as_deref(), Some("pad/observation"));
    assert_eq!(g.node("aruco-pnp").unwrap().spec().periodic, None);
}

#[test]
fn a_heartbeat_deadline_or_latency_out_of_range_is_refused() {
    let e = error(&with(
        "heartbeat_deadline_ms = 500\nlatency_ms = 0.0\ninputs = [\n",
        "heartbeat_deadline_ms = 5\nlatency_ms = 0.0\ninputs = [\n",
    ));
    assert!(
        e.contains("node fsm: heartbeat_deadline_ms 5 is out of range (allowed: 20 to 60000 ms)"),
        "{e}"
    );
    let e = error(&with(
        "latency_ms = 0.0\ninputs = [\n",
        "latency_ms = -1.0\ninputs = [\n",
    ));
    assert!(
        e.contains("node fsm: latency_ms -1 is not allowed (allowed: 0 to 10000 ms)"),
        "{e}"
    );
}

#[test]
fn an_argument_with_an_unknown_placeholder_is_refused() {
    let e = error(&with("\"{config}\"", "\"{confg}\""));
    assert!(
        e.contains("node fsm: argument `{confg}`: unknown placeholder {confg} (allowed: {config}, {deploy}, "),
        "{e}"
    );
    let e = error(&with("\"{config}\"", "\"{config\""));
    assert!(
        e.contains("node fsm: argument `{config`: `{` without `}`"),
        "{e}"
    );
}

#[test]
fn a_graph_without_nodes_is_refused() {
    let e = error("");
    assert_eq!(
        e,
        "deploy/graph.toml: no nodes (allowed: one [[node]] table per process)"
    );
}

#[test]
fn an_unreadable_file_is_one_line_naming_it() {
    let e = Graph::load(Path::new("/no/such/graph.toml"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("/no/such/graph.toml") && e.lines().count() == 1,
        "{e}"
    );
}
