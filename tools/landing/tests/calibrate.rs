#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test
//! `landing calibrate camera` as a user runs it: a directory of views of a ChArUco board
//! (rendered here through the shipped down camera, 22 of them plus an unreadable file),
//! the calibration YAML written and read back by the stack's own loader, the figure.

use std::path::PathBuf;
use std::process::Command;

use calibration::CharucoSpec;
use calibration::synthetic::{Renderer, spread_poses};
use opencv::prelude::*;
use optics::CameraCalibration;

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn landing(args: &[&str]) -> (Option<i32>, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_landing"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

const BOARD: &str = "charuco:6x4:0.04:0.03:DICT_4X4_50";

#[test]
fn landing_calibrate_camera_writes_the_calibration_the_stack_reads_and_its_figure() {
    let truth = CameraCalibration::load(workspace().join("deploy/config/camera_down_640x480.yaml"))
        .unwrap();
    let spec: CharucoSpec = BOARD.parse().unwrap();
    let texture = spec.image(120).unwrap();
    let size_m = (0.24, 0.16);
    let renderer = Renderer::new(&truth, 3);
    let dir = std::env::temp_dir().join(format!("calib_views_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    for (i, (r, t)) in spread_poses(22, 11, size_m, (0.16, 0.28), 1.0)
        .iter()
        .enumerate()
    {
        let view = renderer.render(&texture, size_m, r, t).unwrap();
        let path = dir.join(format!("view{i:02}.png"));
        assert!(
            opencv::imgcodecs::imwrite(
                &*path.to_string_lossy(),
                &view,
                &opencv::core::Vector::new()
            )
            .unwrap()
        );
    }
    std::fs::write(dir.join("zz_broken.png"), b"not a png").unwrap();
    let yaml = dir.join("camera.yaml");
    let plot = dir.join("calibration.png");
    let (code, out, err) = landing(&[
        "calibrate",
        "camera",
        "--board",
        BOARD,
        "--images",
        &dir.to_string_lossy(),
        "--out",
        &yaml.to_string_lossy(),
        "--plot",
        &plot.to_string_lossy(),
    ]);
    println!("{out}");
    assert_eq!(code, Some(0), "{out}\n{err}");
    assert!(
        out.contains("zz_broken.png") || out.contains("1 rejected"),
        "{out}"
    );
    assert!(out.contains("RMS reprojection error"), "{out}");
    let k = CameraCalibration::load(&yaml).unwrap();
    assert_eq!((k.width, k.height), (640, 480));
    assert!((k.fx / truth.fx - 1.0).abs() < 0.01, "fx {}", k.fx);
    assert!((k.fy / truth.fy - 1.0).abs() < 0.01, "fy {}", k.fy);
    assert!((k.cx - truth.cx).abs() < 2.0 && (k.cy - truth.cy).abs() < 2.0);
    let figure = opencv::imgcodecs::imread_def(&*plot.to_string_lossy()).unwrap();
    assert!(figure.cols() > 800, "the figure was drawn");
    let _ = std::fs::copy(&plot, std::env::temp_dir().join("calibration_figure.png"));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_mistaken_board_or_an_empty_directory_is_one_line_naming_what_is_allowed() {
    let dir = std::env::temp_dir().join(format!("calib_empty_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let d = dir.to_string_lossy().into_owned();
    for (args, expected) in [
        (
            vec![
                "calibrate",
                "camera",
                "--board",
                "charuco:7x5:0.03:0.04:DICT_5X5_100",
                "--images",
                &d,
                "--out",
                "/tmp/x.yaml",
            ],
            "a marker smaller than its square (allowed: charuco:",
        ),
        (
            vec![
                "calibrate",
                "camera",
                "--images",
                &d,
                "--out",
                "/tmp/x.yaml",
            ],
            "no images (looked for png",
        ),
    ] {
        let (code, _, err) = landing(&args);
        assert_eq!(code, Some(2), "{err}");
        assert!(err.contains(expected), "{err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
