//! MAVLink 2 frames the `mavlink` crate cannot express: a COMMAND_LONG whose command
//! number is not in the common dialect fails to parse there, and a COMMAND_ACK for it
//! cannot be built there. PX4 answers such a command MAV_RESULT_UNSUPPORTED
//! (Commander::handle_command's `default:` branch), so the simulator's endpoint reads
//! and writes those two frames itself, and its tests write such a command.

use mavlink::MavlinkVersion;
use mavlink::dialects::common::MavMessage;
use mavlink::error::ParserError;

/// MAVLink 2 start byte.
const STX_V2: u8 = 0xFD;
/// Header bytes after the start byte (len, flags, seq, sys, comp, msgid x3).
const HEADER_LEN: usize = 9;
/// The incompat flag of a signed frame (13 signature bytes follow the checksum).
const SIGNED: u8 = 0x01;
/// COMMAND_LONG's id, wire length and CRC_EXTRA.
const COMMAND_LONG_ID: u32 = 76;
const COMMAND_LONG_LEN: usize = 33;
const COMMAND_LONG_CRC_EXTRA: u8 = 152;
/// COMMAND_ACK's id and CRC_EXTRA.
const COMMAND_ACK_ID: u32 = 77;
/// COMMAND_ACK's CRC_EXTRA (to sign a raw ACK frame).
pub const COMMAND_ACK_CRC_EXTRA: u8 = 143;

/// A COMMAND_LONG whose command number the dialect does not know.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UnknownCommand {
    /// Sender's system id.
    pub sender_system: u8,
    /// Sender's component id.
    pub sender_component: u8,
    /// The command number.
    pub command: u16,
    /// Its target system.
    pub target_system: u8,
    /// Its target component.
    pub target_component: u8,
}

/// MAVLink's checksum (CRC-16/MCRF4XX) over `bytes`, continuing from `crc`.
pub fn crc_accumulate(mut crc: u16, bytes: &[u8]) -> u16 {
    for &b in bytes {
        let mut tmp = b ^ (crc & 0xff) as u8;
        tmp ^= tmp << 4;
        let t = u16::from(tmp);
        crc = (crc >> 8) ^ (t << 8) ^ (t << 3) ^ (t >> 4);
    }
    crc
}

/// The checksum of a frame: header (without the start byte), payload, CRC_EXTRA.
pub(crate) fn frame_crc(header_and_payload: &[u8], crc_extra: u8) -> u16 {
    crc_accumulate(crc_accumulate(0xffff, header_and_payload), &[crc_extra])
}

/// Gives an unsigned MAVLink 2 COMMAND_LONG `frame` (as `mavlink::write_v2_msg` writes
/// one) the command number `number`, which the dialect may lack, and redoes its checksum;
/// false (and `frame` unchanged) when `frame` is not such a frame.
pub fn renumber_command_long(frame: &mut [u8], number: u16) -> bool {
    let n = frame.len();
    let payload_len = frame.get(1).map_or(0, |&l| usize::from(l));
    let is_command_long = n >= 1 + HEADER_LEN + 30 + 2
        && frame[0] == STX_V2
        && frame[2] & SIGNED == 0
        && n == 1 + HEADER_LEN + payload_len + 2
        && u32::from_le_bytes([frame[7], frame[8], frame[9], 0]) == COMMAND_LONG_ID;
    if !is_command_long {
        return false;
    }
    // The command is payload bytes 28-29 (after the seven f32 parameters).
    let at = 1 + HEADER_LEN + 28;
    frame[at..at + 2].copy_from_slice(&number.to_le_bytes());
    let crc = frame_crc(&frame[1..n - 2], COMMAND_LONG_CRC_EXTRA);
    frame[n - 2..].copy_from_slice(&crc.to_le_bytes());
    true
}

/// Every well-formed MAVLink 2 COMMAND_LONG in `datagram` whose command number the
/// dialect does not know (frames with a bad checksum are skipped).
pub fn unknown_commands(datagram: &[u8]) -> Vec<UnknownCommand> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < datagram.len() {
        if datagram[i] != STX_V2 {
            i += 1;
            continue;
        }
        let Some(header) = datagram.get(i + 1..i + 1 + HEADER_LEN) else {
            break;
        };
        let len = usize::from(header[0]);
        let signature = if header[1] & SIGNED != 0 { 13 } else { 0 };
        let end = i + 1 + HEADER_LEN + len + 2;
        let Some(frame) = datagram.get(i..end) else {
            break;
        };
        let msgid = u32::from(header[6]) | u32::from(header[7]) << 8 | u32::from(header[8]) << 16;
        let body = &frame[1..1 + HEADER_LEN + len];
        let crc = u16::from_le_bytes([frame[end - i - 2], frame[end - i - 1]]);
        if msgid != COMMAND_LONG_ID || frame_crc(body, COMMAND_LONG_CRC_EXTRA) != crc {
            i += 1;
            continue;
        }
        let payload = &body[HEADER_LEN..];
        if let Err(ParserError::InvalidEnum { enum_type, .. }) =
            <MavMessage as mavlink::Message>::parse(MavlinkVersion::V2, msgid, payload)
            && enum_type == "MavCmd"
        {
            // MAVLink 2 drops trailing zero bytes: put them back.
            let mut p = [0u8; COMMAND_LONG_LEN];
            let n = payload.len().min(COMMAND_LONG_LEN);
            p[..n].copy_from_slice(&payload[..n]);
            out.push(UnknownCommand {
                sender_system: header[4],
                sender_component: header[5],
                command: u16::from_le_bytes([p[28], p[29]]),
                target_system: p[30],
                target_component: p[31],
            });
        }
        i = end + signature;
    }
    out
}

/// A MAVLink 2 COMMAND_ACK frame for `command` (any number) from `system`/`component`
/// with `sequence`, answering `to`'s sender.
pub fn command_ack_frame(
    sequence: u8,
    system: u8,
    component: u8,
    to: &UnknownCommand,
    result: u8,
) -> Vec<u8> {
    // Wire order: command, result, then the extensions progress, result_param2,
    // target_system, target_component.
    let [c0, c1] = to.command.to_le_bytes();
    let mut payload = vec![
        c0,
        c1,
        result,
        0,
        0,
        0,
        0,
        0,
        to.sender_system,
        to.sender_component,
    ];
    while payload.len() > 1 && payload.last() == Some(&0) {
        payload.pop();
    }
    let [m0, m1, m2, _] = COMMAND_ACK_ID.to_le_bytes();
    let mut frame = vec![
        STX_V2,
        payload.len() as u8,
        0,
        0,
        sequence,
        system,
        component,
        m0,
        m1,
        m2,
    ];
    frame.extend_from_slice(&payload);
    let crc = frame_crc(&frame[1..], COMMAND_ACK_CRC_EXTRA);
    frame.extend_from_slice(&crc.to_le_bytes());
    frame
}

#[cfg(test)]
#[path = "raw_test.rs"]
mod tests;
