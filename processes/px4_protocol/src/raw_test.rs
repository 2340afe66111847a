#![allow(clippy::unwrap_used, clippy::expect_used)]

use mavlink::MavHeader;
use mavlink::dialects::common::{COMMAND_ACK_DATA, MavCmd, MavResult};

use super::*;

const COMPANION: MavHeader = MavHeader {
    system_id: 1,
    component_id: 191,
    sequence: 7,
};

fn command_long(command: MavCmd) -> Vec<u8> {
    let mut buf = Vec::new();
    let msg = crate::command::command_long(command, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], (1, 1));
    mavlink::write_v2_msg(&mut buf, COMPANION, &msg).unwrap();
    buf
}

/// `frame` with its command number replaced by `number` and the checksum redone.
fn with_command_number(mut frame: Vec<u8>, number: u16) -> Vec<u8> {
    assert!(renumber_command_long(&mut frame, number));
    frame
}

#[test]
fn the_checksum_matches_the_mavlink_crate() {
    let frame = command_long(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM);
    assert_eq!(with_command_number(frame.clone(), 400), frame);
}

#[test]
fn a_command_number_the_dialect_lacks_is_found_and_known_ones_are_not() {
    let known = command_long(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM);
    assert!(unknown_commands(&known).is_empty());
    let unknown = with_command_number(known.clone(), 31_999);
    // One datagram may carry several frames, garbage between them.
    let mut datagram = known.clone();
    datagram.extend_from_slice(b"noise");
    datagram.extend_from_slice(&unknown);
    let found = unknown_commands(&datagram);
    assert_eq!(
        found,
        vec![UnknownCommand {
            sender_system: 1,
            sender_component: 191,
            command: 31_999,
            target_system: 1,
            target_component: 1,
        }]
    );
    let mut broken = unknown.clone();
    let n = broken.len();
    broken[n - 1] ^= 0xff;
    assert!(unknown_commands(&broken).is_empty(), "bad checksum");
    assert!(unknown_commands(&unknown[..unknown.len() - 3]).is_empty());
}

#[test]
fn the_ack_frame_is_what_the_mavlink_crate_writes_for_a_known_command() {
    let to = UnknownCommand {
        sender_system: 1,
        sender_component: 191,
        command: 400,
        target_system: 1,
        target_component: 1,
    };
    let ours = command_ack_frame(9, 1, 1, &to, MavResult::MAV_RESULT_UNSUPPORTED as u8);
    let mut theirs = Vec::new();
    mavlink::write_v2_msg(
        &mut theirs,
        MavHeader {
            system_id: 1,
            component_id: 1,
            sequence: 9,
        },
        &MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
            command: MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            result: MavResult::MAV_RESULT_UNSUPPORTED,
            progress: 0,
            result_param2: 0,
            target_system: 1,
            target_component: 191,
        }),
    )
    .unwrap();
    assert_eq!(ours, theirs);
}

#[test]
fn only_an_unsigned_command_long_is_renumbered() {
    let mut frame = command_long(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM);
    let mut cut = frame[..frame.len() - 1].to_vec();
    assert!(!renumber_command_long(&mut cut, 7));
    let mut ack = command_ack_frame(
        0,
        1,
        1,
        &UnknownCommand {
            sender_system: 1,
            sender_component: 191,
            command: 400,
            target_system: 1,
            target_component: 1,
        },
        0,
    );
    let before = ack.clone();
    assert!(!renumber_command_long(&mut ack, 7));
    assert_eq!(ack, before);
    assert!(renumber_command_long(&mut frame, 31_999));
    assert_eq!(unknown_commands(&frame)[0].command, 31_999);
}
