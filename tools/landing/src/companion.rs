//! The tools' side of MAVLink to the lockstep simulator, in-process (no socket): what a
//! companion computer would send, handed straight to the simulated autopilot.

use mavlink::MavHeader;
use mavlink::dialects::common::{MavCmd, MavMessage};
use sim::lockstep::Simulator;

/// The header a companion (MAV_COMP_ID_ONBOARD_COMPUTER) sends with.
pub const COMPANION: MavHeader = MavHeader {
    system_id: 1,
    component_id: 191,
    sequence: 0,
};

/// Sends COMMAND_LONG `command` with parameters `p` to the simulated autopilot.
pub fn command(sim: &mut Simulator, command: MavCmd, p: [f32; 7]) {
    sim.handle_mavlink(&COMPANION, &px4_protocol::command_long(command, p, (1, 1)));
}

/// The AMSL altitude of the local origin if `msg` is a HOME_POSITION (its altitude
/// and local z describe one point), as px4-link reads it.
pub fn origin_amsl(msg: &MavMessage) -> Option<f64> {
    match msg {
        MavMessage::HOME_POSITION(h) => Some(f64::from(h.altitude) * 1e-3 + f64::from(h.z)),
        _ => None,
    }
}

/// Arm, then AUTO.TAKEOFF to `height_m` above the local origin, whose altitude above
/// mean sea level is `origin_amsl` (NAV_TAKEOFF's param7 is AMSL in PX4).
pub fn arm_and_take_off(sim: &mut Simulator, origin_amsl: f64, height_m: f64) {
    command(
        sim,
        MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    );
    let param7 = (origin_amsl + height_m) as f32;
    command(
        sim,
        MavCmd::MAV_CMD_NAV_TAKEOFF,
        [0.0, 0.0, 0.0, f32::NAN, f32::NAN, f32::NAN, param7],
    );
}
