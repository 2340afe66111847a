//! px4-link: the MAVLink 2 link between the stack and PX4.
//!
//! [`Px4Link`] is the whole protocol as a pure state machine (messages and time in,
//! messages and the vehicle state out); [`LinkNode`] wraps it with the stack's messages
//! (requests with ids, safety orders, outcomes, the vehicle state to publish); the
//! `px4-link` binary owns the UDP socket or serial port, the clock and iceoryx2. The
//! protocol pieces the simulated autopilot shares (codec, NED/FRD frames, PX4 modes,
//! COMMAND_LONG) are the `px4_protocol` crate's; NED and FRD appear nowhere else.

pub mod clock;
pub mod config;
pub mod link;
pub mod node;
pub mod odometry;
pub mod stage;

pub use link::{LinkSettings, Outcome, Px4Link, Refusal, Request, SetpointBounds, Status};
pub use node::LinkNode;
pub use stage::{Framing, LinkStage};
