//! Recorded messages back into the stack's types: the one reader of what
//! [`Recorder::record`](crate::Recorder::record) wrote, for every tool that reads a
//! recording (`landing plot`, `landing replay`). The JSON of each message came from the
//! message's own `serde::Serialize` (ipc_types' `serde` feature) and is read back with
//! its derived `Deserialize`, so a field added to a message is read without touching
//! this file; which type a topic holds comes from the topic table and the payload list
//! ([`ipc_types::for_each_payload!`]).
//!
//! JSON has no NaN: the recorder wrote every non-finite number as `null`, and reads each
//! `null` that stands for a number back as NaN ([`NullAsNan`]), whichever field it is in.
//! Fields a message gained after a recording was made (`#[serde(default)]` in
//! ipc_types) read as their default from older recordings.

use std::fmt;
use std::path::Path;

use foxglove::Decode as _;
use foxglove::schemas::VoxelGrid;
use ipc_types::msg::{Header, OccupancyMapHeader};
use ipc_types::topics::{self, Payload};
use serde::Deserialize;
use serde::de::{self, DeserializeSeed, Deserializer, MapAccess, SeqAccess, Visitor};
use stage::{OwnedMessage, SliceHeader};

use crate::read::{ReadError, ReadSummary, RecordedMessage, read_messages};
use crate::schema::{HEADER_SUFFIX, MESSAGE_ENCODING, Recordable};

/// Why a recorded message could not be read back as a stack message.
#[derive(Debug, thiserror::Error)]
pub enum DecodeError {
    /// The channel is not JSON (a Foxglove picture, a transform): no stack message.
    #[error("{topic}: a {encoding} message, not the JSON of a stack message")]
    NotJson {
        /// The channel.
        topic: String,
        /// Its message encoding.
        encoding: String,
    },
    /// The channel holds another type than the one asked for.
    #[error("{topic}: holds {schema}, not {expected}")]
    Schema {
        /// The channel.
        topic: String,
        /// The schema the channel holds.
        schema: String,
        /// The schema asked for.
        expected: &'static str,
    },
    /// The JSON does not read as the type (a field missing, a value out of range).
    #[error("{topic}: not a {schema}: {error}")]
    Json {
        /// The channel.
        topic: String,
        /// The type asked for.
        schema: &'static str,
        /// What serde_json said.
        error: serde_json::Error,
    },
    /// A map's cells (`foxglove.VoxelGrid`) do not decode.
    #[error("{topic}: not a foxglove.VoxelGrid: {error}")]
    Cells {
        /// The channel.
        topic: String,
        /// What the decoder said.
        error: <VoxelGrid as foxglove::Decode>::Error,
    },
}

/// A stack message as the recording holds it. Inline, like [`OwnedMessage`]: one is
/// made per message read and handed over at once.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq)]
pub enum Decoded {
    /// A whole message (every struct payload): `/vehicle/state`.
    Message(OwnedMessage),
    /// The header of a frame or a map (`/camera/frame/header`); its pixels or cells are
    /// recorded apart, in a Foxglove schema, on the topic's own channel.
    Header(SliceHeader),
}

/// Just the header of a stack message, whatever its type.
#[derive(Deserialize)]
struct Headed {
    msg: Header,
}

impl RecordedMessage<'_> {
    /// The topic table's row of this channel and whether it is a header channel
    /// (`/camera/frame/header`); `None` for a channel that is no stack topic (`/tf`,
    /// `/scene/map`).
    pub fn stack_topic(&self) -> Option<(&'static topics::TopicInfo, bool)> {
        let short = self.topic.strip_prefix('/')?;
        match short.strip_suffix(HEADER_SUFFIX).and_then(topics::find) {
            Some(t) if t.payload.elements().is_some() => Some((t, true)),
            _ => topics::find(short).map(|t| (t, false)),
        }
    }

    /// The JSON of this message as a `T`, after checking that the channel holds a `T`
    /// (the same type, of any version: older recordings read with the fields they have).
    pub fn decode<T: Recordable>(&self) -> Result<T, DecodeError> {
        self.json()?;
        if base(self.schema) != base(T::SCHEMA_NAME) {
            return Err(DecodeError::Schema {
                topic: self.topic.to_string(),
                schema: self.schema.to_string(),
                expected: T::SCHEMA_NAME,
            });
        }
        from_json(self.data).map_err(|error| DecodeError::Json {
            topic: self.topic.to_string(),
            schema: T::SCHEMA_NAME,
            error,
        })
    }

    /// The header (`msg`) of the stack message this is, whatever its type.
    pub fn header(&self) -> Result<Header, DecodeError> {
        self.json()?;
        from_json::<Headed>(self.data)
            .map(|h| h.msg)
            .map_err(|error| DecodeError::Json {
                topic: self.topic.to_string(),
                schema: "landing::Header/v1",
                error,
            })
    }

    /// This message as the stack message of its topic, typed by the topic table:
    /// `Ok(None)` for what is no stack message (a Foxglove picture, a transform, a
    /// channel of no stack topic).
    pub fn stack(&self) -> Result<Option<(&'static str, Decoded)>, DecodeError> {
        let Some((info, header)) = self.stack_topic() else {
            return Ok(None);
        };
        if self.encoding != MESSAGE_ENCODING {
            return Ok(None);
        }
        Ok(decode_payload(self, info.payload, header)?.map(|d| (info.name, d)))
    }

    fn json(&self) -> Result<(), DecodeError> {
        if self.encoding == MESSAGE_ENCODING {
            Ok(())
        } else {
            Err(DecodeError::NotJson {
                topic: self.topic.to_string(),
                encoding: self.encoding.to_string(),
            })
        }
    }
}

/// A type name without its version: `landing::VehicleState` of `landing::VehicleState/v2`.
fn base(type_name: &str) -> &str {
    type_name.split_once('/').map_or(type_name, |(b, _)| b)
}

/// Writes [`decode_payload`] from the payload list ([`ipc_types::for_each_payload!`]):
/// what the recorder writes of each kind (see `Recorder::record_json`) read back.
macro_rules! decode_payload {
    (
        structs: [$($(#[$sd:meta])* $s:ident($st:ty => $so:ty) = $sn:literal,)*],
        truth: [$($(#[$td:meta])* $t:ident($tt:ty => $to:ty) = $tn:literal,)*],
        slices: [$($(#[$cd:meta])* $c:ident($ch:ty, [$ce:ty]) = $cn:literal,)*],
        local: [$($(#[$ld:meta])* $l:ident($lt:ty) = $ln:literal,)*],
        bytes: [$($(#[$bd:meta])* $b:ident = $bn:literal,)*],
    ) => {
        /// `m`, recorded on a topic of `payload` (on its header channel when `header`),
        /// as that payload; `None` when the recorder writes no JSON of it there.
        fn decode_payload(
            m: &RecordedMessage<'_>,
            payload: Payload,
            header: bool,
        ) -> Result<Option<Decoded>, DecodeError> {
            Ok(Some(match (payload, header) {
                $((Payload::$s, false) => {
                    Decoded::Message(OwnedMessage::$s(m.decode::<$st>()?.into()))
                })*
                $((Payload::$t, false) => {
                    Decoded::Message(OwnedMessage::$t(m.decode::<$tt>()?.into()))
                })*
                $((Payload::$c, true) => Decoded::Header(SliceHeader::$c(m.decode::<$ch>()?)),)*
                _ => return Ok(None),
            }))
        }
    };
}
ipc_types::for_each_payload!(decode_payload);

/// Reads `data`, JSON the recorder wrote, as a `T`, every `null` where a number belongs
/// as NaN.
fn from_json<T: de::DeserializeOwned>(data: &[u8]) -> Result<T, serde_json::Error> {
    let mut json = serde_json::Deserializer::from_slice(data);
    let value = T::deserialize(NullAsNan(&mut json))?;
    json.end()?;
    Ok(value)
}

/// A deserializer that hands a `null` (or a missing option) over as NaN wherever a
/// float is asked for, at any depth, and passes everything else through: the inverse of
/// JSON writing a non-finite number as `null`. In the reader, not in the message types,
/// because it is JSON's quirk, not the messages': the derives stay format-agnostic, and
/// every float field of every message, present and future, is covered in one place.
/// Everything but floats goes through the inner deserializer's `deserialize_any` (JSON
/// describes itself, so no type hint is lost).
struct NullAsNan<D>(D);

impl<'de, D: Deserializer<'de>> Deserializer<'de> for NullAsNan<D> {
    type Error = D::Error;

    fn deserialize_any<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, D::Error> {
        self.0.deserialize_any(Passing(visitor))
    }

    fn deserialize_f64<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, D::Error> {
        self.0.deserialize_any(Float(visitor))
    }

    fn deserialize_f32<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, D::Error> {
        self.0.deserialize_any(Float(visitor))
    }

    serde::forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 char str string bytes byte_buf option
        unit unit_struct newtype_struct seq tuple tuple_struct map struct enum identifier
        ignored_any
    }
}

/// A visitor whose nested values go through [`NullAsNan`] again.
struct Passing<V>(V);

/// Forwards `visit_*` methods that carry no nested value.
macro_rules! forward_visits {
    ($($method:ident($ty:ty)),* $(,)?) => {$(
        fn $method<E: de::Error>(self, v: $ty) -> Result<Self::Value, E> {
            self.0.$method(v)
        }
    )*};
}

impl<'de, V: Visitor<'de>> Visitor<'de> for Passing<V> {
    type Value = V::Value;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.0.expecting(f)
    }

    forward_visits!(
        visit_bool(bool),
        visit_i64(i64),
        visit_u64(u64),
        visit_i128(i128),
        visit_u128(u128),
        visit_f64(f64),
        visit_str(&str),
        visit_borrowed_str(&'de str),
        visit_string(String),
        visit_bytes(&[u8]),
        visit_borrowed_bytes(&'de [u8]),
        visit_byte_buf(Vec<u8>),
    );

    fn visit_unit<E: de::Error>(self) -> Result<Self::Value, E> {
        self.0.visit_unit()
    }

    fn visit_none<E: de::Error>(self) -> Result<Self::Value, E> {
        self.0.visit_none()
    }

    fn visit_some<D2: Deserializer<'de>>(self, d: D2) -> Result<Self::Value, D2::Error> {
        self.0.visit_some(NullAsNan(d))
    }

    fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<Self::Value, A::Error> {
        self.0.visit_seq(Items(seq))
    }

    fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<Self::Value, A::Error> {
        self.0.visit_map(Fields(map))
    }
}

/// A float's visitor: `null` is NaN, a number is itself.
struct Float<V>(V);

impl<'de, V: Visitor<'de>> Visitor<'de> for Float<V> {
    type Value = V::Value;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.0.expecting(f)
    }

    forward_visits!(visit_i64(i64), visit_u64(u64), visit_f64(f64));

    fn visit_unit<E: de::Error>(self) -> Result<Self::Value, E> {
        self.0.visit_f64(f64::NAN)
    }

    fn visit_none<E: de::Error>(self) -> Result<Self::Value, E> {
        self.0.visit_f64(f64::NAN)
    }
}

/// A sequence whose items go through [`NullAsNan`].
struct Items<A>(A);

impl<'de, A: SeqAccess<'de>> SeqAccess<'de> for Items<A> {
    type Error = A::Error;

    fn next_element_seed<T: DeserializeSeed<'de>>(
        &mut self,
        seed: T,
    ) -> Result<Option<T::Value>, A::Error> {
        self.0.next_element_seed(Seed(seed))
    }

    fn size_hint(&self) -> Option<usize> {
        self.0.size_hint()
    }
}

/// A map whose values go through [`NullAsNan`] (keys are names, passed as they are).
struct Fields<A>(A);

impl<'de, A: MapAccess<'de>> MapAccess<'de> for Fields<A> {
    type Error = A::Error;

    fn next_key_seed<K: DeserializeSeed<'de>>(
        &mut self,
        seed: K,
    ) -> Result<Option<K::Value>, A::Error> {
        self.0.next_key_seed(seed)
    }

    fn next_value_seed<S: DeserializeSeed<'de>>(&mut self, seed: S) -> Result<S::Value, A::Error> {
        self.0.next_value_seed(Seed(seed))
    }

    fn size_hint(&self) -> Option<usize> {
        self.0.size_hint()
    }
}

/// A seed that deserializes through [`NullAsNan`].
struct Seed<S>(S);

impl<'de, S: DeserializeSeed<'de>> DeserializeSeed<'de> for Seed<S> {
    type Value = S::Value;

    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<S::Value, D::Error> {
        self.0.deserialize(NullAsNan(d))
    }
}

/// What a caller's reading of one message may fail with: any error (a [`DecodeError`],
/// an `anyhow::Error`, a Foxglove decoder's), boxed, so that `?` works on each inside
/// the caller's closure.
pub type CallerError = Box<dyn std::error::Error + Send + Sync>;

/// Why [`read_recording`] stopped.
#[derive(Debug, thiserror::Error)]
pub enum ReadRecordingError {
    /// The file cannot be read, or is no MCAP file.
    #[error(transparent)]
    Read(#[from] ReadError),
    /// The caller's reading of one message failed.
    #[error("message on {topic} at {log_time} ns")]
    Message {
        /// The message's channel.
        topic: String,
        /// Its log time, ns.
        log_time: u64,
        /// What the caller's reading said.
        #[source]
        source: CallerError,
    },
}

/// Reads every message of the recording `path` with `each`, in file order; the first
/// error `each` returns ends the reading as an error naming the message (topic, log
/// time). What the reader found besides (metadata, where a damaged file broke) is the
/// summary: a damaged file is read up to the damage, as [`read_messages`] reads it.
pub fn read_recording(
    path: &Path,
    mut each: impl FnMut(&RecordedMessage<'_>) -> Result<(), CallerError>,
) -> Result<ReadSummary, ReadRecordingError> {
    let mut failure = None;
    let summary = read_messages(path, &mut |m| {
        if failure.is_none()
            && let Err(source) = each(m)
        {
            failure = Some(ReadRecordingError::Message {
                topic: m.topic.to_string(),
                log_time: m.log_time,
                source,
            });
        }
    })?;
    match failure {
        Some(e) => Err(e),
        None => Ok(summary),
    }
}

/// One recorded map: the log time of its header, the header, and its cells when the
/// recording holds them.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedMap {
    /// When the recorder took the map, ns.
    pub log_time: u64,
    /// The map's header.
    pub header: OccupancyMapHeader,
    /// One byte per cell (`foxglove.VoxelGrid`), when recorded.
    pub cells: Option<Vec<u8>>,
}

/// The maps of a recording, each header (`/map/occupancy/header`) paired with the cells
/// (`/map/occupancy`, `foxglove.VoxelGrid`) the recorder wrote right after it. Log times
/// alone do not pair them: they are the recorder's round start, which two maps share
/// when it takes both in one round.
#[derive(Debug, Default)]
pub struct RecordedMaps {
    /// The maps, in the order recorded.
    pub maps: Vec<RecordedMap>,
    /// VoxelGrid messages met, paired or not.
    pub grids: usize,
}

impl RecordedMaps {
    /// Takes `m` when it is part of a map; `Ok(false)` leaves it to the caller.
    pub fn take(&mut self, m: &RecordedMessage<'_>) -> Result<bool, DecodeError> {
        let Some(short) = m.topic.strip_prefix('/') else {
            return Ok(false);
        };
        let map = topics::MAP_OCCUPANCY;
        if short == map && m.schema == "foxglove.VoxelGrid" {
            let grid = VoxelGrid::decode(m.data).map_err(|error| DecodeError::Cells {
                topic: m.topic.to_string(),
                error,
            })?;
            self.grids += 1;
            if let Some(last) = self.maps.last_mut()
                && last.log_time == m.log_time
                && last.cells.is_none()
            {
                last.cells = Some(grid.data.to_vec());
            }
            return Ok(true);
        }
        if short.strip_prefix(map) == Some(HEADER_SUFFIX) {
            self.maps.push(RecordedMap {
                log_time: m.log_time,
                header: m.decode()?,
                cells: None,
            });
            return Ok(true);
        }
        Ok(false)
    }
}

#[cfg(test)]
#[path = "decode_test.rs"]
mod tests;
