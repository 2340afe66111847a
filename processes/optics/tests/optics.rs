#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Calibration files and the pad model, checked against OpenCV itself.

use std::path::PathBuf;

use nalgebra::{Point2, Point3};
use opencv::aruco;
use opencv::core::{Point2f, Vector};
use opencv::prelude::*;
use optics::{CalibrationError, CameraCalibration, MARKER_CELLS, PadError, PadModel, marker_cells};

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
            text.replacen("max_m = [0.42, 0.42]", "max_m = [0.42, 0.5]", 1),
            "board.max_m[1] = 0.5: must be -board.min_m[1] (0.42): the board is centred",
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

#[test]
fn the_shipped_board_is_centred_on_the_landing_point() {
    let b = pad().board;
    assert_eq!(b.min_m, [-b.max_m[0], -b.max_m[1]]);
}

/// The colour the model gives pad point (x, y): `Some(true)` for black, `None`
/// within `tie` of a cell edge (where rounding may go either way).
fn model_is_black(
    pad: &PadModel,
    cells: &[[[bool; MARKER_CELLS]; MARKER_CELLS]],
    x: f64,
    y: f64,
    tie: f64,
) -> Option<bool> {
    for (m, cells) in pad.markers.iter().zip(cells) {
        let cell = m.size_m / MARKER_CELLS as f64;
        let u = (x - (m.centre_m[0] - m.size_m / 2.0)) / cell;
        let v = ((m.centre_m[1] + m.size_m / 2.0) - y) / cell;
        let n = MARKER_CELLS as f64;
        if u < -tie || v < -tie || u > n + tie || v > n + tie {
            continue;
        }
        let near_edge = |t: f64| (t - t.round()).abs() * cell < tie;
        if near_edge(u) || near_edge(v) {
            return None;
        }
        if u < 0.0 || v < 0.0 || u > n || v > n {
            continue;
        }
        return Some(cells[v as usize][u as usize]);
    }
    Some(false)
}

#[test]
fn every_texel_is_black_exactly_when_its_centre_is_in_a_black_cell() {
    let pad = pad();
    let cells: Vec<_> = pad
        .markers
        .iter()
        .map(|m| marker_cells(m.id).unwrap())
        .collect();
    for ppm in [100.0, 1000.0, 150.0 / 0.0254, 2000.0] {
        let tex = pad.render_texture(ppm).unwrap();
        let bytes = tex.data_bytes().unwrap();
        let cols = tex.cols() as usize;
        let tie = 1e-6 / ppm;
        let (mut checked, mut black) = (0, 0);
        for (i, &texel) in bytes.iter().enumerate() {
            let (c, r) = (i % cols, i / cols);
            let x = pad.board.min_m[0] + (c as f64 + 0.5) / ppm;
            let y = pad.board.max_m[1] - (r as f64 + 0.5) / ppm;
            assert!(
                texel == 0 || texel == 255,
                "texel ({c}, {r}) = {texel}: no blur"
            );
            if let Some(expect) = model_is_black(&pad, &cells, x, y, tie) {
                assert_eq!(texel == 0, expect, "ppm {ppm}: texel ({c}, {r})");
                checked += 1;
                black += usize::from(expect);
            }
        }
        assert!(black > 0 && checked > bytes.len() * 99 / 100);
    }
}

#[test]
fn a_marker_drawn_one_pixel_per_cell_is_its_cell_matrix() {
    let cells = marker_cells(43).unwrap();
    // The border is black all round; the 5 x 5 data bits are not all one colour.
    let last = MARKER_CELLS - 1;
    assert!(cells[0].iter().chain(&cells[last]).all(|&b| b));
    assert!(cells.iter().all(|row| row[0] && row[last]));
    let data: usize = (1..6)
        .flat_map(|r| (1..6).map(move |c| (r, c)))
        .filter(|&(r, c)| cells[r][c])
        .count();
    assert!(data > 0 && data < 25, "{data}");
    assert!(matches!(
        marker_cells(1024),
        Err(PadError::UnknownMarker(1024))
    ));
}

#[test]
fn the_texture_at_a_print_resolution_is_the_board_in_whole_dots() {
    let pad = pad();
    let (w, h) = (
        pad.board.max_m[0] - pad.board.min_m[0],
        pad.board.max_m[1] - pad.board.min_m[1],
    );
    for dpi in (50..=1200).map(f64::from).chain([72.5, 96.0, 299.9]) {
        let expect = (
            (w / 0.0254 * dpi).round() as i32,
            (h / 0.0254 * dpi).round() as i32,
        );
        assert_eq!(pad.texture_size(dpi / 0.0254), expect, "{dpi} dpi");
    }
    assert!(pad.render_texture(1200.0 / 0.0254 * 1.1).is_err());
}

#[test]
fn a_pad_file_that_does_not_parse_is_one_line_naming_the_file_and_the_line() {
    let text = std::fs::read_to_string(config("pad.toml")).unwrap();
    let p = temp_file(
        "bad_pad.toml",
        &text.replacen("size_m = 0.064", "size_m = \"big\"", 1),
    );
    let err = PadModel::load(&p).unwrap_err().to_string();
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains(p.to_str().unwrap()), "{err}");
    let line = text.lines().position(|l| l == "size_m = 0.064").unwrap() + 1;
    assert!(err.contains(&format!("line {line}: ")), "{err}");
}

#[test]
fn a_file_that_hangs_opencvs_yaml_parser_is_refused_at_once_naming_the_line() {
    // OpenCV 4.6's FileStorage loops forever on this (found by landing-fuzz); the
    // stack's own reader refuses it.
    let p = temp_file("hang.yaml", "%YAML:1.\n t:d\nncv-\n");
    let err = CameraCalibration::load(&p).unwrap_err();
    assert!(
        matches!(err, CalibrationError::Syntax { line: 2, .. }),
        "{err}"
    );
    assert!(err.to_string().contains("hang.yaml: line 2:"), "{err}");
}

#[test]
fn a_ros_camera_calibration_file_loads_like_opencvs() {
    // What ROS's camera_calibration writes (ost.yaml): untagged matrices, extra keys.
    let ros = "image_width: 640\nimage_height: 480\ncamera_name: narrow_stereo\n\
        camera_matrix:\n  rows: 3\n  cols: 3\n  data: [184.75, 0, 320, 0, 184.75, 240, 0, 0, 1]\n\
        distortion_model: plumb_bob\n\
        distortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [-0.05, 0.01, 0.0005, 0.0005, 0]\n\
        rectification_matrix:\n  rows: 3\n  cols: 3\n  data: [1, 0, 0,\n         0, 1, 0,\n         0, 0, 1]\n";
    let from_ros = CameraCalibration::load(temp_file("ost.yaml", ros)).unwrap();
    let from_opencv = CameraCalibration::load(temp_file("good.yaml", GOOD_YAML)).unwrap();
    assert_eq!(from_ros, from_opencv);
    let fisheye = ros.replace("plumb_bob", "equidistant");
    let err = CameraCalibration::load(temp_file("fisheye.yaml", &fisheye)).unwrap_err();
    assert!(err.to_string().contains("equidistant"), "{err}");
}

#[test]
fn opencvs_multi_line_data_comments_and_extra_keys_are_read() {
    let text = "%YAML:1.0\n---\ncalibration_time: \"Fri 27 Nov # not a comment\"\nnframes: 20\n\
        image_width: 640 # px\nimage_height: 480\ncamera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n\
        \x20  data: [ 1.8475000000000000e+02, 0., 320., 0.,\n       1.8475000000000000e+02, 240., 0., 0., 1. ]\n\
        distortion_coefficients: !!opencv-matrix\n   rows: 5\n   cols: 1\n   dt: d\n   data: [ -0.05, 0.01, 0.0005, 0.0005, 0. ]\n\
        avg_reprojection_error: 0.21\n";
    let c = CameraCalibration::load(temp_file("multi.yaml", text)).unwrap();
    assert_eq!(
        c,
        CameraCalibration::load(temp_file("good2.yaml", GOOD_YAML)).unwrap()
    );
}

#[test]
fn malformed_calibrations_are_refused_naming_the_line_and_what_is_allowed() {
    for (name, text, says) in [
        (
            "twice.yaml",
            GOOD_YAML.replace("image_height: 480", "image_width: 480"),
            "line 4: `image_width` is given twice",
        ),
        (
            "count.yaml",
            GOOD_YAML.replace("1. ]", "]"),
            "3x3 needs 9 values, data has 8",
        ),
        (
            "unclosed.yaml",
            GOOD_YAML.replace("1. ]", "1."),
            "data is not one list",
        ),
        (
            "nan.yaml",
            GOOD_YAML.replace("320.", "three-twenty"),
            "`three-twenty` is not a number",
        ),
        (
            "tab.yaml",
            GOOD_YAML.replace("   rows: 1", "\trows: 1"),
            "a tab in the indentation",
        ),
        (
            "huge.yaml",
            GOOD_YAML.replace("rows: 3", "rows: 100000"),
            "rows 100000: allowed 1 to 64",
        ),
        (
            "twochannel.yaml",
            GOOD_YAML.replace("dt: d\n   data: [ 184", "dt: 2d\n   data: [ 184"),
            "allowed one channel",
        ),
        (
            "big.yaml",
            format!("{GOOD_YAML}# {}\n", "x".repeat(70_000)),
            "larger than 65536 bytes",
        ),
    ] {
        let err = CameraCalibration::load(temp_file(name, &text)).unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains(name) && msg.contains(says), "{name}: {msg}");
    }
    let mut bytes = GOOD_YAML.as_bytes().to_vec();
    bytes[40] = 0xff;
    let p = temp_file("latin.yaml", "");
    std::fs::write(&p, bytes).unwrap();
    let msg = CameraCalibration::load(&p).unwrap_err().to_string();
    assert!(msg.contains("not UTF-8 text (byte 40)"), "{msg}");
}
