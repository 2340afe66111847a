//! The MAVLink/PX4 protocol pieces both ends of the link share: the companion side
//! (px4-link) and the simulated autopilot (sim). Each end depends on this crate rather
//! than on the other, so the two cannot disagree on a frame, a sign or a mode number,
//! and neither pulls in the other's code.
//!
//! - [`codec`]: MAVLink frames in and out of datagrams and byte streams.
//! - [`frames`]: NED/FRD (PX4) <-> ENU/FLU (the stack); the only place NED appears.
//! - [`mode`]: PX4's custom modes as HEARTBEAT carries them.
//! - [`command`]: the one COMMAND_LONG builder.
//! - [`raw`]: the COMMAND_LONG/ACK frames the `mavlink` crate cannot express (a command
//!   number the dialect lacks) and MAVLink's checksum.
//! - [`signing`]: MAVLink 2 message signing, keys and replay checks.
//!
//! No I/O, no clock, no IPC.

pub mod codec;
pub mod command;
pub mod frames;
pub mod mode;
pub mod raw;
pub mod signing;

pub use command::{command_long, command_long_confirmation};
