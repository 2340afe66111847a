//! What the camera renderer and the pad detector must agree on: the camera
//! calibration (intrinsics + distortion, OpenCV's model and file format) and the
//! landing pad model (which ArUco markers sit where on the board).
//!
//! Nothing here knows the ground truth: the simulator renders images with these
//! models and the detector inverts them, so both stay consistent by sharing
//! this crate. The library is pure (no clock, no IPC); it reads files only when
//! asked to load one.

pub mod calibration;
mod calibration_yaml;
pub mod mount;
pub mod pad;

pub use calibration::{CalibrationError, CameraCalibration};
pub use mount::{body_from_forward_camera, down_camera_from_body};
pub use pad::{Board, MARKER_CELLS, Marker, PadError, PadModel, marker_cells};
