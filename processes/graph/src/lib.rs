//! The landing pipeline's dataflow graph, declared once in `deploy/graph.toml`: the
//! processes (nodes), the topics each reads and publishes, rates, drop policies and
//! queue depths, heartbeat deadlines, the processing time a lockstep driver models, and
//! the arguments `landing run --processes` starts each process with.
//!
//! A crate of its own rather than a module of the `landing` tool: the tool is not the
//! only reader (the watchdog process will take its heartbeat deadlines from the graph)
//! and a process must not pull in the tool's dependencies (OpenCV, the simulator).
//! Loading follows `stack_config`: the file is parsed strictly, then every
//! rule is checked, and a mistake is one line naming the file, the node or topic and
//! what is allowed.

mod check;
mod render;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use stack_config::{self as config, ConfigError, Invalid, Validate};

pub use render::{dot, text};

/// The graph's file name inside the deploy directory.
pub const FILE_NAME: &str = "graph.toml";

/// The stack's own process binaries. A node may also run a binary of its own (a stage
/// added through the graph and the stage interface); the shipped graph uses only these
/// (processes/graph/tests/deploy.rs).
pub const STACK_BINARIES: &[&str] = &[
    "sim",
    "camera-ingest",
    "aruco-pnp",
    "depth-map",
    "planner",
    "fsm",
    "px4-link",
    "watchdog",
];

/// Stack binaries that watch the graph rather than being one of its nodes: they read
/// every topic and publish none, and nothing waits for them (the recorder).
pub const OBSERVER_BINARIES: &[&str] = &["recorder"];

/// Stack binaries for a vehicle's real sensors that the simulated graph does without
/// (depth-ingest: a depth camera's frames for depth-map `--input depth-frame`).
pub const SENSOR_BINARIES: &[&str] = &["depth-ingest"];

/// The placeholders a node's `args` may use, filled in per run from [`RunValues`].
pub const PLACEHOLDERS: &[&str] = &[
    "config",
    "deploy",
    "calibration",
    "pad",
    "scenario",
    "seed",
    "duration",
    "sim_addr",
    "link_addr",
    "sim_remote",
    "link_remote",
    "preset",
    "commit_height",
    "search_height_max",
    "signing_key",
];

/// How a process waits for the input that triggers it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Wake {
    /// Sleeps until an input's event (the wait set): no CPU while idle, tens of
    /// microseconds to wake on a loaded machine.
    Event,
    /// Learns the trigger stream's period, sleeps until shortly before the next sample
    /// is due and polls through (`runtime::PeriodicWait`): about 10 us to wake, for a
    /// latency-critical sensor stream, at ~1.5% of a core at 30 Hz.
    Periodic,
}

/// The `trigger` of a node that steps on its own clock (rather than on an input).
pub const CLOCK: &str = "clock";

/// The graph file of a deploy directory.
pub fn default_path(deploy: &Path) -> PathBuf {
    deploy.join(FILE_NAME)
}

/// Which messages of an input matter; a lockstep driver must drop as the process does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Policy {
    /// Only the newest message matters: older ones still waiting are skipped.
    Newest,
    /// Every message is taken, in order.
    Queue,
}

impl Policy {
    /// The name used in the file.
    pub fn name(self) -> &'static str {
        match self {
            Self::Newest => "newest",
            Self::Queue => "queue",
        }
    }
}

/// How a topic travels: the pipeline's shared memory, or MAVLink to the autopilot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Transport {
    /// An iceoryx2 publish-subscribe service (with its event service).
    #[default]
    Iceoryx2,
    /// MAVLink 2 over UDP or a serial port (PX4, or the simulator standing in for it).
    Mavlink,
    /// Served inside the reading process by the runtime itself (the watchdog's
    /// heartbeats and dead nodes): no service, no publisher node.
    Runtime,
}

/// One input of a node: the edge from the topic's publishers to it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Input {
    /// The topic read.
    pub topic: String,
    /// Which of its messages matter.
    pub policy: Policy,
    /// The subscriber's buffer, messages (iceoryx2 topics only; an overflow drops the
    /// oldest).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth: Option<u32>,
    /// The node uses the value it had before (no same-instant dependency): what breaks a
    /// cycle.
    pub delay: bool,
}

/// One process of the pipeline.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Node {
    /// Its name (iceoryx2 node, heartbeat, log file).
    pub name: String,
    /// The stack binary it runs, one of [`STACK_BINARIES`].
    pub binary: String,
    /// False for simulation-only nodes: no systemd unit on the vehicle.
    pub on_vehicle: bool,
    /// Started after every other node (the simulator: its clock starts the world).
    pub start_last: bool,
    /// How often it steps, Hz: its clock's rate, or its trigger input's nominal rate.
    pub rate_hz: f64,
    /// [`CLOCK`], or the input topic whose messages wake it.
    pub trigger: String,
    /// How the iceoryx2 driver waits for its trigger input.
    pub wake: Wake,
    /// How long without a heartbeat before it counts as hung, ms.
    pub heartbeat_deadline_ms: u64,
    /// Processing time a lockstep driver models: outputs this long after the input, ms.
    pub latency_ms: f64,
    /// Topics read.
    pub inputs: Vec<Input>,
    /// Topics published.
    pub outputs: Vec<String>,
    /// Arguments for `landing run --processes`, with placeholders.
    pub args: Vec<String>,
}

impl Node {
    /// Its arguments for one run: every placeholder replaced by its value.
    pub fn command_args(&self, values: &RunValues) -> Vec<String> {
        self.args.iter().map(|a| expand(a, values)).collect()
    }

    /// What a driver needs of it: inputs with their policy and delay, outputs, the
    /// modelled processing time.
    pub fn spec(&self) -> stage::lockstep::NodeSpec {
        stage::lockstep::NodeSpec {
            name: self.name.clone(),
            inputs: self
                .inputs
                .iter()
                .map(|i| stage::lockstep::InputSpec {
                    topic: i.topic.clone(),
                    newest: i.policy == Policy::Newest,
                    delay: i.delay,
                    depth: i.depth,
                })
                .collect(),
            outputs: self.outputs.clone(),
            latency_ns: (self.latency_ms * 1e6).round() as u64,
            periodic: (self.wake == Wake::Periodic).then(|| self.trigger.clone()),
        }
    }

    /// Whether it reads `topic`.
    pub fn reads(&self, topic: &str) -> bool {
        self.inputs.iter().any(|i| i.topic == topic)
    }

    /// Whether it publishes `topic`.
    pub fn publishes(&self, topic: &str) -> bool {
        self.outputs.iter().any(|o| o == topic)
    }
}

/// One topic: a service (or a MAVLink stream) and what it carries.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Topic {
    /// The short name nodes use (`camera/frame`).
    pub name: String,
    /// How it travels.
    pub transport: Transport,
    /// The iceoryx2 service (`landing/camera/frame`); none for MAVLink.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub service: Option<String>,
    /// The payload's versioned type name (a slice's header).
    #[serde(rename = "type")]
    pub type_name: String,
    /// A slice payload's element type.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub elements: Option<String>,
    /// Ground truth: only the evaluator may read it, never a node.
    pub evaluator_only: bool,
    /// Published outside the graph (an operator, a later watchdog).
    pub external: bool,
}

/// The validated graph: every rule of [`Graph::load`] holds.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Graph {
    /// The nodes, in the file's order.
    pub nodes: Vec<Node>,
    /// The topics, in the file's order.
    pub topics: Vec<Topic>,
}

impl Graph {
    /// Reads and validates a graph file.
    pub fn load(path: &Path) -> Result<Self, GraphError> {
        let text = std::fs::read_to_string(path).map_err(|source| {
            GraphError::File(ConfigError::Read {
                path: path.to_path_buf(),
                source,
            })
        })?;
        Self::parse(&text, path)
    }

    /// Parses and validates graph text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &Path) -> Result<Self, GraphError> {
        let file: GraphFile =
            config::parse(text, origin).map_err(|e| name_the_entry(e, text, origin))?;
        check::build(file, origin)
    }

    /// The node called `name`.
    pub fn node(&self, name: &str) -> Option<&Node> {
        self.nodes.iter().find(|n| n.name == name)
    }

    /// The topic called `name`.
    pub fn topic(&self, name: &str) -> Option<&Topic> {
        self.topics.iter().find(|t| t.name == name)
    }

    /// The nodes that publish `topic`, in the file's order.
    pub fn publishers<'a>(&'a self, topic: &'a str) -> impl Iterator<Item = &'a Node> + 'a {
        self.nodes.iter().filter(move |n| n.publishes(topic))
    }

    /// The nodes that read `topic`, in the file's order.
    pub fn readers<'a>(&'a self, topic: &'a str) -> impl Iterator<Item = &'a Node> + 'a {
        self.nodes.iter().filter(move |n| n.reads(topic))
    }

    /// The nodes that run on the vehicle (one systemd unit each).
    pub fn vehicle_nodes(&self) -> impl Iterator<Item = &Node> {
        self.nodes.iter().filter(|n| n.on_vehicle)
    }

    /// The order `landing run --processes` starts the nodes in: the file's order, the
    /// nodes marked `start_last` after the others.
    pub fn start_order(&self) -> Vec<&Node> {
        let (last, first): (Vec<&Node>, Vec<&Node>) = self.nodes.iter().partition(|n| n.start_last);
        first.into_iter().chain(last).collect()
    }

    /// An order in which stepping the nodes at one instant gives every node the
    /// same-instant outputs it depends on (delayed inputs do not count); ties keep the
    /// file's order. What a lockstep driver steps by.
    pub fn step_order(&self) -> Vec<&Node> {
        match check::same_instant_order(self) {
            Ok(order) => order
                .into_iter()
                .filter_map(|i| self.nodes.get(i))
                .collect(),
            // Validation refused every cycle without a delay.
            Err(_) => self.nodes.iter().collect(),
        }
    }
}

/// The run-specific values of the placeholders in the nodes' `args`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RunValues {
    /// `{config}`: the stack configuration file.
    pub config: String,
    /// `{deploy}`: the deploy directory.
    pub deploy: String,
    /// `{calibration}`: the down camera's calibration file.
    pub calibration: String,
    /// `{pad}`: the pad layout file.
    pub pad: String,
    /// `{scenario}`: the scenario file.
    pub scenario: String,
    /// `{seed}`: the simulator's seed.
    pub seed: String,
    /// `{duration}`: simulated seconds to run.
    pub duration: String,
    /// `{sim_addr}`: where the simulated autopilot listens for MAVLink (HOST:PORT).
    pub sim_addr: String,
    /// `{link_addr}`: where px4-link listens for MAVLink (HOST:PORT).
    pub link_addr: String,
    /// `{sim_remote}`: where the simulated autopilot sends (px4-link's `link_addr`, or a
    /// router's endpoint for the autopilot).
    pub sim_remote: String,
    /// `{link_remote}`: where px4-link sends (the autopilot's `sim_addr`, or a router's
    /// endpoint for px4-link).
    pub link_remote: String,
    /// `{preset}`: the mission's preset point, `x,y,z` in metres.
    pub preset: String,
    /// `{commit_height}`: the mission's commit height, m.
    pub commit_height: String,
    /// `{search_height_max}`: the highest the mission may search for the pad from, m
    /// (where the camera still reads the pad's largest marker).
    pub search_height_max: String,
    /// `{signing_key}`: the MAVLink signing key file (`[px4_link] signing_key`,
    /// resolved), empty for an unsigned link; the simulated autopilot holds it as PX4
    /// holds a key installed before the flight.
    pub signing_key: String,
}

impl RunValues {
    /// The value of placeholder `name`.
    pub fn get(&self, name: &str) -> Option<&str> {
        Some(match name {
            "config" => &self.config,
            "deploy" => &self.deploy,
            "calibration" => &self.calibration,
            "pad" => &self.pad,
            "scenario" => &self.scenario,
            "seed" => &self.seed,
            "duration" => &self.duration,
            "sim_addr" => &self.sim_addr,
            "link_addr" => &self.link_addr,
            "sim_remote" => &self.sim_remote,
            "link_remote" => &self.link_remote,
            "preset" => &self.preset,
            "commit_height" => &self.commit_height,
            "search_height_max" => &self.search_height_max,
            "signing_key" => &self.signing_key,
            _ => return None,
        })
    }
}

/// `arg` with every `{name}` replaced; validation has refused unknown names.
fn expand(arg: &str, values: &RunValues) -> String {
    let mut out = String::with_capacity(arg.len());
    let mut rest = arg;
    while let Some(open) = rest.find('{') {
        let (before, after) = rest.split_at(open);
        out.push_str(before);
        let after = &after[1..];
        let Some(close) = after.find('}') else {
            out.push('{');
            rest = after;
            continue;
        };
        let name = &after[..close];
        match values.get(name) {
            Some(v) => out.push_str(v),
            None => {
                out.push('{');
                out.push_str(name);
                out.push('}');
            }
        }
        rest = &after[close + 1..];
    }
    out.push_str(rest);
    out
}

/// Why a graph could not be used. `Display` is one line naming the file.
#[derive(Debug, thiserror::Error)]
pub enum GraphError {
    /// The file could not be read, is not TOML, or has an unknown, missing or mistyped
    /// key outside any node or topic.
    #[error(transparent)]
    File(#[from] ConfigError),
    /// A node breaks a rule.
    #[error("{}: node {node}: {message}", .path.display())]
    Node {
        /// The file.
        path: PathBuf,
        /// The node's name.
        node: String,
        /// What is wrong and what is allowed.
        message: String,
    },
    /// A topic breaks a rule.
    #[error("{}: topic {topic}: {message}", .path.display())]
    Topic {
        /// The file.
        path: PathBuf,
        /// The topic's name.
        topic: String,
        /// What is wrong and what is allowed.
        message: String,
    },
    /// The graph as a whole breaks a rule.
    #[error("{}: {message}", .path.display())]
    Graph {
        /// The file.
        path: PathBuf,
        /// What is wrong and what is allowed.
        message: String,
    },
}

/// The file as written: names are required, everything else is checked by
/// [`check::build`] so that its errors can name the node.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct GraphFile {
    #[serde(default)]
    topic: Vec<TopicFile>,
    #[serde(default)]
    node: Vec<NodeFile>,
}

impl Validate for GraphFile {
    fn validate(&self) -> Result<(), Invalid> {
        // The rules need names and cross-references: check::build.
        Ok(())
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, rename = "topic")]
struct TopicFile {
    name: String,
    #[serde(default)]
    transport: Transport,
    service: Option<String>,
    #[serde(rename = "type")]
    type_name: Option<String>,
    elements: Option<String>,
    #[serde(default)]
    evaluator_only: bool,
    #[serde(default)]
    external: bool,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, rename = "node")]
struct NodeFile {
    name: String,
    binary: Option<String>,
    #[serde(default = "on_vehicle_default")]
    on_vehicle: bool,
    #[serde(default)]
    start_last: bool,
    rate_hz: Option<f64>,
    trigger: Option<String>,
    wake: Option<String>,
    heartbeat_deadline_ms: Option<u64>,
    latency_ms: Option<f64>,
    #[serde(default)]
    inputs: Vec<InputFile>,
    #[serde(default)]
    outputs: Vec<String>,
    #[serde(default)]
    args: Vec<String>,
}

fn on_vehicle_default() -> bool {
    true
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, rename = "input { topic, policy, depth, delay }")]
struct InputFile {
    topic: String,
    policy: Policy,
    depth: Option<u32>,
    #[serde(default)]
    delay: bool,
}

/// A key error inside `[[node]]` or `[[topic]]` number i, told by the entry's name when
/// it has one (`node fsm: key `inputs[2].policy`: ...`) rather than by its index.
fn name_the_entry(e: ConfigError, text: &str, origin: &Path) -> GraphError {
    let ConfigError::Key { key, message, .. } = &e else {
        return e.into();
    };
    let Some((kind, index, rest)) = split_entry_key(key) else {
        return e.into();
    };
    let name = text.parse::<toml::Table>().ok().and_then(|t| {
        t.get(kind)?
            .as_array()?
            .get(index)?
            .get("name")?
            .as_str()
            .map(str::to_string)
    });
    let Some(name) = name else {
        return e.into();
    };
    let message = match rest {
        Some(rest) => format!("key `{rest}`: {message}"),
        None => message.clone(),
    };
    let path = origin.to_path_buf();
    match kind {
        "node" => GraphError::Node {
            path,
            node: name,
            message,
        },
        _ => GraphError::Topic {
            path,
            topic: name,
            message,
        },
    }
}

/// `node[3].inputs[0].policy` -> ("node", 3, Some("inputs[0].policy")).
fn split_entry_key(key: &str) -> Option<(&'static str, usize, Option<&str>)> {
    let (kind, rest) = if let Some(r) = key.strip_prefix("node[") {
        ("node", r)
    } else if let Some(r) = key.strip_prefix("topic[") {
        ("topic", r)
    } else {
        return None;
    };
    let (index, rest) = rest.split_once(']')?;
    let index = index.parse().ok()?;
    let rest = rest.strip_prefix('.').filter(|r| !r.is_empty());
    Some((kind, index, rest))
}

#[cfg(test)]
#[path = "lib_test.rs"]
mod tests;
