#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Calibration files and the pad model, checked against OpenCV itself.

use std::path::PathBuf;

use nalgebra::{Point2, Point3};
use opencv::aruco;
use opencv::core::{Point2f, Vector};
use opencv::prelude::*;
use optics::{CalibrationError, CameraCalibration, PadError, PadModel};

fn config(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../deploy/config")
        .join(name)
}

fn temp_file(name: &str, text: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("optics-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

const GOOD_YAML: &str = "%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\ncamera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 184.75, 0., 320., 0., 184.75, 240., 0., 0., 1. ]\ndistortion_coefficients: !!opencv-matrix\n   rows: 1\n   cols: 5\n   dt: d\n   data: [ -0.05, 0.01, 0.0005, 0.0005, 0. ]\n";

#[test]
fn the_shipped_calibrations_load_with_a_120_degree_horizontal_field_of_view() {
    for (name, w, h, f) in [
        ("camera_down_1280x720.yaml", 1280, 720, 369.5),
        ("camera_down_640x480.yaml", 640, 480, 184.75),
    ] {
        let c = CameraCalibration::load(config(name)).unwrap();
        assert_eq!((c.width, c.height), (w, h));
        assert_eq!((c.fx, c.fy), (f, f));
        assert_eq!((c.cx, c.cy), (f64::from(w) / 2.0, f64::from(h) / 2.0));
        assert_eq!(c.distortion, [-0.05, 0.01, 0.0005, 0.0005, 0.0]);
        let hfov = 2.0 * (f64::from(w) / 2.0 / c.fx).atan().to_degrees();
        assert!((hfov - 120.0).abs() < 0.01, "{name}: hfov {hfov}");
    }
}

#[test]
fn undistort_pixel_inverts_project_across_the_whole_image() {
    let c = CameraCalibration::load(config("camera_down_1280x720.yaml")).unwrap();
    for v in (0..=720).step_by(40) {
        for u in (0..=1280).step_by(40) {
            let px = Point2::new(f64::from(u), f64::from(v));
            let n = c.undistort_pixel(&px);
            let back = c.project(&Point3::new(n.x * 2.0, n.y * 2.0, 2.0)).unwrap();
            assert!(
                (back - px).norm() < 1e-6,
                "pixel {px:?} came back as {back:?}"
            );
        }
    }
}

#[test]
fn undistort_pixel_agrees_with_opencv_undistort_points() {
    let c = CameraCalibration::load(config("camera_down_640x480.yaml")).unwrap();
    let pixels: Vec<Point2f> = [
        (0.0, 0.0),
        (639.0, 479.0),
        (100.0, 400.0),
        (320.0, 240.0),
        (600.0, 30.0),
    ]
    .iter()
    .map(|&(u, v)| Point2f::new(u, v))
    .collect();
    let src = Vector::<Point2f>::from_iter(pixels.iter().copied());
    let mut dst = Vector::<Point2f>::new();
    let criteria = opencv::core::TermCriteria::new(3, 100, 1e-12).unwrap();
    opencv::calib3d::undistort_points_iter(
        &src,
        &mut dst,
        &c.camera_matrix_mat().unwrap(),
        &c.distortion_mat().unwrap(),
        &opencv::core::no_array(),
        &opencv::core::no_array(),
        criteria,
    )
    .unwrap();
    for (p, o) in pixels.iter().zip(dst.iter()) {
        let n = c.undistort_pixel(&Point2::new(f64::from(p.x), f64::from(p.y)));
        assert!(
            (n.x - f64::from(o.x)).abs() < 1e-4 && (n.y - f64::from(o.y)).abs() < 1e-4,
            "{p:?}: {n:?} vs {o:?}"
        );
    }
}

#[test]
fn a_saved_calibration_loads_back_unchanged() {
    let c = CameraCalibration::load(config("camera_down_1280x720.yaml")).unwrap();
    let p = temp_file("saved.yaml", "");
    c.save(&p).unwrap();
    assert_eq!(CameraCalibration::load(&p).unwrap(), c);
}

#[test]
fn a_missing_calibration_file_is_an_error_naming_the_file() {
    let err = CameraCalibration::load("/nonexistent/cam_missing.yaml").unwrap_err();
    assert!(matches!(err, CalibrationError::Missing { .. }));
    assert!(
        err.to_string().contains("/nonexistent/cam_missing.yaml"),
        "{err}"
    );
}

#[test]
fn a_calibration_without_a_camera_matrix_is_an_error_naming_the_key() {
    let text = GOOD_YAML.replace("camera_matrix", "kamera_matrix");
    let p = temp_file("nokey.yaml", &text);
    let err = CameraCalibration::load(&p).unwrap_err();
    assert!(
        matches!(
            err,
            CalibrationError::MissingKey {
                key: "camera_matrix",
                ..
            }
        ),
        "{err}"
    );
    assert!(err.to_string().contains("nokey.yaml"), "{err}");
}

#[test]
fn a_camera_matrix_of_the_wrong_size_is_rejected() {
    let text = GOOD_YAML.replace(
        "rows: 3\n   cols: 3\n   dt: d\n   data: [ 184.75, 0., 320., 0., 184.75, 240., 0., 0., 1. ]",
        "rows: 2\n   cols: 3\n   dt: d\n   data: [ 184.75, 0., 320., 0., 184.75, 240. ]",
    );
    let p = temp_file("size.yaml", &text);
    let err = CameraCalibration::load(&p).unwrap_err();
    assert!(
        matches!(
            err,
            CalibrationError::WrongSize {
                key: "camera_matrix",
                rows: 2,
                cols: 3,
                ..
            }
        ),
        "{err}"
    );
}

#[test]
fn a_non_positive_focal_length_is_rejected() {
    let text = GOOD_YAML.replace("data: [ 184.75, 0., 320.", "data: [ -184.75, 0., 320.");
    let p = temp_file("focal.yaml", &text);
    let err = CameraCalibration::load(&p).unwrap_err();
    assert!(err.to_string().contains("fx"), "{err}");
    assert!(CameraCalibration::new(640, 480, f64::NAN, 100.0, 320.0, 240.0, [0.0; 5]).is_err());
}

fn pad() -> PadModel {
    PadModel::load(config("pad.toml")).unwrap()
}

#[test]
fn the_pad_has_the_papers_markers_with_43_at_the_landing_point() {
    let pad = pad();
    let mut ids: Vec<u32> = pad.markers.iter().map(|m| m.id).collect();
    ids.sort_unstable();
    assert_eq!(ids, vec![1, 2, 3, 4, 5, 6, 7, 8, 43, 68]);
    for (id, size) in [
        (43, 0.025),
        (5, 0.064),
        (8, 0.064),
        (1, 0.095),
        (4, 0.095),
        (68, 0.257),
    ] {
        assert_eq!(pad.marker(id).unwrap().size_m, size, "marker {id}");
    }
    assert_eq!(pad.marker(43).unwrap().centre_m, [0.0, 0.0]);
}

#[test]
fn marker_corners_follow_opencvs_order_with_image_up_as_pad_y() {
    let pad = pad();
    let c = pad.marker_corners_pad(43).unwrap();
    let h = 0.0125;
    assert_eq!(c[0], Point3::new(-h, h, 0.0)); // top-left
    assert_eq!(c[1], Point3::new(h, h, 0.0)); // top-right
    assert_eq!(c[2], Point3::new(h, -h, 0.0)); // bottom-right
    assert_eq!(c[3], Point3::new(-h, -h, 0.0)); // bottom-left
    assert!(matches!(
        pad.marker_corners_pad(99),
        Err(PadError::UnknownMarker(99))
    ));
}

#[test]
fn pad_validation_errors_name_the_key() {
    let text = std::fs::read_to_string(config("pad.toml")).unwrap();
    let cases = [
        (text.replacen("id = 5\n", "id = 43\n", 1), "markers[1].id"),
        (
            text.replacen("size_m = 0.064", "size_m = -0.064", 1),
            "markers[1].size_m",
        ),
        (
            text.replacen("centre_m = [0.054, 0.054]", "centre_m = [0.01, 0.01]", 1),
            "markers[1].centre_m",
        ),
        (
            text.replacen("centre_m = [0.252, 0.252]", "centre_m = [0.4, 0.252]", 1),
            "markers[9].centre_m[0]",
        ),
        (text.replacen("id = 68", "id = 2000", 1), "markers[9].id"),
        (
            text.replacen(
                "active_range_m = [0.8, 3.5]",
                "active_range_m = [0.8, 0.5]",
                1,
            ),
            "markers[9].active_range_m[1]",
        ),
        (
            text.replacen("max_m = [0.42, 0.42]", "max_m = [-0.3, 0.42]", 1),
            "board.max_m[0]",
        ),
        (
            text.replacen("\"ARUCO_ORIGINAL\"", "\"DICT_4X4_50\"", 1),
            "dictionary",
        ),
    ];
    for (t, key) in cases {
        let err = PadModel::from_toml(&t).unwrap_err();
        assert!(err.to_string().contains(key), "expected {key} in: {err}");
    }
}

#[test]
fn the_pad_texture_decodes_to_every_marker_with_opencvs_detector() {
    let pad = pad();
    let ppm = 800.0;
    let tex = pad.render_texture(ppm).unwrap();
    assert_eq!((tex.cols(), tex.rows()), pad.texture_size(ppm));
    let dict =
        aruco::get_predefined_dictionary(aruco::PREDEFINED_DICTIONARY_NAME::DICT_ARUCO_ORIGINAL)
            .unwrap();
    let mut corners = Vector::<Vector<Point2f>>::new();
    let mut ids = Vector::<i32>::new();
    aruco::detect_markers_def(&tex, &dict, &mut corners, &mut ids).unwrap();
    let mut found: Vec<i32> = ids.to_vec();
    found.sort_unstable();
    assert_eq!(found, vec![1, 2, 3, 4, 5, 6, 7, 8, 43, 68]);
    // The detected top-left corner of 68 is where the model says it is.
    let k = ids.iter().position(|i| i == 68).unwrap();
    let tl = corners.get(k).unwrap().get(0).unwrap();
    let model = pad.marker_corners_pad(68).unwrap()[0];
    let expect_u = (model.x - pad.board.min_m[0]) * ppm;
    let expect_v = (pad.board.max_m[1] - model.y) * ppm;
    assert!(
        (f64::from(tl.x) - expect_u).abs() < 1.5 && (f64::from(tl.y) - expect_v).abs() < 1.5,
        "{tl:?} vs ({expect_u}, {expect_v})"
    );
}
