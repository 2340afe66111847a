#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test
//! depth-map as a real OS process, fed by the real `sim` process (obstacle-demo: a box
//! 2.5 m ahead of the parked vehicle) and by a vehicle-state publisher in this test,
//! under its own iceoryx2 prefix; the test reads `landing/map/occupancy` through shared
//! memory as the planner would.
//!
//! The `sim` binary is found next to this test's executable (`target/release/sim`): cargo
//! builds it for `cargo test --release --workspace` (and `make test`), not for
//! `-p depth_map` alone; build it once with `cargo build --release -p sim`.

use std::path::PathBuf;
use std::process::Command;
use std::time::{Duration, Instant};

use ipc_types::msg::{Header, OccupancyMapHeader, Pose, Stage, VehicleState};
use ipc_types::services;
use landing_tests::process::{Running, sim_binary};
use runtime::{Ipc, IpcPrefix, monotonic_ns};

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The value of `key=N` in the last line containing `what`.
fn logged_count(log: &str, what: &str, key: &str) -> u64 {
    let line = log
        .lines()
        .rev()
        .find(|l| l.contains(what))
        .unwrap_or_else(|| panic!("no `{what}` line in:\n{log}"));
    line.split_whitespace()
        .find_map(|kv| kv.strip_prefix(&format!("{key}=")))
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no {key} in `{line}`"))
}

/// What the test keeps of one published map.
struct Seen {
    at: Instant,
    header: OccupancyMapHeader,
    len: usize,
    occupied_near_box: usize,
    /// Occupied cells above the ground's band (cell centre above 0.3 m).
    occupied_above_ground: usize,
    free: usize,
    invalid: usize,
}

#[test]
fn maps_of_the_simulators_box_arrive_at_ten_hertz_or_more_with_the_documented_window() {
    let prefix = IpcPrefix::unique("depthproc");
    let sim = Running::start(
        "sim",
        Command::new(sim_binary())
            .args(["--scenario", "obstacle-demo", "--duration-s", "60"])
            .args(["--mavlink-listen", "127.0.0.1:0"])
            // Nothing listens there: the simulator's unsolicited MAVLink goes nowhere.
            .args(["--mavlink-remote", "127.0.0.1:9"])
            .arg("--ipc-prefix")
            .arg(prefix.as_str())
            .arg("--deploy-dir")
            .arg(workspace().join("deploy")),
    );
    sim.wait_for("sim running", Duration::from_secs(30));
    let mut mapper = Running::start(
        "depth-map",
        Command::new(env!("CARGO_BIN_EXE_depth-map"))
            .arg("--config")
            .arg(workspace().join("deploy/config/landing.toml"))
            .arg("--ipc-prefix")
            .arg(prefix.as_str()),
    );
    mapper.wait_for("depth-map running", Duration::from_secs(30));

    let ipc = Ipc::open("depth-map-test", &prefix).unwrap();
    let mut states = ipc
        .publisher::<VehicleState>(services::VEHICLE_STATE)
        .unwrap();
    let maps = ipc
        .slice_subscriber::<u8, OccupancyMapHeader>(services::MAP_OCCUPANCY)
        .unwrap();

    // The parked vehicle as the autopilot reports it: at the origin on the ground,
    // facing east (+x), toward the box.
    let hover = |t: u64| VehicleState {
        msg: Header::captured_at(t),
        world_from_body: Pose {
            translation: [0.0, 0.0, 0.0],
            rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
        },
        ..VehicleState::default()
    };
    let mut seen: Vec<Seen> = Vec::new();
    let start = Instant::now();
    let mut next_state = Instant::now();
    let mut window_end: Option<Instant> = None;
    while window_end.is_none_or(|e| Instant::now() < e) {
        assert!(
            window_end.is_some() || start.elapsed() < Duration::from_secs(30),
            "no map with occupied cells in 30 s; depth-map said:\n{}",
            mapper.log()
        );
        if Instant::now() >= next_state {
            let s = hover(monotonic_ns());
            states.send(s.msg, &s).unwrap();
            next_state += Duration::from_millis(20);
        }
        while let Some(m) = maps.receive().unwrap() {
            let h = *m.user_header();
            let cells = m.payload();
            let [nx, ny, _] = h.dims.map(|d| d as usize);
            let (mut above, mut free, mut near, mut invalid) = (0, 0, 0, 0);
            for (i, &c) in cells.iter().enumerate() {
                match c {
                    2 => {
                        let x = h.origin[0] + ((i % nx) as f64 + 0.5) * h.resolution;
                        let y = h.origin[1] + (((i / nx) % ny) as f64 + 0.5) * h.resolution;
                        let z = h.origin[2] + ((i / (nx * ny)) as f64 + 0.5) * h.resolution;
                        let at_box = (2.3..=2.7).contains(&x) && y.abs() <= 0.7;
                        if at_box {
                            near += 1;
                        }
                        if z > 0.3 && !at_box {
                            above += 1;
                        }
                    }
                    1 => free += 1,
                    0 | 3 => {}
                    _ => invalid += 1,
                }
            }
            if window_end.is_none() && near > 0 {
                window_end = Some(Instant::now() + Duration::from_secs(2));
            }
            seen.push(Seen {
                at: Instant::now(),
                header: h,
                len: cells.len(),
                occupied_near_box: near,
                occupied_above_ground: above,
                free,
                invalid,
            });
        }
        std::thread::sleep(Duration::from_millis(2));
    }

    // From the first map that shows the box, two seconds of maps.
    let first = seen.iter().position(|s| s.occupied_near_box > 0).unwrap();
    let window = &seen[first..];
    let span = window.last().unwrap().at - window[0].at;
    let rate = (window.len() - 1) as f64 / span.as_secs_f64();
    println!(
        "{} maps in {span:?} ({rate:.1} Hz), {} occupied cells at the box, {} free",
        window.len(),
        window[window.len() - 1].occupied_near_box,
        window[window.len() - 1].free
    );
    assert!(
        rate >= 10.0,
        "{} maps in {span:?} ({rate:.1} Hz); depth-map said:\n{}",
        window.len(),
        mapper.log()
    );
    for s in window {
        let h = &s.header;
        assert_eq!(h.dims, [68, 68, 32], "the documented window");
        assert_eq!(s.len, 68 * 68 * 32);
        assert_eq!((h.resolution, h.inflation), (0.15, 0.299));
        assert!(h.origin.iter().all(|v| v.is_finite()));
        assert_eq!(s.invalid, 0);
        assert!(s.occupied_near_box > 20, "the box's face is occupied");
        assert!(s.free > 2000, "the space before it is free ({})", s.free);
        // Nothing occupied away from the box but the ground the camera (10 cm up)
        // sees ahead: the ground vehicle is parked beyond the window.
        assert_eq!(s.occupied_above_ground, 0, "occupied above the ground");
        // The frame's stamps go on, with depth-map's after the simulator's.
        let stages: Vec<_> = h
            .msg
            .stages()
            .iter()
            .map(|st| Stage::from_raw(st.stage))
            .collect();
        assert_eq!(stages, [Some(Stage::Sensor), Some(Stage::DepthMap)]);
        assert!(h.msg.capture_ns > 0);
    }
    for pair in window.windows(2) {
        assert!(pair[1].header.msg.seq > pair[0].header.msg.seq);
        assert!(pair[1].header.msg.capture_ns >= pair[0].header.msg.capture_ns);
    }

    assert!(mapper.terminate().success(), "{}", mapper.log());
    let log = mapper.log();
    let integrated = logged_count(&log, "depth-map stopped", "integrated");
    let published = logged_count(&log, "depth-map stopped", "published");
    assert!(integrated >= 40, "{log}");
    assert!(published >= window.len() as u64);
    assert_eq!(logged_count(&log, "depth-map stopped", "bad_frames"), 0);
}

#[test]
fn help_works_and_a_bad_flag_or_config_is_one_line_and_exit_code_2() {
    let bin = env!("CARGO_BIN_EXE_depth-map");
    let help = Command::new(bin).arg("--help").output().unwrap();
    assert!(help.status.success());
    let text = String::from_utf8_lossy(&help.stdout);
    assert!(
        text.contains("--input") && text.contains("--config"),
        "{text}"
    );

    let bad_flag = Command::new(bin).arg("--frobnicate").output().unwrap();
    assert_eq!(bad_flag.status.code(), Some(2));
    let err = String::from_utf8_lossy(&bad_flag.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("--frobnicate"), "{err}");

    let bad_input = Command::new(bin)
        .args(["--input", "v4l2", "--ipc-prefix", "lt_depthbad_"])
        .output()
        .unwrap();
    assert_eq!(bad_input.status.code(), Some(2));
    let err = String::from_utf8_lossy(&bad_input.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("sim, depth-frame"), "{err}");

    let dir = std::env::temp_dir().join(format!("depth_map_proc_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("bad.toml");
    std::fs::write(&file, "[depth_map]\nmax_ray_m = -1.0\n").unwrap();
    let bad_config = Command::new(bin)
        .arg("--config")
        .arg(&file)
        .output()
        .unwrap();
    assert_eq!(bad_config.status.code(), Some(2));
    let err = String::from_utf8_lossy(&bad_config.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("depth_map.max_ray_m"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
