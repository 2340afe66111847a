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

#[test]
fn landing_calibrate_mount_finds_a_tilted_down_camera_within_one_degree_from_a_survey_over_a_static_pad()
 {
    // The shipped indoor-static world (a static pad), the preset moved so that the
    // vehicle flies 2 m to the pad, and a camera as calibrated but mounted off its
    // drawing: 2 deg (1 sigma) about each axis, drawn per seed. The stack flies the
    // shipped configuration with the survey on ([fsm.survey]: a square around the pad
    // at two heights, yawed either way at each corner) before it lands.
    let dir = std::env::temp_dir().join(format!("calib_mount_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let base =
        std::fs::read_to_string(workspace().join("deploy/scenarios/indoor-static.toml")).unwrap();
    let scenario = base
        .replace("name = \"indoor-static\"", "name = \"mount-hover\"")
        .replace(
            "preset_m = [0.0, 0.0, 0.75]",
            "preset_m = [-1.0, -0.6, 2.0]",
        )
        + "\n[camera.errors]\nfocal_fraction = 0.0\nprincipal_point_px = 0.0\n\
           distortion = [0.0, 0.0, 0.0, 0.0, 0.0]\nmount_rotation_deg = 2.0\n\
           mount_translation_m = 0.0\n";
    let path = dir.join("mount-hover.toml");
    std::fs::write(&path, scenario).unwrap();
    let loaded = sim::scenario::load(&path.to_string_lossy(), &workspace().join("deploy")).unwrap();
    let nominal = CameraCalibration::load(loaded.calibration_path()).unwrap();
    let config_dir = workspace().join("deploy/config");
    let config = dir.join("landing.toml");
    let mut text = std::fs::read_to_string(config_dir.join("landing.toml")).unwrap();
    for file in ["camera_down_640x480.yaml", "pad.toml"] {
        let quoted = format!("\"{file}\"");
        assert!(text.contains(&quoted), "landing.toml names no {file}");
        text = text.replace(&quoted, &format!("{:?}", config_dir.join(file)));
    }
    let off = "[fsm.survey]\n";
    assert!(text.contains(off), "landing.toml has no [fsm.survey]");
    text = text.replace(off, "[fsm.survey]\nhalf_side_m = 0.6\n");
    text = text.replacen("half_side_m = 0.0\n", "", 1);
    std::fs::write(&config, text).unwrap();
    // MOUNT_SEEDS=1-12 runs more (the notes of issue 40 quote twelve).
    let seeds: Vec<u64> = match std::env::var("MOUNT_SEEDS") {
        Ok(r) => {
            let (a, b) = r.split_once('-').unwrap_or((&r, &r));
            (a.parse().unwrap()..=b.parse().unwrap()).collect()
        }
        Err(_) => vec![3, 4, 5],
    };
    let (mut worst, mut worst_axis): (f64, f64) = (0.0, 0.0);
    let mut offs = Vec::new();
    for seed in seeds {
        let rec = dir.join(format!("flight{seed}.mcap"));
        let (code, out, err) = landing(&[
            "run",
            "--scenario",
            &path.to_string_lossy(),
            "--seed",
            &seed.to_string(),
            "--record",
            &rec.to_string_lossy(),
            "--config",
            &config.to_string_lossy(),
        ]);
        assert!(
            out.contains("landed") || err.contains("landed"),
            "{out}\n{err}"
        );
        assert_eq!(code, Some(0), "{out}\n{err}");
        let (code, out, err) = landing(&[
            "calibrate",
            "mount",
            "--recording",
            &rec.to_string_lossy(),
            "--json",
        ]);
        assert_eq!(code, Some(0), "{out}\n{err}");
        let fit: serde_json::Value = serde_json::from_str(&out).unwrap();
        assert!(fit["rms_position_m"].as_f64().unwrap() < 0.05, "{fit}");
        assert!(
            fit["time_offset_ms"].as_f64().unwrap().abs() <= 100.0,
            "{fit}"
        );
        let q: Vec<f64> = fit["body_from_camera_xyzw"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let found = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
            q[3], q[0], q[1], q[2],
        ));
        // The mount the simulator built for this seed (the tool never sees it).
        let (_, mount_error) = loaded
            .scenario
            .camera
            .errors
            .draw(&nominal, seed.wrapping_add(4))
            .unwrap();
        let camera_from_body =
            mount_error.inverse() * loaded.scenario.camera.sensor.camera_from_body();
        let truth = camera_from_body.inverse().rotation;
        let drawing = loaded
            .scenario
            .camera
            .sensor
            .camera_from_body()
            .inverse()
            .rotation;
        let off = (found.inverse() * truth).angle().to_degrees();
        // Where the camera looks (its optical axis in the body): what puts the pad off
        // by 1.7 cm per degree and metre of height.
        let axis = (found * nalgebra::Vector3::z())
            .angle(&(truth * nalgebra::Vector3::z()))
            .to_degrees();
        let built = (drawing.inverse() * truth).angle().to_degrees();
        let (r, p, y) = (truth * drawing.inverse()).euler_angles();
        println!(
            "seed {seed}: the camera is {built:.2} deg off its drawing (roll {:.2} pitch {:.2} yaw {:.2} about body x y z); found within {off:.2} deg, its optical axis within {axis:.2} deg ({fit})",
            r.to_degrees(),
            p.to_degrees(),
            y.to_degrees()
        );
        assert!(
            built > 1.0,
            "the world must tilt the camera for the test to mean anything"
        );
        worst = worst.max(off);
        worst_axis = worst_axis.max(axis);
        offs.push(off);
    }
    offs.sort_by(f64::total_cmp);
    println!(
        "over {} seeds: median {:.2} deg, worst {worst:.2} deg; optical axis worst {worst_axis:.2} deg",
        offs.len(),
        offs[offs.len() / 2]
    );
    // Without the survey (the mission's flight alone, a slanted line from the preset
    // down to the pad) roll and yaw showed too weakly: 0.6 and 2.0 deg on seeds 3 and 4.
    // The optical axis is held to 1 deg. The turn about it is held to 1.5: the
    // simulated autopilot's heading drifts (0.1 deg per square root of a second, a VIO's),
    // and in level flight a heading error is the same to the camera as a camera turned
    // on the body (docs/calibration.md); over 12 seeds 11 were within 1 deg.
    assert!(
        worst_axis < 1.0,
        "the optical axis was found {worst_axis:.2} deg off"
    );
    assert!(worst < 1.5, "the mount was found {worst:.2} deg off");
    std::fs::remove_dir_all(&dir).unwrap();
}
