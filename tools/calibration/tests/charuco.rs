#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test
//! The calibration recovers a camera it did not see: 24 views of a ChArUco board
//! rendered (supersampled) through the stack's own down camera (640x480, fx = fy =
//! 184.75 px, a 120 deg wide-angle lens with its distortion), at poses spread over the
//! image, and two views that must be rejected.

use std::path::PathBuf;

use calibration::synthetic::{Renderer, spread_poses};
use calibration::{CharucoSpec, calibrate, detect};
use nalgebra::{Rotation3, Vector3};
use opencv::core::{CV_8UC1, Mat, Scalar};
use optics::CameraCalibration;

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

#[test]
fn twenty_four_rendered_views_recover_the_down_camera_within_one_percent_and_two_pixels() {
    let truth = CameraCalibration::load(workspace().join("deploy/config/camera_down_640x480.yaml"))
        .unwrap();
    let spec: CharucoSpec = "charuco:6x4:0.04:0.03:DICT_4X4_50".parse().unwrap();
    let board = spec.board().unwrap();
    let texture = spec.image(120).unwrap();
    let size_m = (6.0 * 0.04, 4.0 * 0.04);
    let renderer = Renderer::new(&truth, 3);
    let facing = Rotation3::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
    let centre = Vector3::new(size_m.0 / 2.0, size_m.1 / 2.0, 0.0);
    let mut detections = Vec::new();
    let mut rejected = Vec::new();
    // The centre 0.16 to 0.28 m away, out to the image's corners.
    let poses = spread_poses(24, 7, size_m, (0.16, 0.28), 1.0);
    for (i, (rotation, translation)) in poses.iter().enumerate() {
        let view = renderer
            .render(&texture, size_m, rotation, translation)
            .unwrap();
        match detect(&format!("view{i:02}"), &view, &spec, &board) {
            Ok(det) => detections.push(det),
            Err(r) => rejected.push(r),
        }
    }
    // A view without the board, and one with the board too far to read.
    let blank = Mat::new_rows_cols_with_default(480, 640, CV_8UC1, Scalar::all(200.0)).unwrap();
    rejected.push(detect("blank", &blank, &spec, &board).unwrap_err());
    let far = renderer
        .render(
            &texture,
            size_m,
            &facing,
            &(Vector3::new(0.0, 0.0, 2.5) - facing * centre),
        )
        .unwrap();
    rejected.push(detect("far", &far, &spec, &board).unwrap_err());

    let c = calibrate(&detections, rejected, (640, 480), &board).unwrap();
    let k = &c.calibration;
    println!(
        "{} views used, {} rejected {:?}; rms {:.3} px; coverage {:.0} %; fx {:.3} fy {:.3} cx {:.3} cy {:.3} dist {:?}",
        c.per_view_px.len(),
        c.rejected.len(),
        c.rejected
            .iter()
            .map(|r| format!("{}: {}", r.name, r.why))
            .collect::<Vec<_>>(),
        c.rms_px,
        c.coverage * 100.0,
        k.fx,
        k.fy,
        k.cx,
        k.cy,
        k.distortion
    );
    assert!(c.per_view_px.len() >= 20, "20 or more views used");
    assert!(
        (k.fx / truth.fx - 1.0).abs() < 0.01,
        "fx {} vs {}",
        k.fx,
        truth.fx
    );
    assert!(
        (k.fy / truth.fy - 1.0).abs() < 0.01,
        "fy {} vs {}",
        k.fy,
        truth.fy
    );
    assert!((k.cx - truth.cx).abs() < 2.0, "cx {} vs {}", k.cx, truth.cx);
    assert!((k.cy - truth.cy).abs() < 2.0, "cy {} vs {}", k.cy, truth.cy);
    assert!(c.rms_px < 0.5, "rms {}", c.rms_px);
    let names: Vec<&str> = c.rejected.iter().map(|r| r.name.as_str()).collect();
    assert!(
        names.contains(&"blank") && names.contains(&"far"),
        "{names:?}"
    );
    // The fitted lens maps the image's corner where the true one does (the distortion
    // as a whole, not coefficient by coefficient, which trade off).
    for corner in [(0.0, 0.0), (639.0, 479.0), (320.0, 0.0)] {
        let p = nalgebra::Point2::new(corner.0, corner.1);
        let (a, b) = (truth.undistort_pixel(&p), k.undistort_pixel(&p));
        let err_px = (a - b).norm() * truth.fx;
        assert!(
            err_px < 3.0,
            "the ray of pixel {corner:?} is {err_px:.2} px off"
        );
    }
}
