#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test
//! depth-map as a real OS process, fed by the real `sim` process (obstacle-demo: a box
//! 2.5 m ahead of the parked vehicle) and by a vehicle-state publisher in this test,
//! under its own iceoryx2 prefix; the test reads `landing/map/occupancy` through shared
//! memory as the planner would.
//!
//! The `sim` binary is found next to this test's executable (`target/release/sim`): cargo
//! builds it for `cargo test --release --workspace` (and `make test`), not for
//! `-p depth_map` alone; build it once with `cargo build --release -p sim`.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use ipc_types::msg::{Header, OccupancyMapHeader, Pose, Stage, VehicleState};
use ipc_types::runtime::{Ipc, IpcPrefix, monotonic_ns};
use ipc_types::services;

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// `target/<profile>/sim`, next to `target/<profile>/deps/<this test>`.
fn sim_binary() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    let profile_dir = exe.parent().and_then(Path::parent).unwrap();
    let sim = profile_dir.join("sim");
    assert!(
        sim.is_file(),
        "{} is missing: build it with `cargo build --release -p sim` \
         (`cargo test --release --workspace` builds it)",
        sim.display()
    );
    sim
}

/// A child process killed when the test ends, however it ends; its stderr collected.
struct Running {
    name: &'static str,
    child: Child,
    lines: Arc<Mutex<Vec<String>>>,
    reader: Option<std::thread::JoinHandle<()>>,
}

impl Running {
    fn start(name: &'static str, cmd: &mut Command) -> Self {
        let mut child = cmd
            .env("NO_COLOR", "1")
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("start {name}: {e}"));
        let stderr = child.stderr.take().unwrap();
        let lines = Arc::new(Mutex::new(Vec::new()));
        let sink = Arc::clone(&lines);
        let reader = std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                sink.lock().unwrap().push(strip_ansi(&line));
            }
        });
        Self {
            name,
            child,
            lines,
            reader: Some(reader),
        }
    }

    fn log(&self) -> String {
        self.lines.lock().unwrap().join("\n")
    }

    fn wait_for(&self, needle: &str, timeout: Duration) {
        let end = Instant::now() + timeout;
        while Instant::now() < end {
            if self
                .lines
                .lock()
                .unwrap()
                .iter()
                .any(|l| l.contains(needle))
            {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        panic!("{} never said `{needle}`:\n{}", self.name, self.log());
    }

    fn wait_exit(&mut self, timeout: Duration) -> ExitStatus {
        let end = Instant::now() + timeout;
        loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                if let Some(r) = self.reader.take() {
                    r.join().unwrap();
                }
                return status;
            }
            assert!(
                Instant::now() < end,
                "{} did not exit:\n{}",
                self.name,
                self.log()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    fn terminate(&mut self) -> ExitStatus {
        // SAFETY: signalling our own child, whose pid stays valid until it is waited for.
        unsafe { libc::kill(self.child.id() as i32, libc::SIGTERM) };
        self.wait_exit(Duration::from_secs(10))
    }
}

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn strip_ansi(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    let mut chars = s.chars();
    while let Some(c) = chars.next() {
        if c == '\u{1b}' {
            for c in chars.by_ref() {
                if c.is_ascii_alphabetic() {
                    break;
                }
            }
        } else {
            out.push(c);
        }
    }
    out
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
    occupied: usize,
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
    sim.wait_for("simulator running", Duration::from_secs(30));
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
            let (mut occupied, mut free, mut near, mut invalid) = (0, 0, 0, 0);
            for (i, &c) in cells.iter().enumerate() {
                match c {
                    2 => {
                        occupied += 1;
                        let x = h.origin[0] + ((i % nx) as f64 + 0.5) * h.resolution;
                        let y = h.origin[1] + (((i / nx) % ny) as f64 + 0.5) * h.resolution;
                        if (2.3..=2.7).contains(&x) && y.abs() <= 0.7 {
                            near += 1;
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
                occupied,
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
        // Nothing occupied away from the box: the camera sits at ground level and sees
        // no ground, only the box.
        assert_eq!(
            s.occupied, s.occupied_near_box,
            "occupied away from the box"
        );
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
