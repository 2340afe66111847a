//! Parity of the two drivers: one recorded input sequence (camera frames, depth frames
//! and the vehicle states px4-link derived from the autopilot's telemetry), taken from a
//! lockstep flight of paper-sim, is fed
//! - through the lockstep driver, to camera-ingest, aruco-pnp and depth-map built as
//!   `landing run` builds them, each input at its recorded time, and
//! - through the real camera-ingest, aruco-pnp and depth-map processes over iceoryx2,
//!   published by this test in the same order,
//!
//! and the stages' outputs must be the same: every camera frame byte for byte, every pad
//! observation field for field, every occupancy map cell for cell. Only what timing
//! decides may differ, and is left out of the comparison: sequence numbers and the
//! enter/exit times of the stage stamps (which stages stamped a message must agree).
//! The processes must also report that they skipped and lost nothing, so they saw the
//! sequence the lockstep driver saw. (The timing-dependent stages, planner and fsm, are
//! compared at mission level: `landing run` against `landing run --processes`, README.)
//!
//! The process side waits for each frame's outputs before the next frame goes out (for
//! a camera frame without a pad, a fixed 30 ms), so the stages never have two frames
//! waiting: the newest-only policy must not decide anything here.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use graph::Graph;
use ipc_types::msg::{
    CameraFrameHeader, DepthFrameHeader, Header, OccupancyMapHeader, PadObservation, VehicleState,
};
use ipc_types::{services, topics};
use landing_tests::stack::{Stack, deploy_dir};
use landing_tests::stop::{count_in, last_line_with};
use runtime::Ipc;
use stack::StackConfig;
use stack::lockstep::{self as run_lockstep, Setup};
use stage::lockstep::{Lockstep, Published};
use stage::{Message, OwnedMessage};

/// How much of the flight is recorded: take-off, the way to the preset point and the
/// first seconds with the pad in view.
const RECORD_NS: u64 = 9_000_000_000;
/// The stages under comparison.
const STAGES: [&str; 3] = ["camera-ingest", "aruco-pnp", "depth-map"];
/// How long a process may take to answer one input before the test fails.
const ANSWER: Duration = Duration::from_secs(10);
/// How long aruco-pnp is given for a frame in which it finds no pad.
const NO_PAD: Duration = Duration::from_millis(30);

/// One recorded input: when it was published in the flight, on which topic, what.
struct Recorded {
    at_ns: u64,
    topic: &'static str,
    msg: OwnedMessage,
}

/// The outputs of the three stages, keyed by the capture time they derive from.
#[derive(Default, Debug, PartialEq)]
struct Outputs {
    /// Camera frames: header without timing, digest of the pixels.
    frames: BTreeMap<u64, (CameraFrameHeader, u64)>,
    /// Pad observations without timing.
    observations: BTreeMap<u64, PadObservation>,
    /// The first map after each depth frame: header without timing, cells.
    maps: BTreeMap<u64, (OccupancyMapHeader, Vec<u8>)>,
}

/// `h` with what timing decides cleared: the sequence number and the stamps' times.
fn untimed(h: &Header) -> Header {
    let mut u = *h;
    u.seq = 0;
    for s in &mut u.stages {
        s.enter_ns = 0;
        s.exit_ns = 0;
    }
    u
}

fn digest(bytes: &[u8]) -> u64 {
    // FNV-1a: enough to tell two frames apart.
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(*b)).wrapping_mul(0x0100_0000_01b3)
    })
}

impl Outputs {
    fn add(&mut self, msg: Message<'_>) {
        match msg {
            Message::CameraFrame(h, pixels) => {
                let mut h = *h;
                h.msg = untimed(&h.msg);
                self.frames.insert(h.msg.capture_ns, (h, digest(pixels)));
            }
            Message::PadObservation(o) => {
                let mut o = *o;
                o.msg = untimed(&o.msg);
                self.observations.insert(o.msg.capture_ns, o);
            }
            Message::OccupancyMap(h, cells) => {
                let mut h = *h;
                h.msg = untimed(&h.msg);
                self.maps
                    .entry(h.msg.capture_ns)
                    .or_insert_with(|| (h, cells.to_vec()));
            }
            _ => {}
        }
    }
}

fn shipped_graph() -> Graph {
    Graph::load(&deploy_dir().join("graph.toml")).unwrap()
}

fn config() -> StackConfig {
    stack_config::load(&deploy_dir().join("config/landing.toml")).unwrap()
}

/// Flies paper-sim (seed 1) in lockstep for `RECORD_NS` and keeps every input of the
/// three stages, and what the three stages published in that flight.
fn record() -> (Vec<Recorded>, Outputs) {
    let deploy = deploy_dir();
    let cfg = config();
    let scn = sim::scenario::load("paper-sim", &deploy).unwrap();
    let setup = Setup {
        scenario: &scn,
        seed: 1,
        config: &cfg,
        fsm: run_lockstep::mission(&cfg, &scn).unwrap(),
    };
    let mut driver = run_lockstep::driver(&shipped_graph(), &setup, |_| None).unwrap();
    let mut inputs = Vec::new();
    let mut outputs = Outputs::default();
    while driver.now_ns() < RECORD_NS {
        driver
            .step(&mut |p: &Published<'_>| {
                let topic = match p.topic {
                    topics::SIM_CAMERA => topics::SIM_CAMERA,
                    topics::SIM_DEPTH => topics::SIM_DEPTH,
                    topics::VEHICLE_STATE => topics::VEHICLE_STATE,
                    _ => {
                        outputs.add(p.msg);
                        return;
                    }
                };
                inputs.push(Recorded {
                    at_ns: p.now_ns,
                    topic,
                    msg: p.msg.to_owned(),
                });
            })
            .unwrap();
    }
    (inputs, outputs)
}

/// The recorded inputs through the lockstep driver, to the three stages alone.
fn through_lockstep(inputs: &[Recorded]) -> (Outputs, Vec<(&'static str, u64)>) {
    let deploy = deploy_dir();
    let cfg = config();
    let scn = sim::scenario::load("paper-sim", &deploy).unwrap();
    let setup = Setup {
        scenario: &scn,
        seed: 1,
        config: &cfg,
        fsm: run_lockstep::mission(&cfg, &scn).unwrap(),
    };
    let graph = shipped_graph();
    let stages = graph
        .step_order()
        .into_iter()
        .filter(|n| STAGES.contains(&n.name.as_str()))
        .map(|n| {
            let stage = run_lockstep::stage_for(n, &setup).unwrap().unwrap();
            (n.spec(), stage)
        })
        .collect();
    let mut driver = Lockstep::new(stages).unwrap();
    for r in inputs {
        driver.inject_at(r.at_ns, r.topic, r.msg.as_message());
    }
    let end = inputs.last().map_or(0, |r| r.at_ns) + 200_000_000;
    let mut outputs = Outputs::default();
    while driver.now_ns() < end {
        let step = driver
            .step(&mut |p: &Published<'_>| outputs.add(p.msg))
            .unwrap();
        if step.is_none() {
            break;
        }
    }
    let skipped = STAGES.iter().map(|s| (*s, driver.skipped(s))).collect();
    (outputs, skipped)
}

/// The recorded inputs published to the three stages as OS processes, in order.
fn through_processes(inputs: &[Recorded], expected: &Outputs) -> (Outputs, Vec<String>) {
    let mut stack = Stack::new("paper-sim", 60.0);
    for name in STAGES {
        stack.start(name);
    }
    let ipc = Ipc::open("parity-test", stack.prefix()).unwrap();
    let (cam_len, depth_len) = inputs.iter().fold((1, 1), |(c, d), r| match &r.msg {
        OwnedMessage::CameraFrame(_, p) => (c.max(p.len()), d),
        OwnedMessage::DepthFrame(_, p) => (c, d.max(p.len())),
        _ => (c, d),
    });
    let mut cameras = ipc
        .slice_publisher::<u8, CameraFrameHeader>(services::SIM_CAMERA, cam_len)
        .unwrap();
    let mut depths = ipc
        .slice_publisher::<u16, DepthFrameHeader>(services::SIM_DEPTH, depth_len)
        .unwrap();
    let mut states = ipc
        .publisher::<VehicleState>(services::VEHICLE_STATE)
        .unwrap();
    let frames_out = ipc
        .slice_subscriber::<u8, CameraFrameHeader>(services::CAMERA_FRAME)
        .unwrap();
    let observations = ipc
        .subscriber::<PadObservation>(services::PAD_OBSERVATION)
        .unwrap();
    let maps = ipc
        .slice_subscriber::<u8, OccupancyMapHeader>(services::MAP_OCCUPANCY)
        .unwrap();
    // The processes' subscribers connect to these publishers before anything is sent.
    std::thread::sleep(Duration::from_millis(500));

    let mut got = Outputs::default();
    let drain = |got: &mut Outputs| {
        while let Some(s) = frames_out.receive().unwrap() {
            got.add(Message::CameraFrame(s.user_header(), s.payload()));
        }
        while let Some(s) = observations.receive().unwrap() {
            got.add(Message::PadObservation(s.payload()));
        }
        while let Some(s) = maps.receive().unwrap() {
            got.add(Message::OccupancyMap(s.user_header(), s.payload()));
        }
    };
    let wait = |got: &mut Outputs, what: &str, done: &dyn Fn(&Outputs) -> bool| {
        let start = Instant::now();
        loop {
            drain(got);
            if done(got) {
                return;
            }
            assert!(start.elapsed() < ANSWER, "no answer in {ANSWER:?}: {what}");
            std::thread::sleep(Duration::from_micros(200));
        }
    };
    for r in inputs {
        match &r.msg {
            OwnedMessage::VehicleState(v) => {
                states.send(v.msg, v).unwrap();
            }
            OwnedMessage::CameraFrame(h, pixels) => {
                let mut s = cameras.loan(pixels.len()).unwrap();
                s.payload_mut().copy_from_slice(pixels);
                *s.user_header_mut() = *h;
                cameras.send(s).unwrap();
                let t = h.msg.capture_ns;
                wait(&mut got, &format!("camera/frame of {t}"), &|o| {
                    o.frames.contains_key(&t)
                });
                if expected.observations.contains_key(&t) {
                    wait(&mut got, &format!("pad/observation of {t}"), &|o| {
                        o.observations.contains_key(&t)
                    });
                } else {
                    std::thread::sleep(NO_PAD);
                }
            }
            OwnedMessage::DepthFrame(h, depth) => {
                let mut s = depths.loan(depth.len()).unwrap();
                s.payload_mut().copy_from_slice(depth);
                *s.user_header_mut() = *h;
                depths.send(s).unwrap();
                let t = h.msg.capture_ns;
                wait(&mut got, &format!("map/occupancy of {t}"), &|o| {
                    o.maps.contains_key(&t)
                });
            }
            _ => {}
        }
    }
    std::thread::sleep(Duration::from_millis(200));
    drain(&mut got);
    let mut lines = Vec::new();
    for (name, status, log) in stack.stop_all() {
        assert!(status.success(), "{name} ended with {status}:\n{log}");
        let line = last_line_with(&log, &format!("{name} stopped"))
            .unwrap_or_else(|| panic!("{name} logged no counters:\n{log}"));
        lines.push(line.to_string());
    }
    (got, lines)
}

#[test]
fn one_recorded_input_sequence_gives_the_same_outputs_in_lockstep_and_as_processes() {
    let (inputs, in_flight) = record();
    let count = |topic: &str| inputs.iter().filter(|r| r.topic == topic).count();
    let (frames, depths) = (count(topics::SIM_CAMERA), count(topics::SIM_DEPTH));
    assert!(
        frames > 200 && depths > 200,
        "{frames} frames, {depths} depth frames"
    );
    assert!(count(topics::VEHICLE_STATE) > 400);

    // Maps follow each depth frame, and go out on depth-map's clock when frames stop (as
    // before the first one): the clock's are timing, left out.
    let depth_captures: Vec<u64> = inputs
        .iter()
        .filter_map(|r| match &r.msg {
            OwnedMessage::DepthFrame(h, _) => Some(h.msg.capture_ns),
            _ => None,
        })
        .collect();
    let frame_maps = |o: &mut Outputs| o.maps.retain(|t, _| depth_captures.contains(t));
    let (mut lockstep, skipped) = through_lockstep(&inputs);
    frame_maps(&mut lockstep);
    for (stage, n) in skipped {
        assert_eq!(n, 0, "{stage} skipped inputs in lockstep");
    }
    // The three stages alone on the recorded inputs did what they did in the flight.
    assert_eq!(lockstep.frames, in_flight.frames);
    assert_eq!(lockstep.observations, in_flight.observations);
    for (t, map) in &lockstep.maps {
        assert_eq!(Some(map), in_flight.maps.get(t), "map of {t}");
    }
    // The recording exercised every stage: frames, pads found, maps.
    assert_eq!(lockstep.frames.len(), frames);
    assert!(
        lockstep.observations.len() > 30,
        "{} observations",
        lockstep.observations.len()
    );
    assert_eq!(lockstep.maps.len(), depths);

    let (mut processes, lines) = through_processes(&inputs, &lockstep);
    frame_maps(&mut processes);
    for line in &lines {
        assert_eq!(count_in(line, "skipped"), Some(0), "{line}");
        assert_eq!(count_in(line, "lost_upstream"), Some(0), "{line}");
    }
    assert_eq!(
        processes.frames.len(),
        lockstep.frames.len(),
        "camera frames"
    );
    for (t, f) in &lockstep.frames {
        assert_eq!(processes.frames.get(t), Some(f), "camera frame of {t}");
    }
    assert_eq!(
        processes.observations.keys().collect::<Vec<_>>(),
        lockstep.observations.keys().collect::<Vec<_>>(),
        "frames with a pad observation"
    );
    for (t, o) in &lockstep.observations {
        assert_eq!(processes.observations.get(t), Some(o), "observation of {t}");
    }
    eprintln!(
        "parity: {} camera frames, {} pad observations, {} maps identical from {} inputs",
        processes.frames.len(),
        processes.observations.len(),
        processes.maps.len(),
        inputs.len()
    );
    assert_eq!(processes.maps.len(), lockstep.maps.len(), "maps");
    for (t, m) in &lockstep.maps {
        let p = processes
            .maps
            .get(t)
            .unwrap_or_else(|| panic!("no map of {t}"));
        assert_eq!(p.0, m.0, "map header of {t}");
        assert!(p.1 == m.1, "map cells of {t} differ");
    }
}
