//! The JSON side of a recording: every stack message as JSON (MCAP message encoding
//! `json`) with a JSON Schema per message type, so Foxglove (or `mcap cat --json`) shows
//! every field by name and a plot of any number is one click; `landing latency` and
//! `landing replay` read the same JSON back.
//!
//! The JSON comes from the messages' own `serde::Serialize` (ipc_types' `serde` feature),
//! so a new field is recorded without touching this file; the schema is derived from the
//! same serialization of the type's default value, so the two cannot disagree. Non-finite
//! floats are written as `null` (JSON has no NaN).
//!
//! Foxglove's JSON Schema reader takes objects, scalars and arrays of scalars or objects
//! (not arrays of arrays, not `null` types): the schemas stay within that (trajectory
//! control points are `{x, y, z}` objects), and the tests hold every message to it. It
//! reads integers as JavaScript numbers: nanosecond stamps are exact up to 2^53 ns
//! (104 days of uptime on the monotonic clock).

use serde::Serialize;
use serde::de::DeserializeOwned;
use serde_json::{Map, Value, json};

/// MCAP message encoding of every channel.
pub const MESSAGE_ENCODING: &str = "json";
/// MCAP schema encoding of every schema.
pub const SCHEMA_ENCODING: &str = "jsonschema";

/// A message type could not be turned into JSON (a serializer refused a value).
#[derive(Debug, thiserror::Error)]
#[error("encoding a {schema} message as JSON: {error}")]
pub struct SchemaError {
    /// Schema name of the message.
    pub schema: &'static str,
    /// What serde_json said.
    pub error: serde_json::Error,
}

/// A message type that can go into a recording and come back out of it: serializable
/// and deserializable, with a default value to derive its schema from and a schema name.
pub trait Recordable: Serialize + DeserializeOwned + Default {
    /// Schema name shown by viewers; the message's iceoryx2 type name (versioned), so a
    /// recording says which layout it holds.
    const SCHEMA_NAME: &'static str;
}

/// Makes every struct of the payload list ([`ipc_types::for_each_payload!`]) recordable
/// under its versioned type name: pipeline structs, the simulator's truth, and the
/// headers of frames and maps (their pixels and cells go into Foxglove's schemas).
/// Local payloads and MAVLink bytes are not recorded.
macro_rules! recordable {
    (
        structs: [$($(#[$sd:meta])* $s:ident($st:ty => $so:ty) = $sn:literal,)*],
        truth: [$($(#[$td:meta])* $t:ident($tt:ty => $to:ty) = $tn:literal,)*],
        slices: [$($(#[$cd:meta])* $c:ident($ch:ty, [$ce:ty]) = $cn:literal,)*],
        $($rest:tt)*
    ) => {
        $(impl Recordable for $st {
            const SCHEMA_NAME: &'static str = $sn;
        })*
        $(impl Recordable for $tt {
            const SCHEMA_NAME: &'static str = $tn;
        })*
        $(impl Recordable for $ch {
            const SCHEMA_NAME: &'static str = $cn;
        })*
    };
}
ipc_types::for_each_payload!(recordable);

/// The channel of a frame's or a map's header: `/camera/frame/header` beside the
/// pictures on `/camera/frame`.
pub const HEADER_SUFFIX: &str = "/header";

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
pub fn schema_for<T: Recordable>() -> Result<Value, SchemaError> {
    let v = serde_json::to_value(T::default()).map_err(|error| SchemaError {
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
