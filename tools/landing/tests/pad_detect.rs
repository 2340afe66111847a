//! `landing pad detect` on images written to disk: the pose of a rendered pad, exit 3 on
//! an image without one, one-line errors for unreadable input.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use opencv::core::{Mat, Scalar, Vector};
use opencv::imgcodecs;
use optics::{CameraCalibration, PadModel};
use sim::camera::{BodyMotion, DownCamera, DownCameraParams};
use sim::ground_vehicle::PadState;

fn config(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../deploy/config")
        .join(name)
}

fn landing(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_landing"))
        .args(args)
        .output()
        .expect("run landing")
}

fn temp(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("landing-pad-detect-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn write_png(path: &Path, rows: i32, cols: i32, data: &[u8]) {
    let m = Mat::new_rows_cols_with_data(rows, cols, data).unwrap();
    imgcodecs::imwrite(path.to_str().unwrap(), &m, &Vector::new()).unwrap();
}

#[test]
fn a_rendered_pad_image_gives_its_ids_and_pose_as_json() {
    let dir = temp("found");
    let cam_file = config("camera_down_640x480.yaml");
    let calib = CameraCalibration::load(&cam_file).unwrap();
    let pad = PadModel::load(config("pad.toml")).unwrap();
    let mut cam = DownCamera::new(DownCameraParams::default(), calib, &pad).unwrap();
    let state = PadState {
        world_from_pad: Isometry3::from_parts(
            Translation3::new(1.0, 2.0, 0.4),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 0.3),
        ),
        linear_velocity: Vector3::zeros(),
        linear_acceleration: Vector3::zeros(),
        angular_velocity: Vector3::zeros(),
        speed_m_s: 0.0,
        distance_m: 0.0,
    };
    // Camera 1 m above the pad centre, looking down.
    let body_from_camera = cam.camera_from_body().inverse();
    let world_from_camera = Isometry3::from_parts(
        Translation3::from(state.world_from_pad.translation.vector + Vector3::new(0.1, -0.05, 1.0)),
        UnitQuaternion::from_euler_angles(0.0, 0.0, 0.5) * body_from_camera.rotation,
    );
    let body = world_from_camera * cam.camera_from_body();
    let truth = world_from_camera.inverse() * state.world_from_pad;
    let frame = cam
        .render(&BodyMotion::at_rest(body), Some(&state))
        .unwrap();
    let image = dir.join("pad.png");
    write_png(&image, calib.height as i32, calib.width as i32, &frame.data);

    let o = landing(&[
        "pad",
        "detect",
        "--image",
        image.to_str().unwrap(),
        "--camera",
        cam_file.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["found"], true);
    let ids: Vec<u64> = v["ids"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_u64().unwrap())
        .collect();
    assert!(
        ids.contains(&68) && ids.iter().all(|id| pad.marker(*id as u32).is_some()),
        "{ids:?}"
    );
    let t: Vec<f64> = v["camera_from_pad"]["translation"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    let q: Vec<f64> = v["camera_from_pad"]["rotation_xyzw"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    let dt = (Vector3::new(t[0], t[1], t[2]) - truth.translation.vector).norm();
    let rot = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[3], q[0], q[1], q[2]));
    let dr = rot.angle_to(&truth.rotation).to_degrees();
    assert!(dt < 0.01, "position error {dt} m");
    assert!(dr < 0.5, "rotation error {dr} deg");
    assert!(v["reprojection_error_px"].as_f64().unwrap() < 1.0);
}

#[test]
fn an_image_without_a_pad_exits_with_3() {
    let dir = temp("empty");
    let image = dir.join("white.png");
    write_png(&image, 480, 640, &vec![200u8; 640 * 480]);
    let cam = config("camera_down_640x480.yaml");
    let o = landing(&[
        "pad",
        "detect",
        "--image",
        image.to_str().unwrap(),
        "--camera",
        cam.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(o.status.code(), Some(3));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["found"], false);
}

#[test]
fn unreadable_images_and_calibrations_are_one_line_errors() {
    let dir = temp("bad");
    let cam = config("camera_down_640x480.yaml");
    let not_png = dir.join("notes.png");
    std::fs::write(&not_png, "not an image").unwrap();
    let small = dir.join("small.png");
    let m =
        Mat::new_rows_cols_with_default(100, 100, opencv::core::CV_8UC1, Scalar::all(0.0)).unwrap();
    imgcodecs::imwrite(small.to_str().unwrap(), &m, &Vector::new()).unwrap();
    let white = dir.join("white.png");
    write_png(&white, 480, 640, &vec![200u8; 640 * 480]);
    for (image, camera, expect) in [
        (not_png.clone(), cam.clone(), "not an image"),
        (dir.join("missing.png"), cam.clone(), "no such file"),
        (small.clone(), cam.clone(), "100x100"),
        (white.clone(), dir.join("missing.yaml"), "missing.yaml"),
    ] {
        let o = landing(&[
            "pad",
            "detect",
            "--image",
            image.to_str().unwrap(),
            "--camera",
            camera.to_str().unwrap(),
        ]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{image:?}: {err}");
        assert_eq!(err.trim().lines().count(), 1, "{image:?}: {err}");
        assert!(err.contains(expect), "{image:?}: {err}");
    }
}
