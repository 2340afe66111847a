#![allow(clippy::unwrap_used, clippy::expect_used)]
//! The down camera's images, pinned: speed work on the renderer must not move a pixel.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use optics::{CameraCalibration, PadModel};
use sim::camera::{BodyMotion, DownCamera, DownCameraParams};
use sim::ground_vehicle::PadState;
use std::path::PathBuf;

fn config(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../deploy/config")
        .join(name)
}

/// FNV-1a over a frame's bytes.
fn fnv1a(bytes: impl IntoIterator<Item = u8>) -> u64 {
    bytes.into_iter().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

/// Sixty frames of each shipped calibration, over the pad and without it, still and
/// blurred, hashed (FNV-1a) and folded together: a faster renderer must give these
/// bytes. Recorded before the strip sampler replaced OpenCV's `remap` (bdfcf08);
/// a change meant to alter the image records the new value and says why.
const RECORDED: u64 = 0xcadb_0a36_90f5_61af;

#[test]
fn the_down_camera_renders_the_recorded_images_byte_for_byte() {
    let pad_model = PadModel::load(config("pad.toml")).unwrap();
    let mut total = 0u64;
    for file in ["camera_down_640x480.yaml", "camera_down_1280x720.yaml"] {
        let calib = CameraCalibration::load(config(file)).unwrap();
        let mut cam = DownCamera::new(DownCameraParams::default(), calib, &pad_model).unwrap();
        for k in 0..60 {
            let kf = k as f64;
            let pad = PadState {
                world_from_pad: Isometry3::from_parts(
                    Translation3::new(3.0 + 0.1 * kf, -2.0, 0.4),
                    UnitQuaternion::from_euler_angles(0.0, 0.0, (30.0 + kf * 7.0f64).to_radians()),
                ),
                linear_velocity: Vector3::new(0.9 * (kf % 5.0), 0.0, 0.0),
                linear_acceleration: Vector3::zeros(),
                angular_velocity: Vector3::new(0.0, 0.0, 0.1),
                speed_m_s: 0.0,
                distance_m: 0.0,
            };
            let h = 0.3 + (kf % 12.0) * 0.6;
            let body = BodyMotion {
                world_from_body: Isometry3::from_parts(
                    Translation3::new(
                        3.0 + 0.1 * kf + (kf % 3.0) * 0.2,
                        -2.0 + (kf % 4.0) * 0.3,
                        0.4 + h,
                    ),
                    UnitQuaternion::from_euler_angles(
                        0.05 * (kf % 3.0),
                        -0.04 * (kf % 5.0),
                        kf * 0.3,
                    ),
                ),
                linear_velocity: Vector3::new(0.5 * (kf % 7.0), -0.3 * (kf % 3.0), 0.1),
                angular_velocity_body: Vector3::new(0.2 * (kf % 2.0), 0.1, 0.3 * (kf % 4.0)),
            };
            let frame = cam
                .render(&body, if k % 5 == 4 { None } else { Some(&pad) })
                .unwrap();
            total ^= fnv1a(frame.data.iter().copied()).rotate_left(k);
        }
    }
    assert_eq!(total, RECORDED, "got {total:#018x}");
}

/// The depth camera's frames among boxes near and far, the camera inside one of them
/// for a frame, hashed as above (recorded before its slab loop replaced parry, b7d52f0
/// and earlier).
const RECORDED_DEPTH: u64 = 0x97f1_1946_e5ed_1778;

#[test]
fn the_depth_camera_renders_the_recorded_frames_byte_for_byte() {
    use sim::depth::{DepthCamera, DepthCameraParams};
    use sim::geometry::Obb;
    let mut cam = DepthCamera::new(DepthCameraParams::default()).unwrap();
    let boxes: Vec<Obb> = (0..6)
        .map(|i| {
            let f = f64::from(i);
            Obb {
                world_from_box: Isometry3::from_parts(
                    Translation3::new(2.0 + 1.5 * f, -1.0 + 0.7 * f, 0.5 + 0.2 * f),
                    UnitQuaternion::from_euler_angles(0.0, 0.1 * f, 0.4 * f),
                ),
                half_m: [0.3 + 0.1 * f, 0.5, 0.5 + 0.1 * f],
            }
        })
        .collect();
    let mut total = 0u64;
    for k in 0..40u32 {
        let kf = f64::from(k);
        let world_from_body = if k == 7 {
            // Inside the first box: every ray starts in it.
            Isometry3::from_parts(
                Translation3::new(2.0, -1.0, 0.5),
                UnitQuaternion::identity(),
            )
        } else {
            Isometry3::from_parts(
                Translation3::new(-1.0 + 0.1 * kf, -0.5 + 0.05 * kf, 0.8 + 0.05 * kf),
                UnitQuaternion::from_euler_angles(0.03 * (kf % 3.0), 0.02 * (kf % 5.0), 0.05 * kf),
            )
        };
        let frame = cam.render(&world_from_body, &boxes);
        total ^= fnv1a(frame.depth_mm.iter().flat_map(|v| v.to_le_bytes())).rotate_left(k);
    }
    assert_eq!(total, RECORDED_DEPTH, "got {total:#018x}");
}
