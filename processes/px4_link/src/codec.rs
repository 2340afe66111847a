//! MAVLink frames in and out of datagrams (both ends of the link use it: px4-link and
//! the simulator's autopilot).

use mavlink::dialects::common::MavMessage;
use mavlink::error::MessageReadError;
use mavlink::{MavHeader, MavlinkReader};

/// Decodes every MAVLink (1 or 2) frame in one datagram into `out`; returns how many
/// frames failed to parse. Bytes that are not a frame are skipped.
pub fn decode_datagram(data: &[u8], out: &mut Vec<(MavHeader, MavMessage)>) -> u64 {
    let mut reader = MavlinkReader::new(data);
    let mut errors = 0;
    // Each iteration consumes at least one frame or ends the datagram; the bound only
    // guards against a decoder that would not advance.
    for _ in 0..=data.len() {
        match reader.read_any_message::<MavMessage>() {
            Ok(m) => out.push(m),
            Err(MessageReadError::Parse(e)) => {
                errors += 1;
                tracing::debug!(error = %e, "MAVLink parse error");
            }
            Err(_) => break,
        }
    }
    errors
}

/// One MAVLink 2 frame of `msg` from `header`, appended to `buf`.
pub fn encode(
    buf: &mut Vec<u8>,
    header: MavHeader,
    msg: &MavMessage,
) -> Result<(), mavlink::error::MessageWriteError> {
    mavlink::write_v2_msg(buf, header, msg).map(|_| ())
}
