//! Calibration for bringing up a vehicle, as a pure library behind `landing calibrate`:
//!
//! - [`board`]: a ChArUco board as `--board charuco:...` names it, and its printable image.
//! - [`camera`]: ChArUco corners found in views of the board, and the camera's
//!   intrinsics and distortion fitted to them (OpenCV's `calibrateCameraCharuco`), with
//!   the reprojection error, the coverage of the image and the views it rejected, written
//!   as the calibration YAML the stack reads ([`optics::CameraCalibration`]).
//! - [`synthetic`]: views of a board rendered through a known camera (intrinsics and
//!   distortion), to check the fit, and a setup, against the truth.
//! - [`mount`]: the down camera's rotation and offset on the body from a flight over a
//!   static pad.
//! - [`plot`]: the coverage and the per-view errors as a PNG.

pub mod board;
pub mod camera;
pub mod mount;
pub mod plot;
pub mod synthetic;

pub use board::{BoardError, CharucoSpec};
pub use camera::{CalibrateError, Calibrated, Detection, Rejected, calibrate, detect};
pub use mount::{MountError, MountFit, Sample, fit_mount, fit_mount_and_offset};
