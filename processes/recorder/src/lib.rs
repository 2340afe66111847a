//! The recorder: every topic of the pipeline into one MCAP file per run, in Foxglove's
//! schemas (images, transforms, the 3-D scene, logs) and as plottable JSON, written with
//! the Foxglove SDK. [`RecorderStage`] is the stage both drivers run: the `recorder`
//! process under the iceoryx2 driver, and `landing run` in lockstep with the same code.
//! [`read`] reads recordings back, up to where a damaged one breaks.

pub mod config;
pub mod metadata;
pub mod read;
pub mod schema;
pub mod stage;
pub mod visual;
pub mod writer;

pub use config::RecorderConfig;
pub use read::{
    Broken, ReadError, ReadSummary, RecordedMessage, RecordingInfo, info, read_messages,
};
pub use schema::{Recordable, SchemaError, json_schema_of, schema_for};
pub use stage::RecorderStage;
pub use writer::{ChunkCompression, ImageFormat, RecordError, RecordOptions, Recorder};
