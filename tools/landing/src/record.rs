//! MCAP recordings of a run (`landing run --record out.mcap`), and what is in one
//! (`landing mcap info`).
//!
//! Messages are written as JSON (MCAP message encoding `json`) with a JSON Schema per
//! message type, so Foxglove Studio (or `mcap cat --json`) shows every field by name
//! without a plug-in, and a plot of any number is one click. The JSON comes from the
//! messages' own `serde::Serialize` (ipc_types' `serde` feature), so a new field is
//! recorded without touching this file; the schema is derived from the same
//! serialization of the type's default value, so the two cannot disagree. Non-finite
//! floats are written as `null` (JSON has no NaN). Chunks are zstd-compressed.
//!
//! Foxglove's JSON Schema reader takes objects, scalars and arrays of scalars or objects
//! (not arrays of arrays, not `null` types): the schemas stay within that (trajectory
//! control points are `{x, y, z}` objects), and the tests hold every message to it. It
//! reads integers as JavaScript numbers: nanosecond stamps are exact up to 2^53 ns
//! (104 days of uptime on the monotonic clock).
//!
//! Camera and depth images are not recorded: a JSON image is base64 text (4/3 the raw
//! size, 1.2 MB per 640x480 colour frame) and would dominate the file; their headers
//! can be recorded if wanted ([`Recordable`] covers them).

use std::borrow::Cow;
use std::collections::{BTreeMap, HashMap};
use std::fmt;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use ipc_types::msg::{
    CameraFrameHeader, DepthFrameHeader, FsmStatus, LinkOutcome, LinkRequest, OccupancyMapHeader,
    PadObservation, PlannerGoal, PlannerStats, SafetyCommand, Setpoint, Trajectory, TruthEvent,
    TruthState, VehicleState, WatchdogView,
};
use mcap::records::MessageHeader;
use mcap::{Compression, WriteOptions, Writer};
use serde::Serialize;
use serde_json::{Map, Value, json};
use thiserror::Error;

/// MCAP message encoding of every channel.
pub const MESSAGE_ENCODING: &str = "json";
/// MCAP schema encoding of every schema.
pub const SCHEMA_ENCODING: &str = "jsonschema";

/// Why a recording could not be written or read.
#[derive(Debug, Error)]
pub enum RecordError {
    /// The file cannot be created (missing directory, permissions).
    #[error("cannot create the recording {}: {error}", path.display())]
    Create {
        /// The recording.
        path: PathBuf,
        /// What the OS said.
        error: std::io::Error,
    },
    /// The MCAP writer failed (disk full, I/O error, writing after `finish`).
    #[error("writing the recording {}: {error}", path.display())]
    Write {
        /// The recording.
        path: PathBuf,
        /// What the writer said.
        error: mcap::McapError,
    },
    /// A message could not be turned into JSON.
    #[error("encoding a {schema} message as JSON: {error}")]
    Encode {
        /// Schema name of the message.
        schema: &'static str,
        /// What serde_json said.
        error: serde_json::Error,
    },
    /// A topic was given a second message type.
    #[error("topic {topic} carries {has}, not {got}")]
    TopicType {
        /// The topic.
        topic: String,
        /// The type it was made with.
        has: &'static str,
        /// The type given now.
        got: &'static str,
    },
    /// The file cannot be read as MCAP.
    #[error("reading the recording {}: {reason}", path.display())]
    Read {
        /// The recording.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
}

/// A message type that can go into a recording: serializable, with a default value to
/// derive its schema from and a schema name.
pub trait Recordable: Serialize + Default {
    /// Schema name shown by viewers; the message's iceoryx2 type name (versioned), so a
    /// recording says which layout it holds.
    const SCHEMA_NAME: &'static str;
}

macro_rules! recordable {
    ($($t:ty => $name:literal),* $(,)?) => {
        $(impl Recordable for $t {
            const SCHEMA_NAME: &'static str = $name;
        })*
    };
}

recordable!(
    PadObservation => "landing::PadObservation/v1",
    VehicleState => "landing::VehicleState/v1",
    Trajectory => "landing::Trajectory/v1",
    PlannerStats => "landing::PlannerStats/v1",
    PlannerGoal => "landing::PlannerGoal/v1",
    Setpoint => "landing::Setpoint/v1",
    FsmStatus => "landing::FsmStatus/v1",
    TruthEvent => "landing::TruthEvent/v2",
    TruthState => "landing::TruthState/v3",
    LinkRequest => "landing::LinkRequest/v1",
    LinkOutcome => "landing::LinkOutcome/v1",
    SafetyCommand => "landing::SafetyCommand/v1",
    WatchdogView => "landing::WatchdogView/v2",
    OccupancyMapHeader => "landing::OccupancyMapHeader/v1",
    CameraFrameHeader => "landing::CameraFrameHeader/v1",
    DepthFrameHeader => "landing::DepthFrameHeader/v1",
);

/// The JSON Schema of a serialized value: objects by property, arrays by their first
/// item, integers apart from other numbers. `null` (a non-finite float) reads as a number.
pub fn json_schema_of(v: &Value) -> Value {
    match v {
        Value::Null => json!({ "type": "number" }),
        Value::Bool(_) => json!({ "type": "boolean" }),
        Value::Number(n) if n.is_f64() => json!({ "type": "number" }),
        Value::Number(_) => json!({ "type": "integer" }),
        Value::String(_) => json!({ "type": "string" }),
        Value::Array(items) => {
            let item = items.first().map(json_schema_of).unwrap_or(json!({}));
            json!({
                "type": "array",
                "items": item,
                "minItems": items.len(),
                "maxItems": items.len(),
            })
        }
        Value::Object(fields) => {
            let props: Map<String, Value> = fields
                .iter()
                .map(|(k, v)| (k.clone(), json_schema_of(v)))
                .collect();
            json!({ "type": "object", "properties": props })
        }
    }
}

/// The schema document of a recordable type, as stored in the recording.
pub fn schema_for<T: Recordable>() -> Result<Value, RecordError> {
    let v = serde_json::to_value(T::default()).map_err(|error| RecordError::Encode {
        schema: T::SCHEMA_NAME,
        error,
    })?;
    let mut s = json_schema_of(&v);
    if let Value::Object(m) = &mut s {
        m.insert(
            "$schema".into(),
            json!("https://json-schema.org/draft/2020-12/schema"),
        );
        m.insert("title".into(), json!(T::SCHEMA_NAME));
    }
    Ok(s)
}

/// A channel of the recording being written.
#[derive(Debug, Clone, Copy)]
struct Channel {
    id: u16,
    /// Sequence number of the last message written (MCAP numbers from 1 here).
    seq: u32,
    /// Schema name of the type the topic carries.
    schema: &'static str,
}

/// Writes an MCAP file of JSON messages, one channel per topic.
///
/// Dropping it finishes the file too, but silently: call [`Recorder::finish`] to learn
/// whether the end of the file was written.
pub struct Recorder {
    path: PathBuf,
    writer: Writer<BufWriter<File>>,
    /// Schema ids by schema name.
    schemas: HashMap<&'static str, u16>,
    /// Channels by topic.
    channels: HashMap<String, Channel>,
    messages: u64,
}

impl fmt::Debug for Recorder {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Recorder")
            .field("path", &self.path)
            .field("channels", &self.channels.len())
            .field("messages", &self.messages)
            .finish()
    }
}

impl Recorder {
    /// Creates (or truncates) the recording at `path`.
    pub fn create(path: &Path) -> Result<Self, RecordError> {
        let file = File::create(path).map_err(|error| RecordError::Create {
            path: path.to_path_buf(),
            error,
        })?;
        // Compression in the caller's thread: no hidden worker threads next to the stack.
        let options = WriteOptions::new()
            .compression(Some(Compression::Zstd))
            .compression_threads(0)
            .library(concat!("landing ", env!("CARGO_PKG_VERSION")));
        let writer = options
            .create(BufWriter::new(file))
            .map_err(|error| RecordError::Write {
                path: path.to_path_buf(),
                error,
            })?;
        Ok(Self {
            path: path.to_path_buf(),
            writer,
            schemas: HashMap::new(),
            channels: HashMap::new(),
            messages: 0,
        })
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Messages written so far.
    #[cfg_attr(not(test), allow(dead_code))]
    pub fn message_count(&self) -> u64 {
        self.messages
    }

    fn write_error(&self, error: mcap::McapError) -> RecordError {
        RecordError::Write {
            path: self.path.clone(),
            error,
        }
    }

    /// The channel of `topic` (made on first use with `T`'s schema) and the sequence
    /// number of its next message. A topic keeps the type it was made with: one topic, one
    /// message type, as on the bus.
    fn next_on_channel<T: Recordable>(&mut self, topic: &str) -> Result<(u16, u32), RecordError> {
        if let Some(ch) = self.channels.get_mut(topic) {
            if ch.schema != T::SCHEMA_NAME {
                return Err(RecordError::TopicType {
                    topic: topic.to_string(),
                    has: ch.schema,
                    got: T::SCHEMA_NAME,
                });
            }
            ch.seq = ch.seq.wrapping_add(1);
            return Ok((ch.id, ch.seq));
        }
        let schema_id = match self.schemas.get(T::SCHEMA_NAME) {
            Some(id) => *id,
            None => {
                let doc = schema_for::<T>()?;
                let bytes = serde_json::to_vec(&doc).map_err(|error| RecordError::Encode {
                    schema: T::SCHEMA_NAME,
                    error,
                })?;
                let id = self
                    .writer
                    .add_schema(T::SCHEMA_NAME, SCHEMA_ENCODING, &bytes)
                    .map_err(|e| self.write_error(e))?;
                self.schemas.insert(T::SCHEMA_NAME, id);
                id
            }
        };
        let id = self
            .writer
            .add_channel(schema_id, topic, MESSAGE_ENCODING, &BTreeMap::new())
            .map_err(|e| self.write_error(e))?;
        self.channels.insert(
            topic.to_string(),
            Channel {
                id,
                seq: 1,
                schema: T::SCHEMA_NAME,
            },
        );
        Ok((id, 1))
    }

    /// Records `msg` on `topic` at `log_time_ns` (the time axis viewers play back on; use
    /// one clock for the whole recording, e.g. simulated ns).
    pub fn write_message<T: Recordable>(
        &mut self,
        topic: &str,
        log_time_ns: u64,
        msg: &T,
    ) -> Result<(), RecordError> {
        let data = serde_json::to_vec(msg).map_err(|error| RecordError::Encode {
            schema: T::SCHEMA_NAME,
            error,
        })?;
        let (channel_id, seq) = self.next_on_channel::<T>(topic)?;
        let header = MessageHeader {
            channel_id,
            sequence: seq,
            log_time: log_time_ns,
            publish_time: log_time_ns,
        };
        self.writer
            .write_to_known_channel(&header, &data)
            .map_err(|e| self.write_error(e))?;
        self.messages += 1;
        Ok(())
    }

    /// Writes the index and summary that make the file complete; returns the number of
    /// messages recorded.
    pub fn finish(mut self) -> Result<u64, RecordError> {
        self.writer.finish().map_err(|e| self.write_error(e))?;
        Ok(self.messages)
    }
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

impl ChannelInfo {
    /// A recording channel's topic, schema and encoding, with `count` messages.
    fn of(c: &mcap::Channel, count: u64) -> Self {
        Self {
            topic: c.topic.clone(),
            schema: c
                .schema
                .as_ref()
                .map(|s| s.name.clone())
                .unwrap_or_default(),
            message_encoding: c.message_encoding.clone(),
            count,
        }
    }
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
}

/// Reads what `path` holds, from its summary when the file was finished, else by reading
/// every message up to where the file ends.
pub fn info(path: &Path) -> Result<RecordingInfo, RecordError> {
    let fail = |reason: String| RecordError::Read {
        path: path.to_path_buf(),
        reason,
    };
    let buf = std::fs::read(path).map_err(|e| fail(e.to_string()))?;
    let bytes = buf.len() as u64;
    if let Ok(Some(summary)) = mcap::read::Summary::read(&buf)
        && let Some(stats) = &summary.stats
    {
        let mut channels: Vec<ChannelInfo> = summary
            .channels
            .values()
            .map(|c| {
                let count = stats.channel_message_counts.get(&c.id).copied();
                ChannelInfo::of(c, count.unwrap_or(0))
            })
            .collect();
        channels.sort_by(|a, b| a.topic.cmp(&b.topic));
        return Ok(RecordingInfo {
            path: path.to_path_buf(),
            bytes,
            channels,
            message_count: stats.message_count,
            time_range_ns: (stats.message_count > 0)
                .then_some((stats.message_start_time, stats.message_end_time)),
            complete: true,
        });
    }
    let stream = mcap::MessageStream::new(&buf).map_err(|e| fail(e.to_string()))?;
    let mut by_topic: BTreeMap<String, ChannelInfo> = BTreeMap::new();
    let mut range: Option<(u64, u64)> = None;
    let mut count = 0;
    for m in stream {
        // A file cut short ends in an error: what came before it still counts.
        let Ok(m) = m else { break };
        count += 1;
        range = Some(match range {
            None => (m.log_time, m.log_time),
            Some((a, b)) => (a.min(m.log_time), b.max(m.log_time)),
        });
        let c = &m.channel;
        by_topic
            .entry(c.topic.clone())
            .or_insert_with(|| ChannelInfo::of(c, 0))
            .count += 1;
    }
    Ok(RecordingInfo {
        path: path.to_path_buf(),
        bytes,
        channels: by_topic.into_values().collect(),
        message_count: count,
        time_range_ns: range,
        complete: false,
    })
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
                ", NOT FINISHED (no summary; counted what is there)"
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
#[path = "record_test.rs"]
mod tests;
