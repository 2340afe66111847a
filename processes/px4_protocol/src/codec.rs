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

/// MAVLink 1 start marker.
const STX_V1: u8 = 0xFE;
/// MAVLink 2 start marker.
const STX_V2: u8 = 0xFD;
/// MAVLink 2 incompat flag: the frame carries a 13-byte signature.
const IFLAG_SIGNED: u8 = 0x01;
/// Most bytes a buffered partial frame can need (MAVLink 2, signed, 255-byte payload).
const MAX_FRAME: usize = 10 + 255 + 2 + 13;

/// MAVLink frames out of a byte stream (a serial port), where frames arrive split across
/// reads and a line can carry noise: bytes are buffered until a frame is complete, and
/// bytes that are not a frame are skipped until the next frame start that checks out
/// (its CRC or, for a message this dialect does not know, the next frame start right
/// after it).
#[derive(Debug, Default, Clone)]
pub struct StreamDecoder {
    buf: Vec<u8>,
    skipping: bool,
    parse_errors: u64,
    unknown: u64,
}

impl StreamDecoder {
    /// A decoder that has seen nothing.
    pub fn new() -> Self {
        Self::default()
    }

    /// Runs of bytes skipped because they were not a valid frame (noise, a frame with a
    /// wrong CRC, a cut frame), each run counted once.
    pub fn parse_errors(&self) -> u64 {
        self.parse_errors
    }

    /// Well-formed frames of messages this dialect does not know, skipped whole (PX4 may
    /// send messages from its development dialect: they are not errors).
    pub fn unknown_messages(&self) -> u64 {
        self.unknown
    }

    /// Appends `bytes` and decodes every complete frame into `out`, oldest first;
    /// returns how many parse errors this call found. An incomplete frame waits for the
    /// next call.
    pub fn push(&mut self, bytes: &[u8], out: &mut Vec<(MavHeader, MavMessage)>) -> u64 {
        self.buf.extend_from_slice(bytes);
        let before = self.parse_errors;
        let mut start = 0;
        while start < self.buf.len() {
            let rest = &self.buf[start..];
            let Some(at) = rest.iter().position(|&b| b == STX_V1 || b == STX_V2) else {
                self.skip();
                start = self.buf.len();
                break;
            };
            if at > 0 {
                self.skip();
                start += at;
                continue;
            }
            match self.candidate(start) {
                Candidate::Incomplete => break,
                Candidate::Garbage => {
                    self.skip();
                    start += 1;
                }
                Candidate::Unknown(len) => {
                    self.unknown += 1;
                    self.skipping = false;
                    start += len;
                }
                Candidate::Frame(len) => {
                    let frame = &self.buf[start..start + len];
                    match MavlinkReader::new(frame).read_any_message::<MavMessage>() {
                        Ok(m) => {
                            out.push(m);
                            self.skipping = false;
                            start += len;
                        }
                        Err(e) => {
                            tracing::debug!(error = %e, "MAVLink frame rejected");
                            self.skip();
                            start += 1;
                        }
                    }
                }
            }
        }
        self.buf.drain(..start.min(self.buf.len()));
        self.parse_errors - before
    }

    fn skip(&mut self) {
        if !self.skipping {
            self.skipping = true;
            self.parse_errors += 1;
        }
    }

    /// What the bytes at `start` (a start marker) are.
    fn candidate(&self, start: usize) -> Candidate {
        let b = &self.buf[start..];
        let (id, crc_at, len_needed) = match b[0] {
            STX_V2 => {
                if b.len() < 10 {
                    return Candidate::Incomplete;
                }
                if b[2] & !IFLAG_SIGNED != 0 {
                    // MAVLink 2: a frame with an incompatibility flag we do not know must
                    // be dropped; here it is more likely noise.
                    return Candidate::Garbage;
                }
                let signature = if b[2] & IFLAG_SIGNED != 0 { 13 } else { 0 };
                let id = u32::from_le_bytes([b[7], b[8], b[9], 0]);
                let crc_at = 10 + usize::from(b[1]);
                (id, crc_at, crc_at + 2 + signature)
            }
            _ => {
                if b.len() < 6 {
                    return Candidate::Incomplete;
                }
                let crc_at = 6 + usize::from(b[1]);
                (u32::from(b[5]), crc_at, crc_at + 2)
            }
        };
        debug_assert!(len_needed <= MAX_FRAME);
        if b.len() < len_needed {
            return Candidate::Incomplete;
        }
        if <MavMessage as mavlink::Message>::default_message_from_id(id).is_some() {
            // Checked here, on exactly these bytes: the reader would skip a bad frame and
            // return a later one, hiding both the error and where the next frame starts.
            let extra = <MavMessage as mavlink::Message>::extra_crc(id);
            let crc = mavlink::calculate_crc(&b[1..crc_at], extra);
            return if crc.to_le_bytes() == [b[crc_at], b[crc_at + 1]] {
                Candidate::Frame(len_needed)
            } else {
                Candidate::Garbage
            };
        }
        // An id we do not know: cannot check its CRC. It is a frame if another frame
        // starts right after it; otherwise (most likely noise) resynchronise byte by byte.
        match b.get(len_needed) {
            None => Candidate::Incomplete,
            Some(&next) if next == STX_V1 || next == STX_V2 => Candidate::Unknown(len_needed),
            Some(_) => Candidate::Garbage,
        }
    }
}

enum Candidate {
    /// More bytes are needed to tell.
    Incomplete,
    /// Not a frame start.
    Garbage,
    /// A complete frame of a known message with a good CRC, this long.
    Frame(usize),
    /// A frame of a message the dialect does not know, this long.
    Unknown(usize),
}

#[cfg(test)]
#[path = "codec_test.rs"]
mod tests;
