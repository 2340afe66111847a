//! Reading a recording back: record by record, so that a file cut short (the recorder
//! killed, the disk full) or damaged reads up to the damage, and the damage is named by
//! its byte offset. `landing mcap info`, `landing latency`, `landing plot` and `landing
//! replay` read through [`read_messages`].
//!
//! The walk frames the file's top-level records itself (opcode, length, body) so that
//! every offset is exact, and opens chunks with the mcap crate's chunk reader.

use std::borrow::Cow;
use std::collections::{BTreeMap, HashMap};
use std::fmt;
use std::path::{Path, PathBuf};

use mcap::records::Record;
use serde::Serialize;

/// The 8 bytes an MCAP file starts and ends with.
const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";
/// Footer opcode.
const OP_FOOTER: u8 = 0x02;
/// The highest opcode the MCAP specification defines.
const OP_MAX: u8 = 0x0F;
/// Record opcodes the reader parses; every other record is skipped unread (indexes,
/// statistics, attachments: nothing the messages need).
const OP_SCHEMA: u8 = 0x03;
const OP_CHANNEL: u8 = 0x04;
const OP_MESSAGE: u8 = 0x05;
const OP_CHUNK: u8 = 0x06;
const OP_METADATA: u8 = 0x0C;
/// The largest chunk the reader unpacks, bytes: a header may claim any size, and
/// memory is given only to what the file can hold (the recorder's chunks are a few MB).
const CHUNK_MAX: u64 = 256 << 20;

/// Walks the length-prefixed fields of a record body (MCAP's layout), so that no field
/// claims more bytes than the record holds: the parser allocates what a length says
/// before it reads, and a crafted 4 kB file must not ask for gigabytes.
struct Fields<'a> {
    body: &'a [u8],
    at: usize,
}

impl<'a> Fields<'a> {
    fn new(body: &'a [u8]) -> Self {
        Self { body, at: 0 }
    }

    fn take(&mut self, n: u64, what: &str) -> Result<&'a [u8], String> {
        let end = usize::try_from(n)
            .ok()
            .and_then(|n| self.at.checked_add(n))
            .filter(|&e| e <= self.body.len())
            .ok_or_else(|| {
                format!(
                    "corrupted: {what} of {n} bytes in a record with {} left",
                    self.body.len() - self.at
                )
            })?;
        let s = &self.body[self.at..end];
        self.at = end;
        Ok(s)
    }

    fn fixed(&mut self, n: u64) -> Result<(), String> {
        self.take(n, "a field").map(|_| ())
    }

    fn u32(&mut self) -> Result<u64, String> {
        let b = self.take(4, "a length")?;
        Ok(u64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])))
    }

    fn u64(&mut self) -> Result<u64, String> {
        let b = self.take(8, "a length")?;
        let mut a = [0u8; 8];
        a.copy_from_slice(b);
        Ok(u64::from_le_bytes(a))
    }

    /// A string or byte array with a u32 length.
    fn prefixed(&mut self, what: &str) -> Result<&'a [u8], String> {
        let n = self.u32()?;
        self.take(n, what)
    }

    /// A map of strings to strings (u32 byte length, then pairs).
    fn string_map(&mut self) -> Result<(), String> {
        let bytes = self.prefixed("a map")?;
        let mut m = Fields::new(bytes);
        while m.at < bytes.len() {
            m.prefixed("a map key")?;
            m.prefixed("a map value")?;
        }
        Ok(())
    }
}

/// Checks that every length in a record the reader parses fits in it.
fn fields_fit(opcode: u8, body: &[u8]) -> Result<(), String> {
    let mut f = Fields::new(body);
    match opcode {
        OP_SCHEMA => {
            f.fixed(2)?;
            f.prefixed("a schema name")?;
            f.prefixed("a schema encoding")?;
            f.prefixed("schema data")?;
        }
        OP_CHANNEL => {
            f.fixed(4)?;
            f.prefixed("a topic")?;
            f.prefixed("a message encoding")?;
            f.string_map()?;
        }
        OP_MESSAGE => f.fixed(2 + 4 + 8 + 8)?,
        OP_METADATA => {
            f.prefixed("a metadata name")?;
            f.string_map()?;
        }
        OP_CHUNK => {
            f.fixed(16)?;
            let size = f.u64()?;
            if size > CHUNK_MAX {
                return Err(format!(
                    "corrupted: a chunk claims {size} bytes unpacked (at most {CHUNK_MAX} read)"
                ));
            }
            f.fixed(4)?;
            f.prefixed("a compression name")?;
            let n = f.u64()?;
            f.take(n, "chunk records")?;
        }
        _ => {}
    }
    Ok(())
}

/// A chunk's records, unpacked (at most its declared size, itself bounded) and checked
/// against its CRC (0: none written).
fn unpack(compression: &str, data: &[u8], size: u64, crc: u32) -> Result<Vec<u8>, String> {
    use std::io::Read;
    let mut out = Vec::with_capacity(usize::try_from(size.min(16 << 20)).unwrap_or(0));
    let limit = size.saturating_add(1);
    let read = match compression {
        "" => {
            out.extend_from_slice(data);
            Ok(out.len())
        }
        "zstd" => {
            zstd::stream::read::Decoder::new(data).and_then(|d| d.take(limit).read_to_end(&mut out))
        }
        "lz4" => lz4::Decoder::new(data).and_then(|d| d.take(limit).read_to_end(&mut out)),
        other => {
            return Err(format!(
                "corrupted chunk: compression `{other}` (allowed: zstd, lz4, none)"
            ));
        }
    };
    read.map_err(|e| format!("corrupted chunk: {e}"))?;
    if out.len() as u64 != size {
        return Err(format!(
            "corrupted chunk: {} bytes unpacked, {size} declared",
            out.len()
        ));
    }
    if crc != 0 && crc32fast::hash(&out) != crc {
        return Err("corrupted chunk: its records do not match its CRC".into());
    }
    Ok(out)
}

/// The records of an unpacked chunk into `channels`, each checked as at the top level.
fn chunk_records(
    records: &[u8],
    channels: &mut Channels,
    summary: &mut ReadSummary,
    f: &mut dyn FnMut(&RecordedMessage<'_>),
) -> Result<(), String> {
    let mut pos = 0;
    while pos < records.len() {
        let Some(head) = records.get(pos..pos + 9) else {
            return Err("corrupted chunk: a record cut short".into());
        };
        let opcode = head[0];
        let mut n = [0u8; 8];
        n.copy_from_slice(&head[1..9]);
        let len = u64::from_le_bytes(n);
        let body = usize::try_from(len)
            .ok()
            .and_then(|l| (pos + 9).checked_add(l))
            .and_then(|end| records.get(pos + 9..end))
            .ok_or_else(|| format!("corrupted chunk: a record of {len} bytes past its end"))?;
        if matches!(opcode, OP_SCHEMA | OP_CHANNEL | OP_MESSAGE | OP_METADATA) {
            fields_fit(opcode, body)?;
            let r = mcap::parse_record(opcode, body)
                .map_err(|e| format!("corrupted record in a chunk (opcode 0x{opcode:02x}): {e}"))?;
            channels.take(r, summary, f)?;
        }
        pos += 9 + body.len();
    }
    Ok(())
}

/// Why a recording could not be read at all.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The file cannot be opened or read.
    #[error("cannot read the recording {}: {error}", path.display())]
    Open {
        /// The recording.
        path: PathBuf,
        /// What the OS said.
        error: std::io::Error,
    },
    /// The file does not start with the MCAP magic.
    #[error("{} is not an MCAP file (it does not start with the MCAP magic bytes)", path.display())]
    NotMcap {
        /// The file.
        path: PathBuf,
    },
}

/// Where and why a recording stops making sense.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Broken {
    /// Byte offset of the record that could not be read.
    pub offset: u64,
    /// File size, bytes.
    pub size: u64,
    /// What is wrong there.
    pub reason: String,
}

impl fmt::Display for Broken {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "broken at byte {} of {}: {}",
            self.offset, self.size, self.reason
        )
    }
}

/// One message as read back.
#[derive(Debug, Clone, Copy)]
pub struct RecordedMessage<'a> {
    /// The channel's topic.
    pub topic: &'a str,
    /// The channel's schema name ("" without one).
    pub schema: &'a str,
    /// The channel's message encoding (`json`, `protobuf`).
    pub encoding: &'a str,
    /// Log time, ns.
    pub log_time: u64,
    /// The writer's per-channel sequence number.
    pub sequence: u32,
    /// The encoded message.
    pub data: &'a [u8],
}

/// What a walk over a recording found besides its messages.
#[derive(Debug, Clone, Default)]
pub struct ReadSummary {
    /// Messages handed over.
    pub messages: u64,
    /// True when the file ends with its footer and the closing magic (finished).
    pub complete: bool,
    /// Where it broke, if it did.
    pub broken: Option<Broken>,
    /// Metadata records by name.
    pub metadata: BTreeMap<String, BTreeMap<String, String>>,
}

/// A channel as the walk knows it.
struct ChannelMeta {
    topic: String,
    schema: String,
    encoding: String,
}

/// Schemas and channels seen so far.
#[derive(Default)]
struct Channels {
    schemas: HashMap<u16, String>,
    channels: HashMap<u16, ChannelMeta>,
}

impl Channels {
    /// Takes a schema, channel or message record; a message goes to `f`.
    fn take(
        &mut self,
        record: Record<'_>,
        summary: &mut ReadSummary,
        f: &mut dyn FnMut(&RecordedMessage<'_>),
    ) -> Result<(), String> {
        match record {
            Record::Schema { header, .. } => {
                self.schemas.insert(header.id, header.name);
            }
            Record::Channel(c) => {
                let schema = self.schemas.get(&c.schema_id).cloned().unwrap_or_default();
                self.channels.insert(
                    c.id,
                    ChannelMeta {
                        topic: c.topic,
                        schema,
                        encoding: c.message_encoding,
                    },
                );
            }
            Record::Message { header, data } => {
                let c = self.channels.get(&header.channel_id).ok_or_else(|| {
                    format!(
                        "a message on channel {} before that channel was declared",
                        header.channel_id
                    )
                })?;
                summary.messages += 1;
                f(&RecordedMessage {
                    topic: &c.topic,
                    schema: &c.schema,
                    encoding: &c.encoding,
                    log_time: header.log_time,
                    sequence: header.sequence,
                    data: &data,
                });
            }
            Record::Metadata(m) => {
                summary.metadata.insert(m.name, m.metadata);
            }
            _ => {}
        }
        Ok(())
    }
}

/// Reads every message of the recording at `path`, in file order, into `f`. A file cut
/// short or damaged is read up to the damage, which the summary names; only a file that
/// cannot be opened or is not MCAP at all is an error.
pub fn read_messages(
    path: &Path,
    f: &mut dyn FnMut(&RecordedMessage<'_>),
) -> Result<ReadSummary, ReadError> {
    let buf = std::fs::read(path).map_err(|error| ReadError::Open {
        path: path.to_path_buf(),
        error,
    })?;
    read_buffer(&buf, f).ok_or_else(|| ReadError::NotMcap {
        path: path.to_path_buf(),
    })
}

/// [`read_messages`] over bytes in memory; `None` when they are not MCAP.
pub fn read_buffer(buf: &[u8], f: &mut dyn FnMut(&RecordedMessage<'_>)) -> Option<ReadSummary> {
    if buf.len() < MAGIC.len() || &buf[..MAGIC.len()] != MAGIC {
        return None;
    }
    let size = buf.len() as u64;
    let mut summary = ReadSummary::default();
    let mut channels = Channels::default();
    let mut pos = MAGIC.len();
    let broken = |offset: usize, reason: String| Broken {
        offset: offset as u64,
        size,
        reason,
    };
    loop {
        if pos == buf.len() {
            // Ends between records: the writer stopped before its summary.
            break;
        }
        if buf.len() - pos < 9 {
            summary.broken = Some(broken(
                pos,
                format!(
                    "truncated: {} bytes where a record's 9-byte opcode and length belong",
                    buf.len() - pos
                ),
            ));
            break;
        }
        let opcode = buf[pos];
        let mut len_bytes = [0u8; 8];
        len_bytes.copy_from_slice(&buf[pos + 1..pos + 9]);
        let len = u64::from_le_bytes(len_bytes);
        if opcode == 0 || opcode > OP_MAX {
            summary.broken = Some(broken(
                pos,
                format!("corrupted: opcode 0x{opcode:02x} is not an MCAP record"),
            ));
            break;
        }
        let body_start = pos + 9;
        let Some(end) = usize::try_from(len)
            .ok()
            .and_then(|l| body_start.checked_add(l))
            .filter(|e| *e <= buf.len())
        else {
            summary.broken = Some(broken(
                pos,
                format!(
                    "truncated: a record (opcode 0x{opcode:02x}) of {len} bytes, but the file ends {} bytes later",
                    buf.len() - body_start
                ),
            ));
            break;
        };
        let body = &buf[body_start..end];
        let parsed = matches!(
            opcode,
            OP_SCHEMA | OP_CHANNEL | OP_MESSAGE | OP_METADATA | OP_CHUNK
        );
        let result = if !parsed {
            Ok(())
        } else if let Err(e) = fields_fit(opcode, body) {
            Err(e)
        } else {
            match mcap::parse_record(opcode, body) {
                Err(e) => Err(format!("corrupted record (opcode 0x{opcode:02x}): {e}")),
                Ok(Record::Chunk { header, data }) => unpack(
                    &header.compression,
                    &data,
                    header.uncompressed_size,
                    header.uncompressed_crc,
                )
                .and_then(|records| chunk_records(&records, &mut channels, &mut summary, f)),
                Ok(r) => channels.take(r, &mut summary, f),
            }
        };
        if let Err(reason) = result {
            summary.broken = Some(broken(pos, reason));
            break;
        }
        pos = end;
        if opcode == OP_FOOTER {
            summary.complete = buf.len() - pos == MAGIC.len() && &buf[pos..] == MAGIC;
            if !summary.complete {
                summary.broken = Some(broken(
                    pos,
                    "corrupted: the footer is not followed by the closing magic".into(),
                ));
            }
            break;
        }
    }
    Some(summary)
}

/// What the recording at `path` holds: topics, counts and time range; a damaged file is
/// counted up to the damage, which `broken` names.
pub fn info(path: &Path) -> Result<RecordingInfo, ReadError> {
    let bytes = std::fs::metadata(path)
        .map_err(|error| ReadError::Open {
            path: path.to_path_buf(),
            error,
        })?
        .len();
    let mut by_topic: BTreeMap<String, ChannelInfo> = BTreeMap::new();
    let mut range: Option<(u64, u64)> = None;
    let summary = read_messages(path, &mut |m| {
        range = Some(match range {
            None => (m.log_time, m.log_time),
            Some((a, b)) => (a.min(m.log_time), b.max(m.log_time)),
        });
        by_topic
            .entry(m.topic.to_string())
            .or_insert_with(|| ChannelInfo {
                topic: m.topic.to_string(),
                schema: m.schema.to_string(),
                message_encoding: m.encoding.to_string(),
                count: 0,
            })
            .count += 1;
    })?;
    Ok(RecordingInfo {
        path: path.to_path_buf(),
        bytes,
        channels: by_topic.into_values().collect(),
        message_count: summary.messages,
        time_range_ns: range,
        complete: summary.complete,
        broken: summary.broken,
    })
}

/// One topic of a recording.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ChannelInfo {
    /// Topic name.
    pub topic: String,
    /// Schema name ("" without a schema).
    pub schema: String,
    /// Message encoding (e.g. "json").
    pub message_encoding: String,
    /// Messages on the topic.
    pub count: u64,
}

/// What a recording holds: topics, counts and time range.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RecordingInfo {
    /// The file.
    pub path: PathBuf,
    /// File size, bytes.
    pub bytes: u64,
    /// Topics, sorted by name.
    pub channels: Vec<ChannelInfo>,
    /// Messages in all.
    pub message_count: u64,
    /// Log time of the first and last message, ns (`None` without messages).
    pub time_range_ns: Option<(u64, u64)>,
    /// False when the file has no summary (not finished: the writer died); the counts
    /// then come from reading every message that is there.
    pub complete: bool,
    /// Where the file stops making sense, when it does (truncated or corrupted): what
    /// came before was read and counted.
    pub broken: Option<Broken>,
}

impl fmt::Display for RecordingInfo {
    /// A table for the terminal: file, time range, then one line per topic.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let size = if self.bytes >= 1_000_000 {
            format!("{:.1} MB", self.bytes as f64 / 1e6)
        } else {
            format!("{:.1} kB", self.bytes as f64 / 1e3)
        };
        writeln!(
            f,
            "file      {} ({size}){}",
            self.path.display(),
            if self.complete {
                ""
            } else {
                ", NOT FINISHED (no summary: the writer stopped; counted what is there)"
            }
        )?;
        let duration_s = match self.time_range_ns {
            Some((a, b)) => {
                writeln!(
                    f,
                    "time      {:.3} s .. {:.3} s ({:.3} s)",
                    a as f64 / 1e9,
                    b as f64 / 1e9,
                    (b - a) as f64 / 1e9
                )?;
                (b - a) as f64 / 1e9
            }
            None => {
                writeln!(f, "time      (no messages)")?;
                0.0
            }
        };
        writeln!(
            f,
            "messages  {} on {} topics",
            self.message_count,
            self.channels.len()
        )?;
        let w = self
            .channels
            .iter()
            .map(|c| c.topic.len())
            .max()
            .unwrap_or(5)
            .max(5);
        write!(
            f,
            "{:<w$}  {:>8}  {:>8}  schema",
            "topic", "count", "rate Hz"
        )?;
        for c in &self.channels {
            let rate = if duration_s > 0.0 && c.count > 1 {
                Cow::Owned(format!("{:.1}", c.count as f64 / duration_s))
            } else {
                Cow::Borrowed("-")
            };
            write!(
                f,
                "\n{:<w$}  {:>8}  {:>8}  {} ({})",
                c.topic, c.count, rate, c.schema, c.message_encoding
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
#[path = "read_test.rs"]
mod tests;
