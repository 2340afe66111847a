//! What the lockstep tests of px4-link against the simulator share.
#![allow(dead_code)] // each test file uses a part

use std::path::PathBuf;

use ipc_types::msg::{Header, LinkOutcome, LinkRequest, Setpoint, VehicleState};
use ipc_types::services;
use runtime::{Ipc, IpcPrefix, Publisher, Subscriber};
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

/// The fsm's side of px4-link's topics, as a test plays it.
pub struct FsmSide {
    /// The test's node (for further ports).
    pub ipc: Ipc,
    /// `vehicle/state` from px4-link.
    pub states: Subscriber<VehicleState>,
    /// `px4/outcome` from px4-link.
    pub outcomes: Subscriber<LinkOutcome>,
    /// `px4/request` to px4-link.
    pub requests: Publisher<LinkRequest>,
}

/// Opens the fsm's side under `prefix`.
pub fn fsm_side(prefix: &IpcPrefix) -> FsmSide {
    let ipc = Ipc::open("test-fsm", prefix).unwrap();
    FsmSide {
        states: ipc.subscriber(services::VEHICLE_STATE).unwrap(),
        outcomes: ipc.subscriber(services::PX4_OUTCOME).unwrap(),
        requests: ipc.publisher(services::PX4_REQUEST).unwrap(),
        ipc,
    }
}
