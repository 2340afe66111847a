//! The graph for people: readable text and Graphviz DOT (`landing graph`).

use std::fmt::Write;

use crate::{CLOCK, Graph, Input, Node, Topic, Transport, Wake};

/// The graph as readable text: each node with its rate, trigger, heartbeat deadline,
/// latency and edges; then the topics; then the order a lockstep driver steps by.
pub fn text(graph: &Graph) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{} nodes, {} topics",
        graph.nodes.len(),
        graph.topics.len()
    );
    for n in &graph.nodes {
        let _ = writeln!(s);
        let _ = writeln!(s, "{}", node_line(n));
        for i in &n.inputs {
            let from = names(graph.publishers(&i.topic));
            let from = if from.is_empty() {
                "external".to_string()
            } else {
                from
            };
            let _ = writeln!(s, "  in   {:<20} {:<25} from {from}", i.topic, policy(i));
        }
        for o in &n.outputs {
            let to = names(graph.readers(o));
            let to = match graph.topic(o) {
                Some(t) if t.evaluator_only => "the evaluator only".to_string(),
                Some(t) if t.external && to.is_empty() => "external".to_string(),
                _ if to.is_empty() => "no node".to_string(),
                _ => to,
            };
            let _ = writeln!(s, "  out  {o:<20} {:<25} to {to}", "");
        }
    }
    let _ = writeln!(s);
    let _ = writeln!(s, "topics");
    for t in &graph.topics {
        let _ = writeln!(
            s,
            "  {:<20} {:<28} {}{}",
            t.name,
            service(t),
            payload(t),
            topic_flags(t)
        );
    }
    let _ = writeln!(s);
    let order: Vec<&str> = graph.step_order().iter().map(|n| n.name.as_str()).collect();
    let _ = writeln!(s, "step order at one instant: {}", order.join(", "));
    let start: Vec<&str> = graph
        .start_order()
        .iter()
        .map(|n| n.name.as_str())
        .collect();
    let _ = writeln!(
        s,
        "start order (landing run --processes): {}",
        start.join(", ")
    );
    s
}

fn node_line(n: &Node) -> String {
    let trigger = match (n.trigger == CLOCK, n.wake) {
        (true, _) => "on its clock".to_string(),
        (false, Wake::Event) => format!("on {}", n.trigger),
        (false, Wake::Periodic) => format!("on {}, waited for by its period", n.trigger),
    };
    let mut line = format!(
        "{}  (binary {}; {} Hz {trigger}; heartbeat {} ms; latency {} ms",
        n.name, n.binary, n.rate_hz, n.heartbeat_deadline_ms, n.latency_ms
    );
    if !n.on_vehicle {
        line.push_str("; simulation only");
    }
    if n.start_last {
        line.push_str("; started last");
    }
    line.push(')');
    line
}

fn policy(i: &Input) -> String {
    let mut p = i.policy.name().to_string();
    if let Some(d) = i.depth {
        let _ = write!(p, ", depth {d}");
    }
    if i.delay {
        p.push_str(", delayed");
    }
    p
}

fn service(t: &Topic) -> &str {
    match t.transport {
        Transport::Iceoryx2 => t.service.as_deref().unwrap_or("-"),
        Transport::Mavlink => "(MAVLink)",
        Transport::Runtime => "(runtime)",
    }
}

fn payload(t: &Topic) -> String {
    match &t.elements {
        Some(e) => format!("{} + [{e}]", t.type_name),
        None => t.type_name.clone(),
    }
}

fn topic_flags(t: &Topic) -> &'static str {
    if t.evaluator_only {
        "  (evaluator only)"
    } else if t.external {
        "  (external)"
    } else {
        ""
    }
}

fn names<'a>(nodes: impl Iterator<Item = &'a Node>) -> String {
    nodes
        .map(|n| n.name.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

/// The graph in Graphviz DOT (`dot -Tsvg`): nodes as boxes, topics as ellipses, an edge
/// from each publisher to its topic and from the topic to each reader; delayed inputs
/// dashed, simulation-only nodes and external or evaluator-only topics grey.
pub fn dot(graph: &Graph) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "digraph landing {{");
    let _ = writeln!(s, "  rankdir=LR;");
    let _ = writeln!(s, "  node [fontname=\"Helvetica\", fontsize=11];");
    let _ = writeln!(s, "  edge [fontname=\"Helvetica\", fontsize=9];");
    for n in &graph.nodes {
        let colour = if n.on_vehicle { "black" } else { "grey45" };
        let _ = writeln!(
            s,
            "  {} [shape=box, style=bold, color={colour}, label={}];",
            quote(&format!("n:{}", n.name)),
            quote(&format!("{}\n{} Hz", n.name, n.rate_hz))
        );
    }
    for t in &graph.topics {
        let style = if t.evaluator_only || t.external {
            "dashed"
        } else {
            "solid"
        };
        let shape = match t.transport {
            Transport::Iceoryx2 => "ellipse",
            Transport::Mavlink => "hexagon",
            Transport::Runtime => "box",
        };
        let _ = writeln!(
            s,
            "  {} [shape={shape}, style={style}, label={}];",
            quote(&format!("t:{}", t.name)),
            quote(&t.name)
        );
    }
    for n in &graph.nodes {
        for o in &n.outputs {
            let _ = writeln!(
                s,
                "  {} -> {};",
                quote(&format!("n:{}", n.name)),
                quote(&format!("t:{o}"))
            );
        }
    }
    for n in &graph.nodes {
        for i in &n.inputs {
            let mut attrs = format!("label={}", quote(i.policy.name()));
            if i.delay {
                attrs = format!(
                    "label={}, style=dashed",
                    quote(&format!("{}, delay", i.policy.name()))
                );
            }
            let _ = writeln!(
                s,
                "  {} -> {} [{attrs}];",
                quote(&format!("t:{}", i.topic)),
                quote(&format!("n:{}", n.name))
            );
        }
    }
    let _ = writeln!(s, "}}");
    s
}

/// A DOT string literal.
fn quote(text: &str) -> String {
    let mut q = String::with_capacity(text.len() + 2);
    q.push('"');
    for c in text.chars() {
        match c {
            '"' => q.push_str("\\\""),
            '\\' => q.push_str("\\\\"),
            '\n' => q.push_str("\\n"),
            c => q.push(c),
        }
    }
    q.push('"');
    q
}

#[cfg(test)]
#[path = "render_test.rs"]
mod tests;
