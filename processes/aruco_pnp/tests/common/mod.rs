//! Rendered frames with known truth, shared by the accuracy and behaviour tests.
#![allow(dead_code)]

use std::path::PathBuf;

use aruco_pnp::{EstimatorSettings, Frame, PadEstimator};
use ipc_types::msg::PixelEncoding;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use optics::{CameraCalibration, PadModel};
use sim::camera::{BodyMotion, DownCamera, DownCameraParams};
use sim::ground_vehicle::PadState;

pub const CAMERAS: [&str; 2] = ["camera_down_640x480.yaml", "camera_down_1280x720.yaml"];

pub fn config(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../deploy/config")
        .join(name)
}

pub fn pad_model() -> PadModel {
    PadModel::load(config("pad.toml")).unwrap()
}

pub fn calibration(file: &str) -> CameraCalibration {
    CameraCalibration::load(config(file)).unwrap()
}

pub fn camera(file: &str) -> DownCamera {
    DownCamera::new(DownCameraParams::default(), calibration(file), &pad_model()).unwrap()
}

pub fn estimator(file: &str, cam: &DownCamera) -> PadEstimator {
    PadEstimator::new(
        calibration(file),
        pad_model(),
        cam.camera_from_body(),
        EstimatorSettings::default(),
    )
    .unwrap()
}

pub fn pad_state() -> PadState {
    PadState {
        world_from_pad: Isometry3::from_parts(
            Translation3::new(3.0, -2.0, 0.4),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 30f64.to_radians()),
        ),
        linear_velocity: Vector3::zeros(),
        linear_acceleration: Vector3::zeros(),
        angular_velocity: Vector3::zeros(),
        speed_m_s: 0.0,
        distance_m: 0.0,
    }
}

/// A camera `height` above the pad plane, shifted by `offset` (pad x, y, m), tilted by
/// `roll`/`pitch` (deg, about the camera's own x and y) and yawed by `yaw` (deg).
pub struct View {
    pub height: f64,
    pub offset: [f64; 2],
    pub roll_deg: f64,
    pub pitch_deg: f64,
    pub yaw_deg: f64,
}

/// (world_from_body, camera_from_pad truth).
pub fn place(cam: &DownCamera, pad: &PadState, v: &View) -> (Isometry3<f64>, Isometry3<f64>) {
    let body_from_camera = cam.camera_from_body().inverse();
    let p = pad.world_from_pad;
    let centre = p * nalgebra::Point3::new(v.offset[0], v.offset[1], v.height);
    let down = p.rotation
        * UnitQuaternion::from_euler_angles(0.0, 0.0, v.yaw_deg.to_radians())
        * body_from_camera.rotation;
    let tilt =
        UnitQuaternion::from_euler_angles(v.roll_deg.to_radians(), v.pitch_deg.to_radians(), 0.0);
    let world_from_camera = Isometry3::from_parts(Translation3::from(centre.coords), down * tilt);
    let world_from_body = world_from_camera * cam.camera_from_body();
    (world_from_body, world_from_camera.inverse() * p)
}

/// Renders the view; returns the frame bytes.
pub fn render(cam: &mut DownCamera, pad: &PadState, world_from_body: Isometry3<f64>) -> Vec<u8> {
    cam.render(&BodyMotion::at_rest(world_from_body), Some(pad))
        .unwrap()
        .data
}

pub fn frame<'a>(cal: &CameraCalibration, data: &'a [u8]) -> Frame<'a> {
    Frame {
        width: cal.width,
        height: cal.height,
        stride: cal.width,
        encoding: PixelEncoding::Mono8,
        data,
        undistorted: false,
    }
}

/// (position error m, yaw error deg, full rotation error deg).
pub fn errors(est: &Isometry3<f64>, truth: &Isometry3<f64>) -> (f64, f64, f64) {
    let dt = (est.translation.vector - truth.translation.vector).norm();
    let d = truth.rotation.inverse() * est.rotation;
    (
        dt,
        d.euler_angles().2.to_degrees().abs(),
        d.angle().to_degrees(),
    )
}

pub fn percentile(v: &mut [f64], p: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        return f64::NAN;
    }
    let k = ((p / 100.0) * (v.len() - 1) as f64).round() as usize;
    v[k.min(v.len() - 1)]
}
