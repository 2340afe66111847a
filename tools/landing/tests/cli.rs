//! The `landing` command as a user meets it: help everywhere, one-line errors for bad
//! configuration, and the IPC benchmark's JSON shape.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test

mod common;
use common::landing;
use std::process::Output;

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).to_string()
}

#[test]
fn every_subcommand_has_help() {
    for args in [
        vec![],
        vec!["bench"],
        vec!["bench", "ipc"],
        vec!["bench", "sim"],
        vec!["bench", "aruco"],
        vec!["bench", "perception"],
        vec!["bench", "depth"],
        vec!["map"],
        vec!["bench", "planner"],
        vec!["plan"],
        vec!["pad"],
        vec!["pad", "detect"],
        vec!["config"],
        vec!["config", "check"],
        vec!["pad"],
        vec!["pad", "print"],
        vec!["mcap"],
        vec!["mcap", "info"],
        vec!["graph"],
        vec!["link"],
        vec!["link", "setup-signing"],
    ] {
        let mut a = args.clone();
        a.push("--help");
        let o = landing(&a);
        assert!(o.status.success(), "{a:?} --help failed");
        let out = String::from_utf8_lossy(&o.stdout);
        assert!(out.contains("Usage: landing"), "{a:?}: {out}");
    }
}

fn check_bad_config(name: &str, text: &str, key: &str, allowed: &str) {
    let dir = std::env::temp_dir().join(format!("landing-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join(name);
    std::fs::write(&path, text).expect("write config");
    let o = landing(&["config", "check", path.to_str().expect("utf-8 path")]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{name}: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{name}: one line: {err}");
    assert!(
        err.contains(path.to_str().unwrap_or_default()),
        "{name}: names the file: {err}"
    );
    assert!(
        err.contains(&format!("`{key}`")),
        "{name}: names the key: {err}"
    );
    assert!(err.contains(allowed), "{name}: says what is allowed: {err}");
    assert!(
        !err.contains("panicked") && !err.contains("backtrace"),
        "{err}"
    );
}

#[test]
fn a_wrong_key_is_one_line_naming_the_file_the_key_and_the_allowed_keys() {
    check_bad_config(
        "wrong_key.toml",
        "[ipc]\nprefix = \"a\"\nheartbeat_perod_ms = 100\nheartbeat_deadline_ms = 500\n",
        "ipc.heartbeat_perod_ms",
        "expected one of `prefix`, `heartbeat_period_ms`, `heartbeat_deadline_ms`",
    );
}

#[test]
fn a_wrong_type_is_one_line_naming_the_expected_type() {
    check_bad_config(
        "wrong_type.toml",
        "[ipc]\nprefix = \"a\"\nheartbeat_period_ms = \"fast\"\nheartbeat_deadline_ms = 500\n",
        "ipc.heartbeat_period_ms",
        "expected u64",
    );
}

#[test]
fn an_out_of_range_value_is_one_line_naming_the_range() {
    check_bad_config(
        "out_of_range.toml",
        "[ipc]\nprefix = \"a\"\nheartbeat_period_ms = 100\nheartbeat_deadline_ms = 50\n",
        "ipc.heartbeat_deadline_ms",
        "allowed: 200 to 60000",
    );
}

#[test]
fn an_unknown_camera_source_is_one_line_naming_the_allowed_sources() {
    check_bad_config(
        "bad_source.toml",
        "[ipc]\nprefix = \"a\"\nheartbeat_period_ms = 100\nheartbeat_deadline_ms = 500\n\
         [camera_ingest]\nsource = \"usb:0\"\n",
        "camera_ingest.source",
        "allowed: sim, v4l2:/dev/videoN",
    );
}

#[test]
fn a_depth_map_value_out_of_range_is_one_line_naming_the_key() {
    check_bad_config(
        "bad_depth_map.toml",
        "[ipc]\nprefix = \"a\"\nheartbeat_period_ms = 100\nheartbeat_deadline_ms = 500\n\
         [depth_map]\npixel_step = 0\n",
        "depth_map.pixel_step",
        "allowed: 1 to 16",
    );
}

#[test]
fn an_empty_config_or_a_misspelt_section_is_refused_by_config_check_and_by_a_process() {
    let dir = std::env::temp_dir().join(format!("landing-cli-empty-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let empty = dir.join("empty.toml");
    std::fs::write(&empty, "# nothing set\n").unwrap();
    let o = landing(&["config", "check", empty.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let px4_link = std::path::Path::new(env!("CARGO_BIN_EXE_landing")).with_file_name("px4-link");
    let o = std::process::Command::new(&px4_link)
        .arg("--config")
        .arg(&empty)
        .output()
        .unwrap();
    let err = stderr(&o);
    assert!(!o.status.success());
    assert!(err.contains("the file sets nothing"), "{err}");
    let typo = dir.join("typo.toml");
    std::fs::write(&typo, "[px4link]\nlink = \"udp:127.0.0.1:14540\"\n").unwrap();
    let o = std::process::Command::new(&px4_link)
        .arg("--config")
        .arg(&typo)
        .output()
        .unwrap();
    let err = stderr(&o);
    assert!(!o.status.success());
    assert!(
        err.contains("`px4link`: unknown section (allowed: ipc,"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

#[test]
fn config_check_loads_the_files_a_config_names_relative_to_it() {
    let dir = std::env::temp_dir().join(format!("landing-cli-files-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let text = common::shipped_config();
    // Alone in a directory, without its calibration and pad beside it.
    let alone = dir.join("landing.toml");
    std::fs::write(&alone, &text).unwrap();
    let o = landing(&["config", "check", alone.to_str().unwrap()]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(
        err.contains("aruco_pnp.camera") && err.contains(dir.to_str().unwrap()),
        "{err}"
    );
    // With them: ok. A broken pad layout beside it is named.
    let with = common::write_config(&dir.join("with"), "landing.toml", &text);
    let o = landing(&["config", "check", with.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    std::fs::write(dir.join("with/pad.toml"), "[board]\n").unwrap();
    let o = landing(&["config", "check", with.to_str().unwrap()]);
    assert!(stderr(&o).contains("aruco_pnp.pad"), "{}", stderr(&o));
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

#[test]
fn the_shipped_config_is_valid() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../deploy/config/landing.toml"
    );
    let o = landing(&["config", "check", path]);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn a_missing_config_file_is_one_line() {
    let o = landing(&["config", "check", "/nonexistent/landing.toml"]);
    assert_eq!(o.status.code(), Some(2));
    let err = stderr(&o);
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(
        err.contains("/nonexistent/landing.toml: cannot read"),
        "{err}"
    );
}

#[test]
fn a_bad_ipc_prefix_is_refused_in_one_line() {
    let o = landing(&["--ipc-prefix", "../etc", "bench", "ipc", "--frames", "50"]);
    assert_eq!(o.status.code(), Some(2));
    let err = stderr(&o);
    assert!(err.contains("prefix `../etc` is not allowed"), "{err}");
}

#[test]
fn the_ipc_benchmark_prints_the_documented_json() {
    let o = landing(&[
        "bench",
        "ipc",
        "--json",
        "--frames",
        "50",
        "--period-us",
        "1000",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    for transport in ["iceoryx2", "unix_socket", "iceoryx2_event_wakeup"] {
        for case in ["640x480_mono8", "1280x720_bgr8"] {
            for q in ["p50_us", "p99_us"] {
                let x = v[transport][case][q].as_f64().unwrap_or(-1.0);
                assert!(x > 0.0, "{transport}.{case}.{q} = {x}");
            }
            assert!(v[transport][case]["p99_us"].as_f64() >= v[transport][case]["p50_us"].as_f64());
        }
    }
    assert!(v["ratio_p50_1280x720"].as_f64().unwrap_or(0.0) > 0.0);
}

#[test]
fn the_sim_benchmark_prints_the_documented_json() {
    let o = landing(&["bench", "sim", "--json", "--seconds", "1"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    for key in [
        "realtime_factor",
        "realtime_factor_640x480",
        "sim_realtime_factor",
        "render_ms_p50_640x480",
        "render_ms_p50_1280x720",
        "depth_ms_p50",
    ] {
        let x = v[key].as_f64().unwrap_or(-1.0);
        assert!(x > 0.0, "{key} = {x}");
    }
}

#[test]
fn the_depth_benchmark_prints_the_documented_json() {
    let o = landing(&["bench", "depth", "--json", "--frames", "30"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    for key in [
        "integrate_ms_p50",
        "integrate_ms_p99",
        "inflate_ms_p50",
        "write_wire_ms_p50",
        "exact_integrate_ms_p50",
        "observed_vs_exact_min",
    ] {
        let x = v[key].as_f64().unwrap_or(-1.0);
        assert!(x > 0.0, "{key} = {x}");
    }
    assert_eq!(v["window_cells"], serde_json::json!([68, 68, 32]));
    assert_eq!(v["rays_per_frame_p50"].as_f64(), Some(76_800.0));
}

#[test]
fn the_aruco_benchmark_prints_the_documented_json() {
    let o = landing(&["bench", "aruco", "--json", "--frames", "10"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    for key in [
        "ours_ms_p50_640x480",
        "opencv_ms_p50_640x480",
        "ours_ms_p50_1280x720",
        "opencv_ms_p50_1280x720",
        "opencv_tracked_ms_p50_640x480",
        "opencv_tracked_ms_p50_1280x720",
    ] {
        let x = v[key].as_f64().unwrap_or(-1.0);
        assert!(x > 0.0, "{key} = {x}");
    }
    assert!(v["ours_found_640x480"].as_u64().unwrap_or(0) > 0);
    assert!(["subpix", "contour"].contains(&v["opencv_refinement_640x480"].as_str().unwrap_or("")));
}

#[test]
fn real_px4_needs_the_processes_mode_and_a_px4_build_directory_each_said_in_one_line() {
    let o = landing(&[
        "run",
        "--autopilot",
        "px4-sitl",
        "--px4",
        "/nonexistent/build",
    ]);
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(
        err.contains("--autopilot px4-sitl needs --processes"),
        "{err}"
    );
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    let dir = std::env::temp_dir().join(format!("landing-no-px4-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let o = landing(&[
        "run",
        "--processes",
        "--autopilot",
        "px4-sitl",
        "--px4",
        dir.to_str().unwrap(),
        "--log-dir",
        dir.join("logs").to_str().unwrap(),
    ]);
    std::fs::remove_dir_all(&dir).ok();
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(
        err.contains("not a PX4 SITL build directory (allowed: one holding bin/px4 and etc/"),
        "{err}"
    );
    let o = landing(&["run", "--autopilot", "px4-sitl"]);
    assert_eq!(
        o.status.code(),
        Some(2),
        "--px4 is required: {}",
        stderr(&o)
    );
}
