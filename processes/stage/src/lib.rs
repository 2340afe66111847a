//! The stage interface: what every pipeline process's library implements, and what both
//! drivers (the lockstep driver here, the iceoryx2 driver in `runtime`) call.
//!
//! A stage gets its inputs and the time, and hands its outputs to an [`Outbox`]; it opens
//! no port, reads no clock and never sleeps. That is what lets one stage run unchanged as
//! its own OS process over shared memory and, with the others, in one process on
//! simulated time (copper-rs keeps its task logic apart from scheduling the same way).
//! Which topics a stage reads and publishes, at what rate, with what drop policy and
//! what modelled processing time, is the graph's business (`deploy/graph.toml`), not the
//! stage's.

pub mod lockstep;
mod message;
pub mod testing;

pub use message::{Message, OwnedMessage, SliceHeader, SliceMut};

/// The deepest subscriber buffer a topic of fixed-size messages may be declared with
/// (`depth` in the graph): the iceoryx2 services are made for it, so a deep reader (the
/// watchdog, which lists nodes between reads) and a shallow one can share a topic.
pub const MAX_MESSAGE_DEPTH: u32 = 16;
/// The same for frames and maps: each sample is up to megabytes, and each publisher
/// holds this many per subscriber; their readers take the newest.
pub const MAX_SLICE_DEPTH: u32 = 4;

/// The deepest buffer a subscriber of a topic may ask for: `elements` is the topic's slice
/// element type, if it carries slices.
pub fn max_depth(elements: Option<&str>) -> u32 {
    if elements.is_some() {
        MAX_SLICE_DEPTH
    } else {
        MAX_MESSAGE_DEPTH
    }
}

/// One input as a driver hands it over: the topic's short name (`ipc_types::topics`) and
/// the message, borrowed from shared memory or from the driver's queue.
#[derive(Debug, Clone, Copy)]
pub struct Input<'a> {
    /// The topic it came on.
    pub topic: &'a str,
    /// The message.
    pub msg: Message<'a>,
}

/// Why an output could not be published. A stage passes it up (`?`); the driver ends
/// the process (iceoryx2) or the run (lockstep) with it.
#[derive(Debug, thiserror::Error)]
pub enum StageError {
    /// The stage published on a topic its node does not declare as an output.
    #[error("`{stage}` publishes on `{topic}`, which is not one of its outputs in the graph")]
    NotAnOutput {
        /// The stage.
        stage: String,
        /// The topic.
        topic: String,
    },
    /// The message is not of the topic's type.
    #[error("`{topic}` carries {expected}, not {got}")]
    WrongType {
        /// The topic.
        topic: String,
        /// Its type.
        expected: &'static str,
        /// The message's.
        got: &'static str,
    },
    /// The stage itself failed (the simulator could not step).
    #[error("{0}")]
    Failed(String),
    /// The transport failed (iceoryx2 send or loan, the MAVLink link); what it said.
    #[error("{0}")]
    Transport(String),
}

/// Where a stage's outputs go. The iceoryx2 driver sends them into shared memory (frames
/// written in place into a loaned sample); the lockstep driver queues them for the
/// readers the graph names, after the node's modelled processing time. Either closes the
/// stage's latency stamp (the last [`ipc_types::msg::StageStamp`], whose exit the stage
/// cannot know) when the message leaves.
pub trait Outbox {
    /// Publishes `msg` on `topic`.
    fn publish(&mut self, topic: &str, msg: Message<'_>) -> Result<(), StageError>;

    /// Publishes a header-and-slice message of `len` elements written in place: `fill`
    /// gets the output buffer and returns its header, or `None` to drop it. Returns
    /// whether a message went out (`false`: dropped by `fill`, or no buffer free; the
    /// stage counts it, it never waits).
    fn publish_slice(
        &mut self,
        topic: &str,
        len: usize,
        fill: &mut dyn FnMut(SliceMut<'_>) -> Option<SliceHeader>,
    ) -> Result<bool, StageError>;
}

/// A named counter for the stop line (`<name> stopped k=v ...`) and status views.
pub type Counter = (&'static str, u64);

/// A pipeline stage: inputs and time in, outputs out.
///
/// Drivers call [`Stage::on_input`] for every message the graph routes to the node (in
/// the order the graph lists the inputs; for a `newest` input only the newest waiting
/// message), then [`Stage::on_tick`] when the stage's period has passed. `now_ns` is the
/// driver's clock: monotonic ns in a process, simulated ns in lockstep.
pub trait Stage {
    /// The node name (`aruco-pnp`): the iceoryx2 node, the heartbeat and the log line.
    fn name(&self) -> &'static str;

    /// How often [`Stage::on_tick`] is wanted, ns; `None`: only inputs wake the stage.
    fn tick_period_ns(&self) -> Option<u64> {
        None
    }

    /// One input.
    fn on_input(
        &mut self,
        now_ns: u64,
        input: Input<'_>,
        out: &mut dyn Outbox,
    ) -> Result<(), StageError>;

    /// After the inputs of one wake-up were handed over (one batch of datagrams, one
    /// pass in lockstep): for a stage that answers a batch once, not each message.
    fn on_inputs_done(&mut self, _now_ns: u64, _out: &mut dyn Outbox) -> Result<(), StageError> {
        Ok(())
    }

    /// The stage's own clock (its decisions, timeouts, periodic outputs).
    fn on_tick(&mut self, _now_ns: u64, _out: &mut dyn Outbox) -> Result<(), StageError> {
        Ok(())
    }

    /// The most elements a slice output on `topic` may have (the iceoryx2 driver sizes
    /// the shared-memory samples with it); 0 for a topic that is not a slice.
    fn max_slice_len(&self, _topic: &str) -> usize {
        0
    }

    /// Counters worth a line when the stage stops (inputs, outputs, drops by reason).
    fn counters(&self) -> Vec<Counter>;

    /// Whether the stage has nothing more to do (the simulator at its scenario's end):
    /// the iceoryx2 driver then stops the process cleanly, as on SIGTERM. Lockstep runs
    /// end by their own rule (the referee, a duration).
    fn finished(&self) -> bool {
        false
    }
}

/// The stop line of a stage: `name stopped k=v k=v`.
pub fn stop_line(stage: &dyn Stage) -> String {
    let mut line = format!("{} stopped", stage.name());
    for (k, v) in stage.counters() {
        line.push_str(&format!(" {k}={v}"));
    }
    line
}

/// I/O a stage needs besides the graph's iceoryx2 topics: the MAVLink socket or serial
/// port of px4-link, a camera read on its own thread, the simulator's MAVLink endpoint.
/// The iceoryx2 driver waits on it instead of on its wait set and hands what arrived to
/// the stage like any input; the lockstep driver needs none (its stages exchange those
/// messages in memory).
pub trait External {
    /// The topics it delivers (inputs) and takes (outputs), by short name.
    fn topics(&self) -> &[&'static str];

    /// Waits at most `timeout_ns` for input and hands each arrival to `deliver`, borrowed
    /// from the source's own buffer (a datagram, a decoded image: nothing is copied on
    /// the way to the stage), with its time of arrival on the driver's clock `clock`.
    /// What the stage publishes on this source's topics meanwhile is sent after `wait`
    /// returns.
    fn wait(
        &mut self,
        timeout_ns: u64,
        clock: &dyn Fn() -> u64,
        deliver: &mut dyn FnMut(Input<'_>, u64) -> Result<(), StageError>,
    ) -> Result<Flow, StageError>;

    /// Sends an output on one of its topics.
    fn send(&mut self, topic: &str, msg: Message<'_>) -> Result<(), StageError>;

    /// File descriptors that signal the stage's other inputs (the iceoryx2 listeners),
    /// given once by the driver: a source that can ends its [`External::wait`] as soon as
    /// one is readable, so that a setpoint does not wait out a receive timeout. The
    /// default ignores them (the wait runs to its timeout, as before).
    fn wake_on(&mut self, _fds: &[i32]) {}

    /// The driver stopped: what arrived and was never taken can be counted now, before
    /// the stop line. The default does nothing.
    fn finish(&mut self) {}

    /// What the source itself counts (frames a camera thread overwrote, unreadable
    /// files, reconnects), for the process's counter lines after the stage's own.
    fn counters(&self) -> Vec<Counter> {
        Vec::new()
    }
}

/// Whether an [`External`] source goes on.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Flow {
    /// More may come.
    Open,
    /// The source ended (a recording played to its end): the process stops cleanly.
    Ended,
}
