//! Fuzz targets: every parser the stack runs on input it cannot trust, each as a
//! function from bytes to an outcome (a number that tells outcomes apart: which error,
//! how many frames), with seed inputs taken from the real files and frames. The
//! `landing-fuzz` binary mutates the seeds and runs the targets for a bounded time; the
//! regression test runs every seed and every input kept in `regressions/`.
//!
//! A target must never panic, hang or allocate without bound, whatever the bytes.

use std::collections::hash_map::DefaultHasher;
use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};

use aruco_pnp::ArucoStage;
use depth_map::{DepthMapConfig, DepthStage};
use ipc_types::msg::{
    CameraFrameHeader, DepthFrameHeader, Header, Intrinsics, PixelEncoding, Pose, VehicleState,
};
use ipc_types::topics;
use mavlink::MavHeader;
use mavlink::dialects::common::{
    ATTITUDE_QUATERNION_DATA, COMMAND_ACK_DATA, HEARTBEAT_DATA, LOCAL_POSITION_NED_DATA,
    MavAutopilot, MavMessage, MavModeFlag, MavState, MavType,
};
use optics::{CameraCalibration, PadModel};
use px4_link::{Framing, LinkStage};
use px4_protocol::codec::{Guard, StreamDecoder, encode};
use px4_protocol::signing::{Signer, SigningKey};
use stage::{Input, Message, Outbox, SliceHeader, SliceMut, Stage, StageError};

/// One fuzz target.
pub struct Target {
    /// Its name (`landing-fuzz --target NAME`).
    pub name: &'static str,
    /// What it parses.
    pub about: &'static str,
    /// Runs one input; returns a number that tells its outcome from others.
    pub run: fn(&mut State, &[u8]) -> u64,
    /// Real inputs to start from.
    pub seeds: fn(&Path) -> Vec<Vec<u8>>,
    /// Whether its inputs are text (the fuzzer also mutates them as text).
    pub text: bool,
}

/// What targets keep between runs (stages and files built once).
#[derive(Default)]
pub struct State {
    aruco: Option<ArucoStage>,
    depth: Option<DepthStage>,
    dir: Option<PathBuf>,
}

/// Every target.
pub const TARGETS: &[Target] = &[
    Target {
        name: "mavlink-stream",
        about: "MAVLink frames out of a serial byte stream, in chunks (px4_protocol::codec::StreamDecoder)",
        run: mavlink_stream,
        seeds: mavlink_seeds,
        text: false,
    },
    Target {
        name: "mavlink-datagram",
        about: "one UDP datagram into px4-link's stage, unsigned and signed (decoder, guard, link)",
        run: mavlink_datagram,
        seeds: mavlink_seeds,
        text: false,
    },
    Target {
        name: "config",
        about: "landing.toml (every section, checked)",
        run: config,
        seeds: config_seeds,
        text: true,
    },
    Target {
        name: "scenario",
        about: "a scenario file",
        run: scenario,
        seeds: scenario_seeds,
        text: true,
    },
    Target {
        name: "graph",
        about: "the dataflow graph (graph.toml), checked",
        run: graph_file,
        seeds: graph_seeds,
        text: true,
    },
    Target {
        name: "pad",
        about: "the pad layout (pad.toml), checked",
        run: pad,
        seeds: pad_seeds,
        text: true,
    },
    Target {
        name: "calibration",
        about: "a calibration YAML (OpenCV's or ROS's), through the stack's own reader",
        run: calibration,
        seeds: calibration_seeds,
        text: true,
    },
    Target {
        name: "mcap",
        about: "an MCAP recording (the recorder's reader)",
        run: mcap,
        seeds: mcap_seeds,
        text: false,
    },
    Target {
        name: "camera-frame",
        about: "camera frames (sizes, strides, encodings, pixels) into aruco-pnp's stage",
        run: camera_frame,
        seeds: camera_seeds,
        text: false,
    },
    Target {
        name: "realsense-bag",
        about: "a RealSense .bag recording, played to its end (depth_ingest::RsBag)",
        run: realsense_bag,
        seeds: realsense_bag_seeds,
        text: false,
    },
    Target {
        name: "depth-frame",
        about: "depth frames (sizes, scale, intrinsics, depths) into depth-map's stage",
        run: depth_frame,
        seeds: depth_seeds,
        text: false,
    },
];

/// The target called `name`.
pub fn target(name: &str) -> Option<&'static Target> {
    TARGETS.iter().find(|t| t.name == name)
}

fn hash(v: impl Hash) -> u64 {
    let mut h = DefaultHasher::new();
    v.hash(&mut h);
    h.finish()
}

/// An error's outcome: its text up to the first quoted value, without numbers (one per
/// kind of error and key, not one per value).
fn error_kind(e: &dyn std::fmt::Display) -> u64 {
    let s = e.to_string();
    let kind: String = s
        .chars()
        .take_while(|c| !matches!(c, '`' | '"' | '\''))
        .filter(|c| !c.is_ascii_digit())
        .take(120)
        .collect();
    hash(kind)
}

/// Counts what a stage published.
#[derive(Default)]
struct Count(u64, u64);

impl Outbox for Count {
    fn publish(&mut self, topic: &str, _msg: Message<'_>) -> Result<(), StageError> {
        self.0 += 1;
        self.1 = self.1.wrapping_add(hash(topic));
        Ok(())
    }

    fn publish_slice(
        &mut self,
        topic: &str,
        len: usize,
        fill: &mut dyn FnMut(SliceMut<'_>) -> Option<SliceHeader>,
    ) -> Result<bool, StageError> {
        // A stage's claimed length is bounded by its own max_slice_len in the drivers;
        // here, by what a test may allocate.
        if len > 64 << 20 {
            return Err(StageError::Failed(format!("{topic}: {len} elements")));
        }
        let mut buf = vec![0u8; len];
        let wrote = fill(SliceMut::U8(&mut buf)).is_some();
        self.0 += u64::from(wrote);
        Ok(wrote)
    }
}

// ---- MAVLink ---------------------------------------------------------------------

fn frame(buf: &mut Vec<u8>, seq: u8, msg: &MavMessage) {
    let h = MavHeader {
        system_id: 1,
        component_id: 1,
        sequence: seq,
    };
    let _ = encode(buf, h, msg);
}

fn mavlink_seeds(_deploy: &Path) -> Vec<Vec<u8>> {
    let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 6 << 16,
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
        base_mode: MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED,
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    });
    let pos = MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
        time_boot_ms: 1000,
        x: 1.0,
        y: 2.0,
        z: -3.0,
        ..LOCAL_POSITION_NED_DATA::default()
    });
    let att = MavMessage::ATTITUDE_QUATERNION(ATTITUDE_QUATERNION_DATA {
        time_boot_ms: 1000,
        q1: 1.0,
        ..ATTITUDE_QUATERNION_DATA::default()
    });
    let ack = MavMessage::COMMAND_ACK(COMMAND_ACK_DATA::default());
    let mut seeds = Vec::new();
    for m in [&hb, &pos, &att, &ack] {
        let mut b = vec![0x10];
        frame(&mut b, 1, m);
        seeds.push(b);
    }
    let mut all = vec![0x07];
    for (i, m) in [&hb, &pos, &att, &ack].into_iter().enumerate() {
        frame(&mut all, i as u8, m);
    }
    seeds.push(all);
    // A signed one.
    let mut signed = vec![0x81];
    let mut g = Guard::new(None, Some(Signer::new(fuzz_key(), 0, 0)));
    let _ = g.encode(
        &mut signed,
        MavHeader {
            system_id: 1,
            component_id: 1,
            sequence: 0,
        },
        &hb,
        1_000_000,
    );
    seeds.push(signed);
    seeds
}

fn fuzz_key() -> SigningKey {
    SigningKey::from_bytes([0x3c; 32])
}

/// First byte: chunk length (1-64); the rest fed in chunks of it.
fn mavlink_stream(_: &mut State, data: &[u8]) -> u64 {
    let Some((&first, rest)) = data.split_first() else {
        return 0;
    };
    let chunk = usize::from(first % 64) + 1;
    let mut d = StreamDecoder::new();
    let mut guard = Guard::open();
    let mut out = Vec::new();
    let mut errors = 0;
    for c in rest.chunks(chunk) {
        errors += d.push(c, 0, &mut guard, &mut out);
    }
    hash((out.len().min(8), errors.min(8), d.unknown_messages().min(8)))
}

/// First byte: bit 7 signed link; the rest is one datagram (then the same again).
fn mavlink_datagram(_: &mut State, data: &[u8]) -> u64 {
    let Some((&first, rest)) = data.split_first() else {
        return 0;
    };
    let key = (first & 0x80 != 0).then(fuzz_key);
    let cfg = px4_link::config::Px4LinkConfig::default();
    let mut stage = LinkStage::from_config(&cfg, Framing::Datagram, key, 0);
    let mut out = Count::default();
    for t in [1_000_000u64, 2_000_000] {
        let input = Input {
            topic: topics::MAVLINK_FROM_PX4,
            msg: Message::Mavlink(rest),
        };
        if stage.on_input(t, input, &mut out).is_err() || stage.on_inputs_done(t, &mut out).is_err()
        {
            return 1;
        }
    }
    let counts: Vec<u64> = stage.counters().iter().map(|(_, v)| (*v).min(4)).collect();
    hash((out.0.min(16), counts))
}

// ---- Files -----------------------------------------------------------------------

fn read(path: PathBuf) -> Vec<Vec<u8>> {
    std::fs::read(path).map(|b| vec![b]).unwrap_or_default()
}

fn dir_files(dir: PathBuf, ext: &str) -> Vec<Vec<u8>> {
    let mut out = Vec::new();
    if let Ok(entries) = std::fs::read_dir(dir) {
        let mut paths: Vec<PathBuf> = entries.flatten().map(|e| e.path()).collect();
        paths.sort();
        for p in paths {
            if p.extension().is_some_and(|e| e == ext)
                && let Ok(b) = std::fs::read(&p)
            {
                out.push(b);
            }
        }
    }
    out
}

fn text(data: &[u8]) -> Option<&str> {
    std::str::from_utf8(data).ok()
}

fn config_seeds(deploy: &Path) -> Vec<Vec<u8>> {
    let mut s = read(deploy.join("config").join("landing.toml"));
    s.push(b"[ipc]\nprefix = \"x_\"\n".to_vec());
    s
}

fn config(_: &mut State, data: &[u8]) -> u64 {
    let Some(t) = text(data) else { return 0 };
    match stack_config::parse::<stack::StackConfig>(t, Path::new("fuzz.toml")) {
        Ok(_) => 1,
        Err(e) => error_kind(&e),
    }
}

fn scenario_seeds(deploy: &Path) -> Vec<Vec<u8>> {
    dir_files(deploy.join("scenarios"), "toml")
}

fn scenario(_: &mut State, data: &[u8]) -> u64 {
    let Some(t) = text(data) else { return 0 };
    match stack_config::parse::<sim::scenario::Scenario>(t, Path::new("fuzz.toml")) {
        Ok(_) => 1,
        Err(e) => error_kind(&e),
    }
}

fn graph_seeds(deploy: &Path) -> Vec<Vec<u8>> {
    read(graph::default_path(deploy))
}

fn graph_file(_: &mut State, data: &[u8]) -> u64 {
    let Some(t) = text(data) else { return 0 };
    match graph::Graph::parse(t, Path::new("graph.toml")) {
        Ok(g) => hash(g.nodes.len()),
        Err(e) => error_kind(&e),
    }
}

fn pad_seeds(deploy: &Path) -> Vec<Vec<u8>> {
    read(deploy.join("config").join("pad.toml"))
}

fn pad(_: &mut State, data: &[u8]) -> u64 {
    let Some(t) = text(data) else { return 0 };
    match PadModel::from_toml(t) {
        Ok(p) => hash(p.markers.len()),
        Err(e) => error_kind(&e),
    }
}

fn calibration_seeds(deploy: &Path) -> Vec<Vec<u8>> {
    dir_files(deploy.join("config"), "yaml")
}

/// Through a file, as the stack reads it (`CameraCalibration::load`, the stack's own
/// bounded reader: OpenCV's FileStorage hung on `regressions/calibration/`).
fn calibration(state: &mut State, data: &[u8]) -> u64 {
    let dir = state.dir.get_or_insert_with(|| {
        let d = std::env::temp_dir().join(format!("landing-fuzz-{}", std::process::id()));
        let _ = std::fs::create_dir_all(&d);
        d
    });
    let path = dir.join("calibration.yaml");
    if std::fs::write(&path, data).is_err() {
        return 0;
    }
    match CameraCalibration::load(&path) {
        Ok(c) => hash((c.width, c.height)),
        Err(e) => error_kind(&e),
    }
}

fn realsense_bag_seeds(deploy: &Path) -> Vec<Vec<u8>> {
    // A recording librealsense itself wrote (tests/fixtures, beside deploy/).
    let fixture = deploy.join("../tests/fixtures/realsense-160x120-3-frames.bag");
    std::fs::read(fixture).into_iter().collect()
}

/// Through a file, as depth-ingest reads it: opened, then every image read.
fn realsense_bag(state: &mut State, data: &[u8]) -> u64 {
    let dir = state.dir.get_or_insert_with(|| {
        let d = std::env::temp_dir().join(format!("landing-fuzz-{}", std::process::id()));
        let _ = std::fs::create_dir_all(&d);
        d
    });
    let path = dir.join("recording.bag");
    if std::fs::write(&path, data).is_err() {
        return 0;
    }
    let mut bag = match depth_ingest::RsBag::open(&path) {
        Ok(b) => b,
        Err(e) => return error_kind(&e),
    };
    let mut image = depth_ingest::DepthImage::default();
    let mut frames = 0u64;
    loop {
        match bag.next_image(&mut image) {
            Ok(Some(_)) => frames += 1,
            Ok(None) => return hash(("end", frames.min(8))),
            Err(e) => return error_kind(&e) ^ frames.min(8),
        }
    }
}

fn mcap_seeds(_deploy: &Path) -> Vec<Vec<u8>> {
    // A small recording, written by the recorder itself.
    let path = std::env::temp_dir().join(format!("landing-fuzz-seed-{}.mcap", std::process::id()));
    let mut seeds = Vec::new();
    if let Ok(mut rec) = recorder::Recorder::create(&path) {
        let s = VehicleState::default();
        let _ = rec.record(topics::VEHICLE_STATE, 1_000, &Message::VehicleState(&s));
        let _ = rec.record(topics::VEHICLE_STATE, 2_000, &Message::VehicleState(&s));
        let _ = rec.write_metadata(
            "landing",
            std::collections::BTreeMap::from([("scenario".to_string(), "fuzz".to_string())]),
        );
        if rec.finish().is_ok()
            && let Ok(b) = std::fs::read(&path)
        {
            seeds.push(b);
        }
    }
    let _ = std::fs::remove_file(&path);
    seeds
}

fn mcap(_: &mut State, data: &[u8]) -> u64 {
    let mut n = 0u64;
    match recorder::read::read_buffer(data, &mut |m| {
        n += 1;
        let _ = m.topic.len();
    }) {
        None => 0,
        Some(s) => hash((n.min(8), s.broken.is_some(), s.metadata.len().min(4))),
    }
}

// ---- Frames ----------------------------------------------------------------------

/// Header bytes in front of a frame input: width, height, stride (u16 each), encoding,
/// a flag byte.
const FRAME_HEADER: usize = 8;

fn u16_at(d: &[u8], i: usize) -> u32 {
    u32::from(u16::from_le_bytes([d[i], d[i + 1]]))
}

fn camera_seeds(deploy: &Path) -> Vec<Vec<u8>> {
    let (w, h) = (640usize, 480usize);
    let mut pixels = vec![90u8; w * h];
    // The pad, drawn by the pad model, in the middle of the frame.
    if let Ok(pad) = PadModel::load(deploy.join("config").join("pad.toml")) {
        let (tw, th) = pad.texture_size(300.0);
        if let Ok(tex) = pad.render_texture(300.0)
            && tw as usize <= w
            && th as usize <= h
        {
            use opencv::prelude::*;
            let (x0, y0) = ((w - tw as usize) / 2, (h - th as usize) / 2);
            for r in 0..th as usize {
                for c in 0..tw as usize {
                    if let Ok(v) = tex.at_2d::<u8>(r as i32, c as i32) {
                        pixels[(y0 + r) * w + x0 + c] = *v;
                    }
                }
            }
        }
    }
    let mut seed = Vec::new();
    seed.extend_from_slice(&(w as u16).to_le_bytes());
    seed.extend_from_slice(&(h as u16).to_le_bytes());
    seed.extend_from_slice(&(w as u16).to_le_bytes());
    seed.push(PixelEncoding::Mono8 as u8);
    seed.push(0);
    seed.extend_from_slice(&pixels);
    let mut small = seed[..FRAME_HEADER].to_vec();
    small[0..2].copy_from_slice(&8u16.to_le_bytes());
    small[2..4].copy_from_slice(&8u16.to_le_bytes());
    small[4..6].copy_from_slice(&8u16.to_le_bytes());
    small.extend_from_slice(&[0u8; 64]);
    vec![seed, small]
}

fn state_at(t_ns: u64) -> VehicleState {
    VehicleState {
        msg: Header::captured_at(t_ns),
        world_from_body: Pose {
            translation: [0.0, 0.0, 1.5],
            rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
        },
        ..VehicleState::default()
    }
}

fn aruco_stage(deploy: &Path) -> Option<ArucoStage> {
    let cfg = aruco_pnp::ArucoConfig::default();
    ArucoStage::from_config(
        &cfg,
        CameraCalibration::load(deploy.join("config").join("camera_down_640x480.yaml")).ok()?,
        PadModel::load(deploy.join("config").join("pad.toml")).ok()?,
    )
    .ok()
}

fn camera_frame(state: &mut State, data: &[u8]) -> u64 {
    if data.len() < FRAME_HEADER {
        return 0;
    }
    if state.aruco.is_none() {
        state.aruco = aruco_stage(&stack_config::deploy_dir());
    }
    let Some(stage) = state.aruco.as_mut() else {
        return 0;
    };
    let h = CameraFrameHeader {
        msg: Header::captured_at(10_000_000),
        width: u16_at(data, 0),
        height: u16_at(data, 2),
        stride: u16_at(data, 4),
        encoding: u32::from(data[6]),
        undistorted: u32::from(data[7] & 1),
        ..CameraFrameHeader::default()
    };
    let mut out = Count::default();
    let s = state_at(10_000_000);
    let steps = [
        Input {
            topic: topics::VEHICLE_STATE,
            msg: Message::VehicleState(&s),
        },
        Input {
            topic: topics::CAMERA_FRAME,
            msg: Message::CameraFrame(&h, &data[FRAME_HEADER..]),
        },
    ];
    for i in steps {
        if stage.on_input(10_000_000, i, &mut out).is_err() {
            return 1;
        }
    }
    let _ = stage.on_tick(20_000_000, &mut out);
    hash((
        out.0.min(4),
        out.1,
        h.expected_len() == Some(data.len() - FRAME_HEADER),
    ))
}

fn depth_seeds(_deploy: &Path) -> Vec<Vec<u8>> {
    // The configured depth camera's size: a frame of another size is refused whole.
    let c = DepthMapConfig::default();
    let (w, h) = (c.width as u16, c.height as u16);
    let mut seed = Vec::new();
    seed.extend_from_slice(&w.to_le_bytes());
    seed.extend_from_slice(&h.to_le_bytes());
    seed.extend_from_slice(&[0, 0, 0, 0]);
    for i in 0..usize::from(w) * usize::from(h) {
        seed.extend_from_slice(&(1000 + (i % 500) as u16).to_le_bytes());
    }
    vec![seed]
}

fn depth_frame(state: &mut State, data: &[u8]) -> u64 {
    if data.len() < FRAME_HEADER {
        return 0;
    }
    if state.depth.is_none() {
        let cfg = DepthMapConfig {
            publish_period_ms: 100,
            ..DepthMapConfig::default()
        };
        state.depth = DepthStage::from_config(&cfg).ok();
    }
    let Some(stage) = state.depth.as_mut() else {
        return 0;
    };
    // Scale and intrinsics from the flag bytes: sane, zero, negative, huge or NaN.
    let pick = |b: u8, sane: f64| match b % 6 {
        0 | 1 => sane,
        2 => 0.0,
        3 => -sane,
        4 => f64::NAN,
        _ => 1e300,
    };
    let (w, hgt) = (u16_at(data, 0), u16_at(data, 2));
    let h = DepthFrameHeader {
        msg: Header::captured_at(10_000_000),
        width: w,
        height: hgt,
        depth_scale_m: pick(data[4], 0.001),
        intrinsics: Intrinsics {
            fx: pick(data[5], 60.0),
            fy: pick(data[5] / 6, 60.0),
            cx: pick(data[6], f64::from(w) / 2.0),
            cy: pick(data[7], f64::from(hgt) / 2.0),
        },
        ..DepthFrameHeader::default()
    };
    let depths: Vec<u16> = data[FRAME_HEADER..]
        .chunks_exact(2)
        .map(|b| u16::from_le_bytes([b[0], b[1]]))
        .collect();
    let mut out = Count::default();
    let s = state_at(10_000_000);
    let steps = [
        Input {
            topic: topics::VEHICLE_STATE,
            msg: Message::VehicleState(&s),
        },
        Input {
            topic: topics::SIM_DEPTH,
            msg: Message::DepthFrame(&h, &depths),
        },
    ];
    for i in steps {
        if stage.on_input(10_000_000, i, &mut out).is_err() {
            return 1;
        }
    }
    let _ = stage.on_tick(200_000_000, &mut out);
    let counts: Vec<(&str, u64)> = stage
        .counters()
        .into_iter()
        .map(|(k, v)| (k, v.min(1)))
        .collect();
    hash((out.0.min(4), counts))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    #[test]
    fn every_seed_reaches_its_parser_and_the_frame_seeds_are_taken() {
        let deploy = stack_config::deploy_dir();
        let mut state = State::default();
        for t in TARGETS {
            let seeds = (t.seeds)(&deploy);
            assert!(!seeds.is_empty(), "{}: no seeds", t.name);
            for s in &seeds {
                (t.run)(&mut state, s);
            }
        }
        // The seeds are real: the depth frame goes into the map, the camera frame gives
        // a pad pose.
        let count = |c: Vec<(&'static str, u64)>, k: &str| {
            c.iter().find(|(n, _)| *n == k).map_or(0, |(_, v)| *v)
        };
        let depth = state.depth.as_ref().unwrap().counters();
        assert_eq!(count(depth.clone(), "integrated"), 1, "{depth:?}");
        let aruco = state.aruco.as_ref().unwrap().counters();
        assert_eq!(count(aruco.clone(), "poses"), 1, "{aruco:?}");
    }
}
