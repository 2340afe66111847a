//! The graph's rules: from the file as written to a [`Graph`] where every rule holds.
//! The first broken rule is the error, one line naming the node or topic and what is
//! allowed.

use std::collections::HashSet;
use std::path::Path;

use ipc_types::services;

use crate::{
    CLOCK, Graph, GraphError, GraphFile, Input, InputFile, Node, NodeFile, PLACEHOLDERS,
    STACK_BINARIES, Topic, TopicFile, Transport, Wake,
};

/// Highest rate a node may declare, Hz (the simulator's physics runs at 500).
const MAX_RATE_HZ: f64 = 10_000.0;
/// Heartbeat deadlines allowed, ms: twice the shortest heartbeat period `[ipc]` allows
/// (10 ms) to its longest deadline.
const DEADLINE_MS: (u64, u64) = (20, 60_000);
/// Highest processing latency a node may declare, ms.
const MAX_LATENCY_MS: f64 = 10_000.0;

/// Checks every rule of `file`; `origin` names it in errors.
pub(crate) fn build(file: GraphFile, origin: &Path) -> Result<Graph, GraphError> {
    let path = origin.to_path_buf();
    let topics = topics(&file.topic, &path)?;
    if file.node.is_empty() {
        return Err(GraphError::Graph {
            path,
            message: "no nodes (allowed: one [[node]] table per process)".into(),
        });
    }
    let mut names = HashSet::new();
    for n in &file.node {
        if !names.insert(n.name.as_str()) {
            return Err(node_error(
                &path,
                &n.name,
                "is declared twice (allowed: each node name once)",
            ));
        }
    }
    let nodes = file
        .node
        .iter()
        .map(|n| node(n, &topics, &path))
        .collect::<Result<Vec<_>, _>>()?;
    let graph = Graph { nodes, topics };
    connections(&graph, &path)?;
    if let Err(cycle) = same_instant_order(&graph) {
        return Err(node_error(
            &path,
            &cycle.node,
            &format!(
                "cycle {} has no delayed input (allowed: mark one input on the cycle `delay = true`: its node then uses the value it had before)",
                cycle.text
            ),
        ));
    }
    Ok(graph)
}

fn node_error(path: &Path, node: &str, message: &str) -> GraphError {
    GraphError::Node {
        path: path.to_path_buf(),
        node: node.to_string(),
        message: message.to_string(),
    }
}

fn topic_error(path: &Path, topic: &str, message: &str) -> GraphError {
    GraphError::Topic {
        path: path.to_path_buf(),
        topic: topic.to_string(),
        message: message.to_string(),
    }
}

/// The services a topic may name: every pipeline topic and the simulator's truth.
fn known_services() -> Vec<&'static str> {
    let mut all = services::PIPELINE_TOPICS.to_vec();
    all.extend(TRUTH_SERVICES);
    all
}

/// The evaluator-only services: no pipeline process may open them.
const TRUTH_SERVICES: [&str; 2] = [services::SIM_TRUTH, services::SIM_TRUTH_STATE];

fn topics(raw: &[TopicFile], path: &Path) -> Result<Vec<Topic>, GraphError> {
    let mut names = HashSet::new();
    let mut used_services = HashSet::new();
    let mut out = Vec::with_capacity(raw.len());
    for t in raw {
        let err = |m: &str| topic_error(path, &t.name, m);
        if t.name.is_empty() || t.name.chars().any(char::is_whitespace) {
            return Err(err(
                "the name is not allowed (allowed: a non-empty name without spaces, e.g. camera/frame)",
            ));
        }
        if !names.insert(t.name.as_str()) {
            return Err(err("is declared twice (allowed: each topic name once)"));
        }
        let type_name = match t.type_name.as_deref() {
            Some(ty) if !ty.trim().is_empty() => ty.to_string(),
            _ => {
                return Err(err(
                    "no type (allowed: the payload's versioned type name, e.g. landing::VehicleState/v2)",
                ));
            }
        };
        if t.evaluator_only && t.external {
            return Err(err(
                "is both evaluator_only and external (allowed: at most one of them)",
            ));
        }
        match t.transport {
            Transport::Iceoryx2 => {
                let known = known_services();
                let service = match t.service.as_deref() {
                    None => {
                        return Err(err(&format!(
                            "no service (allowed: one of {})",
                            known.join(", ")
                        )));
                    }
                    Some(s) if !known.contains(&s) => {
                        return Err(err(&format!(
                            "service {s} is not a service of the stack (allowed: one of {})",
                            known.join(", ")
                        )));
                    }
                    Some(s) => s,
                };
                if !used_services.insert(service) {
                    return Err(err(&format!(
                        "service {service} is already another topic's (allowed: one topic per service)"
                    )));
                }
                let truth = TRUTH_SERVICES.contains(&service);
                if truth != t.evaluator_only {
                    return Err(err(&if truth {
                        format!(
                            "service {service} is ground truth (allowed: evaluator_only = true on it)"
                        )
                    } else {
                        format!(
                            "evaluator_only = true on a pipeline service (allowed: only on {})",
                            TRUTH_SERVICES.join(", ")
                        )
                    }));
                }
            }
            Transport::Mavlink | Transport::Runtime => {
                let kind = if t.transport == Transport::Mavlink {
                    "MAVLink"
                } else {
                    "runtime"
                };
                if t.service.is_some() || t.elements.is_some() {
                    return Err(err(&format!(
                        "service and elements do not apply to a {kind} topic (allowed: name, transport, type, external)"
                    )));
                }
                if t.evaluator_only {
                    return Err(err(&format!(
                        "evaluator_only = true on a {kind} topic (allowed: only on the simulator's truth services)"
                    )));
                }
            }
        }
        out.push(Topic {
            name: t.name.clone(),
            transport: t.transport,
            service: t.service.clone(),
            type_name,
            elements: t.elements.clone(),
            evaluator_only: t.evaluator_only,
            external: t.external,
        });
    }
    Ok(out)
}

fn node(n: &NodeFile, topics: &[Topic], path: &Path) -> Result<Node, GraphError> {
    let err = |m: &str| node_error(path, &n.name, m);
    if n.name.is_empty() || n.name.chars().any(char::is_whitespace) {
        return Err(err(
            "the name is not allowed (allowed: a non-empty name without spaces, e.g. aruco-pnp)",
        ));
    }
    // A stage of your own runs a binary of your own: any command name, installed
    // beside the stack's.
    let binaries = format!(
        "a command name of lowercase letters, digits and -: one of the stack's ({}) or your own",
        STACK_BINARIES.join(", ")
    );
    let command_name = |b: &str| {
        b.starts_with(|c: char| c.is_ascii_lowercase())
            && b.chars()
                .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-')
    };
    let binary = match n.binary.as_deref() {
        None | Some("") => return Err(err(&format!("no binary (allowed: {binaries})"))),
        Some(b) if !command_name(b) => {
            return Err(err(&format!(
                "binary {b} is not allowed (allowed: {binaries})"
            )));
        }
        Some(b) => b.to_string(),
    };
    let rates = format!("allowed: above 0 and at most {MAX_RATE_HZ} Hz");
    let rate_hz = match n.rate_hz {
        None => return Err(err(&format!("no rate_hz ({rates})"))),
        Some(r) if !(r.is_finite() && r > 0.0 && r <= MAX_RATE_HZ) => {
            return Err(err(&format!("rate_hz {r} is not allowed ({rates})")));
        }
        Some(r) => r,
    };
    let deadlines = format!("allowed: {} to {} ms", DEADLINE_MS.0, DEADLINE_MS.1);
    let heartbeat_deadline_ms = match n.heartbeat_deadline_ms {
        None => return Err(err(&format!("no heartbeat_deadline_ms ({deadlines})"))),
        Some(d) if !(DEADLINE_MS.0..=DEADLINE_MS.1).contains(&d) => {
            return Err(err(&format!(
                "heartbeat_deadline_ms {d} is out of range ({deadlines})"
            )));
        }
        Some(d) => d,
    };
    let latencies = format!("allowed: 0 to {MAX_LATENCY_MS} ms");
    let latency_ms = match n.latency_ms {
        None => return Err(err(&format!("no latency_ms ({latencies})"))),
        Some(l) if !(l.is_finite() && (0.0..=MAX_LATENCY_MS).contains(&l)) => {
            return Err(err(&format!("latency_ms {l} is not allowed ({latencies})")));
        }
        Some(l) => l,
    };
    let declared = || {
        topics
            .iter()
            .map(|t| t.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut inputs: Vec<Input> = Vec::with_capacity(n.inputs.len());
    for i in &n.inputs {
        inputs.push(input(i, topics, &inputs, &declared, &err)?);
    }
    let mut outputs: Vec<String> = Vec::with_capacity(n.outputs.len());
    for o in &n.outputs {
        if !topics.iter().any(|t| &t.name == o) {
            return Err(err(&format!(
                "output topic {o} is not declared (allowed: {})",
                declared()
            )));
        }
        if outputs.contains(o) {
            return Err(err(&format!(
                "output topic {o} is listed twice (allowed: each topic once)"
            )));
        }
        outputs.push(o.clone());
    }
    let triggers = || {
        std::iter::once(CLOCK)
            .chain(inputs.iter().map(|i| i.topic.as_str()))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let trigger = match n.trigger.as_deref() {
        None => {
            return Err(err(&format!(
                "no trigger (allowed: {}: its clock or one of its inputs)",
                triggers()
            )));
        }
        Some(t) if t != CLOCK && !inputs.iter().any(|i| i.topic == t) => {
            return Err(err(&format!(
                "trigger {t} is not allowed (allowed: {}: its clock or one of its inputs)",
                triggers()
            )));
        }
        Some(t) => t.to_string(),
    };
    let wake = match n.wake.as_deref() {
        None | Some("event") => Wake::Event,
        Some("periodic") => {
            let shared_memory = topics
                .iter()
                .any(|t| t.name == trigger && t.transport == Transport::Iceoryx2);
            if !shared_memory {
                return Err(err(&format!(
                    "wake = \"periodic\" needs an input over shared memory as the trigger, not {trigger} (allowed: wake = \"event\", or a trigger among its shared-memory inputs)"
                )));
            }
            Wake::Periodic
        }
        Some(w) => {
            return Err(err(&format!(
                "wake {w} is not allowed (allowed: event, periodic)"
            )));
        }
    };
    for a in &n.args {
        placeholders(a).map_err(|m| err(&format!("argument `{a}`: {m}")))?;
    }
    Ok(Node {
        name: n.name.clone(),
        binary,
        on_vehicle: n.on_vehicle,
        start_last: n.start_last,
        rate_hz,
        trigger,
        wake,
        heartbeat_deadline_ms,
        latency_ms,
        inputs,
        outputs,
        args: n.args.clone(),
    })
}

fn input(
    i: &InputFile,
    topics: &[Topic],
    earlier: &[Input],
    declared: &dyn Fn() -> String,
    err: &dyn Fn(&str) -> GraphError,
) -> Result<Input, GraphError> {
    let name = &i.topic;
    let Some(topic) = topics.iter().find(|t| &t.name == name) else {
        return Err(err(&format!(
            "input topic {name} is not declared (allowed: {})",
            declared()
        )));
    };
    if earlier.iter().any(|e| &e.topic == name) {
        return Err(err(&format!(
            "input topic {name} is listed twice (allowed: each topic once)"
        )));
    }
    if topic.evaluator_only {
        return Err(err(&format!(
            "input topic {name} is evaluator-only ground truth (allowed readers: the evaluator of landing run, never a node)"
        )));
    }
    let deepest = stage::max_depth(topic.elements.as_deref());
    let depths = format!("allowed: 1 to {deepest}");
    match (topic.transport, i.depth) {
        (Transport::Iceoryx2, None) => {
            return Err(err(&format!(
                "input topic {name} has no depth ({depths} messages, the subscriber's buffer)"
            )));
        }
        (Transport::Iceoryx2, Some(d)) if !(1..=deepest).contains(&d) => {
            return Err(err(&format!(
                "input topic {name}: depth {d} is out of range ({depths})"
            )));
        }
        (Transport::Mavlink | Transport::Runtime, Some(_)) => {
            return Err(err(&format!(
                "input topic {name}: depth does not apply to a MAVLink or runtime topic (allowed: no depth; the link's socket or port buffers)"
            )));
        }
        _ => {}
    }
    Ok(Input {
        topic: name.clone(),
        policy: i.policy,
        depth: i.depth,
        delay: i.delay,
    })
}

/// Every topic a node reads has a publisher (or is external), and every topic is used.
fn connections(graph: &Graph, path: &Path) -> Result<(), GraphError> {
    for n in &graph.nodes {
        for i in &n.inputs {
            let external = graph.topic(&i.topic).is_some_and(|t| t.external);
            if !external && graph.publishers(&i.topic).next().is_none() {
                return Err(node_error(
                    path,
                    &n.name,
                    &format!(
                        "input topic {} has no publisher (allowed: a topic some node lists in its outputs, or one marked external = true)",
                        i.topic
                    ),
                ));
            }
        }
    }
    for t in &graph.topics {
        let read = graph.readers(&t.name).next().is_some();
        let published = graph.publishers(&t.name).next().is_some();
        if !read && !published {
            return Err(topic_error(
                path,
                &t.name,
                "no node reads or publishes it (allowed: a topic some node lists in its inputs or outputs)",
            ));
        }
    }
    Ok(())
}

/// A cycle of same-instant dependencies.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Cycle {
    /// Its first node in the file's order.
    pub node: String,
    /// `a -> topic -> b -> topic -> a`, from that node.
    pub text: String,
}

/// The same-instant edges into node `c`: (publisher index, topic) for each input that
/// is not delayed, in input order and then the file's order of the publishers.
fn edges_into(graph: &Graph, c: usize) -> Vec<(usize, &str)> {
    let Some(node) = graph.nodes.get(c) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for i in node.inputs.iter().filter(|i| !i.delay) {
        for (p, pn) in graph.nodes.iter().enumerate() {
            if pn.publishes(&i.topic) {
                out.push((p, i.topic.as_str()));
            }
        }
    }
    out
}

/// Node indices in an order where every same-instant input comes from an earlier node
/// (Kahn's algorithm, lowest file index first), or a cycle without a delayed input.
pub(crate) fn same_instant_order(graph: &Graph) -> Result<Vec<usize>, Cycle> {
    let n = graph.nodes.len();
    let into: Vec<Vec<(usize, &str)>> = (0..n).map(|c| edges_into(graph, c)).collect();
    let mut waiting: Vec<usize> = into.iter().map(Vec::len).collect();
    let mut done = vec![false; n];
    let mut order = Vec::with_capacity(n);
    while let Some(next) = (0..n).find(|&i| !done[i] && waiting[i] == 0) {
        done[next] = true;
        order.push(next);
        for (c, edges) in into.iter().enumerate() {
            waiting[c] -= edges.iter().filter(|(p, _)| *p == next).count();
        }
    }
    if order.len() == n {
        return Ok(order);
    }
    // Every node left has an edge from another node left: walk those edges backwards
    // until a node repeats.
    let Some(start) = (0..n).find(|&i| !done[i]) else {
        return Ok(order);
    };
    let mut seq = vec![start];
    let mut via: Vec<&str> = Vec::new();
    let cycle: Vec<(usize, &str)> = loop {
        let cur = seq.last().copied().unwrap_or(start);
        let Some(&(p, topic)) = into[cur].iter().find(|(p, _)| !done[*p]) else {
            // Not reachable: Kahn left `cur` with a same-instant edge from a node left.
            return Ok(order);
        };
        via.push(topic);
        if let Some(k) = seq.iter().position(|&x| x == p) {
            // seq[i + 1] -> seq[i] through via[i]; p = seq[k] -> seq[last] through
            // via[last]. Forward from seq[k]: seq[k], seq[last], ..., seq[k + 1].
            let last = seq.len() - 1;
            let mut fwd = vec![(seq[k], via[last])];
            for j in (k + 1..=last).rev() {
                fwd.push((seq[j], via[j - 1]));
            }
            break fwd;
        }
        seq.push(p);
    };
    let first = cycle
        .iter()
        .enumerate()
        .min_by_key(|(_, (node, _))| *node)
        .map_or(0, |(pos, _)| pos);
    let name = |i: usize| graph.nodes.get(i).map_or("?", |n| n.name.as_str());
    let mut text = String::new();
    for j in 0..cycle.len() {
        let (node, topic) = cycle[(first + j) % cycle.len()];
        text.push_str(&format!("{} -> {topic} -> ", name(node)));
    }
    let head = cycle[first].0;
    text.push_str(name(head));
    Err(Cycle {
        node: name(head).to_string(),
        text,
    })
}

/// The placeholder names in `arg`, or why it is malformed.
pub(crate) fn placeholders(arg: &str) -> Result<Vec<&str>, String> {
    let allowed = || {
        PLACEHOLDERS
            .iter()
            .map(|p| format!("{{{p}}}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut out = Vec::new();
    let mut rest = arg;
    while let Some(at) = rest.find(['{', '}']) {
        if rest[at..].starts_with('}') {
            return Err(format!(
                "`}}` without `{{` (allowed placeholders: {})",
                allowed()
            ));
        }
        let after = &rest[at + 1..];
        let Some(close) = after.find('}') else {
            return Err(format!(
                "`{{` without `}}` (allowed placeholders: {})",
                allowed()
            ));
        };
        let name = &after[..close];
        if !PLACEHOLDERS.contains(&name) {
            return Err(format!(
                "unknown placeholder {{{name}}} (allowed: {})",
                allowed()
            ));
        }
        out.push(name);
        rest = &after[close + 1..];
    }
    Ok(out)
}

#[cfg(test)]
#[path = "check_test.rs"]
pub(crate) mod tests;
