//! MAVLink 2 message signing (mavlink.io/en/guide/message_signing.html), as PX4 does
//! it (`mavlink_sign_control.cpp`): a 32-byte secret shared by the companion and the
//! autopilot; every frame carries a link id, a 48-bit timestamp (10 us since
//! 2015-01-01) and the first 6 bytes of SHA-256(key, frame, link id, timestamp).
//! A receiver keeps the newest timestamp of each stream (system, component, link id)
//! and refuses anything not newer, so a recorded frame played again is refused.
//!
//! Time comes in as the caller's monotonic `now_ns` plus the Unix time at its zero,
//! given once: the signer reads no clock.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

/// Bytes of a signing key.
pub const KEY_LEN: usize = 32;
/// Bytes of the signature block: link id, timestamp (6), signature (6).
pub const SIGNATURE_LEN: usize = 13;
/// Messages PX4 accepts unsigned on a signed link (`unsigned_messages[]` in
/// `mavlink_sign_control.cpp`): RADIO_STATUS, ADSB_VEHICLE, COLLISION.
pub const UNSIGNED_ALLOWED: [u32; 3] = [109, 246, 247];
/// 2015-01-01T00:00:00Z, the signing timestamp's zero, in Unix seconds.
const EPOCH_UNIX_S: u64 = 1_420_070_400;
/// A new stream's first timestamp may lag ours by at most this (1 minute, in 10 us).
const NEW_STREAM_MAX_AGE: u64 = 6_000_000;
/// Streams remembered at most (MAVLink's C library keeps 16); a new stream beyond them
/// is refused.
const MAX_STREAMS: usize = 64;
/// MAVLink 2 start byte and the signed flag.
const STX_V2: u8 = 0xFD;
const IFLAG_SIGNED: u8 = 0x01;

/// The shared secret.
#[derive(Clone, PartialEq, Eq)]
pub struct SigningKey([u8; KEY_LEN]);

impl std::fmt::Debug for SigningKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Never printed: logs and error lines are not for secrets.
        f.write_str("SigningKey(..)")
    }
}

/// Why a key file cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum KeyError {
    /// It cannot be read.
    #[error("signing key {path}: {error}")]
    Read {
        /// The file.
        path: PathBuf,
        /// What the system said.
        error: std::io::Error,
    },
    /// Others than its owner may read or write it.
    #[error(
        "signing key {path}: mode {mode:o} lets others than its owner read or write it (allowed: 600 or 400; chmod 600 {path})"
    )]
    Permissions {
        /// The file.
        path: PathBuf,
        /// Its permission bits.
        mode: u32,
    },
    /// Not 32 bytes, raw or as 64 hex digits.
    #[error("signing key {path}: {what} (allowed: 32 raw bytes, or 64 hex digits)")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        what: String,
    },
    /// All zeros: PX4 reads that as "signing off".
    #[error("signing key {path}: all zeros, which PX4 reads as signing off")]
    Zero {
        /// The file.
        path: PathBuf,
    },
}

impl SigningKey {
    /// A key of these bytes.
    pub fn from_bytes(bytes: [u8; KEY_LEN]) -> Self {
        Self(bytes)
    }

    /// The key's bytes (for SETUP_SIGNING).
    pub fn bytes(&self) -> &[u8; KEY_LEN] {
        &self.0
    }

    /// The key in `path`: 32 raw bytes or 64 hex digits (a trailing newline allowed),
    /// in a file only its owner may read or write.
    pub fn load(path: &Path) -> Result<Self, KeyError> {
        use std::os::unix::fs::PermissionsExt;
        let read = |error| KeyError::Read {
            path: path.to_path_buf(),
            error,
        };
        let mode = std::fs::metadata(path).map_err(read)?.permissions().mode() & 0o777;
        if mode & 0o077 != 0 {
            return Err(KeyError::Permissions {
                path: path.to_path_buf(),
                mode,
            });
        }
        let bytes = std::fs::read(path).map_err(read)?;
        let format = |what: String| KeyError::Format {
            path: path.to_path_buf(),
            what,
        };
        let key: [u8; KEY_LEN] = if bytes.len() == KEY_LEN {
            bytes
                .try_into()
                .map_err(|_| format("not 32 bytes".into()))?
        } else {
            let text = std::str::from_utf8(&bytes)
                .map_err(|_| format(format!("{} bytes, not text", bytes.len())))?
                .trim_end();
            if text.len() != 2 * KEY_LEN {
                return Err(format(format!("{} characters", text.len())));
            }
            let mut key = [0u8; KEY_LEN];
            for (i, k) in key.iter_mut().enumerate() {
                let digits = text.get(2 * i..2 * i + 2).unwrap_or("");
                *k = u8::from_str_radix(digits, 16)
                    .map_err(|_| format(format!("`{digits}` is not a hex byte")))?;
            }
            key
        };
        if key == [0; KEY_LEN] {
            return Err(KeyError::Zero {
                path: path.to_path_buf(),
            });
        }
        Ok(Self(key))
    }

    /// Writes the key to `path` as 64 hex digits, readable and writable by its owner
    /// only (created so: never a moment with wider permissions).
    pub fn save(&self, path: &Path) -> std::io::Result<()> {
        use std::io::Write;
        use std::os::unix::fs::{OpenOptionsExt, PermissionsExt};
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .create(true)
            .truncate(true)
            .mode(0o600)
            .open(path)?;
        // An existing file keeps its mode on open: narrow it.
        f.set_permissions(std::fs::Permissions::from_mode(0o600))?;
        let hex: String = self.0.iter().map(|b| format!("{b:02x}")).collect();
        writeln!(f, "{hex}")
    }
}

/// The signing timestamp (10 us since 2015-01-01) of a Unix time in ns.
pub fn timestamp_of_unix_ns(unix_ns: u64) -> u64 {
    unix_ns.saturating_sub(EPOCH_UNIX_S * 1_000_000_000) / 10_000
}

/// Why a frame was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refused {
    /// Unsigned, and not a message allowed unsigned.
    Unsigned,
    /// The signature does not match (another key, or altered bytes), or a new stream
    /// when too many are known.
    BadSignature,
    /// Not newer than the stream's last, or a new stream more than a minute old: a
    /// frame played again.
    Replayed,
}

/// Signs what one end sends and checks what it receives.
#[derive(Debug, Clone)]
pub struct Signer {
    key: SigningKey,
    link_id: u8,
    unix_ns_at_zero: u64,
    /// The newest timestamp used or accepted.
    timestamp: u64,
    streams: HashMap<(u8, u8, u8), u64>,
}

impl Signer {
    /// A signer with `key`, signing as `link_id`; `unix_ns_at_zero` is the Unix time,
    /// ns, at the caller's `now_ns` = 0.
    pub fn new(key: SigningKey, link_id: u8, unix_ns_at_zero: u64) -> Self {
        Self {
            key,
            link_id,
            unix_ns_at_zero,
            timestamp: 0,
            streams: HashMap::new(),
        }
    }

    /// Starts the timestamps no earlier than `timestamp` (SETUP_SIGNING's
    /// initial_timestamp).
    pub fn advance_to(&mut self, timestamp: u64) {
        self.timestamp = self.timestamp.max(timestamp);
    }

    /// The key.
    pub fn key(&self) -> &SigningKey {
        &self.key
    }

    /// The current timestamp at `now_ns`: the clock's, or the newest seen if later.
    pub fn timestamp(&self, now_ns: u64) -> u64 {
        timestamp_of_unix_ns(self.unix_ns_at_zero.saturating_add(now_ns)).max(self.timestamp)
    }

    fn signature(&self, frame: &[u8], link_id: u8, timestamp: &[u8]) -> [u8; 6] {
        let mut h = Sha256::new();
        h.update(self.key.0);
        h.update(frame);
        h.update([link_id]);
        h.update(timestamp);
        let d = h.finalize();
        let mut sig = [0u8; 6];
        sig.copy_from_slice(&d[..6]);
        sig
    }

    /// Signs the unsigned MAVLink 2 frame `frame` (as `codec::encode` writes it; its
    /// message's CRC_EXTRA is `crc_extra`) in place: sets the signed flag, redoes the
    /// checksum and appends the signature block. False (the frame untouched) when it
    /// is not such a frame.
    pub fn sign(&mut self, frame: &mut Vec<u8>, crc_extra: u8, now_ns: u64) -> bool {
        self.sign_from(frame, 0, crc_extra, now_ns)
    }

    /// [`Self::sign`] for the frame that starts at `start` in `buf` (the last one
    /// appended): signed where it lies, without a copy.
    pub fn sign_from(
        &mut self,
        buf: &mut Vec<u8>,
        start: usize,
        crc_extra: u8,
        now_ns: u64,
    ) -> bool {
        let Some(frame) = buf.get_mut(start..) else {
            return false;
        };
        let n = frame.len();
        let ok = n >= 12
            && frame[0] == STX_V2
            && frame[2] & IFLAG_SIGNED == 0
            && n == 12 + usize::from(frame[1]);
        if !ok {
            return false;
        }
        frame[2] |= IFLAG_SIGNED;
        let crc = crate::raw::frame_crc(&frame[1..n - 2], crc_extra);
        frame[n - 2..].copy_from_slice(&crc.to_le_bytes());
        let ts = self.timestamp(now_ns).max(self.timestamp.saturating_add(1));
        self.timestamp = ts;
        let ts_bytes = &ts.to_le_bytes()[..6];
        let sig = self.signature(frame, self.link_id, ts_bytes);
        buf.push(self.link_id);
        buf.extend_from_slice(ts_bytes);
        buf.extend_from_slice(&sig);
        true
    }

    /// Checks one whole frame whose checksum is good (MAVLink 1 or 2) received at
    /// `now_ns`; `msg_id` is its message id.
    pub fn verify(&mut self, frame: &[u8], msg_id: u32, now_ns: u64) -> Result<(), Refused> {
        let signed = frame.len() > SIGNATURE_LEN
            && frame[0] == STX_V2
            && frame.get(2).is_some_and(|f| f & IFLAG_SIGNED != 0);
        if !signed {
            return if UNSIGNED_ALLOWED.contains(&msg_id) {
                Ok(())
            } else {
                Err(Refused::Unsigned)
            };
        }
        let (body, block) = frame.split_at(frame.len() - SIGNATURE_LEN);
        let link_id = block[0];
        let ts_bytes = &block[1..7];
        let mut ts8 = [0u8; 8];
        ts8[..6].copy_from_slice(ts_bytes);
        let ts = u64::from_le_bytes(ts8);
        if self.signature(body, link_id, ts_bytes) != block[7..13] {
            return Err(Refused::BadSignature);
        }
        let stream = (frame[5], frame[6], link_id);
        match self.streams.get(&stream) {
            Some(&last) if ts <= last => return Err(Refused::Replayed),
            Some(_) => {}
            None => {
                if ts.saturating_add(NEW_STREAM_MAX_AGE) < self.timestamp(now_ns) {
                    return Err(Refused::Replayed);
                }
                if self.streams.len() >= MAX_STREAMS {
                    return Err(Refused::BadSignature);
                }
            }
        }
        self.streams.insert(stream, ts);
        self.timestamp = self.timestamp.max(ts);
        Ok(())
    }
}

#[cfg(test)]
#[path = "signing_test.rs"]
mod tests;
