#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Tests of `command`.

use super::*;

#[test]
fn every_parameter_lands_in_its_field() {
    let params = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0];
    let MavMessage::COMMAND_LONG(c) =
        command_long_confirmation(MavCmd::MAV_CMD_NAV_TAKEOFF, params, (1, 2), 3)
    else {
        panic!("not a COMMAND_LONG");
    };
    assert_eq!(
        [
            c.param1, c.param2, c.param3, c.param4, c.param5, c.param6, c.param7
        ],
        params
    );
    assert_eq!(c.command, MavCmd::MAV_CMD_NAV_TAKEOFF);
    assert_eq!(
        (c.target_system, c.target_component, c.confirmation),
        (1, 2, 3)
    );
}

#[test]
fn the_first_transmission_has_confirmation_0() {
    let m = command_long(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, [1.0; 7], (1, 1));
    assert!(matches!(m, MavMessage::COMMAND_LONG(c) if c.confirmation == 0));
}
