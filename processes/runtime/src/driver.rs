//! The iceoryx2 driver: runs any [`Stage`] as its own process. It opens the ports its
//! node declares (one subscriber per input, one publisher per output, types from the
//! topic table), hands over every input in the order the node lists them (a `newest`
//! input: only the newest waiting sample, older ones skipped and counted), calls the
//! stage's tick on its period, beats the heartbeat, stamps each output's stage exit
//! with the monotonic clock, and stops cleanly on SIGTERM/SIGINT. A stage that needs
//! I/O besides iceoryx2 (a socket, a camera thread) brings it as an [`External`], which
//! the driver then waits on instead of its wait set.

use std::time::Duration;

use iceoryx2::prelude::IceoryxSend;

use ipc_types::msg::FaultOrder;
use ipc_types::topics::{self, Payload};
use stage::lockstep::NodeSpec;
use stage::{
    External, Flow, Input, Message, Outbox, OwnedMessage, SliceHeader, SliceMut, Stage, StageError,
    stop_line,
};

use crate::clock::monotonic_ns;
use crate::ipc::{
    HeartbeatError, Ipc, PeriodicWait, Publisher, ReceiveError, ServiceError, SlicePublisher,
    SliceSubscriber, Subscriber, WaitError, Wake, run_wait_loop,
};
use crate::port_faults::{self, PortFaults};

/// How often a running stage logs its counters, ns.
const REPORT_PERIOD_NS: u64 = 10_000_000_000;

/// Why the driver stopped with an error. Each names the topic or node it concerns.
#[derive(Debug, thiserror::Error)]
pub enum DriverError {
    /// A topic of the node is not in the topic table.
    #[error("node `{node}`: unknown topic `{topic}` (see ipc_types::topics)")]
    UnknownTopic {
        /// The node.
        node: String,
        /// The topic.
        topic: String,
    },
    /// A topic is not carried by iceoryx2 and the stage brought no I/O that serves it.
    #[error("node `{node}`: `{topic}` is not an iceoryx2 topic and nothing else serves it")]
    NoTransport {
        /// The node.
        node: String,
        /// The topic.
        topic: String,
    },
    /// A pipeline node reads an evaluator-only topic.
    #[error("node `{node}` reads `{topic}`, which only the evaluator may read")]
    EvaluatorOnly {
        /// The node.
        node: String,
        /// The topic.
        topic: String,
    },
    /// A port could not be opened.
    #[error("`{topic}`: {source}")]
    Open {
        /// The topic.
        topic: String,
        /// What went wrong.
        source: ServiceError,
    },
    /// Receiving failed.
    #[error(transparent)]
    Receive(#[from] ReceiveError),
    /// The stage failed (publishing, or its own work).
    #[error(transparent)]
    Stage(#[from] StageError),
    /// The wait loop failed.
    #[error(transparent)]
    Wait(#[from] WaitError),
    /// The heartbeat could not be sent.
    #[error(transparent)]
    Heartbeat(#[from] HeartbeatError),
}

/// The heartbeat: how often the process beats, and the deadline it declares.
#[derive(Debug, Clone, Copy)]
pub struct Beat {
    /// Beat period.
    pub period: Duration,
    /// Declared deadline (the watchdog calls the process hung after it).
    pub deadline: Duration,
}

struct InSpec {
    topic: &'static str,
    newest: bool,
    port: InPort,
}

/// Takes what waits on `sub`: every sample in order, or only the newest. Returns how
/// many were handed over; `skipped` counts the older ones a `newest` input passed over.
fn drain<P, H>(
    sub: &Subscriber<P, H>,
    newest: bool,
    skipped: &mut u64,
    mut take: impl FnMut(&iceoryx2::sample::Sample<crate::ipc::Svc, P, H>) -> Result<(), StageError>,
) -> Result<u64, DriverError>
where
    P: ?Sized + std::fmt::Debug + IceoryxSend + 'static,
    H: crate::MessageHeader,
    iceoryx2::port::subscriber::Subscriber<crate::ipc::Svc, P, H>: crate::ipc::ReceivePort<P, H>,
{
    if newest {
        let mut last = None;
        while let Some(s) = sub.receive()? {
            if last.replace(s).is_some() {
                *skipped += 1;
            }
        }
        match last {
            Some(s) => {
                take(&s)?;
                Ok(1)
            }
            None => Ok(0),
        }
    } else {
        let mut n = 0;
        while let Some(s) = sub.receive()? {
            take(&s)?;
            n += 1;
        }
        Ok(n)
    }
}

/// The stage's outbox: its output ports and its external I/O.
struct Ports<'a, 'e> {
    outputs: &'a mut [(&'static str, OutPort)],
    external: Option<&'a mut (dyn External + 'e)>,
    /// While the external source delivers (it is busy), what the stage publishes on its
    /// topics waits here and is sent when the source's `wait` returns.
    deferred: Option<&'a mut Vec<(&'static str, OwnedMessage)>>,
    /// Injected faults (fault tests only).
    faults: &'a mut PortFaults,
    /// The process's heartbeat, beaten while an injected delay is waited.
    heartbeat: &'a mut crate::Heartbeat,
}

/// How often the heartbeat beats while an injected delay is waited.
const DELAY_BEAT: Duration = Duration::from_millis(20);

/// Whether a message on `topic` goes out, after waiting any injected delay. The wait
/// beats the heartbeat: a delay fault makes data late, it does not hang the process (a
/// 100 ms delay on two messages of one round made aruco-pnp look hung).
fn pass(faults: &mut PortFaults, heartbeat: &mut crate::Heartbeat, topic: &str) -> bool {
    let Some(delay_ns) = faults.admit(topic) else {
        return false;
    };
    if delay_ns == 0 {
        // Every message without a delay fault: no clock read on the way out.
        return true;
    }
    let end = monotonic_ns().saturating_add(delay_ns);
    loop {
        let left = end.saturating_sub(monotonic_ns());
        if left == 0 {
            return true;
        }
        std::thread::sleep(Duration::from_nanos(left).min(DELAY_BEAT));
        // A failed beat is reported by the round's own beat, which comes next.
        let _ = heartbeat.beat();
    }
}

fn transport(e: impl std::fmt::Display) -> StageError {
    StageError::Transport(e.to_string())
}

macro_rules! send_plain {
    ($faults:expr, $heartbeat:expr, $topic:expr, $port:expr, $m:expr) => {{
        let mut v = *$m;
        if !pass($faults, $heartbeat, $topic) {
            return Ok(());
        }
        $faults.corrupt($topic, &mut v);
        v.msg.close_stage(monotonic_ns());
        $port.send(v.msg, &v).map(|_| ()).map_err(transport)
    }};
}

/// The evaluator's truth: never faulted (it is the world's record, not the stack's data).
macro_rules! send_truth {
    ($port:expr, $m:expr) => {{
        let mut v = *$m;
        v.msg.close_stage(monotonic_ns());
        $port.send(v.msg, &v).map(|_| ()).map_err(transport)
    }};
}

/// A blank fault paints camera images one grey (the pad hidden, the view blocked); other
/// slices (depths, maps) pass as they are.
fn blank_image(faults: &mut PortFaults, payload: Payload, topic: &str, slice: SliceMut<'_>) {
    if let (Payload::CameraFrame, SliceMut::U8(pixels)) = (payload, slice) {
        faults.blank(topic, pixels);
    }
}

/// Writes the typed ports from the payload list ([`ipc_types::for_each_payload!`]): per
/// payload kind, its subscriber and publisher type and one arm that opens, drains or
/// sends through it. Pipeline structs and slices have input and output ports; the
/// simulator's truth only output ports (no pipeline stage may read it); local payloads
/// and bytes none (a stage's [`External`] serves them, or nothing does).
macro_rules! ports {
    (
        structs: [$($(#[$sd:meta])* $s:ident($st:ty => $so:ty) = $sn:literal,)*],
        truth: [$($(#[$td:meta])* $t:ident($tt:ty => $to:ty) = $tn:literal,)*],
        slices: [$($(#[$cd:meta])* $c:ident($ch:ty, [$ce:ty]) = $cn:literal,)*],
        local: [$($(#[$ld:meta])* $l:ident($lt:ty) = $ln:literal,)*],
        bytes: [$($(#[$bd:meta])* $b:ident = $bn:literal,)*],
    ) => {
        /// One input port.
        enum InPort {
            $($s(Subscriber<$st>),)*
            $($c(SliceSubscriber<$ce, $ch>),)*
        }

        /// One output port.
        enum OutPort {
            $($s(Publisher<$st>),)*
            $($t(Publisher<$tt>),)*
            $($c(SlicePublisher<$ce, $ch>),)*
            /// Served by the stage's [`External`].
            External,
        }

        /// The subscriber of `service` for `payload`, buffering `depth` (the graph's) or
        /// the default; `None` for a payload no stage reads from iceoryx2.
        fn open_in(
            ipc: &Ipc,
            service: &str,
            payload: Payload,
            depth: Option<u32>,
        ) -> Result<Option<InPort>, ServiceError> {
            let depth = depth.map_or(crate::ipc::DEFAULT_DEPTH, |d| d as usize);
            Ok(Some(match payload {
                $(Payload::$s => InPort::$s(ipc.subscriber_with_depth(service, depth)?),)*
                $(Payload::$c => InPort::$c(ipc.slice_subscriber_with_depth(service, depth)?),)*
                $(Payload::$t => return Ok(None),)*
                $(Payload::$l => return Ok(None),)*
                $(Payload::$b => return Ok(None),)*
            }))
        }

        /// The publisher of `service` for `payload`, its slices up to `max_len` long;
        /// `None` for a payload not carried by iceoryx2.
        fn open_out(
            ipc: &Ipc,
            service: &str,
            payload: Payload,
            max_len: usize,
        ) -> Result<Option<OutPort>, ServiceError> {
            let len = max_len.max(1);
            Ok(Some(match payload {
                $(Payload::$s => OutPort::$s(ipc.publisher(service)?),)*
                $(Payload::$t => OutPort::$t(ipc.publisher(service)?),)*
                $(Payload::$c => OutPort::$c(ipc.slice_publisher(service, len)?),)*
                $(Payload::$l => return Ok(None),)*
                $(Payload::$b => return Ok(None),)*
            }))
        }

        impl InPort {
            fn listener(&self) -> &iceoryx2::port::listener::Listener<crate::ipc::Svc> {
                match self {
                    $(Self::$s(s) => s.listener(),)*
                    $(Self::$c(s) => s.listener(),)*
                }
            }

            fn gaps(&self) -> u64 {
                match self {
                    $(Self::$s(s) => s.gaps(),)*
                    $(Self::$c(s) => s.gaps(),)*
                }
            }

            fn restarts(&self) -> u64 {
                match self {
                    $(Self::$s(s) => s.restarts(),)*
                    $(Self::$c(s) => s.restarts(),)*
                }
            }

            fn has_samples(&self) -> bool {
                match self {
                    $(Self::$s(s) => s.has_samples(),)*
                    $(Self::$c(s) => s.has_samples(),)*
                }
            }

            /// Hands what waits to `stage`; returns how many messages that was.
            fn deliver(
                &self,
                topic: &str,
                newest: bool,
                now: u64,
                stage: &mut dyn Stage,
                out: &mut dyn Outbox,
                skipped: &mut u64,
            ) -> Result<u64, DriverError> {
                let mut call = |msg: Message<'_>| stage.on_input(now, Input { topic, msg }, out);
                match self {
                    $(Self::$s(s) => drain(s, newest, skipped, |x| {
                        call(Message::$s(x.payload()))
                    }),)*
                    $(Self::$c(s) => drain(s, newest, skipped, |x| {
                        call(Message::$c(x.user_header(), x.payload()))
                    }),)*
                }
            }
        }

        impl Outbox for Ports<'_, '_> {
            fn publish(&mut self, topic: &str, msg: Message<'_>) -> Result<(), StageError> {
                let Some((name, port)) = self.outputs.iter_mut().find(|(t, _)| *t == topic) else {
                    return Err(StageError::NotAnOutput {
                        stage: String::new(),
                        topic: topic.to_string(),
                    });
                };
                let name: &'static str = name;
                match (port, msg) {
                    (OutPort::External, _) if !pass(self.faults, self.heartbeat, name) => Ok(()),
                    (OutPort::External, m) => {
                        match (self.external.as_deref_mut(), &mut self.deferred) {
                            (Some(ext), _) => ext.send(topic, m),
                            (None, Some(later)) => {
                                later.push((name, m.to_owned()));
                                Ok(())
                            }
                            (None, None) => {
                                Err(StageError::Transport(format!("nothing serves `{topic}`")))
                            }
                        }
                    }
                    $((OutPort::$s(p), Message::$s(m)) => {
                        send_plain!(self.faults, self.heartbeat, name, p, m)
                    })*
                    $((OutPort::$t(p), Message::$t(m)) => send_truth!(p, m),)*
                    (_, m) => Err(StageError::WrongType {
                        topic: topic.to_string(),
                        expected: topics::find(topic).map_or("?", |t| t.payload.type_name()),
                        got: m.payload().type_name(),
                    }),
                }
            }

            fn publish_slice(
                &mut self,
                topic: &str,
                len: usize,
                fill: &mut dyn FnMut(SliceMut<'_>) -> Option<SliceHeader>,
            ) -> Result<bool, StageError> {
                let Some((_, port)) = self.outputs.iter_mut().find(|(t, _)| *t == topic) else {
                    return Err(StageError::NotAnOutput {
                        stage: String::new(),
                        topic: topic.to_string(),
                    });
                };
                if !pass(self.faults, self.heartbeat, topic) {
                    return Ok(false);
                }
                // A loan that fails (every sample held by subscribers) drops this message:
                // the stage counts it, the process never waits.
                match port {
                    $(OutPort::$c(p) => {
                        let Ok(mut sample) = p.loan(len) else {
                            return Ok(false);
                        };
                        let Some(SliceHeader::$c(mut h)) = fill(sample.payload_mut().into())
                        else {
                            return Ok(false);
                        };
                        self.faults.corrupt(topic, &mut h);
                        blank_image(self.faults, Payload::$c, topic, sample.payload_mut().into());
                        h.msg.close_stage(monotonic_ns());
                        *sample.user_header_mut() = h;
                        p.send(sample).map_err(transport)?;
                    })*
                    _ => {
                        return Err(StageError::WrongType {
                            topic: topic.to_string(),
                            expected: topics::find(topic).map_or("?", |t| t.payload.type_name()),
                            got: "a slice",
                        });
                    }
                }
                Ok(true)
            }
        }
    };
}
ipc_types::for_each_payload!(ports);

/// The running node: ports, schedule and counters.
struct Node<'a> {
    outputs: Vec<(&'static str, OutPort)>,
    external: Option<&'a mut dyn External>,
    heartbeat: crate::Heartbeat,
    /// systemd's notify socket: `WATCHDOG=1` with every beat.
    notify: crate::notify::Notifier,
    /// Fault orders, when the process takes them (`LANDING_FAULT_INJECTION=1`).
    fault_orders: Option<Subscriber<FaultOrder>>,
    faults: PortFaults,
    name: String,
    beat_ns: u64,
    next_beat_ns: u64,
    tick_ns: Option<u64>,
    next_tick_ns: u64,
    next_report_ns: u64,
    skipped: u64,
}

impl Node<'_> {
    /// One wake-up: every iceoryx2 input, then `inputs_done`, the tick and the beat
    /// when due.
    fn round(
        &mut self,
        inputs: &[InSpec],
        stage: &mut dyn Stage,
        external_inputs: u64,
    ) -> Result<(), DriverError> {
        if let Some(orders) = &self.fault_orders {
            while let Some(o) = orders.receive()? {
                self.faults.apply(&self.name, o.payload(), monotonic_ns());
            }
        }
        let now = monotonic_ns();
        let mut taken = external_inputs;
        let mut out = Ports {
            outputs: &mut self.outputs,
            external: self.external.as_deref_mut(),
            deferred: None,
            faults: &mut self.faults,
            heartbeat: &mut self.heartbeat,
        };
        for i in inputs {
            taken += i
                .port
                .deliver(i.topic, i.newest, now, stage, &mut out, &mut self.skipped)?;
        }
        if taken > 0 {
            stage.on_inputs_done(now, &mut out)?;
        }
        if let Some(p) = self.tick_ns
            && now >= self.next_tick_ns
        {
            stage.on_tick(now, &mut out)?;
            // Keep the grid; a late wake-up skips ticks rather than bursting.
            self.next_tick_ns += p;
            if self.next_tick_ns <= now {
                self.next_tick_ns = now + p;
            }
        }
        if now >= self.next_beat_ns {
            self.heartbeat.beat()?;
            self.notify.alive();
            self.next_beat_ns = now + self.beat_ns;
        }
        if now >= self.next_report_ns {
            self.next_report_ns = now + REPORT_PERIOD_NS;
            tracing::info!("{}", self.line(inputs, stage, "counters"));
        }
        Ok(())
    }

    /// How long the next wait may last, ns.
    fn until_due(&self) -> u64 {
        let now = monotonic_ns();
        let mut due = self.next_beat_ns;
        if self.tick_ns.is_some() {
            due = due.min(self.next_tick_ns);
        }
        due.saturating_sub(now)
    }

    fn line(&self, inputs: &[InSpec], stage: &dyn Stage, what: &str) -> String {
        // On a `newest` input a sequence gap is an older message the buffer dropped while
        // the stage was busy: the policy takes only the newest, so it counts as skipped.
        // On a `queue` input every message counts, and a gap is lost data.
        let (newest, queued): (Vec<&InSpec>, Vec<&InSpec>) = inputs.iter().partition(|i| i.newest);
        let lost: u64 = queued.iter().map(|i| i.port.gaps()).sum();
        let overflowed: u64 = newest.iter().map(|i| i.port.gaps()).sum();
        let mut line = stop_line(stage).replacen(" stopped", &format!(" {what}"), 1);
        for (k, v) in self
            .external
            .as_deref()
            .map(|e| e.counters())
            .unwrap_or_default()
        {
            line.push_str(&format!(" {k}={v}"));
        }
        let mut line = format!(
            "{line} skipped={} lost_upstream={lost}",
            self.skipped + overflowed
        );
        if lost > 0 {
            // Which inputs lost them (topic:count), so that a gap can be traced.
            let by_topic: Vec<String> = queued
                .iter()
                .filter(|i| i.port.gaps() > 0)
                .map(|i| format!("{}:{}", i.topic, i.port.gaps()))
                .collect();
            line.push_str(&format!(" lost_on={}", by_topic.join(",")));
        }
        // A publisher that started over is a restart upstream, not lost data.
        let restarted: Vec<String> = inputs
            .iter()
            .filter(|i| i.port.restarts() > 0)
            .map(|i| format!("{}:{}", i.topic, i.port.restarts()))
            .collect();
        if !restarted.is_empty() {
            line.push_str(&format!(" restarted_upstream={}", restarted.join(",")));
        }
        if self.fault_orders.is_some() {
            let f = &self.faults;
            line.push_str(&format!(
                " injected_dropped={} injected_corrupted={} injected_delayed={} injected_blanked={}",
                f.dropped, f.corrupted, f.delayed, f.blanked
            ));
        }
        line
    }
}

/// Runs `stage` as the node `spec` on `ipc` until SIGTERM/SIGINT (or its external source
/// ends); logs `<name> stopped k=v ...` at the end.
pub fn run(
    ipc: &Ipc,
    spec: &NodeSpec,
    stage: &mut dyn Stage,
    mut external: Option<&mut dyn External>,
    beat: Beat,
) -> Result<(), DriverError> {
    let node_err = |topic: &str| DriverError::UnknownTopic {
        node: spec.name.clone(),
        topic: topic.to_string(),
    };
    let served = |topic: &str| {
        external
            .as_deref()
            .is_some_and(|e| e.topics().contains(&topic))
    };
    // A stage with its own I/O serves the outside protocol of the mode it runs in (the
    // simulator: its autopilot's MAVLink on UDP, or PX4 SITL's simulator API on TCP); a
    // byte topic of the other mode is not opened (publishing on it is an error).
    let unserved_bytes = |info: &topics::TopicInfo| {
        let skip = external.is_some() && info.service.is_none() && !served(info.name);
        if skip {
            tracing::debug!(node = %spec.name, topic = info.name, "not served in this mode");
        }
        skip
    };
    let mut inputs = Vec::new();
    for i in &spec.inputs {
        let info = topics::find(&i.topic).ok_or_else(|| node_err(&i.topic))?;
        if info.evaluator_only {
            return Err(DriverError::EvaluatorOnly {
                node: spec.name.clone(),
                topic: i.topic.clone(),
            });
        }
        if served(info.name) || unserved_bytes(info) {
            continue;
        }
        let port = match info.service {
            Some(service) => open_in(ipc, service, info.payload, i.depth).map_err(|source| {
                DriverError::Open {
                    topic: i.topic.clone(),
                    source,
                }
            })?,
            None => None,
        };
        let Some(port) = port else {
            return Err(DriverError::NoTransport {
                node: spec.name.clone(),
                topic: i.topic.clone(),
            });
        };
        inputs.push(InSpec {
            topic: info.name,
            newest: i.newest,
            port,
        });
    }
    let mut outputs = Vec::new();
    for o in &spec.outputs {
        let info = topics::find(o).ok_or_else(|| node_err(o))?;
        if unserved_bytes(info) {
            continue;
        }
        let port = if served(info.name) {
            Some(OutPort::External)
        } else {
            match info.service {
                Some(service) => open_out(ipc, service, info.payload, stage.max_slice_len(o))
                    .map_err(|source| DriverError::Open {
                        topic: o.clone(),
                        source,
                    })?,
                None => None,
            }
        };
        let Some(port) = port else {
            return Err(DriverError::NoTransport {
                node: spec.name.clone(),
                topic: o.clone(),
            });
        };
        outputs.push((info.name, port));
    }
    let heartbeat = ipc
        .heartbeat(beat.deadline)
        .map_err(|source| DriverError::Open {
            topic: format!("heartbeat/{}", spec.name),
            source,
        })?;
    let fault_orders = if port_faults::enabled() {
        Some(
            ipc.subscriber::<FaultOrder>(ipc_types::services::FAULT_INJECT)
                .map_err(|source| DriverError::Open {
                    topic: "fault/inject".into(),
                    source,
                })?,
        )
    } else {
        None
    };
    let now = monotonic_ns();
    let tick_ns = stage.tick_period_ns().filter(|p| *p > 0);
    let beat_ns = u64::try_from(beat.period.as_nanos())
        .unwrap_or(u64::MAX)
        .max(1);
    let has_external = external.is_some();
    let mut node = Node {
        outputs,
        external: external.take(),
        heartbeat,
        notify: crate::notify::Notifier::from_env(),
        fault_orders,
        faults: PortFaults::default(),
        name: spec.name.clone(),
        beat_ns,
        next_beat_ns: now,
        tick_ns,
        next_tick_ns: now,
        next_report_ns: now + REPORT_PERIOD_NS,
        skipped: 0,
    };
    // `<name> running` is what launchers and tests wait for before they go on.
    tracing::info!(
        inputs = inputs.len(),
        outputs = node.outputs.len(),
        "{} running",
        spec.name
    );
    node.notify.ready();
    let periodic = spec
        .periodic
        .as_deref()
        .and_then(|t| inputs.iter().position(|i| i.topic == t));
    let result = if has_external {
        run_external(ipc, &inputs, &mut node, stage)
    } else if let Some(trigger) = periodic {
        run_periodic(ipc, &inputs, trigger, &mut node, stage)
    } else {
        let wake = Duration::from_nanos(tick_ns.map_or(beat_ns, |t| t.min(beat_ns)));
        let listeners: Vec<_> = inputs.iter().map(|i| i.port.listener()).collect();
        let mut failure = None;
        let exit = run_wait_loop(&listeners, &[], Some(wake), |_wake: Wake| {
            match node.round(&inputs, stage, 0) {
                Ok(()) => !stage.finished(),
                Err(e) => {
                    failure = Some(e);
                    false
                }
            }
        });
        match (exit, failure) {
            (_, Some(e)) => Err(e),
            (Err(e), None) => Err(e.into()),
            (Ok(_), None) => Ok(()),
        }
    };
    node.notify.stopping();
    if let Some(ext) = node.external.as_deref_mut() {
        ext.finish();
    }
    if stage.finished() {
        tracing::info!("{} finished", spec.name);
    }
    tracing::info!("{}", node.line(&inputs, stage, "stopped"));
    result
}

/// How long before a periodic trigger's next sample is due the wait starts polling.
const PERIODIC_GUARD: Duration = Duration::from_micros(500);
/// How long after it was due the wait polls before it sleeps on the event again.
const PERIODIC_MAX_SPIN: Duration = Duration::from_millis(2);

/// The loop of a node that waits for its trigger by the stream's period
/// ([`PeriodicWait`]): a round when the trigger has a sample, or when a tick or beat is
/// due.
fn run_periodic(
    ipc: &Ipc,
    inputs: &[InSpec],
    trigger: usize,
    node: &mut Node<'_>,
    stage: &mut dyn Stage,
) -> Result<(), DriverError> {
    let mut wait = PeriodicWait::new(PERIODIC_GUARD, PERIODIC_MAX_SPIN);
    let Some(port) = inputs.get(trigger).map(|i| &i.port) else {
        return Ok(());
    };
    while !ipc.shutdown_requested() && !stage.finished() {
        let timeout = Duration::from_nanos(node.until_due());
        wait.wait(port.listener(), timeout, || {
            port.has_samples().then_some(())
        });
        node.round(inputs, stage, 0)?;
    }
    Ok(())
}

/// The loop of a stage with external I/O: wait on it (at most until the next tick or
/// beat), hand each arrival to the stage as it comes, send what the stage published on
/// the source's topics meanwhile, then a round over the iceoryx2 inputs.
fn run_external(
    ipc: &Ipc,
    inputs: &[InSpec],
    node: &mut Node<'_>,
    stage: &mut dyn Stage,
) -> Result<(), DriverError> {
    use iceoryx2::prelude::FileDescriptorBased;
    // SAFETY: the descriptors are only polled while the listeners, which own them, live
    // (the inputs outlive this loop); they are not stored past it or closed.
    let fds: Vec<i32> = inputs
        .iter()
        .map(|i| unsafe { i.port.listener().file_descriptor().native_handle() })
        .collect();
    if let Some(ext) = node.external.as_deref_mut() {
        ext.wake_on(&fds);
    }
    let mut deferred: Vec<(&'static str, OwnedMessage)> = Vec::new();
    while !ipc.shutdown_requested() && !stage.finished() {
        let timeout = node.until_due();
        let mut delivered = 0u64;
        let flow = match node.external.as_deref_mut() {
            Some(ext) => {
                let mut out = Ports {
                    outputs: &mut node.outputs,
                    external: None,
                    deferred: Some(&mut deferred),
                    faults: &mut node.faults,
                    heartbeat: &mut node.heartbeat,
                };
                ext.wait(timeout, &monotonic_ns, &mut |input, at| {
                    delivered += 1;
                    stage.on_input(at, input, &mut out)
                })?
            }
            None => Flow::Ended,
        };
        if let Some(ext) = node.external.as_deref_mut() {
            for (topic, msg) in deferred.drain(..) {
                ext.send(topic, msg.as_message())?;
            }
        }
        // Their events consumed before the samples are taken: a sample that comes after
        // this signals the next wait.
        for i in inputs {
            let _ = i.port.listener().try_wait(|_| {});
        }
        node.round(inputs, stage, delivered)?;
        if flow == Flow::Ended {
            tracing::info!("the source ended");
            break;
        }
    }
    Ok(())
}
