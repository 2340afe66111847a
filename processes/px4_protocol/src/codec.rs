//! MAVLink frames in and out of datagrams (both ends of the link use it: px4-link and
//! the simulator's autopilot).

use mavlink::dialects::common::MavMessage;
use mavlink::{MavHeader, MavlinkReader};

use crate::signing::{Refused, Signer};

/// Decodes every MAVLink (1 or 2) frame in one datagram into `out`, with no checks but
/// the checksum (a tool's reading); returns how many runs of bytes failed to parse.
pub fn decode_datagram(data: &[u8], out: &mut Vec<(MavHeader, MavMessage)>) -> u64 {
    let mut d = StreamDecoder::new();
    d.push_datagram(data, 0, &mut Guard::open(), out)
}

/// Frames refused, by reason: what a link shows of the traffic it did not act on.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Rejections {
    /// From a system or component other than the peer's.
    pub wrong_source: u64,
    /// Of a message id this dialect does not know.
    pub unknown_id: u64,
    /// Unsigned on a signed link.
    pub unsigned: u64,
    /// A signature that does not match.
    pub bad_signature: u64,
    /// A signed frame played again (not newer than its stream's last).
    pub replayed: u64,
}

/// What a link accepts: frames from one peer (system and component), and, with a
/// signer, only frames signed with its key. Everything else is counted and dropped.
#[derive(Debug, Clone, Default)]
pub struct Guard {
    peer: Option<(u8, u8)>,
    signer: Option<Signer>,
    rejected: Rejections,
}

impl Guard {
    /// Accepts every frame with a good checksum.
    pub fn open() -> Self {
        Self::default()
    }

    /// Accepts frames from `peer` (system, component) only, signed by `signer` when
    /// there is one.
    pub fn new(peer: Option<(u8, u8)>, signer: Option<Signer>) -> Self {
        Self {
            peer,
            signer,
            rejected: Rejections::default(),
        }
    }

    /// Frames refused so far.
    pub fn rejected(&self) -> Rejections {
        self.rejected
    }

    /// The signer, when the link is signed.
    pub fn signer(&self) -> Option<&Signer> {
        self.signer.as_ref()
    }

    /// Turns signing on with `signer` (a key installed by SETUP_SIGNING).
    pub fn set_signer(&mut self, signer: Signer) {
        self.signer = Some(signer);
    }

    /// Encodes `msg` from `header` as one MAVLink 2 frame appended to `buf`, signed when
    /// the link is.
    pub fn encode(
        &mut self,
        buf: &mut Vec<u8>,
        header: MavHeader,
        msg: &MavMessage,
        now_ns: u64,
    ) -> Result<(), mavlink::error::MessageWriteError> {
        let start = buf.len();
        encode(buf, header, msg)?;
        if let Some(s) = self.signer.as_mut() {
            let extra =
                <MavMessage as mavlink::Message>::extra_crc(mavlink::Message::message_id(msg));
            s.sign_from(buf, start, extra, now_ns);
        }
        Ok(())
    }

    /// Signs a raw unsigned MAVLink 2 frame (one the dialect cannot express, see
    /// [`crate::raw`]) whose message has `crc_extra`, when the link is signed.
    pub fn sign_raw(&mut self, frame: &mut Vec<u8>, crc_extra: u8, now_ns: u64) {
        if let Some(s) = self.signer.as_mut() {
            s.sign(frame, crc_extra, now_ns);
        }
    }

    /// Turns signing off (SETUP_SIGNING with a blank key, itself signed).
    pub fn clear_signer(&mut self) {
        self.signer = None;
    }

    /// Whether the whole frame `frame` (checksum good, message `id`) may be acted on.
    fn admit(&mut self, frame: &[u8], id: u32, now_ns: u64) -> bool {
        if let Some(s) = self.signer.as_mut() {
            match s.verify(frame, id, now_ns) {
                Ok(()) => {}
                Err(Refused::Unsigned) => {
                    self.rejected.unsigned += 1;
                    return false;
                }
                Err(Refused::BadSignature) => {
                    self.rejected.bad_signature += 1;
                    return false;
                }
                Err(Refused::Replayed) => {
                    self.rejected.replayed += 1;
                    return false;
                }
            }
        }
        let source = match frame.first() {
            Some(&STX_V2) => (frame.get(5), frame.get(6)),
            _ => (frame.get(3), frame.get(4)),
        };
        if let (Some(peer), (Some(&sys), Some(&comp))) = (self.peer, source)
            && (sys, comp) != peer
        {
            self.rejected.wrong_source += 1;
            return false;
        }
        true
    }
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
    /// Admitted frames of a known id the dialect could not read (a command number it
    /// lacks), for the caller's raw reading.
    undecoded: Vec<Vec<u8>>,
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

    /// Admitted frames the dialect could not read since the last call (a COMMAND_LONG
    /// with a command number it lacks), whole.
    pub fn take_undecoded(&mut self) -> Vec<Vec<u8>> {
        std::mem::take(&mut self.undecoded)
    }

    /// Decodes one datagram of whole frames: [`Self::push`], then whatever is left
    /// over (a frame cut short) is an error, not the start of the next datagram.
    pub fn push_datagram(
        &mut self,
        bytes: &[u8],
        now_ns: u64,
        guard: &mut Guard,
        out: &mut Vec<(MavHeader, MavMessage)>,
    ) -> u64 {
        let mut errors = self.push(bytes, now_ns, guard, out);
        if !self.buf.is_empty() {
            self.buf.clear();
            if !self.skipping {
                self.parse_errors += 1;
                errors += 1;
            }
        }
        self.skipping = false;
        errors
    }

    /// Appends `bytes` and decodes every complete frame `guard` admits into `out`,
    /// oldest first; returns how many parse errors this call found. An incomplete frame
    /// waits for the next call.
    pub fn push(
        &mut self,
        bytes: &[u8],
        now_ns: u64,
        guard: &mut Guard,
        out: &mut Vec<(MavHeader, MavMessage)>,
    ) -> u64 {
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
                    guard.rejected.unknown_id += 1;
                    self.skipping = false;
                    start += len;
                }
                Candidate::Frame(len, id) => {
                    let frame = &self.buf[start..start + len];
                    self.skipping = false;
                    start += len;
                    if !guard.admit(frame, id, now_ns) {
                        continue;
                    }
                    match MavlinkReader::new(frame).read_any_message::<MavMessage>() {
                        Ok(m) => out.push(m),
                        Err(e) => {
                            // Checksum good, fields not: a value the dialect lacks.
                            tracing::debug!(error = %e, "MAVLink frame not readable");
                            self.parse_errors += 1;
                            if self.undecoded.len() < 64 {
                                self.undecoded.push(frame.to_vec());
                            }
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
                Candidate::Frame(len_needed, id)
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
    /// A complete frame of a known message with a good CRC, this long, of this id.
    Frame(usize, u32),
    /// A frame of a message the dialect does not know, this long.
    Unknown(usize),
}

#[cfg(test)]
#[path = "codec_test.rs"]
mod tests;
