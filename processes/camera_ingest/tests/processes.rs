#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test
//! camera-ingest as a real OS process: fed by the `sim` process, by a misbehaving
//! publisher, and by an image directory, each under its own iceoryx2 prefix; the test reads
//! `landing/camera/frame` through shared memory as the detector would.
//!
//! The `sim` binary is found next to this test's executable (`target/release/sim`): cargo
//! builds it for `cargo test --release --workspace` (and `make test`), not for
//! `-p camera_ingest` alone; build it once with `cargo build --release -p sim`.

use std::collections::{HashMap, HashSet};
use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use ipc_types::msg::{CameraFrameHeader, Header, PixelEncoding, Stage};
use ipc_types::services;
use landing_tests::process::{Running, sim_binary};
use runtime::{Ipc, IpcPrefix};

const WIDTH: u32 = 640;
const HEIGHT: u32 = 480;

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn calibration_file() -> PathBuf {
    workspace().join("deploy/config/camera_down_640x480.yaml")
}

/// The value of `key=N` in the process's `camera-ingest stopped` summary line.
fn summary_count(log: &str, key: &str) -> u64 {
    let line = log
        .lines()
        .rev()
        .find(|l| l.contains("camera-ingest stopped"))
        .unwrap_or_else(|| panic!("no summary line in:\n{log}"));
    line.split_whitespace()
        .find_map(|kv| kv.strip_prefix(&format!("{key}=")))
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no {key} in `{line}`"))
}

/// camera-ingest's heartbeat deadline as the graph declares it (a listener must open the
/// heartbeat's event service with the deadline its notifier declared).
fn heartbeat_deadline() -> Duration {
    let g = graph::Graph::load(&workspace().join("deploy/graph.toml")).unwrap();
    Duration::from_millis(g.node("camera-ingest").unwrap().heartbeat_deadline_ms)
}

fn start_sim(prefix: &IpcPrefix) -> Running {
    let sim = Running::start(
        "sim",
        Command::new(sim_binary())
            .args(["--scenario", "indoor-static", "--duration-s", "60"])
            .args(["--mavlink-listen", "127.0.0.1:0"])
            // Nothing listens there: the simulator's unsolicited MAVLink goes nowhere.
            .args(["--mavlink-remote", "127.0.0.1:9"])
            .arg("--ipc-prefix")
            .arg(prefix.as_str())
            .arg("--deploy-dir")
            .arg(workspace().join("deploy")),
    );
    sim.wait_for("sim running", Duration::from_secs(30));
    sim
}

fn start_ingest(prefix: &IpcPrefix, extra: &[&str]) -> Running {
    Running::start(
        "camera-ingest",
        Command::new(env!("CARGO_BIN_EXE_camera-ingest"))
            .arg("--camera")
            .arg(calibration_file())
            .arg("--ipc-prefix")
            .arg(prefix.as_str())
            .args(extra),
    )
}

fn digest(bytes: &[u8]) -> u64 {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    bytes.hash(&mut h);
    h.finish()
}

/// What the test keeps of one published frame.
#[derive(Debug, Clone)]
struct Seen {
    header: CameraFrameHeader,
    digest: u64,
    min: u8,
    max: u8,
    len: usize,
}

/// Reads `landing/camera/frame` (and optionally the simulator's own frames) for `window`
/// once the first published frame has arrived.
fn collect(
    ipc: &Ipc,
    window: Duration,
    with_sim: bool,
    ingest: &Running,
) -> (Vec<Seen>, HashMap<u64, u64>) {
    let frames = ipc
        .slice_subscriber::<u8, CameraFrameHeader>(services::CAMERA_FRAME)
        .unwrap();
    let sim_frames = with_sim.then(|| {
        ipc.slice_subscriber::<u8, CameraFrameHeader>(services::SIM_CAMERA)
            .unwrap()
    });
    let mut seen = Vec::new();
    let mut sim_digests = HashMap::new();
    let start = Instant::now();
    let mut window_end: Option<Instant> = None;
    loop {
        let now = Instant::now();
        if window_end.is_some_and(|end| now >= end) {
            break;
        }
        assert!(
            window_end.is_some() || now - start < Duration::from_secs(30),
            "no frame published in 30 s; camera-ingest said:\n{}",
            ingest.log()
        );
        let mut idle = true;
        if let Some(sub) = &sim_frames {
            while let Some(s) = sub.receive().unwrap() {
                sim_digests.insert(s.user_header().msg.capture_ns, digest(s.payload()));
                idle = false;
            }
        }
        while let Some(s) = frames.receive().unwrap() {
            if window_end.is_none() {
                window_end = Some(Instant::now() + window);
            }
            let p = s.payload();
            seen.push(Seen {
                header: *s.user_header(),
                digest: digest(p),
                min: p.iter().copied().min().unwrap_or(0),
                max: p.iter().copied().max().unwrap_or(0),
                len: p.len(),
            });
            idle = false;
        }
        if idle {
            std::thread::sleep(Duration::from_millis(1));
        }
    }
    (seen, sim_digests)
}

#[test]
fn frames_from_the_simulator_process_are_republished_at_the_camera_rate() {
    let prefix = IpcPrefix::unique("ingestsim");
    let mut sim = start_sim(&prefix);
    let mut ingest = start_ingest(&prefix, &["--source", "sim"]);
    ingest.wait_for("camera-ingest running", Duration::from_secs(30));
    let ipc = Ipc::open("ingest-test", &prefix).unwrap();

    let (seen, sim_digests) = collect(&ipc, Duration::from_secs(2), true, &ingest);

    // The camera runs at 30 Hz; a loaded 2-core machine may lose some, not most.
    assert!(
        seen.len() >= 40,
        "{} frames in 2 s; camera-ingest said:\n{}",
        seen.len(),
        ingest.log()
    );
    for pair in seen.windows(2) {
        assert!(
            pair[1].header.msg.capture_ns > pair[0].header.msg.capture_ns,
            "capture times increase"
        );
        assert!(pair[1].header.msg.seq > pair[0].header.msg.seq);
    }
    let mut matched = 0;
    for f in &seen {
        let h = &f.header;
        assert_eq!((h.width, h.height, h.stride), (WIDTH, HEIGHT, WIDTH));
        assert_eq!(h.encoding, PixelEncoding::Mono8 as u32);
        assert_eq!(h.undistorted, 0);
        assert_eq!(f.len, (WIDTH * HEIGHT) as usize);
        assert!(f.max > f.min, "the image has content");
        // The simulator's stamp, then camera-ingest's, inside the capture-to-now span.
        let stages: Vec<_> = h
            .msg
            .stages()
            .iter()
            .map(|s| Stage::from_raw(s.stage))
            .collect();
        assert_eq!(stages, [Some(Stage::Sensor), Some(Stage::CameraIngest)]);
        let ingest_stage = h.msg.stages()[1];
        assert!(ingest_stage.enter_ns >= h.msg.capture_ns);
        assert!(ingest_stage.exit_ns >= ingest_stage.enter_ns);
        if let Some(d) = sim_digests.get(&h.msg.capture_ns) {
            assert_eq!(*d, f.digest, "pixels are the simulator's, unchanged");
            matched += 1;
        }
    }
    assert!(
        matched >= seen.len() / 2,
        "only {matched} of {} frames matched a simulator frame",
        seen.len()
    );

    assert!(ingest.terminate().success(), "{}", ingest.log());
    let log = ingest.log();
    assert!(summary_count(&log, "published") >= seen.len() as u64);
    assert_eq!(summary_count(&log, "dropped_bad_header"), 0);
    assert!(sim.is_running(), "the simulator is still up");
}

#[test]
fn undistorted_frames_from_the_simulator_are_marked_and_differ_from_the_raw_ones() {
    let prefix = IpcPrefix::unique("ingestundist");
    let _sim = start_sim(&prefix);
    let mut ingest = start_ingest(&prefix, &["--source", "sim", "--undistort"]);
    ingest.wait_for("camera-ingest running", Duration::from_secs(30));
    let ipc = Ipc::open("ingest-test", &prefix).unwrap();

    let (seen, sim_digests) = collect(&ipc, Duration::from_secs(1), true, &ingest);

    assert!(seen.len() >= 10, "{} frames in 1 s", seen.len());
    let mut compared = 0;
    for f in &seen {
        assert_eq!(f.header.undistorted, 1);
        assert_eq!(f.len, (WIDTH * HEIGHT) as usize);
        if let Some(d) = sim_digests.get(&f.header.msg.capture_ns) {
            assert_ne!(
                *d, f.digest,
                "the pixels went through the undistortion maps"
            );
            compared += 1;
        }
    }
    assert!(compared > 0, "no frame matched a simulator frame");
    assert!(ingest.terminate().success(), "{}", ingest.log());
}

/// The frames a misbehaving producer sends, each with what camera-ingest should count.
fn bad_frame(kind: usize) -> (CameraFrameHeader, usize) {
    let mono = PixelEncoding::Mono8 as u32;
    let header = |width, height, stride, encoding| CameraFrameHeader {
        msg: Header::captured_at(1),
        width,
        height,
        stride,
        encoding,
        ..CameraFrameHeader::default()
    };
    let full = (WIDTH * HEIGHT) as usize;
    match kind {
        0 => (header(0, HEIGHT, WIDTH, mono), full), // zero width
        1 => (header(WIDTH, HEIGHT, WIDTH, mono), 1000), // payload too short
        2 => (header(WIDTH, HEIGHT, WIDTH, 77), full), // unknown encoding
        3 => (header(WIDTH, HEIGHT, WIDTH / 2, mono), full), // stride shorter than a row
        _ => (header(320, 240, 320, mono), 320 * 240), // consistent, but not the calibration's size
    }
}

#[test]
fn bad_frames_from_a_misbehaving_producer_are_dropped_and_good_ones_still_flow() {
    let prefix = IpcPrefix::unique("ingestbad");
    let ipc = Ipc::open("bad-producer", &prefix).unwrap();
    let mut producer = ipc
        .slice_publisher::<u8, CameraFrameHeader>(
            services::SIM_CAMERA,
            (WIDTH * HEIGHT * 3) as usize,
        )
        .unwrap();
    let frames = ipc
        .slice_subscriber::<u8, CameraFrameHeader>(services::CAMERA_FRAME)
        .unwrap();
    let heartbeat = ipc
        .heartbeat_listener("camera-ingest", heartbeat_deadline())
        .unwrap();
    let mut ingest = start_ingest(&prefix, &["--source", "sim"]);
    ingest.wait_for("camera-ingest running", Duration::from_secs(30));

    // Every 10 ms one frame, most of them bad; good ones carry capture times from 1000 on.
    let mut good_sent = HashSet::new();
    let mut published = Vec::new();
    let mut beats = 0u64;
    let start = Instant::now();
    let mut i = 0usize;
    while start.elapsed() < Duration::from_secs(3) {
        if i % 6 == 5 {
            let capture_ns = 1000 + i as u64;
            let mut s = producer.loan((WIDTH * HEIGHT) as usize).unwrap();
            for (k, p) in s.payload_mut().iter_mut().enumerate() {
                *p = ((k + i) % 251) as u8;
            }
            *s.user_header_mut() = CameraFrameHeader {
                msg: Header::captured_at(capture_ns),
                width: WIDTH,
                height: HEIGHT,
                stride: WIDTH,
                encoding: PixelEncoding::Mono8 as u32,
                ..CameraFrameHeader::default()
            };
            producer.send(s).unwrap();
            good_sent.insert(capture_ns);
        } else {
            let (header, len) = bad_frame(i % 6);
            let mut s = producer.loan(len).unwrap();
            *s.user_header_mut() = header;
            producer.send(s).unwrap();
        }
        i += 1;
        std::thread::sleep(Duration::from_millis(10));
        while let Some(s) = frames.receive().unwrap() {
            let p = s.payload();
            let capture_ns = s.user_header().msg.capture_ns;
            let expected_first = ((capture_ns - 1000) % 251) as u8;
            published.push((capture_ns, p.len(), p[0] == expected_first));
        }
        heartbeat.try_wait(|_| beats += 1).unwrap();
    }

    assert!(ingest.is_running(), "camera-ingest died:\n{}", ingest.log());
    assert!(
        beats >= 10,
        "{beats} heartbeats in 3 s (one per 100 ms expected)"
    );
    assert!(
        published.len() >= good_sent.len() / 2,
        "{} of {} good frames came through",
        published.len(),
        good_sent.len()
    );
    for (capture_ns, len, pixels_ok) in &published {
        assert!(
            good_sent.contains(capture_ns),
            "only good frames are published"
        );
        assert_eq!(*len, (WIDTH * HEIGHT) as usize);
        assert!(pixels_ok);
    }

    assert!(ingest.terminate().success(), "{}", ingest.log());
    let log = ingest.log();
    assert!(summary_count(&log, "dropped_bad_header") >= 40, "{log}");
    assert!(summary_count(&log, "dropped_size") >= 10, "{log}");
    assert!(
        log.lines().any(|l| l.contains("frames dropped")),
        "drops are logged:\n{log}"
    );
    let drop_lines = log.lines().filter(|l| l.contains("frames dropped")).count();
    assert!(
        drop_lines <= 5,
        "drop logging is rate-limited: {drop_lines} lines in 3 s"
    );
}

/// A fresh directory, removed when dropped.
struct TempDir(PathBuf);

impl TempDir {
    fn new(name: &str) -> Self {
        let dir =
            std::env::temp_dir().join(format!("camera_ingest_it_{name}_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        Self(dir)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Writes a binary PGM (which OpenCV reads) of `w`x`h` with a gradient shifted by `k`.
fn write_pgm(path: &Path, w: u32, h: u32, k: u32) {
    let mut bytes = format!("P5\n{w} {h}\n255\n").into_bytes();
    bytes.extend((0..w * h).map(|i| ((i % w + i / w + k) % 256) as u8));
    std::fs::write(path, bytes).unwrap();
}

#[test]
fn an_image_directory_is_played_at_the_given_rate_and_an_unreadable_image_is_counted() {
    let dir = TempDir::new("play");
    for k in 0..4 {
        write_pgm(&dir.0.join(format!("frame_{k}.pgm")), WIDTH, HEIGHT, k * 10);
    }
    std::fs::write(dir.0.join("frame_2b.pgm"), b"P5 broken").unwrap();
    let prefix = IpcPrefix::unique("ingestdir");
    let ipc = Ipc::open("ingest-test", &prefix).unwrap();
    let source = format!("file:{}", dir.0.display());
    let mut ingest = start_ingest(&prefix, &["--source", &source, "--rate-hz", "20", "--loop"]);
    ingest.wait_for("camera-ingest running", Duration::from_secs(30));

    let (seen, _) = collect(&ipc, Duration::from_secs(2), false, &ingest);

    // 20 Hz for 2 s, one slot in five lost to the broken file: about 32 frames. The
    // upper bound shows the pacing; the lower one is loose, as a loaded 2-core machine
    // (a parallel build) can starve the player for a while.
    assert!(
        (10..=45).contains(&seen.len()),
        "{} frames in 2 s",
        seen.len()
    );
    for pair in seen.windows(2) {
        assert!(pair[1].header.msg.capture_ns > pair[0].header.msg.capture_ns);
    }
    assert!(
        seen.iter()
            .all(|f| f.len == (WIDTH * HEIGHT) as usize && f.max > f.min)
    );
    assert!(ingest.terminate().success(), "{}", ingest.log());
    assert!(summary_count(&ingest.log(), "dropped_unreadable") >= 2);
}

#[test]
fn a_recording_of_another_size_than_the_calibration_stops_at_start_with_one_line() {
    let dir = TempDir::new("size");
    write_pgm(&dir.0.join("frame_0.pgm"), 320, 240, 0);
    let prefix = IpcPrefix::unique("ingestsize");
    let source = format!("file:{}", dir.0.display());
    let mut ingest = start_ingest(&prefix, &["--source", &source, "--rate-hz", "10"]);
    let status = ingest.wait_exit(Duration::from_secs(20));
    assert_eq!(status.code(), Some(2));
    let log = ingest.log();
    let error: Vec<_> = log.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(error.len(), 1, "{log}");
    assert!(
        error[0].contains("delivers 320x240 frames") && error[0].contains("640x480"),
        "{}",
        error[0]
    );
}

#[test]
fn a_missing_calibration_or_unknown_source_is_one_line_and_exit_code_2() {
    let run = |args: &[&str]| {
        let o = Command::new(env!("CARGO_BIN_EXE_camera-ingest"))
            .args(args)
            .output()
            .unwrap();
        (
            o.status.code(),
            String::from_utf8_lossy(&o.stderr).trim().to_string(),
        )
    };
    let (code, err) = run(&["--source", "sim", "--camera", "/nonexistent/cam.yaml"]);
    assert_eq!(code, Some(2));
    assert_eq!(
        err,
        "error: calibration file /nonexistent/cam.yaml: not found"
    );

    let cal = calibration_file();
    let (code, err) = run(&["--source", "usb:0", "--camera", cal.to_str().unwrap()]);
    assert_eq!(code, Some(2));
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.contains("unknown --source `usb:0`") && err.contains("allowed: sim, v4l2:"),
        "{err}"
    );

    let (code, out) = {
        let o = Command::new(env!("CARGO_BIN_EXE_camera-ingest"))
            .arg("--help")
            .output()
            .unwrap();
        (
            o.status.code(),
            String::from_utf8_lossy(&o.stdout).to_string(),
        )
    };
    assert_eq!(code, Some(0));
    for flag in [
        "--source",
        "--camera",
        "--undistort",
        "--rate-hz",
        "--loop",
        "--ipc-prefix",
        "--config",
        "--deploy-dir",
    ] {
        assert!(out.contains(flag), "--help lists {flag}");
    }
}

/// A GStreamer pipeline that delivers `n` frames of 640x480 and then stops, as a camera
/// that disconnects does.
fn test_camera_pipeline(n: u32) -> String {
    format!(
        "videotestsrc num-buffers={n} ! video/x-raw,width={WIDTH},height={HEIGHT},framerate=30/1 ! videoconvert ! appsink"
    )
}

/// Whether this machine's OpenCV can run GStreamer's test source (GStreamer support and the
/// base plugins); the Jetson CSI path needs the same.
fn gstreamer_available() -> bool {
    use opencv::prelude::*;
    opencv::videoio::VideoCapture::from_file(
        test_camera_pipeline(1),
        opencv::videoio::CAP_GSTREAMER,
    )
    .and_then(|c| c.is_opened())
    .unwrap_or(false)
}

#[test]
fn a_camera_that_stops_delivering_is_reopened_and_the_process_keeps_heartbeating() {
    if !gstreamer_available() {
        eprintln!(
            "SKIPPED: OpenCV cannot run `videotestsrc ! appsink` here (no GStreamer support or base plugins)"
        );
        return;
    }
    let prefix = IpcPrefix::unique("ingestgst");
    let ipc = Ipc::open("ingest-test", &prefix).unwrap();
    let heartbeat = ipc
        .heartbeat_listener("camera-ingest", heartbeat_deadline())
        .unwrap();
    let source = format!("gst:{}", test_camera_pipeline(15));
    let mut ingest = start_ingest(&prefix, &["--source", &source]);
    ingest.wait_for("camera-ingest running", Duration::from_secs(30));

    // Each connection yields 15 frames (half a second), then the camera "disconnects".
    let (seen, _) = collect(&ipc, Duration::from_secs(3), false, &ingest);
    let mut beats = 0u64;
    heartbeat.try_wait(|_| beats += 1).unwrap();

    assert!(ingest.is_running(), "camera-ingest died:\n{}", ingest.log());
    assert!(beats > 0, "the heartbeat went on");
    assert!(
        seen.len() > 30,
        "{} frames in 3 s: the camera was reopened after each loss",
        seen.len()
    );
    for f in &seen {
        let h = &f.header;
        assert_eq!((h.width, h.height, h.stride), (WIDTH, HEIGHT, WIDTH * 3));
        assert_eq!(h.encoding, PixelEncoding::Bgr8 as u32);
        assert_eq!(h.msg.stages()[0].stage, Stage::CameraIngest as u32);
        assert!(
            h.msg.stages()[0].enter_ns == h.msg.capture_ns,
            "the stage starts at the grab"
        );
    }
    assert!(ingest.terminate().success(), "{}", ingest.log());
    let log = ingest.log();
    assert!(log.contains("camera lost; reopening"), "{log}");
    assert!(summary_count(&log, "source_errors") >= 2, "{log}");
}

#[test]
fn a_capture_thread_blocked_in_a_read_ends_the_process_with_its_exit_code_not_a_crash() {
    // One image of the directory becomes a FIFO nobody writes: cv::imread blocks in it,
    // inside OpenCV, as a camera read blocked in its driver would.
    let dir = TempDir::new("stuck");
    for k in 0..2 {
        write_pgm(&dir.0.join(format!("frame_{k}.pgm")), WIDTH, HEIGHT, k * 10);
    }
    let prefix = IpcPrefix::unique("ingeststuck");
    let ipc = Ipc::open("ingest-test", &prefix).unwrap();
    let source = format!("file:{}", dir.0.display());
    let mut ingest = start_ingest(&prefix, &["--source", &source, "--rate-hz", "20", "--loop"]);
    ingest.wait_for("camera-ingest running", Duration::from_secs(30));
    let (seen, _) = collect(&ipc, Duration::from_millis(200), false, &ingest);
    assert!(!seen.is_empty());
    let fifo = dir.0.join("fifo");
    let c_path = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
    // SAFETY: a valid NUL-terminated path; mkfifo has no other preconditions.
    assert_eq!(unsafe { libc::mkfifo(c_path.as_ptr(), 0o600) }, 0);
    std::fs::rename(&fifo, dir.0.join("frame_1.pgm")).unwrap();
    // Wait for the thread to reach it: frames stop coming.
    let frames = ipc
        .slice_subscriber::<u8, CameraFrameHeader>(services::CAMERA_FRAME)
        .unwrap();
    let start = Instant::now();
    loop {
        std::thread::sleep(Duration::from_millis(300));
        let mut arrived = 0;
        while frames.receive().unwrap().is_some() {
            arrived += 1;
        }
        if arrived == 0 {
            break;
        }
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "the capture thread never blocked"
        );
    }

    let asked = Instant::now();
    let status = ingest.terminate();
    let took = asked.elapsed();
    let log = ingest.log();
    assert_eq!(
        status.code(),
        Some(80),
        "exit code of the capture thread:\n{log}"
    );
    assert!(
        took < Duration::from_secs(5),
        "a bounded wait, not a hang: {took:?}"
    );
    assert!(
        log.contains("error: the capture thread did not stop within 2000 ms; exiting with code 80"),
        "{log}"
    );
    assert!(
        summary_count(&log, "published") >= seen.len() as u64,
        "final counters logged"
    );
    let (alive, dead) = landing_tests::process::node_census(&ipc);
    assert_eq!(
        (alive, dead),
        (1, 0),
        "only the test's node is left, none dead"
    );
}
