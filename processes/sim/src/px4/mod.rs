//! The simulator's PX4 side: a PX4-like commander that the `sim` process puts behind a
//! MAVLink 2 UDP socket (`runtime::UdpLink`, as PX4 SITL's onboard link), so px4-link
//! talks to the simulator exactly as it would to PX4 SITL or a real Pixhawk.
//!
//! - [`commander`]: pure PX4 behaviour (modes, commands and ACKs, offboard
//!   rules and failsafe, takeoff, land, auto-disarm, telemetry).
//! - [`frames`]: ENU/FLU <-> NED/FRD, used only at this boundary.
//!
//! The codec, the frame conversions, PX4's modes and the raw COMMAND_LONG/ACK frames
//! (a command number the dialect lacks, which PX4 answers UNSUPPORTED) are
//! `px4_protocol`'s, shared with px4-link.

pub mod commander;
pub mod frames;
