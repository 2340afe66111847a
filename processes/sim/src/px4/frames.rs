//! Frame conversions at the MAVLink boundary: the world is ENU / FLU, PX4 speaks NED /
//! FRD. They are the shared protocol crate's (`px4_protocol::frames`), so the simulated
//! autopilot and the companion side (px4-link) convert with the same code; only the MAVLink side of the simulator
//! uses them, so the rest of the crate never sees a NED quantity.

pub use px4_protocol::frames::{
    enu_to_ned, flu_to_frd, ned_from_frd, ned_to_enu, quaternion_wxyz, wrap_pi, yaw_enu_to_ned,
    yaw_ned_to_enu,
};
