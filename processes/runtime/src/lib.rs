//! The runtime every process shares: iceoryx2 node and ports, heartbeats, the wait loop,
//! the clock, logging, signals, threads and `process_main`. Configuration loading is
//! `stack_config`, a crate below this one that process libraries may use.
//!
//! Process *libraries* never use this crate: they take inputs and time as arguments. Only
//! the thin `main.rs` of each process, the lockstep runner and tools bind those libraries
//! to it.

pub mod capture;
pub mod clock;
pub mod driver;
pub mod ipc;
pub mod logging;
pub mod notify;
pub mod port_faults;
pub mod process_main;
pub mod serve;
pub mod shutdown;
pub mod supervise;
pub mod tcp;
pub mod threads;
pub mod udp;

/// The iceoryx2 this runtime is built on, for the few binaries that name its types
/// (a sample, the `ZeroCopySend` bound of a generic port helper).
pub use iceoryx2;

pub use clock::{Clock, MonotonicClock, SimClock, monotonic_ns, unix_ns_at_monotonic_zero};
pub use driver::{Beat, DriverError};
pub use ipc::{
    Heartbeat, HeartbeatError, Ipc, IpcPrefix, ListedNode, LoanError, LoopExit, MessageHeader,
    NodeError, PeriodicWait, PrefixError, Publisher, ReceiveError, SendError, ServiceError,
    SlicePublisher, SliceSubscriber, Subscriber, WaitError, Wake, run_wait_loop,
};
pub use process_main::process_main;
pub use serve::{ServeError, StageArgs, serve, serve_spec};
pub use supervise::{Supervision, SupervisionError};
pub use tcp::{TcpError, TcpServerLink, TcpStats};
pub use threads::{JOIN_TIMEOUT, JoinError, StopFlag, ThreadRole, Worker};
pub use udp::{Reply, UdpLink, UdpStats};
