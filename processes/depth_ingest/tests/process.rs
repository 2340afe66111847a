#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test
//! depth-ingest and depth-map as real OS processes under their own iceoryx2 prefix: a
//! recording (16-bit PNGs written here, or a RealSense .bag written by librealsense's own
//! recorder through pyrealsense2) played by depth-ingest onto `landing/depth/frame`,
//! mapped by depth-map `--input depth-frame` with a vehicle state published by this test,
//! and the map read through shared memory as the planner would.
//!
//! The scene of both recordings: a box face 2.5 m ahead of the depth camera, filling
//! columns 240-399 and rows 140-339 of a 640x480 image (fx = fy = 380 px, principal
//! point at the centre), no return elsewhere. The vehicle hovers at 1.5 m facing +x, so
//! the face stands at x = 2.6 m (the camera is 0.1 m ahead of the body origin), |y| <=
//! 0.53 m, z from 0.95 to 2.26 m.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use ipc_types::msg::{Header, OccupancyMapHeader, Pose, Stage, VehicleState};
use ipc_types::services;
use landing_tests::process::Running;
use landing_tests::stack::stack_binary;
use runtime::{Ipc, IpcPrefix, monotonic_ns};

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// What the test read in the maps.
struct Report {
    maps: usize,
    /// Occupied cells on the box's face, in the last map.
    on_the_face: usize,
    /// Occupied cells anywhere else, in any map.
    elsewhere: usize,
    /// Free cells in the last map.
    free: usize,
    stages: Vec<Option<Stage>>,
    ingest_log: String,
}

/// Plays `source` through depth-ingest into depth-map for 3 s after the first map that
/// shows the face.
fn map_of(source: &str, extra: &[&str], tag: &str) -> Report {
    let prefix = IpcPrefix::unique(tag);
    let config = workspace().join("deploy/config/landing.toml");
    let mut mapper = Running::start(
        "depth-map",
        Command::new(stack_binary("depth-map"))
            .arg("--config")
            .arg(&config)
            .args(["--input", "depth-frame", "--ipc-prefix", prefix.as_str()]),
    );
    mapper.wait_for("depth-map running", Duration::from_secs(30));
    let mut ingest = Running::start(
        "depth-ingest",
        Command::new(env!("CARGO_BIN_EXE_depth-ingest"))
            .arg("--config")
            .arg(&config)
            .args([
                "--source",
                source,
                "--loop",
                "--ipc-prefix",
                prefix.as_str(),
            ])
            .args(extra),
    );
    ingest.wait_for("depth-ingest running", Duration::from_secs(30));

    let ipc = Ipc::open("depth-ingest-test", &prefix).unwrap();
    let mut states = ipc
        .publisher::<VehicleState>(services::VEHICLE_STATE)
        .unwrap();
    let maps = ipc
        .slice_subscriber::<u8, OccupancyMapHeader>(services::MAP_OCCUPANCY)
        .unwrap();
    let hover = |t: u64| VehicleState {
        msg: Header::captured_at(t),
        world_from_body: Pose {
            translation: [0.0, 0.0, 1.5],
            rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
        },
        ..VehicleState::default()
    };
    let start = Instant::now();
    let mut next_state = Instant::now();
    let mut window_end: Option<Instant> = None;
    let mut report = Report {
        maps: 0,
        on_the_face: 0,
        elsewhere: 0,
        free: 0,
        stages: Vec::new(),
        ingest_log: String::new(),
    };
    while window_end.is_none_or(|e| Instant::now() < e) {
        assert!(
            window_end.is_some() || start.elapsed() < Duration::from_secs(30),
            "no map shows the box in 30 s; depth-ingest said:\n{}\ndepth-map said:\n{}",
            ingest.log(),
            mapper.log()
        );
        if Instant::now() >= next_state {
            let s = hover(monotonic_ns());
            states.send(s.msg, &s).unwrap();
            next_state += Duration::from_millis(10);
        }
        while let Some(m) = maps.receive().unwrap() {
            let h = *m.user_header();
            let [nx, ny, _] = h.dims.map(|d| d as usize);
            let (mut face, mut free) = (0, 0);
            for (i, &c) in m.payload().iter().enumerate() {
                match c {
                    2 => {
                        let x = h.origin[0] + ((i % nx) as f64 + 0.5) * h.resolution;
                        let y = h.origin[1] + (((i / nx) % ny) as f64 + 0.5) * h.resolution;
                        let z = h.origin[2] + ((i / (nx * ny)) as f64 + 0.5) * h.resolution;
                        if (2.3..=2.9).contains(&x) && y.abs() <= 0.75 && (0.75..=2.45).contains(&z)
                        {
                            face += 1;
                        } else {
                            report.elsewhere += 1;
                        }
                    }
                    1 => free += 1,
                    _ => {}
                }
            }
            if window_end.is_none() && face > 0 {
                window_end = Some(Instant::now() + Duration::from_secs(3));
            }
            report.maps += 1;
            report.on_the_face = face;
            report.free = free;
            report.stages = h
                .msg
                .stages()
                .iter()
                .map(|st| Stage::from_raw(st.stage))
                .collect();
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    assert!(ingest.terminate().success(), "{}", ingest.log());
    assert!(mapper.terminate().success(), "{}", mapper.log());
    report.ingest_log = ingest.log();
    report
}

/// The value of `key=N` in depth-ingest's stop line.
fn stopped_count(log: &str, key: &str) -> u64 {
    log.lines()
        .rev()
        .find(|l| l.contains("depth-ingest stopped"))
        .and_then(|l| {
            l.split_whitespace()
                .find_map(|kv| kv.strip_prefix(&format!("{key}=")))
        })
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no {key} in the stop line of:\n{log}"))
}

fn assert_the_map_holds_the_box(r: &Report) {
    println!(
        "{} maps, {} occupied cells on the box's face, {} free, {} occupied elsewhere",
        r.maps, r.on_the_face, r.free, r.elsewhere
    );
    assert!(
        r.on_the_face > 20,
        "the face is occupied ({})",
        r.on_the_face
    );
    assert!(r.free > 2000, "the space before it is free ({})", r.free);
    assert_eq!(r.elsewhere, 0, "occupied cells away from the box");
    assert_eq!(
        r.stages,
        [Some(Stage::DepthIngest), Some(Stage::DepthMap)],
        "the frame's stamps: depth-ingest's, then depth-map's"
    );
    assert!(
        stopped_count(&r.ingest_log, "published") >= 10,
        "{}",
        r.ingest_log
    );
    assert_eq!(stopped_count(&r.ingest_log, "dropped_bad"), 0);
    assert_eq!(stopped_count(&r.ingest_log, "dropped_size"), 0);
}

/// Writes the scene as `frames` 16-bit PNGs into `dir`.
fn write_pngs(dir: &Path, frames: usize) {
    use opencv::core::{CV_16UC1, Mat, Rect, Scalar, Vector};
    use opencv::prelude::*;
    std::fs::create_dir_all(dir).unwrap();
    let mut image = Mat::new_rows_cols_with_default(480, 640, CV_16UC1, Scalar::all(0.0)).unwrap();
    let mut face = Mat::roi_mut(&mut image, Rect::new(240, 140, 160, 200)).unwrap();
    face.set_to(&Scalar::all(2500.0), &opencv::core::no_array())
        .unwrap();
    for k in 0..frames {
        let path = dir.join(format!("depth_{k:04}.png"));
        assert!(
            opencv::imgcodecs::imwrite(&*path.to_string_lossy(), &image, &Vector::new()).unwrap()
        );
    }
}

/// Writes `frames` of the scene into `bag` with librealsense's own recorder (pyrealsense2's
/// software device, tests/peers/realsense_bag.py).
fn write_bag(bag: &Path, frames: usize) {
    let writer = workspace().join("tests/peers/realsense_bag.py");
    let out = Command::new("python3")
        .arg(&writer)
        .arg(bag)
        .args(["--frames", &frames.to_string()])
        .output()
        .expect("python3");
    assert!(
        out.status.success(),
        "{} failed (it needs pyrealsense2 older than 2.58: `python3 -m pip install \
         'pyrealsense2<2.58'`; make test installs it):\n{}",
        writer.display(),
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn a_png_sequence_played_by_depth_ingest_is_mapped_with_the_box_it_shows() {
    let dir = std::env::temp_dir().join(format!("depth_pngs_{}", std::process::id()));
    write_pngs(&dir, 10);
    let source = format!("file:{}", dir.display());
    // The PNGs carry no intrinsics: [depth_ingest] intrinsics, the shipped D435 mode.
    let r = map_of(&source, &["--rate-hz", "15"], "dpng");
    let _ = std::fs::remove_dir_all(&dir);
    assert_the_map_holds_the_box(&r);
}

#[test]
fn a_realsense_bag_written_by_librealsense_is_played_and_mapped_with_the_box_it_shows() {
    let bag = std::env::temp_dir().join(format!("depth_{}.bag", std::process::id()));
    write_bag(&bag, 10);
    // The bag carries its intrinsics, depth units and rate.
    let r = map_of(&format!("bag:{}", bag.display()), &[], "dbag");
    let _ = std::fs::remove_file(&bag);
    assert_the_map_holds_the_box(&r);
}

/// The `realsense` build (librealsense2 found by pkg-config): the same recording played
/// by librealsense itself through `realsense:`, the path a live D435 takes.
#[cfg(feature = "realsense")]
#[test]
fn a_realsense_bag_played_by_librealsense_is_mapped_with_the_box_it_shows() {
    let bag = std::env::temp_dir().join(format!("depth_rs_{}.bag", std::process::id()));
    write_bag(&bag, 30);
    let r = map_of(&format!("realsense:{}", bag.display()), &[], "drs");
    let _ = std::fs::remove_file(&bag);
    assert!(r.ingest_log.contains("realsense:"), "{}", r.ingest_log);
    assert_the_map_holds_the_box(&r);
}

/// Without librealsense, `realsense:` is one line saying how to get it.
#[cfg(not(feature = "realsense"))]
#[test]
fn a_realsense_source_without_the_realsense_build_says_how_to_build_it() {
    for source in [
        "realsense:any",
        "realsense:123456789012",
        "realsense:flight.bag",
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_depth-ingest"))
            .args(["--source", source, "--ipc-prefix", "drs_none"])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{err}");
        let lines: Vec<&str> = err.lines().filter(|l| l.contains("error")).collect();
        assert_eq!(lines.len(), 1, "{err}");
        assert!(
            lines[0].contains("--features depth_ingest/realsense") && lines[0].contains(source),
            "{err}"
        );
    }
}

/// A V4L2 depth device that is not there: one line naming it (no device to stream from
/// here; `depth_ingest::v4l2` unpacks Z16 frames, tested on padded rows).
#[test]
fn a_v4l2_depth_device_that_is_not_there_is_one_line_naming_it() {
    let out = Command::new(env!("CARGO_BIN_EXE_depth-ingest"))
        .args(["--source", "v4l2:/dev/video77", "--ipc-prefix", "dv4l_none"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    let lines: Vec<&str> = err.lines().filter(|l| l.contains("error")).collect();
    assert_eq!(lines.len(), 1, "{err}");
    assert!(
        lines[0].contains("/dev/video77") && lines[0].contains("cannot open it"),
        "{err}"
    );
}
