//! Tests of the text and DOT forms.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test

use std::path::Path;

use crate::Graph;
use crate::check::tests::SMALL;

fn small() -> Graph {
    Graph::parse(SMALL, Path::new("g.toml")).unwrap()
}

#[test]
fn the_text_lists_every_node_with_its_rate_and_edges() {
    let t = super::text(&small());
    assert!(t.starts_with("2 nodes, 3 topics"), "{t}");
    assert!(
        t.contains(
            "\naruco-pnp  (binary aruco-pnp; 30 Hz on its clock; heartbeat 500 ms; latency 0 ms)"
        ),
        "{t}"
    );
    assert!(t.contains("\nfsm  (binary fsm; 50 Hz on its clock;"), "{t}");
    assert!(t.contains("in   fsm/setpoint"), "{t}");
    assert!(t.contains("newest, depth 4, delayed"), "{t}");
    assert!(t.contains("from external"), "{t}");
    assert!(
        t.contains("step order at one instant: aruco-pnp, fsm"),
        "{t}"
    );
}

#[test]
fn the_dot_is_one_digraph_with_an_edge_per_input_and_output() {
    let d = super::dot(&small());
    assert!(d.starts_with("digraph landing {"), "{d}");
    assert!(d.trim_end().ends_with('}'), "{d}");
    assert!(
        d.contains("\"n:aruco-pnp\" -> \"t:pad/observation\";"),
        "{d}"
    );
    assert!(
        d.contains("\"t:pad/observation\" -> \"n:fsm\" [label=\"queue\"];"),
        "{d}"
    );
    assert!(
        d.contains(
            "\"t:fsm/setpoint\" -> \"n:aruco-pnp\" [label=\"newest, delay\", style=dashed];"
        ),
        "{d}"
    );
    assert_eq!(d.matches(" -> ").count(), 2 + 3);
}

#[test]
fn dot_strings_escape_quotes_backslashes_and_newlines() {
    assert_eq!(super::quote("a\"b\\c\nd"), "\"a\\\"b\\\\c\\nd\"");
}
