//! The lockstep driver: every stage of a graph in one process on simulated time,
//! deterministic per seed.
//!
//! Time advances from instant to instant: the next due tick of any stage, or the next
//! delivery. At each instant the stages run in the graph's same-instant order, each
//! taking what was delivered to it and then ticking if its period has passed; passes
//! repeat until nothing is left to deliver at this instant. An output goes to every
//! reader the graph names, `latency` (the producer's modelled processing time) after the
//! call; on a delayed edge (one that closes a cycle) the reader gets it in a later pass,
//! so it decides with the value it had before. A `newest` input hands over only the
//! newest message waiting, as the iceoryx2 driver does.

use std::collections::VecDeque;
use std::rc::Rc;
use std::time::Instant;

use ipc_types::topics;

use crate::{Input, Message, Outbox, OwnedMessage, SliceHeader, SliceMut, Stage, StageError};

/// How one input of a node is fed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InputSpec {
    /// The topic's short name.
    pub topic: String,
    /// Only the newest waiting message is handed over (older ones are skipped, counted).
    pub newest: bool,
    /// The edge closes a cycle: delivered in a later pass of the same instant.
    pub delay: bool,
    /// The subscriber's buffer, messages, for a driver that has one (iceoryx2); `None`
    /// takes the driver's default. The lockstep driver delivers everything.
    pub depth: Option<u32>,
}

/// What the driver needs to know of a node (the graph's node, without the deployment).
#[derive(Debug, Clone, PartialEq)]
pub struct NodeSpec {
    /// The node name; the stage's [`Stage::name`] must agree.
    pub name: String,
    /// Its inputs, in the order they are handed over.
    pub inputs: Vec<InputSpec>,
    /// The topics it may publish.
    pub outputs: Vec<String>,
    /// Modelled processing time: outputs are delivered this long after the call, ns.
    pub latency_ns: u64,
    /// The input a process waits on by its learned period rather than by event
    /// (`wake = "periodic"` in the graph); the lockstep driver has no waiting to do.
    pub periodic: Option<String>,
}

/// Why the driver could not be built or stopped.
#[derive(Debug, thiserror::Error)]
pub enum LockstepError {
    /// A stage's name is not its node's.
    #[error("stage `{stage}` was given for node `{node}`")]
    Mismatch {
        /// The node.
        node: String,
        /// The stage's own name.
        stage: String,
    },
    /// A topic is not in the topic table.
    #[error("node `{node}`: unknown topic `{topic}`")]
    UnknownTopic {
        /// The node.
        node: String,
        /// The topic.
        topic: String,
    },
    /// A node reads a topic only the evaluator may read (ground truth).
    #[error("node `{node}` reads `{topic}`, which only the evaluator may read")]
    EvaluatorOnly {
        /// The node.
        node: String,
        /// The topic.
        topic: String,
    },
    /// A stage failed to publish.
    #[error("{node}: {source}")]
    Publish {
        /// The node.
        node: String,
        /// What went wrong.
        source: StageError,
    },
}

/// A message on its way to one reader.
#[derive(Debug)]
struct Pending {
    at_ns: u64,
    /// The pass number from which it may be taken (delayed edges: the next pass).
    pass: u64,
    msg: Rc<OwnedMessage>,
}

/// An output topic and its readers: (node, input, delayed edge).
type Route = (String, Vec<(usize, usize, bool)>);

struct Node {
    spec: NodeSpec,
    stage: Box<dyn Stage>,
    period_ns: Option<u64>,
    next_tick_ns: u64,
    /// Ticks at given times besides the period's ([`Lockstep::tick_at`]), ascending.
    ticks_at: VecDeque<u64>,
    /// One queue per input, in the spec's order.
    queues: Vec<VecDeque<Pending>>,
    /// Where each output goes.
    routes: Vec<Route>,
    skipped: u64,
    /// Wall time of every call, ns (measured, never simulated: a profile, not a model).
    call_ns: Vec<u64>,
}

/// Every message a stage published, for the driver's observer (recording, evaluation).
pub struct Published<'a> {
    /// When (simulated ns).
    pub now_ns: u64,
    /// The node that published it.
    pub node: &'a str,
    /// The topic.
    pub topic: &'a str,
    /// The message (its stage stamp closed).
    pub msg: Message<'a>,
    /// Wall time of the call that published it, ns (measured on this machine: a
    /// profile, never part of the simulation).
    pub wall_ns: u64,
}

/// The lockstep driver over a set of stages.
pub struct Lockstep {
    nodes: Vec<Node>,
    now_ns: u64,
    pass: u64,
    started: bool,
}

/// An outbox collecting a call's outputs.
struct Collect<'a> {
    node: &'a str,
    outputs: &'a [String],
    out: Vec<(usize, OwnedMessage)>,
    /// Buffers reused for slices.
    spare_u8: &'a mut Vec<Vec<u8>>,
    spare_u16: &'a mut Vec<Vec<u16>>,
}

impl Collect<'_> {
    fn output(&self, topic: &str, payload: topics::Payload) -> Result<usize, StageError> {
        let i = self
            .outputs
            .iter()
            .position(|o| o == topic)
            .ok_or_else(|| StageError::NotAnOutput {
                stage: self.node.to_string(),
                topic: topic.to_string(),
            })?;
        if let Some(info) = topics::find(topic)
            && info.payload != payload
        {
            return Err(StageError::WrongType {
                topic: topic.to_string(),
                expected: info.payload.type_name(),
                got: payload.type_name(),
            });
        }
        Ok(i)
    }
}

impl Outbox for Collect<'_> {
    fn publish(&mut self, topic: &str, msg: Message<'_>) -> Result<(), StageError> {
        let i = self.output(topic, msg.payload())?;
        self.out.push((i, msg.to_owned()));
        Ok(())
    }

    fn publish_slice(
        &mut self,
        topic: &str,
        len: usize,
        fill: &mut dyn FnMut(SliceMut<'_>) -> Option<SliceHeader>,
    ) -> Result<bool, StageError> {
        let kind = topics::find(topic).map(|t| t.payload);
        let msg = match kind {
            Some(topics::Payload::DepthFrame) => {
                let mut buf = self.spare_u16.pop().unwrap_or_default();
                buf.clear();
                buf.resize(len, 0);
                match fill(SliceMut::U16(&mut buf)) {
                    Some(SliceHeader::DepthFrame(h)) => OwnedMessage::DepthFrame(h, buf),
                    Some(other) => {
                        return Err(StageError::WrongType {
                            topic: topic.to_string(),
                            expected: topics::Payload::DepthFrame.type_name(),
                            got: other.payload().type_name(),
                        });
                    }
                    None => {
                        self.spare_u16.push(buf);
                        return Ok(false);
                    }
                }
            }
            _ => {
                let mut buf = self.spare_u8.pop().unwrap_or_default();
                buf.clear();
                buf.resize(len, 0);
                match fill(SliceMut::U8(&mut buf)) {
                    Some(SliceHeader::CameraFrame(h)) => OwnedMessage::CameraFrame(h, buf),
                    Some(SliceHeader::OccupancyMap(h)) => OwnedMessage::OccupancyMap(h, buf),
                    Some(other) => {
                        return Err(StageError::WrongType {
                            topic: topic.to_string(),
                            expected: kind.map_or("a u8 slice", |k| k.type_name()),
                            got: other.payload().type_name(),
                        });
                    }
                    None => {
                        self.spare_u8.push(buf);
                        return Ok(false);
                    }
                }
            }
        };
        let i = self.output(topic, msg.as_message().payload())?;
        self.out.push((i, msg));
        Ok(true)
    }
}

impl Lockstep {
    /// A driver over `stages`, each with its node; the order given is the same-instant
    /// order (the graph's step order: producers before consumers on undelayed edges).
    pub fn new(stages: Vec<(NodeSpec, Box<dyn Stage>)>) -> Result<Self, LockstepError> {
        for (spec, stage) in &stages {
            if spec.name != stage.name() {
                return Err(LockstepError::Mismatch {
                    node: spec.name.clone(),
                    stage: stage.name().to_string(),
                });
            }
            if let Some(i) = spec
                .inputs
                .iter()
                .find(|i| topics::find(&i.topic).is_some_and(|t| t.evaluator_only))
            {
                return Err(LockstepError::EvaluatorOnly {
                    node: spec.name.clone(),
                    topic: i.topic.clone(),
                });
            }
            for t in spec
                .inputs
                .iter()
                .map(|i| &i.topic)
                .chain(spec.outputs.iter())
            {
                if topics::find(t).is_none() {
                    return Err(LockstepError::UnknownTopic {
                        node: spec.name.clone(),
                        topic: t.clone(),
                    });
                }
            }
        }
        let specs: Vec<NodeSpec> = stages.iter().map(|(s, _)| s.clone()).collect();
        let nodes = stages
            .into_iter()
            .map(|(spec, stage)| {
                let routes = spec
                    .outputs
                    .iter()
                    .map(|topic| {
                        let readers = specs
                            .iter()
                            .enumerate()
                            .flat_map(|(n, s)| {
                                s.inputs
                                    .iter()
                                    .enumerate()
                                    .filter(|(_, i)| &i.topic == topic)
                                    .map(move |(k, i)| (n, k, i.delay))
                            })
                            .collect();
                        (topic.clone(), readers)
                    })
                    .collect();
                Node {
                    queues: spec.inputs.iter().map(|_| VecDeque::new()).collect(),
                    period_ns: stage.tick_period_ns().filter(|p| *p > 0),
                    next_tick_ns: 0,
                    ticks_at: VecDeque::new(),
                    routes,
                    spec,
                    stage,
                    skipped: 0,
                    call_ns: Vec::new(),
                }
            })
            .collect();
        Ok(Self {
            nodes,
            now_ns: 0,
            pass: 0,
            started: false,
        })
    }

    /// Simulated time now, ns.
    pub fn now_ns(&self) -> u64 {
        self.now_ns
    }

    /// The stage of `node`, to read its state after or during a run.
    pub fn stage(&self, node: &str) -> Option<&dyn Stage> {
        self.nodes
            .iter()
            .find(|n| n.spec.name == node)
            .map(|n| n.stage.as_ref())
    }

    /// Messages on `newest` inputs that were skipped because a newer one was waiting.
    pub fn skipped(&self, node: &str) -> u64 {
        self.nodes
            .iter()
            .find(|n| n.spec.name == node)
            .map_or(0, |n| n.skipped)
    }

    /// The wall time of each call to `node`, ns (a profile of this machine; no
    /// simulated time depends on it).
    pub fn call_times_ns(&self, node: &str) -> &[u64] {
        self.nodes
            .iter()
            .find(|n| n.spec.name == node)
            .map_or(&[], |n| n.call_ns.as_slice())
    }

    /// Delivers `msg` on `topic` to its readers at the current instant, as if a node
    /// outside the graph had published it (an operator's safety order, a test's input).
    pub fn inject(&mut self, topic: &str, msg: Message<'_>) {
        self.inject_at(self.now_ns, topic, msg);
    }

    /// Delivers `msg` on `topic` to its readers at `at_ns` (not before the current
    /// instant): a recorded input sequence replayed at its recorded times. Inject in
    /// time order; the driver advances to each time as it steps.
    pub fn inject_at(&mut self, at_ns: u64, topic: &str, msg: Message<'_>) {
        let at_ns = at_ns.max(self.now_ns);
        let msg = Rc::new(msg.to_owned());
        for node in &mut self.nodes {
            for (k, i) in node.spec.inputs.iter().enumerate() {
                if i.topic == topic
                    && let Some(q) = node.queues.get_mut(k)
                {
                    q.push_back(Pending {
                        at_ns,
                        pass: 0,
                        msg: Rc::clone(&msg),
                    });
                }
            }
        }
    }

    /// Ticks `node` at `at_ns` (not before the current instant), besides its period's
    /// ticks: a recorded step replayed at its recorded time, for a stage whose flight
    /// stepped on a clock the replay does not have. Give the times in ascending order;
    /// one tick per instant, as ever. `false`: no such node.
    pub fn tick_at(&mut self, node: &str, at_ns: u64) -> bool {
        let at_ns = at_ns.max(self.now_ns);
        let Some(n) = self.nodes.iter_mut().find(|n| n.spec.name == node) else {
            return false;
        };
        if n.ticks_at.back().is_none_or(|last| *last < at_ns) {
            n.ticks_at.push_back(at_ns);
        }
        true
    }

    /// The next instant anything happens: a tick or a delivery.
    fn next_instant(&self) -> Option<u64> {
        let ticks = self
            .nodes
            .iter()
            .filter(|n| n.period_ns.is_some())
            .map(|n| n.next_tick_ns)
            .chain(
                self.nodes
                    .iter()
                    .filter_map(|n| n.ticks_at.front().copied()),
            );
        let deliveries = self
            .nodes
            .iter()
            .flat_map(|n| n.queues.iter().filter_map(|q| q.front().map(|p| p.at_ns)));
        ticks.chain(deliveries).min()
    }

    /// Runs one instant (every pass at the next time anything is due) and returns its
    /// time; `observe` sees every published message. `None`: nothing is left to run.
    pub fn step(
        &mut self,
        observe: &mut dyn FnMut(&Published<'_>),
    ) -> Result<Option<u64>, LockstepError> {
        let Some(t) = self.next_instant() else {
            return Ok(None);
        };
        // Time never runs backwards (an injected message is due now).
        self.now_ns = if self.started { t.max(self.now_ns) } else { t };
        self.started = true;
        let mut spare_u8 = Vec::new();
        let mut spare_u16 = Vec::new();
        let mut ticked = vec![false; self.nodes.len()];
        loop {
            self.pass += 1;
            let mut ran = false;
            for n in 0..self.nodes.len() {
                ran |= self.run_node(n, &mut ticked, observe, &mut spare_u8, &mut spare_u16)?;
            }
            if !ran {
                break;
            }
        }
        Ok(Some(self.now_ns))
    }

    /// Hands node `n` what is due for it in this pass and ticks it once per instant when
    /// its period has passed. Returns whether it was called.
    fn run_node(
        &mut self,
        n: usize,
        ticked: &mut [bool],
        observe: &mut dyn FnMut(&Published<'_>),
        spare_u8: &mut Vec<Vec<u8>>,
        spare_u16: &mut Vec<Vec<u16>>,
    ) -> Result<bool, LockstepError> {
        let (now, pass) = (self.now_ns, self.pass);
        let Some(node) = self.nodes.get_mut(n) else {
            return Ok(false);
        };
        let mut inputs: Vec<(usize, Rc<OwnedMessage>)> = Vec::new();
        for (k, q) in node.queues.iter_mut().enumerate() {
            let newest = node.spec.inputs.get(k).is_some_and(|i| i.newest);
            let mut taken: Option<Rc<OwnedMessage>> = None;
            while q.front().is_some_and(|p| p.at_ns <= now && p.pass <= pass) {
                let Some(p) = q.pop_front() else { break };
                if newest {
                    if taken.replace(p.msg).is_some() {
                        node.skipped += 1;
                    }
                } else {
                    inputs.push((k, p.msg));
                }
            }
            if let Some(m) = taken {
                inputs.push((k, m));
            }
        }
        let scheduled = node.ticks_at.front().is_some_and(|t| *t <= now);
        let tick = !ticked.get(n).copied().unwrap_or(true)
            && (scheduled || (node.period_ns.is_some() && node.next_tick_ns <= now));
        if inputs.is_empty() && !tick {
            return Ok(false);
        }
        let started = Instant::now();
        let mut out = Collect {
            node: &node.spec.name,
            outputs: &node.spec.outputs,
            out: Vec::new(),
            spare_u8,
            spare_u16,
        };
        let fail = |source| LockstepError::Publish {
            node: node.spec.name.clone(),
            source,
        };
        // Inputs in the order of the spec, then the tick (as the iceoryx2 driver does).
        inputs.sort_by_key(|(k, _)| *k);
        for (k, m) in &inputs {
            let topic = node.spec.inputs.get(*k).map_or("", |i| i.topic.as_str());
            node.stage
                .on_input(
                    now,
                    Input {
                        topic,
                        msg: m.as_message(),
                    },
                    &mut out,
                )
                .map_err(fail)?;
        }
        if !inputs.is_empty() {
            node.stage.on_inputs_done(now, &mut out).map_err(fail)?;
        }
        if tick {
            if let Some(slot) = ticked.get_mut(n) {
                *slot = true;
            }
            node.stage.on_tick(now, &mut out).map_err(fail)?;
            while node.ticks_at.front().is_some_and(|t| *t <= now) {
                node.ticks_at.pop_front();
            }
            if let Some(p) = node.period_ns {
                // The next period boundary after now (a late start skips, never bursts).
                while node.next_tick_ns <= now {
                    node.next_tick_ns += p;
                }
            }
        }
        let outputs = std::mem::take(&mut out.out);
        let wall_ns = u64::try_from(started.elapsed().as_nanos()).unwrap_or(u64::MAX);
        node.call_ns.push(wall_ns);
        let at = now + node.spec.latency_ns;
        let mut deliveries = Vec::new();
        for (i, mut msg) in outputs {
            if let Some(h) = msg.header_mut() {
                h.close_stage(at);
            }
            let Some((topic, readers)) = node.routes.get(i) else {
                continue;
            };
            observe(&Published {
                now_ns: now,
                node: &node.spec.name,
                topic,
                msg: msg.as_message(),
                wall_ns,
            });
            let msg = Rc::new(msg);
            for &(reader, input, delay) in readers {
                deliveries.push((
                    reader,
                    input,
                    Pending {
                        at_ns: at,
                        pass: if delay || reader <= n { pass + 1 } else { pass },
                        msg: Rc::clone(&msg),
                    },
                ));
            }
        }
        for (reader, input, p) in deliveries {
            if let Some(q) = self
                .nodes
                .get_mut(reader)
                .and_then(|r| r.queues.get_mut(input))
            {
                q.push_back(p);
            }
        }
        Ok(true)
    }
}

impl std::fmt::Debug for Lockstep {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Lockstep")
            .field(
                "nodes",
                &self.nodes.iter().map(|n| &n.spec.name).collect::<Vec<_>>(),
            )
            .field("now_ns", &self.now_ns)
            .finish()
    }
}
