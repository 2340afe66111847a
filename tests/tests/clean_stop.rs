//! Every stack process stops cleanly: started the way `landing run --processes` starts
//! it, with data flowing through it, stopped with SIGTERM at a random moment, 15 times
//! per binary, while two busy loops load both cores. Each stop must end with exit code 0
//! and the process's final counters in its log; no crash, no hang, no error.
//!
//! The moments are drawn from a seed printed at the start of each test; `STOP_TEST_SEED=N`
//! replays them. Tests take turns (one stack at a time).

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Mutex, PoisonError};
use std::time::{Duration, Instant};

use ipc_types::msg::{CameraFrameHeader, DepthFrameHeader, OccupancyMapHeader, VehicleState};
use ipc_types::services;
use landing_tests::process::Running;
use landing_tests::stack::{STAGES, Stack, deploy_dir, stack_binary};
use landing_tests::stop::{BusyLoops, Moments, catches_sigterm, count_in, last_line_with, stop};
use runtime::{Ipc, IpcPrefix};

/// Stops per binary.
const TRIALS: usize = 15;
/// A stop comes at a moment drawn uniformly from this long after data has flowed.
const WINDOW: Duration = Duration::from_secs(1);
/// The scenario the stack flies: the paper's obstacle demo (every stage busy).
const SCENARIO: &str = "obstacle-demo";
/// Long enough for every trial: the simulator must not end on its own mid-test.
const SIM_DURATION_S: f64 = 900.0;

/// One stack on the machine at a time: each test loads it fully already.
static TURN: Mutex<()> = Mutex::new(());

/// Whether something (that matters) arrived on a topic since the last look; draining.
type Watch<'a> = Box<dyn FnMut() -> bool + 'a>;

fn states<'a>(ipc: &Ipc, airborne_only: bool) -> Watch<'a> {
    let sub = ipc
        .subscriber::<VehicleState>(services::VEHICLE_STATE)
        .unwrap();
    Box::new(move || {
        let mut hit = false;
        while let Some(s) = sub.receive().unwrap() {
            let v = s.payload();
            hit |= !airborne_only || (v.armed == 1 && v.world_from_body.translation[2] > 0.3);
        }
        hit
    })
}

/// Any sample of the slice service `service` (frames, depth frames, maps).
fn slices<'a, T, H>(ipc: &Ipc, service: &str) -> Watch<'a>
where
    T: std::fmt::Debug + iceoryx2::prelude::ZeroCopySend + Copy + 'static,
    H: runtime::MessageHeader,
{
    let sub = ipc.slice_subscriber::<T, H>(service).unwrap();
    Box::new(move || {
        let mut hit = false;
        while sub.receive().unwrap().is_some() {
            hit = true;
        }
        hit
    })
}

fn frames<'a>(ipc: &Ipc, service: &str) -> Watch<'a> {
    slices::<u8, CameraFrameHeader>(ipc, service)
}

fn depth_frames<'a>(ipc: &Ipc) -> Watch<'a> {
    slices::<u16, DepthFrameHeader>(ipc, services::SIM_DEPTH)
}

fn maps<'a>(ipc: &Ipc) -> Watch<'a> {
    slices::<u8, OccupancyMapHeader>(ipc, services::MAP_OCCUPANCY)
}

/// The binary under test: its summary line and the counter in it that shows it worked.
struct Target {
    name: &'static str,
    summary: &'static str,
    work_key: &'static str,
}

/// `TRIALS` times: `start` the target (first) and what must restart with it, wait until
/// every watch has seen data since the start, wait a random moment, SIGTERM the target and
/// then the others; each must exit 0 with its summary. Returns the target's work counted
/// over all trials (so a test can tell data went through it).
fn stop_at_random_moments(
    target: &Target,
    load: &mut BusyLoops,
    watches: &mut [Watch<'_>],
    mut start: impl FnMut() -> Vec<Running>,
) -> u64 {
    let mut moments = Moments::new();
    eprintln!(
        "{}: stop moments from seed {} (STOP_TEST_SEED={} replays them)",
        target.name,
        moments.seed(),
        moments.seed()
    );
    let mut work = 0;
    let mut slowest = Duration::ZERO;
    for trial in 1..=TRIALS {
        for w in watches.iter_mut() {
            w();
        }
        let mut started = start();
        let mut seen = vec![false; watches.len()];
        let waiting = Instant::now();
        while !seen.iter().all(|s| *s) {
            for (s, w) in seen.iter_mut().zip(watches.iter_mut()) {
                *s |= w();
            }
            assert!(
                waiting.elapsed() < Duration::from_secs(60),
                "trial {trial}: data never flowed (topics seen: {seen:?}); the processes said:\n{}",
                started
                    .iter()
                    .map(Running::log)
                    .collect::<Vec<_>>()
                    .join("\n----\n")
            );
            std::thread::sleep(Duration::from_millis(5));
        }
        let delay = moments.up_to(WINDOW);
        std::thread::sleep(delay);
        let mut order = started.drain(..);
        let Some(process) = order.next() else {
            panic!("start() returned no process");
        };
        let s = stop(process);
        let context = format!(
            "trial {trial}/{TRIALS}, SIGTERM {} ms after data flowed (seed {})",
            delay.as_millis(),
            moments.seed()
        );
        assert!(
            s.status.success(),
            "{context}: {} ended with {} instead of exit code 0:\n{}",
            target.name,
            s.status,
            s.log
        );
        let line = last_line_with(&s.log, target.summary).unwrap_or_else(|| {
            panic!(
                "{context}: no `{}` line with the final counters:\n{}",
                target.summary, s.log
            )
        });
        work += count_in(line, target.work_key)
            .unwrap_or_else(|| panic!("{context}: no {}= in `{line}`", target.work_key));
        slowest = slowest.max(s.took);
        for other in order {
            let o = stop(other);
            assert!(
                o.status.success(),
                "{context}: the companion ended with {}:\n{}",
                o.status,
                o.log
            );
        }
    }
    assert!(load.all_running(), "the busy loops ran throughout");
    eprintln!(
        "{}: {TRIALS} stops, all exit 0, slowest {} ms, {}={work} in all",
        target.name,
        slowest.as_millis(),
        target.work_key
    );
    work
}

/// Stops what is left of the stack; every process must end with exit code 0 too.
fn stop_the_rest(mut stack: Stack) {
    for (name, status, log) in stack.stop_all() {
        assert!(status.success(), "{name} ended with {status}:\n{log}");
    }
}

fn stack_without(target: &[&str]) -> (Stack, Ipc) {
    let mut stack = Stack::new(SCENARIO, SIM_DURATION_S);
    stack.start_all_but(target);
    let ipc = Ipc::open("stop-test", stack.prefix()).unwrap();
    (stack, ipc)
}

#[test]
fn camera_ingest_on_the_simulator_exits_0_at_every_stop_under_load() {
    let _turn = TURN.lock().unwrap_or_else(PoisonError::into_inner);
    let (stack, ipc) = stack_without(&["camera-ingest"]);
    let mut load = BusyLoops::start(2);
    let target = Target {
        name: "camera-ingest",
        summary: "camera-ingest stopped",
        work_key: "published",
    };
    let mut watches = [frames(&ipc, services::CAMERA_FRAME)];
    let published = stop_at_random_moments(&target, &mut load, &mut watches, || {
        vec![stack.spawn("camera-ingest")]
    });
    assert!(
        published >= TRIALS as u64,
        "{published} frames published in all"
    );
    stop_the_rest(stack);
}

/// A fresh directory of PGM frames and one broken file, removed when dropped.
struct Frames(PathBuf);

impl Frames {
    fn new() -> Self {
        let dir = std::env::temp_dir().join(format!("clean_stop_frames_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let (w, h) = (640u32, 480u32);
        for k in 0..4u32 {
            let mut bytes = format!("P5\n{w} {h}\n255\n").into_bytes();
            bytes.extend((0..w * h).map(|i| ((i % w + i / w + 10 * k) % 256) as u8));
            std::fs::write(dir.join(format!("frame_{k}.pgm")), bytes).unwrap();
        }
        std::fs::write(dir.join("frame_2b.pgm"), b"P5 broken").unwrap();
        Self(dir)
    }

    fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for Frames {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

#[test]
fn camera_ingest_playing_an_image_directory_exits_0_at_every_stop_under_load() {
    // The case: the capture thread inside cv::imread when main returned.
    let _turn = TURN.lock().unwrap_or_else(PoisonError::into_inner);
    let dir = Frames::new();
    let prefix = IpcPrefix::unique("stopfile");
    let ipc = Ipc::open("stop-test", &prefix).unwrap();
    let mut load = BusyLoops::start(2);
    let target = Target {
        name: "camera-ingest",
        summary: "camera-ingest stopped",
        work_key: "published",
    };
    let source = format!("file:{}", dir.path().display());
    let mut watches = [frames(&ipc, services::CAMERA_FRAME)];
    let published = stop_at_random_moments(&target, &mut load, &mut watches, || {
        let ingest = Running::start(
            "camera-ingest",
            Command::new(stack_binary("camera-ingest"))
                .args(["--source", &source, "--rate-hz", "20", "--loop"])
                .arg("--camera")
                .arg(deploy_dir().join("config/camera_down_640x480.yaml"))
                .args(["--ipc-prefix", prefix.as_str()])
                .env("LANDING_LOG", "info"),
        );
        ingest.wait_for("camera-ingest running", Duration::from_secs(30));
        vec![ingest]
    });
    assert!(
        published >= TRIALS as u64,
        "{published} frames published in all"
    );
}

#[test]
fn sim_flying_the_scenario_exits_0_at_every_stop_under_load() {
    let _turn = TURN.lock().unwrap_or_else(PoisonError::into_inner);
    // The fsm restarts with each simulator, so that every new world takes off again.
    // Without the watchdog: it would order the vehicle down when the fsm stops in the
    // air, and its order stands for the rest of its run (one flight), so no new world
    // would take off.
    let (stack, ipc) = stack_without(&["sim", "fsm", "watchdog"]);
    let mut load = BusyLoops::start(2);
    let target = Target {
        name: "sim",
        summary: "sim stopped",
        work_key: "steps",
    };
    let mut watches = [
        states(&ipc, true),
        frames(&ipc, services::SIM_CAMERA),
        depth_frames(&ipc),
    ];
    stop_at_random_moments(&target, &mut load, &mut watches, || {
        let sim = stack.spawn("sim");
        vec![sim, stack.spawn("fsm")]
    });
    stop_the_rest(stack);
}

#[test]
fn aruco_pnp_fed_by_the_stack_exits_0_at_every_stop_under_load() {
    let _turn = TURN.lock().unwrap_or_else(PoisonError::into_inner);
    let (stack, ipc) = stack_without(&["aruco-pnp"]);
    let mut load = BusyLoops::start(2);
    let target = Target {
        name: "aruco-pnp",
        summary: "aruco-pnp stopped",
        work_key: "frames",
    };
    let mut watches = [frames(&ipc, services::CAMERA_FRAME), states(&ipc, false)];
    let searched = stop_at_random_moments(&target, &mut load, &mut watches, || {
        vec![stack.spawn("aruco-pnp")]
    });
    assert!(searched > 0, "aruco-pnp searched no frame in {TRIALS} runs");
    stop_the_rest(stack);
}

#[test]
fn depth_map_fed_by_the_stack_exits_0_at_every_stop_under_load() {
    let _turn = TURN.lock().unwrap_or_else(PoisonError::into_inner);
    let (stack, ipc) = stack_without(&["depth-map"]);
    let mut load = BusyLoops::start(2);
    let target = Target {
        name: "depth-map",
        summary: "depth-map stopped",
        work_key: "integrated",
    };
    let mut watches = [depth_frames(&ipc), states(&ipc, false), maps(&ipc)];
    let integrated = stop_at_random_moments(&target, &mut load, &mut watches, || {
        vec![stack.spawn("depth-map")]
    });
    assert!(
        integrated > 0,
        "depth-map integrated no frame in {TRIALS} runs"
    );
    stop_the_rest(stack);
}

#[test]
fn planner_fed_by_the_stack_exits_0_at_every_stop_under_load() {
    let _turn = TURN.lock().unwrap_or_else(PoisonError::into_inner);
    let (stack, ipc) = stack_without(&["planner"]);
    let mut load = BusyLoops::start(2);
    let target = Target {
        name: "planner",
        summary: "planner stopped",
        work_key: "steps",
    };
    let mut watches = [states(&ipc, false), maps(&ipc)];
    let steps = stop_at_random_moments(&target, &mut load, &mut watches, || {
        vec![stack.spawn("planner")]
    });
    assert!(steps > 0, "the planner took no decision in {TRIALS} runs");
    stop_the_rest(stack);
}

#[test]
fn fsm_fed_by_the_stack_exits_0_at_every_stop_under_load() {
    let _turn = TURN.lock().unwrap_or_else(PoisonError::into_inner);
    let (stack, ipc) = stack_without(&["fsm"]);
    let mut load = BusyLoops::start(2);
    let target = Target {
        name: "fsm",
        summary: "fsm stopped",
        work_key: "states",
    };
    let mut watches = [states(&ipc, false), maps(&ipc)];
    let states_in = stop_at_random_moments(&target, &mut load, &mut watches, || {
        vec![stack.spawn("fsm")]
    });
    assert!(
        states_in > 0,
        "the fsm took in no vehicle state in {TRIALS} runs"
    );
    stop_the_rest(stack);
}

#[test]
fn px4_link_talking_to_the_simulator_exits_0_at_every_stop_under_load() {
    let _turn = TURN.lock().unwrap_or_else(PoisonError::into_inner);
    let (stack, ipc) = stack_without(&["px4-link"]);
    let mut load = BusyLoops::start(2);
    let target = Target {
        name: "px4-link",
        summary: "px4-link stopped",
        work_key: "received",
    };
    // Its own output: states decoded from the simulator's telemetry.
    let mut watches = [states(&ipc, false)];
    let received = stop_at_random_moments(&target, &mut load, &mut watches, || {
        vec![stack.spawn("px4-link")]
    });
    assert!(received > 0, "px4-link decoded no MAVLink in {TRIALS} runs");
    stop_the_rest(stack);
}

#[test]
fn every_process_stopped_while_it_starts_exits_0() {
    // A stop that arrives once `main` runs (its handler is in place) but before the
    // process is set up is kept and honoured when its loop starts, never fatal.
    let _turn = TURN.lock().unwrap_or_else(PoisonError::into_inner);
    let stack = Stack::new(SCENARIO, SIM_DURATION_S);
    let mut moments = Moments::new();
    eprintln!("start-up stops from seed {}", moments.seed());
    for name in STAGES {
        let summary = if name == "sim" {
            "sim stopped".to_string()
        } else {
            format!("{name} stopped")
        };
        for round in 1..=5 {
            let process = Running::start(name, &mut stack.command(name));
            let waiting = Instant::now();
            while !catches_sigterm(process.pid()) {
                assert!(
                    waiting.elapsed() < Duration::from_secs(20),
                    "{name} never installed its SIGTERM handler:\n{}",
                    process.log()
                );
                std::thread::sleep(Duration::from_micros(200));
            }
            let delay = moments.up_to(Duration::from_millis(50));
            std::thread::sleep(delay);
            let s = stop(process);
            assert!(
                s.status.success(),
                "{name}, round {round}, SIGTERM {} us after its handler: {}:\n{}",
                delay.as_micros(),
                s.status,
                s.log
            );
            assert!(
                last_line_with(&s.log, &summary).is_some(),
                "{name}: no `{summary}` line:\n{}",
                s.log
            );
        }
    }
}
