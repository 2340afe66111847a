//! iceoryx2 binding: node set-up, typed ports, heartbeats and the wait loop.
//!
//! Every topic is a publish-subscribe service with a [`MessageHeader`] user header, paired
//! with an event service of the same name: publishers notify after each send, subscribers
//! sleep in a wait set on the listener. Subscribers keep a short buffer with safe overflow,
//! so a consumer that lags loses the oldest samples instead of reading stale data late.

use std::cell::Cell;
use std::fmt::Debug;
use std::mem::ManuallyDrop;
use std::time::Duration;

use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::{Notifier, NotifierNotifyError};
use iceoryx2::port::publisher::Publisher as IoxPublisher;
use iceoryx2::port::subscriber::Subscriber as IoxSubscriber;
use iceoryx2::prelude::*;
use iceoryx2::sample::Sample;
use iceoryx2::sample_mut::SampleMut;
use iceoryx2::sample_mut_uninit::SampleMutUninit;
use iceoryx2::waitset::WaitSetRunResult;

use crate::clock::monotonic_ns;
use ipc_types::msg::{CameraFrameHeader, DepthFrameHeader, Header, OccupancyMapHeader};

/// The iceoryx2 service flavour used between processes.
pub type Svc = ipc::Service;

/// Environment variable holding the per-run iceoryx2 prefix.
pub const PREFIX_ENV: &str = "LANDING_IPC_PREFIX";
pub use stack_config::DEFAULT_PREFIX;

/// How many messages or slices a subscriber buffers before the oldest is overwritten,
/// when its node's graph input gives no `depth`: 4 covers 50 ms of a reader held off the
/// CPU at vehicle/state's ~80 Hz. Services are made for up to [`stage::MAX_MESSAGE_DEPTH`]
/// messages or [`stage::MAX_SLICE_DEPTH`] slices (each up to megabytes, held per
/// subscriber by every publisher), so deeper and shallower readers share a topic.
pub(crate) const DEFAULT_DEPTH: usize = 4;
/// How many samples a subscriber may hold at once.
const MAX_BORROWED: usize = 2;
/// Processes that may subscribe to one topic.
const MAX_SUBSCRIBERS: usize = 8;
/// Processes that may publish one topic (a restarted process briefly overlaps its ghost).
const MAX_PUBLISHERS: usize = 4;

// One error type per operation, as iceoryx2 itself does: a caller sees only what the
// call it made can fail with. Each names the node or service it concerns; what iceoryx2
// said is kept as text, as it was printed before.

/// Why a prefix cannot be used ([`IpcPrefix::new`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("iceoryx2 prefix `{0}` is not allowed (allowed: 1 to 32 characters of A-Z a-z 0-9 _ - .)")]
pub struct PrefixError(pub String);

/// Why a process could not get its node ([`Ipc::open`]).
#[derive(Debug, thiserror::Error)]
pub enum NodeError {
    /// The prefix is not a usable file-name fragment.
    #[error(transparent)]
    Prefix(#[from] PrefixError),
    /// The process name is not a valid node name.
    #[error("cannot create iceoryx2 node `{name}`: {reason}")]
    Name {
        /// Node name.
        name: String,
        /// What iceoryx2 said.
        reason: String,
    },
    /// iceoryx2 could not create the node.
    #[error("cannot create iceoryx2 node `{name}`: {reason}")]
    Create {
        /// Node name.
        name: String,
        /// What iceoryx2 said.
        reason: String,
    },
    /// Another live process already has this node under this prefix: a second stack on
    /// the prefix would cross-talk with the first.
    #[error(
        "another `{name}` is running under iceoryx2 prefix `{prefix}`{pid}: one stack per prefix (stop it, or give this one another --ipc-prefix / LANDING_IPC_PREFIX)"
    )]
    Taken {
        /// Node name.
        name: String,
        /// The prefix.
        prefix: String,
        /// ` (pid N)` when iceoryx2 names it.
        pid: String,
    },
}

/// Why a port could not be opened: its service (publish-subscribe, event or heartbeat)
/// could not be opened or created, or the port on it could not be created.
#[derive(Debug, thiserror::Error)]
pub enum ServiceError {
    /// The service name is not valid for iceoryx2.
    #[error("iceoryx2 service `{service}`: {reason}")]
    Name {
        /// Service name.
        service: String,
        /// What iceoryx2 said.
        reason: String,
    },
    /// The service could not be opened or created (another process created it with
    /// another type or quality of service, or resources ran out).
    #[error("iceoryx2 service `{service}`: {reason}")]
    Open {
        /// Service name.
        service: String,
        /// What iceoryx2 said.
        reason: String,
    },
    /// The service exists but this port could not be created on it (too many ports).
    #[error("iceoryx2 service `{service}`: {reason}")]
    Port {
        /// Service name.
        service: String,
        /// What iceoryx2 said.
        reason: String,
    },
}

/// Why no shared memory could be loaned for a sample (every sample is held by
/// subscribers, or the payload is larger than the publisher's maximum).
#[derive(Debug, thiserror::Error)]
#[error("iceoryx2 `{service}`: loan failed: {reason}")]
pub struct LoanError {
    /// Service name.
    pub service: String,
    /// What iceoryx2 said.
    pub reason: String,
}

/// Why a sample was not delivered.
#[derive(Debug, thiserror::Error)]
pub enum SendError {
    /// No shared memory for it ([`Publisher::send`] loans and sends in one call).
    #[error(transparent)]
    Loan(#[from] LoanError),
    /// iceoryx2 could not deliver the sample.
    #[error("iceoryx2 `{service}`: send failed: {reason}")]
    Send {
        /// Service name.
        service: String,
        /// What iceoryx2 said.
        reason: String,
    },
    /// The sample went out but subscribers could not be woken.
    #[error("iceoryx2 `{service}`: notify failed: {reason}")]
    Notify {
        /// Service name.
        service: String,
        /// What iceoryx2 said.
        reason: String,
    },
}

/// Why a subscriber could not read its next sample.
#[derive(Debug, thiserror::Error)]
#[error("iceoryx2 `{service}`: receive failed: {reason}")]
pub struct ReceiveError {
    /// Service name.
    pub service: String,
    /// What iceoryx2 said.
    pub reason: String,
}

/// Why a heartbeat could not be sent (a beat later than its deadline is not an error).
#[derive(Debug, thiserror::Error)]
#[error("iceoryx2 `{service}`: notify failed: {reason}")]
pub struct HeartbeatError {
    /// The heartbeat's event service.
    pub service: String,
    /// What iceoryx2 said.
    pub reason: String,
}

/// Why the wait loop could not be set up or stopped waiting.
#[derive(Debug, thiserror::Error)]
pub enum WaitError {
    /// The wait set could not be created.
    #[error("wait loop: {reason}")]
    Create {
        /// What iceoryx2 said.
        reason: String,
    },
    /// A listener, deadline or tick could not be attached.
    #[error("wait loop: {reason}")]
    Attach {
        /// What iceoryx2 said.
        reason: String,
    },
    /// Waiting failed.
    #[error("wait loop: {reason}")]
    Wait {
        /// What iceoryx2 said.
        reason: String,
    },
}

fn reason(e: impl Debug) -> String {
    format!("{e:?}")
}

fn open_err(service: &str, e: impl Debug) -> ServiceError {
    ServiceError::Open {
        service: service.to_string(),
        reason: reason(e),
    }
}

fn port_err(service: &str, e: impl Debug) -> ServiceError {
    ServiceError::Port {
        service: service.to_string(),
        reason: reason(e),
    }
}

fn loan_err(service: &str, e: impl Debug) -> LoanError {
    LoanError {
        service: service.to_string(),
        reason: reason(e),
    }
}

fn send_err(service: &str, e: impl Debug) -> SendError {
    SendError::Send {
        service: service.to_string(),
        reason: reason(e),
    }
}

/// The iceoryx2 prefix that isolates one stack (or one test) from every other on the host.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IpcPrefix(String);

impl IpcPrefix {
    /// Checks a prefix: 1 to 32 characters from `[A-Za-z0-9_.-]`.
    pub fn new(s: &str) -> Result<Self, PrefixError> {
        if stack_config::is_valid_prefix(s) {
            Ok(Self(s.to_string()))
        } else {
            Err(PrefixError(s.to_string()))
        }
    }

    /// The flag if given, else `LANDING_IPC_PREFIX`, else [`DEFAULT_PREFIX`].
    pub fn from_flag_or_env(flag: Option<&str>) -> Result<Self, PrefixError> {
        match flag {
            Some(f) => Self::new(f),
            None => match std::env::var(PREFIX_ENV) {
                Ok(v) => Self::new(&v),
                Err(_) => Self::new(DEFAULT_PREFIX),
            },
        }
    }

    /// What a process with a stack config uses: the flag if given, else
    /// `LANDING_IPC_PREFIX`, else the config's `[ipc] prefix`.
    pub fn resolve(flag: Option<&str>, config_prefix: &str) -> Result<Self, PrefixError> {
        match (flag, std::env::var(PREFIX_ENV)) {
            (Some(f), _) => Self::new(f),
            (None, Ok(v)) => Self::new(&v),
            (None, Err(_)) => Self::new(config_prefix),
        }
    }

    /// A fresh prefix for one test or benchmark run: unique per process and call.
    pub fn unique(tag: &str) -> Self {
        use std::sync::atomic::{AtomicU32, Ordering};
        static COUNTER: AtomicU32 = AtomicU32::new(0);
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let tag: String = tag
            .chars()
            .filter(|c| c.is_ascii_alphanumeric())
            .take(10)
            .collect();
        Self(format!("lt_{tag}_{}_{n}_", std::process::id()))
    }

    /// The prefix text.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

/// Access to the common header of any topic's user header.
pub trait MessageHeader: Debug + ZeroCopySend + Default + Copy + 'static {
    /// The common header.
    fn msg(&self) -> &Header;
    /// The common header, mutable.
    fn msg_mut(&mut self) -> &mut Header;
}

macro_rules! impl_message_header {
    ($($t:ty),*) => {$(
        impl MessageHeader for $t {
            fn msg(&self) -> &Header { &self.msg }
            fn msg_mut(&mut self) -> &mut Header { &mut self.msg }
        }
    )*};
}

impl MessageHeader for Header {
    fn msg(&self) -> &Header {
        self
    }
    fn msg_mut(&mut self) -> &mut Header {
        self
    }
}

impl_message_header!(CameraFrameHeader, DepthFrameHeader, OccupancyMapHeader);

type PubSubBuilder<P, H> = iceoryx2::service::builder::publish_subscribe::Builder<P, H, Svc>;

/// One node of the stack, as listed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ListedNode {
    /// Its name: the process's graph node.
    pub name: String,
    /// Its process is alive.
    pub alive: bool,
    /// Its system-wide unique id: a process restarted under the same name has another.
    pub id: u128,
    /// The process that made it (`None` when iceoryx2 cannot tell).
    pub pid: Option<u32>,
}

/// A process's connection to iceoryx2: one node, named after the process. Dropped, it
/// cleans up after dead nodes of its stack and, the last node of its prefix gone, removes
/// the prefix's node-counter segment, which iceoryx2 otherwise leaves in /dev/shm for
/// every prefix ever used.
pub struct Ipc {
    /// Dropped by hand in `Drop`, before the domain is looked at.
    node: ManuallyDrop<Node<Svc>>,
    config: Config,
    process: String,
}

/// What [`clean`] found under a prefix.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Cleaned {
    /// Dead nodes whose resources were removed.
    pub dead_nodes: usize,
    /// Nodes still alive (their resources are kept).
    pub alive_nodes: usize,
}

/// Removes what dead processes of the stack under `prefix` left behind (their nodes'
/// files in /dev/shm and /tmp/iceoryx2, their ports in every service), and the prefix's
/// node-counter segment when no process of it is alive: what systemd runs before it
/// starts (or restarts) the stack, so the new processes reconnect.
pub fn clean(prefix: &IpcPrefix) -> Result<Cleaned, NodeError> {
    // Counted before a node of ours exists (opening one already cleans up).
    let (mut alive, mut dead) = (0usize, 0usize);
    let _ = Node::<Svc>::list(&config_for(prefix)?, |state| {
        match &state {
            NodeState::Alive(_) => alive += 1,
            NodeState::Dead(_) => dead += 1,
            _ => {}
        }
        CallbackProgression::Continue
    });
    // Opening cleans up after the dead, dropping removes the node counter if none lives.
    drop(Ipc::open("landing-clean", prefix)?);
    Ok(Cleaned {
        dead_nodes: dead,
        alive_nodes: alive,
    })
}

/// The iceoryx2 configuration of a stack under `prefix`.
fn config_for(prefix: &IpcPrefix) -> Result<Config, NodeError> {
    let mut config = Config::default();
    config.global.prefix = FileName::new(prefix.as_str().as_bytes())
        .map_err(|_| PrefixError(prefix.as_str().to_string()))?;
    Ok(config)
}

impl Drop for Ipc {
    fn drop(&mut self) {
        // A process that died (SIGKILL) left its node's resources: the survivors clean up.
        let _ = self.node.try_cleanup_dead_nodes();
        // SAFETY: the node is dropped exactly once, here, and never used afterwards.
        unsafe { ManuallyDrop::drop(&mut self.node) };
        // Our node is gone first, so of two processes stopping together at least one sees
        // the other gone too.
        let mut alive = 0usize;
        let listed = Node::<Svc>::list(&self.config, |state| {
            if !matches!(state, NodeState::Dead(_)) {
                alive += 1;
            }
            CallbackProgression::Continue
        });
        if listed.is_ok() && alive == 0 {
            // SAFETY: no node of this prefix is alive; one that starts now recreates the
            // segment (a counter for node ids, whose reuse after every node has gone
            // collides with nothing).
            let _ = unsafe { iceoryx2::testing::remove_global_mgmt_segment::<Svc>(&self.config) };
        }
    }
}

impl Debug for Ipc {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Ipc")
            .field("process", &self.process)
            .finish()
    }
}

impl Ipc {
    /// Creates the node of `process` under `prefix`, cleaning up what dead nodes of earlier
    /// runs left behind (systemd restarts processes; stale resources must not block them).
    pub fn open(process: &str, prefix: &IpcPrefix) -> Result<Self, NodeError> {
        let config = config_for(prefix)?;
        let name = NodeName::new(process).map_err(|e| NodeError::Name {
            name: process.to_string(),
            reason: reason(e),
        })?;
        let node = NodeBuilder::new()
            .name(&name)
            // Signals are ours (runtime::shutdown): iceoryx2's handler would keep only
            // the last signal and could lose a stop.
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .config(&config)
            .create::<Svc>()
            .map_err(|e| NodeError::Create {
                name: process.to_string(),
                reason: reason(e),
            })?;
        // For processes that do not start through `process_main` (tools, probes).
        crate::shutdown::install();
        let cleaned = node.try_cleanup_dead_nodes();
        if cleaned.cleanups > 0 {
            tracing::info!(
                cleaned = cleaned.cleanups,
                "removed stale iceoryx2 resources of dead nodes"
            );
        }
        Ok(Self {
            node: ManuallyDrop::new(node),
            config,
            process: process.to_string(),
        })
    }

    /// [`Ipc::open`] for a process of which a stack runs one: refused when another live
    /// process has the node `process` under `prefix`. Two stacks on one prefix would
    /// deliver each other's messages; this makes the second one stop at its start. (Two
    /// processes starting within the same instant can both pass; a restarted process
    /// finds its predecessor's node dead, not alive.)
    pub fn open_exclusive(process: &str, prefix: &IpcPrefix) -> Result<Self, NodeError> {
        let ipc = Self::open(process, prefix)?;
        let mine = ipc.node.id().value();
        let other = ipc
            .nodes()
            .unwrap_or_default()
            .into_iter()
            .find(|n| n.alive && n.name == process && n.id != mine);
        if let Some(n) = other {
            return Err(NodeError::Taken {
                name: process.to_string(),
                prefix: prefix.as_str().to_string(),
                pid: n.pid.map(|p| format!(" (pid {p})")).unwrap_or_default(),
            });
        }
        Ok(ipc)
    }

    /// True once SIGTERM or SIGINT arrived (see [`crate::shutdown`]). Not
    /// `Node::wait`: iceoryx2 (re)installs its own handlers there, which remember only
    /// the last signal.
    pub fn shutdown_requested(&self) -> bool {
        crate::shutdown::requested()
    }

    /// The iceoryx2 node (for node listing and dead-node detection).
    pub fn node(&self) -> &Node<Svc> {
        &self.node
    }

    /// The process name this node was created with.
    pub fn process(&self) -> &str {
        &self.process
    }

    fn service_name(service: &str) -> Result<ServiceName, ServiceError> {
        ServiceName::new(service).map_err(|e| ServiceError::Name {
            service: service.to_string(),
            reason: reason(e),
        })
    }

    fn event_service(
        &self,
        service: &str,
    ) -> Result<iceoryx2::service::port_factory::event::PortFactory<Svc>, ServiceError> {
        self.node
            .service_builder(&Self::service_name(service)?)
            .event()
            .max_notifiers(MAX_PUBLISHERS)
            .max_listeners(MAX_SUBSCRIBERS)
            .open_or_create()
            .map_err(|e| open_err(service, e))
    }

    /// The publish-subscribe service `service` with this stack's quality of service; every
    /// port of a topic is opened through here, so publishers and subscribers always agree.
    fn pubsub<P, H>(
        &self,
        service: &str,
        history: usize,
        buffer: usize,
    ) -> Result<PubSubBuilder<P, H>, ServiceError>
    where
        P: Debug + IceoryxSend + ?Sized + 'static,
        H: Debug + ZeroCopySend + 'static,
    {
        Ok(self
            .node
            .service_builder(&Self::service_name(service)?)
            .publish_subscribe::<P>()
            .user_header::<H>()
            .enable_safe_overflow(true)
            .subscriber_max_buffer_size(buffer)
            .subscriber_max_borrowed_samples(MAX_BORROWED)
            .history_size(history)
            .max_subscribers(MAX_SUBSCRIBERS)
            .max_publishers(MAX_PUBLISHERS))
    }

    /// A publisher of fixed-size messages `T` on `service`.
    pub fn publisher<T>(&self, service: &str) -> Result<Publisher<T>, ServiceError>
    where
        T: Debug + ZeroCopySend + Copy + 'static,
    {
        let factory = self
            .pubsub::<T, Header>(service, 1, stage::MAX_MESSAGE_DEPTH as usize)?
            .open_or_create()
            .map_err(|e| open_err(service, e))?;
        let port = factory
            .publisher_builder()
            .create()
            .map_err(|e| port_err(service, e))?;
        let notifier = self
            .event_service(service)?
            .notifier_builder()
            .create()
            .map_err(|e| port_err(service, e))?;
        Ok(Publisher {
            port,
            notifier,
            service: service.to_string(),
            seq: 0,
        })
    }

    /// A subscriber of fixed-size messages `T` on `service`, buffering the default 4.
    pub fn subscriber<T>(&self, service: &str) -> Result<Subscriber<T>, ServiceError>
    where
        T: Debug + ZeroCopySend + Copy + 'static,
    {
        self.subscriber_with_depth(service, DEFAULT_DEPTH)
    }

    /// A subscriber of fixed-size messages `T` on `service` buffering `depth` messages
    /// (1 to [`stage::MAX_MESSAGE_DEPTH`]; iceoryx2 refuses more, naming the service).
    pub fn subscriber_with_depth<T>(
        &self,
        service: &str,
        depth: usize,
    ) -> Result<Subscriber<T>, ServiceError>
    where
        T: Debug + ZeroCopySend + Copy + 'static,
    {
        let factory = self
            .pubsub::<T, Header>(service, 1, stage::MAX_MESSAGE_DEPTH as usize)?
            .open_or_create()
            .map_err(|e| open_err(service, e))?;
        let port = factory
            .subscriber_builder()
            .buffer_size(depth.max(1))
            .create()
            .map_err(|e| port_err(service, e))?;
        let listener = self
            .event_service(service)?
            .listener_builder()
            .create()
            .map_err(|e| port_err(service, e))?;
        Ok(Subscriber {
            port,
            listener,
            service: service.to_string(),
            last_seq: Cell::new(0),
            restarts: Cell::new(0),
            gaps: Cell::new(0),
        })
    }

    /// A publisher of variable-length `[T]` payloads (frames, maps) with header `H`.
    /// `max_len` elements is the largest payload it will loan.
    pub fn slice_publisher<T, H>(
        &self,
        service: &str,
        max_len: usize,
    ) -> Result<SlicePublisher<T, H>, ServiceError>
    where
        T: Debug + ZeroCopySend + Copy + 'static,
        H: MessageHeader,
    {
        let factory = self
            .pubsub::<[T], H>(service, 0, stage::MAX_SLICE_DEPTH as usize)?
            .open_or_create()
            .map_err(|e| open_err(service, e))?;
        let port = factory
            .publisher_builder()
            .initial_max_slice_len(max_len)
            .allocation_strategy(AllocationStrategy::Static)
            .create()
            .map_err(|e| port_err(service, e))?;
        let notifier = self
            .event_service(service)?
            .notifier_builder()
            .create()
            .map_err(|e| port_err(service, e))?;
        Ok(SlicePublisher {
            port,
            notifier,
            service: service.to_string(),
            seq: 0,
            max_len,
        })
    }

    /// A subscriber of variable-length `[T]` payloads with header `H`, buffering 4.
    pub fn slice_subscriber<T, H>(
        &self,
        service: &str,
    ) -> Result<SliceSubscriber<T, H>, ServiceError>
    where
        T: Debug + ZeroCopySend + Copy + 'static,
        H: MessageHeader,
    {
        self.slice_subscriber_with_depth(service, DEFAULT_DEPTH)
    }

    /// A subscriber of variable-length payloads buffering `depth` samples (1 to
    /// [`stage::MAX_SLICE_DEPTH`]).
    pub fn slice_subscriber_with_depth<T, H>(
        &self,
        service: &str,
        depth: usize,
    ) -> Result<SliceSubscriber<T, H>, ServiceError>
    where
        T: Debug + ZeroCopySend + Copy + 'static,
        H: MessageHeader,
    {
        let factory = self
            .pubsub::<[T], H>(service, 0, stage::MAX_SLICE_DEPTH as usize)?
            .open_or_create()
            .map_err(|e| open_err(service, e))?;
        let port = factory
            .subscriber_builder()
            .buffer_size(depth.max(1))
            .create()
            .map_err(|e| port_err(service, e))?;
        let listener = self
            .event_service(service)?
            .listener_builder()
            .create()
            .map_err(|e| port_err(service, e))?;
        Ok(Subscriber {
            port,
            listener,
            service: service.to_string(),
            last_seq: Cell::new(0),
            restarts: Cell::new(0),
            gaps: Cell::new(0),
        })
    }

    fn heartbeat_service(
        &self,
        process: &str,
        deadline: Duration,
    ) -> Result<iceoryx2::service::port_factory::event::PortFactory<Svc>, ServiceError> {
        let name = ipc_types::services::heartbeat(process);
        self.node
            .service_builder(&Self::service_name(&name)?)
            .event()
            .deadline(deadline)
            .max_notifiers(MAX_PUBLISHERS)
            .max_listeners(MAX_SUBSCRIBERS)
            .open_or_create()
            .map_err(|e| open_err(&name, e))
    }

    /// This process's heartbeat: an event with a deadline that the watchdog watches.
    /// Beat it at least once per `deadline`, from the loop that does the work, so that a
    /// hung loop misses it.
    pub fn heartbeat(&self, deadline: Duration) -> Result<Heartbeat, ServiceError> {
        let service = ipc_types::services::heartbeat(&self.process);
        let notifier = self
            .heartbeat_service(&self.process, deadline)?
            .notifier_builder()
            .create()
            .map_err(|e| port_err(&service, e))?;
        Ok(Heartbeat {
            notifier,
            service,
            missed: 0,
        })
    }

    /// The nodes of this stack (a dead node is one whose process is gone without
    /// cleaning up); `None` when the list could not be read.
    pub fn nodes(&self) -> Option<Vec<ListedNode>> {
        use iceoryx2::node::NodeView;
        let mut out = Vec::new();
        let listed = Node::<Svc>::list(&self.config, |state| {
            let (details, alive, id) = match &state {
                NodeState::Alive(v) => (v.details(), true, v.id()),
                NodeState::Dead(v) => (v.details(), false, v.id()),
                _ => return CallbackProgression::Continue,
            };
            if let Some(d) = details {
                out.push(ListedNode {
                    name: d.name().as_str().to_string(),
                    alive,
                    id: id.value(),
                    pid: id
                        .pid::<Svc>()
                        .ok()
                        .and_then(|p| u32::try_from(p.value()).ok()),
                });
            }
            CallbackProgression::Continue
        });
        listed.ok().map(|_| out)
    }

    /// Removes the resources dead nodes of this stack left (their ports in every
    /// service), so that a restarted process reconnects; how many were cleaned.
    pub fn cleanup_dead_nodes(&self) -> u64 {
        self.node.try_cleanup_dead_nodes().cleanups
    }

    /// A listener on `process`'s heartbeat, for a supervisor; attach it to the wait loop as
    /// a deadline to learn when the process hangs.
    pub fn heartbeat_listener(
        &self,
        process: &str,
        deadline: Duration,
    ) -> Result<Listener<Svc>, ServiceError> {
        self.heartbeat_service(process, deadline)?
            .listener_builder()
            .create()
            .map_err(|e| port_err(&ipc_types::services::heartbeat(process), e))
    }
}

/// Publishes fixed-size messages and wakes subscribers.
pub struct Publisher<T: Debug + ZeroCopySend + Copy + 'static> {
    port: IoxPublisher<Svc, T, Header>,
    notifier: Notifier<Svc>,
    service: String,
    seq: u64,
}

impl<T: Debug + ZeroCopySend + Copy + 'static> Publisher<T> {
    /// Writes `value` into a loaned shared-memory sample, stamps `header` with the next
    /// sequence number, sends it and notifies subscribers. Returns the sequence number.
    pub fn send(&mut self, header: Header, value: &T) -> Result<u64, SendError> {
        let mut sample = self
            .port
            .loan_uninit()
            .map_err(|e| loan_err(&self.service, e))?;
        self.seq += 1;
        *sample.user_header_mut() = Header {
            seq: self.seq,
            ..header
        };
        let sample = sample.write_payload(*value);
        sample.send().map_err(|e| send_err(&self.service, e))?;
        notify(&self.notifier, &self.service)?;
        Ok(self.seq)
    }

    /// The service this publisher writes.
    pub fn service(&self) -> &str {
        &self.service
    }
}

/// Publishes variable-length payloads, written in place in shared memory.
pub struct SlicePublisher<T: Debug + ZeroCopySend + Copy + 'static, H: MessageHeader> {
    port: IoxPublisher<Svc, [T], H>,
    notifier: Notifier<Svc>,
    service: String,
    seq: u64,
    max_len: usize,
}

/// A loaned, not yet written payload of `len` elements in shared memory.
pub type SliceLoan<T, H> = SampleMutUninit<Svc, [core::mem::MaybeUninit<T>], H>;
/// A loaned, written payload in shared memory, ready to send.
pub type SliceSample<T, H> = SampleMut<Svc, [T], H>;

impl<T: Debug + ZeroCopySend + Copy + 'static, H: MessageHeader> SlicePublisher<T, H> {
    /// The largest payload this publisher can loan, in elements.
    pub fn max_len(&self) -> usize {
        self.max_len
    }

    /// Loans `len` uninitialized elements of shared memory; the producer writes its data
    /// straight into them (a camera driver, a renderer), so nothing is copied afterwards.
    pub fn loan_uninit(&mut self, len: usize) -> Result<SliceLoan<T, H>, LoanError> {
        self.port
            .loan_slice_uninit(len)
            .map_err(|e| loan_err(&self.service, e))
    }

    /// Loans `len` elements of shared memory, zero-initialized, for producers that write
    /// through a `&mut [T]` (a renderer): safe, at the cost of one memset.
    pub fn loan(&mut self, len: usize) -> Result<SliceSample<T, H>, LoanError>
    where
        T: Default,
    {
        self.port
            .loan_slice(len)
            .map_err(|e| loan_err(&self.service, e))
    }

    /// Sends a written sample: stamps the next sequence number into its header, then
    /// notifies subscribers. Returns the sequence number.
    pub fn send(&mut self, mut sample: SliceSample<T, H>) -> Result<u64, SendError> {
        self.seq += 1;
        sample.user_header_mut().msg_mut().seq = self.seq;
        sample.send().map_err(|e| send_err(&self.service, e))?;
        notify(&self.notifier, &self.service)?;
        Ok(self.seq)
    }

    /// The service this publisher writes.
    pub fn service(&self) -> &str {
        &self.service
    }
}

fn notify(notifier: &Notifier<Svc>, service: &str) -> Result<(), SendError> {
    match notifier.notify() {
        Ok(_) | Err(NotifierNotifyError::MissedDeadline) => Ok(()),
        Err(e) => Err(SendError::Notify {
            service: service.to_string(),
            reason: reason(e),
        }),
    }
}

/// The two kinds of iceoryx2 subscriber ports (fixed-size and slice payloads) have
/// separate `receive` methods; this lets one [`Subscriber`] wrap either.
pub trait ReceivePort<P: ?Sized + Debug + IceoryxSend, H: MessageHeader> {
    /// The oldest unread sample.
    fn receive_sample(&self) -> Result<Option<Sample<Svc, P, H>>, iceoryx2::port::ReceiveError>;
}

impl<T: Debug + ZeroCopySend + Copy + 'static, H: MessageHeader> ReceivePort<T, H>
    for IoxSubscriber<Svc, T, H>
{
    fn receive_sample(&self) -> Result<Option<Sample<Svc, T, H>>, iceoryx2::port::ReceiveError> {
        self.receive()
    }
}

impl<T: Debug + ZeroCopySend + Copy + 'static, H: MessageHeader> ReceivePort<[T], H>
    for IoxSubscriber<Svc, [T], H>
{
    fn receive_sample(&self) -> Result<Option<Sample<Svc, [T], H>>, iceoryx2::port::ReceiveError> {
        self.receive()
    }
}

/// Receives a topic's samples, read in place from shared memory: fixed-size messages
/// (`Subscriber<T>`) or variable-length payloads ([`SliceSubscriber`]).
pub struct Subscriber<P: ?Sized + Debug + IceoryxSend + 'static, H: MessageHeader = Header> {
    port: IoxSubscriber<Svc, P, H>,
    listener: Listener<Svc>,
    service: String,
    last_seq: Cell<u64>,
    gaps: Cell<u64>,
    restarts: Cell<u64>,
}

/// Receives variable-length payloads (frames, maps) with header `H`.
pub type SliceSubscriber<T, H> = Subscriber<[T], H>;

impl<P, H> Subscriber<P, H>
where
    P: ?Sized + Debug + IceoryxSend + 'static,
    H: MessageHeader,
    IoxSubscriber<Svc, P, H>: ReceivePort<P, H>,
{
    /// The oldest unread sample, or `None`. The payload is the publisher's memory: no copy.
    pub fn receive(&self) -> Result<Option<Sample<Svc, P, H>>, ReceiveError> {
        let s = self.port.receive_sample().map_err(|e| ReceiveError {
            service: self.service.clone(),
            reason: reason(e),
        })?;
        if let Some(s) = &s {
            track_seq(
                &self.last_seq,
                &self.gaps,
                &self.restarts,
                s.user_header().msg().seq,
            );
        }
        Ok(s)
    }

    /// The newest unread sample, dropping (and counting) older ones, so that a slow
    /// consumer always works on the freshest data.
    pub fn latest(&self) -> Result<Option<Sample<Svc, P, H>>, ReceiveError> {
        let mut newest = None;
        while let Some(s) = self.receive()? {
            newest = Some(s);
        }
        Ok(newest)
    }

    /// The event listener to wait on.
    pub fn listener(&self) -> &Listener<Svc> {
        &self.listener
    }

    /// Whether a sample waits (a failed look says yes: the next receive reports it).
    pub fn has_samples(&self) -> bool {
        self.port.has_samples().unwrap_or(true)
    }

    /// Samples lost to overflow, counted from sequence gaps.
    pub fn gaps(&self) -> u64 {
        self.gaps.get()
    }

    /// Times the publisher started over (its sequence went back: a restarted process
    /// numbers from 1 again): a restart, not lost data.
    pub fn restarts(&self) -> u64 {
        self.restarts.get()
    }
}

fn track_seq(last: &Cell<u64>, gaps: &Cell<u64>, restarts: &Cell<u64>, seq: u64) {
    let l = last.get();
    if l != 0 && seq > l + 1 {
        gaps.set(gaps.get() + seq - l - 1);
    } else if l != 0 && seq <= l {
        restarts.set(restarts.get() + 1);
    }
    last.set(seq);
}

/// This process's heartbeat notifier.
pub struct Heartbeat {
    notifier: Notifier<Svc>,
    /// The heartbeat's event service, for errors.
    service: String,
    missed: u64,
}

impl Heartbeat {
    /// Signals "alive". A beat later than the deadline still goes out; it is counted.
    pub fn beat(&mut self) -> Result<(), HeartbeatError> {
        match self.notifier.notify() {
            Ok(_) => Ok(()),
            Err(NotifierNotifyError::MissedDeadline) => {
                self.missed += 1;
                Ok(())
            }
            Err(e) => Err(HeartbeatError {
                service: self.service.clone(),
                reason: reason(e),
            }),
        }
    }

    /// Beats that came later than the deadline.
    pub fn missed(&self) -> u64 {
        self.missed
    }
}

/// Waits for a periodic stream (a camera, a depth sensor) with the lowest latency a
/// consumer can get without burning a core.
///
/// Waking a sleeping process costs tens of microseconds on a virtual machine or a Jetson in
/// a deep idle state, far more than iceoryx2's ~1 us transport. Sensor streams are periodic,
/// so this waiter learns the period from arrivals, sleeps on the event until `guard` before
/// the next sample is due, then polls for at most `guard + max_spin`, and falls back to
/// sleeping on the event when the sample is late. At 30 Hz with a 200 us guard the spinning
/// costs about 1% of one core.
#[derive(Debug, Clone)]
pub struct PeriodicWait {
    guard_ns: u64,
    max_spin_ns: u64,
    period_ns: Option<u64>,
    intervals: [u64; 8],
    interval_count: usize,
    last_arrival_ns: u64,
    spin_hits: u64,
    sleep_hits: u64,
    slack_set: bool,
}

impl PeriodicWait {
    /// A waiter that starts polling `guard` before the expected arrival and gives up
    /// polling `max_spin` after it.
    pub fn new(guard: Duration, max_spin: Duration) -> Self {
        Self {
            guard_ns: guard.as_nanos() as u64,
            max_spin_ns: max_spin.as_nanos() as u64,
            period_ns: None,
            intervals: [0; 8],
            interval_count: 0,
            last_arrival_ns: 0,
            spin_hits: 0,
            sleep_hits: 0,
            slack_set: false,
        }
    }

    /// How many samples were caught while polling, and how many woke a sleeping wait:
    /// a high second number means the stream is too irregular for the guard.
    pub fn hits(&self) -> (u64, u64) {
        (self.spin_hits, self.sleep_hits)
    }

    /// The learned period, once two samples have arrived.
    pub fn period(&self) -> Option<Duration> {
        self.period_ns.map(Duration::from_nanos)
    }

    /// Learns the period as the median of the last 8 intervals, ignoring bursts (samples
    /// that queued up and were read back to back), so neither a burst nor a dropped sample
    /// moves the estimate much.
    fn on_arrival(&mut self, now: u64) {
        const MIN_INTERVAL_NS: u64 = 100_000;
        if self.last_arrival_ns != 0 {
            let dt = now.saturating_sub(self.last_arrival_ns);
            if (MIN_INTERVAL_NS..2_000_000_000).contains(&dt) {
                let n = self.intervals.len();
                self.intervals[self.interval_count % n] = dt;
                self.interval_count += 1;
                let mut recent = self.intervals;
                let k = self.interval_count.min(n);
                recent[..k].sort_unstable();
                self.period_ns = Some(recent[k / 2]);
            }
        }
        self.last_arrival_ns = now;
    }

    /// Returns the next value of `poll` (which receives from the subscriber that owns
    /// `listener`), or `None` after `timeout`.
    pub fn wait<T>(
        &mut self,
        listener: &Listener<Svc>,
        timeout: Duration,
        mut poll: impl FnMut() -> Option<T>,
    ) -> Option<T> {
        if !self.slack_set {
            // The default 50 us timer slack would make every nap overshoot into the guard.
            // SAFETY: PR_SET_TIMERSLACK takes an integer and affects only this thread.
            unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong) };
            self.slack_set = true;
        }
        let start = monotonic_ns();
        let deadline = start.saturating_add(timeout.as_nanos() as u64);
        let mut spinning = false;
        loop {
            if let Some(v) = poll() {
                if spinning {
                    self.spin_hits += 1;
                } else {
                    self.sleep_hits += 1;
                }
                self.on_arrival(monotonic_ns());
                // Events that accumulated while polling must not wake the next wait.
                let _ = listener.try_wait(|_| {});
                return Some(v);
            }
            let now = monotonic_ns();
            if now >= deadline {
                return None;
            }
            let expected = self.period_ns.map(|p| self.last_arrival_ns + p);
            match expected {
                Some(exp) if now + self.guard_ns < exp => {
                    spinning = false;
                    wait_readable(listener, (exp - self.guard_ns - now).min(deadline - now));
                }
                Some(exp) if now < exp + self.max_spin_ns => {
                    spinning = true;
                    std::hint::spin_loop();
                }
                _ => {
                    spinning = false;
                    wait_readable(listener, (deadline - now).min(100_000_000));
                }
            }
        }
    }
}

/// Sleeps until one of `listeners` has an event or `timeout_ns` passes; which did (their
/// events are not drained).
pub(crate) fn wait_any_readable(listeners: &[&Listener<Svc>], timeout_ns: u64) -> Vec<bool> {
    use iceoryx2::prelude::FileDescriptorBased;
    // SAFETY: the descriptors are only passed to ppoll while the listeners, which own
    // them, are borrowed; they are not stored or closed.
    let fds: Vec<i32> = listeners
        .iter()
        .map(|l| unsafe { l.file_descriptor().native_handle() })
        .collect();
    wait_fds(&fds, timeout_ns)
}

/// Sleeps until one of `fds` is readable or `timeout_ns` passes, with the kernel timer's
/// precision; which are (nothing is read).
pub(crate) fn wait_fds(fds: &[i32], timeout_ns: u64) -> Vec<bool> {
    let mut pfds: Vec<libc::pollfd> = fds
        .iter()
        .map(|fd| libc::pollfd {
            fd: *fd,
            events: libc::POLLIN,
            revents: 0,
        })
        .collect();
    let ts = libc::timespec {
        tv_sec: (timeout_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (timeout_ns % 1_000_000_000) as libc::c_long,
    };
    // SAFETY: `pfds` and `ts` are valid for the call; a null signal mask keeps the
    // current one.
    let rc = unsafe {
        libc::ppoll(
            pfds.as_mut_ptr(),
            pfds.len() as libc::nfds_t,
            &ts,
            std::ptr::null(),
        )
    };
    pfds.iter()
        .map(|p| rc > 0 && p.revents & libc::POLLIN != 0)
        .collect()
}

/// Sleeps until `listener` has an event or `timeout_ns` passes, with the kernel timer's
/// precision (iceoryx2's own `timed_wait` rounds short timeouts up to several ms), then
/// drains the listener.
fn wait_readable(listener: &Listener<Svc>, timeout_ns: u64) {
    use iceoryx2::prelude::FileDescriptorBased;
    // SAFETY: the descriptor is only passed to ppoll while `listener`, which owns it, is
    // borrowed; it is not stored or closed.
    let fd = unsafe { listener.file_descriptor().native_handle() };
    let mut pfd = libc::pollfd {
        fd,
        events: libc::POLLIN,
        revents: 0,
    };
    let ts = libc::timespec {
        tv_sec: (timeout_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (timeout_ns % 1_000_000_000) as libc::c_long,
    };
    // SAFETY: `pfd` and `ts` are valid for the call; a null signal mask keeps the current one.
    let rc = unsafe { libc::ppoll(&mut pfd, 1, &ts, std::ptr::null()) };
    if rc > 0 {
        let _ = listener.try_wait(|_| {});
    }
}

/// Why the wait loop woke the caller.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wake {
    /// `listeners[i]` was notified (new data); its events are already drained.
    Data(usize),
    /// `deadlines[i]` saw no event within its deadline.
    DeadlineMissed(usize),
    /// The periodic tick.
    Tick,
}

/// Why the wait loop returned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LoopExit {
    /// SIGTERM (systemd stop) or SIGINT (Ctrl-C): shut down cleanly.
    Signal,
    /// The callback asked to stop.
    Stopped,
}

/// Sleeps until data arrives on one of `listeners`, a deadline in `deadlines` passes, or the
/// `tick` interval elapses, and calls `on_wake` for each. Returns cleanly on SIGINT/SIGTERM
/// or when `on_wake` returns `false`.
pub fn run_wait_loop(
    listeners: &[&Listener<Svc>],
    deadlines: &[(&Listener<Svc>, Duration)],
    tick: Option<Duration>,
    mut on_wake: impl FnMut(Wake) -> bool,
) -> Result<LoopExit, WaitError> {
    let waitset = WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<Svc>()
        .map_err(|e| WaitError::Create { reason: reason(e) })?;
    let mut data_guards = Vec::with_capacity(listeners.len());
    for l in listeners {
        data_guards.push(
            waitset
                .attach_notification(*l)
                .map_err(|e| WaitError::Attach { reason: reason(e) })?,
        );
    }
    let mut deadline_guards = Vec::with_capacity(deadlines.len());
    for (l, d) in deadlines {
        deadline_guards.push(
            waitset
                .attach_deadline(*l, *d)
                .map_err(|e| WaitError::Attach { reason: reason(e) })?,
        );
    }
    let tick_guard = match tick {
        Some(t) => Some(
            waitset
                .attach_interval(t)
                .map_err(|e| WaitError::Attach { reason: reason(e) })?,
        ),
        None => None,
    };

    let mut on_event = |id: WaitSetAttachmentId<Svc>| {
        let mut keep = true;
        for (i, g) in data_guards.iter().enumerate() {
            if id.has_event_from(g) {
                // Drain the event counter so the wait set does not fire again for it.
                let _ = listeners[i].try_wait(|_| {});
                keep &= on_wake(Wake::Data(i));
            }
        }
        for (i, g) in deadline_guards.iter().enumerate() {
            if id.has_event_from(g) {
                let _ = deadlines[i].0.try_wait(|_| {});
            } else if id.has_missed_deadline(g) {
                keep &= on_wake(Wake::DeadlineMissed(i));
            }
        }
        if let Some(g) = &tick_guard
            && id.has_event_from(g)
        {
            keep &= on_wake(Wake::Tick);
        }
        if keep {
            CallbackProgression::Continue
        } else {
            CallbackProgression::Stop
        }
    };
    // One round at a time, our flag looked at between rounds: with iceoryx2's signal
    // handling disabled, `wait_and_process` would only notice a signal that interrupts
    // the wait itself, and one that arrives while a callback runs would be lost (a busy
    // stage, always in its callback, then never stopped). A signal that lands between
    // the look and the wait is seen when the wait ends, at the latest at the next tick.
    loop {
        if crate::shutdown::requested() {
            return Ok(LoopExit::Signal);
        }
        match waitset.wait_and_process_once(&mut on_event) {
            Ok(WaitSetRunResult::StopRequest) => {
                if crate::shutdown::requested() {
                    return Ok(LoopExit::Signal);
                }
                return Ok(LoopExit::Stopped);
            }
            // Any signal interrupts the wait; SIGCHLD and the like must not end a process,
            // so only the flag decides.
            Ok(
                WaitSetRunResult::TerminationRequest
                | WaitSetRunResult::Interrupt
                | WaitSetRunResult::AllEventsHandled,
            ) => {}
            Err(e) => return Err(WaitError::Wait { reason: reason(e) }),
        }
    }
}

#[cfg(test)]
#[path = "ipc_test.rs"]
mod tests;
