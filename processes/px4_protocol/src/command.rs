//! COMMAND_LONG, built in one place: px4-link's requests, the tools' scripted flights and
//! the tests all send the same seven parameters the same way.

use mavlink::dialects::common::{COMMAND_LONG_DATA, MavCmd, MavMessage};

/// PX4's `param2` of ARM_DISARM that forces a disarm in the air (commander's
/// `handle_command_arm_disarm`): the companion cuts the motors at touchdown with it, and
/// the simulated commander honours it.
pub const FORCE_DISARM_MAGIC: f32 = 21196.0;

/// COMMAND_LONG `command` with `params` (param1 to param7) to `target` (system id,
/// component id), first transmission (confirmation 0).
pub fn command_long(command: MavCmd, params: [f32; 7], target: (u8, u8)) -> MavMessage {
    command_long_confirmation(command, params, target, 0)
}

/// The same COMMAND_LONG, retransmission `confirmation` (MAVLink's command protocol
/// counts it up from 0 on each resend, so the autopilot can tell a retry from a repeat).
pub fn command_long_confirmation(
    command: MavCmd,
    params: [f32; 7],
    target: (u8, u8),
    confirmation: u8,
) -> MavMessage {
    let [param1, param2, param3, param4, param5, param6, param7] = params;
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        param1,
        param2,
        param3,
        param4,
        param5,
        param6,
        param7,
        command,
        target_system: target.0,
        target_component: target.1,
        confirmation,
    })
}

#[cfg(test)]
#[path = "command_test.rs"]
mod tests;
