//! What the lockstep tests of px4-link against the simulator share.
#![allow(dead_code)] // each test file uses a part

use std::path::PathBuf;

use ipc_types::msg::{Header, Setpoint};
use sim::scenario::LoadedScenario;

/// A shipped scenario from `deploy/`.
pub fn scenario(name: &str) -> LoadedScenario {
    let deploy = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../deploy");
    sim::scenario::load(name, &deploy).unwrap()
}

/// Hold position (x, y, z) ENU with yaw 0.
pub fn position_setpoint(x: f64, y: f64, z: f64) -> Setpoint {
    Setpoint {
        msg: Header::default(),
        position: [x, y, z],
        velocity: [0.0; 3],
        acceleration: [0.0; 3],
        yaw: 0.0,
        valid: Setpoint::POSITION | Setpoint::YAW,
        reserved: 0,
    }
}
