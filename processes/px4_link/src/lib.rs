//! px4-link: the MAVLink 2 link between the stack and PX4.
//!
//! [`Px4Link`] is the whole protocol as a pure state machine (messages and time in,
//! messages and the vehicle state out); [`LinkNode`] wraps it with the stack's messages
//! (requests with ids, safety orders, outcomes, the vehicle state to publish); the
//! `px4-link` binary owns the UDP socket or serial port, the clock and iceoryx2. NED and
//! FRD appear only in this crate ([`frames`]).

pub mod codec;
pub mod config;
pub mod frames;
pub mod link;
pub mod mode;
pub mod node;

pub use link::{LinkSettings, Outcome, Px4Link, Request, Status};
pub use node::LinkNode;
