//! camera-ingest as a pure library: the per-frame logic between a camera (the simulator's
//! frames or a real camera read through OpenCV) and the pipeline's `landing/camera/frame`.
//!
//! [`Ingest`] checks a source frame (header against payload, size against the calibration)
//! and writes the published frame into a buffer the caller supplies (in the process, a
//! loaned iceoryx2 sample), copying the pixels or undistorting them straight into it. The
//! OpenCV readers ([`source`]) return frames; the log-line rate limit
//! ([`pacing`]) takes the time as an argument. There is no IPC, no clock read and no sleep
//! here: the `camera-ingest` binary owns those, so the same code runs in lockstep.

pub mod config;
pub mod ingest;
pub mod pacing;
pub mod source;
pub mod stage;
pub mod undistort;

pub use config::CameraIngestConfig;
pub use ingest::{Admitted, Counters, Dropped, Ingest, IngestError, Rejection};
pub use pacing::RateLimit;
pub use source::{
    FrameSource, ImageDir, SourceError, SourceSpec, VideoSource, header_for_mat, mat_bytes,
};
pub use stage::{IngestStage, Problem};
pub use undistort::{RemapError, UndistortMapsError, Undistorter};
