//! depth-ingest as a pure library: the depth camera's side of the pipeline, between a
//! source of depth frames (a RealSense recording, a directory of 16-bit PNGs) and
//! `landing/depth/frame`, which depth-map reads with `--input depth-frame`.
//!
//! The readers ([`bag`], [`png_dir`], [`v4l2`], and with the `realsense` feature a live
//! camera through librealsense) return depth images; [`DepthIngestStage`] checks
//! each frame and writes it into the buffer the driver lends. There is no IPC, no clock
//! read and no sleep here: the `depth-ingest` binary owns those.

pub mod bag;
pub mod config;
pub mod png_dir;
#[cfg(feature = "realsense")]
pub mod realsense;
pub mod source;
pub mod stage;
pub mod v4l2;

pub use bag::{BagError, DepthStreamInfo, RsBag};
pub use config::{DepthIngestConfig, Source, SourceFlags};
pub use png_dir::{DepthImage, PngDir, PngDirError, read_png16};
#[cfg(feature = "realsense")]
pub use realsense::{LiveMode, RealSense, RealSenseError};
pub use source::{ALLOWED_SOURCES, DepthSourceSpec, RealSenseTarget, UnknownSource};
pub use stage::{Counts, DepthIngestStage, Rejection};
pub use v4l2::{V4l2Depth, V4l2Error};

/// The heartbeat deadline depth-ingest declares, ms: a supervisor calls it hung after
/// this long without a beat (as every stage of the graph).
pub const HEARTBEAT_DEADLINE_MS: u64 = 250;

/// depth-ingest's node: no iceoryx2 input (its frames come from its capture thread, on
/// [`ipc_types::topics::DEPTH_DEVICE`]), `depth/frame` out.
pub fn node_spec() -> ::stage::lockstep::NodeSpec {
    ::stage::lockstep::NodeSpec {
        name: "depth-ingest".into(),
        inputs: Vec::new(),
        outputs: vec![ipc_types::topics::DEPTH_FRAME.into()],
        latency_ns: 0,
        periodic: None,
    }
}
