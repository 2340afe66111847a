#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test
//! The stage places a frame by the vehicle's pose when it was exposed: a frame that comes
//! before any state recent enough (the autopilot's telemetry late on a loaded machine)
//! waits for the next state instead of going out unplaced.

mod common;

use aruco_pnp::ArucoStage;
use common::{View, camera, estimator, pad_state, place, render};
use ipc_types::msg::{
    CameraFrameHeader, Header, PadObservation, PixelEncoding, Pose, VehicleState,
};
use ipc_types::topics;
use nalgebra::Isometry3;
use stage::testing::Collector;
use stage::{Input, Message, OwnedMessage, Stage};

const MS: u64 = 1_000_000;
const FILE: &str = "camera_down_640x480.yaml";

/// The observations the stage published, oldest first.
fn observations(out: &Collector) -> Vec<PadObservation> {
    out.on(topics::PAD_OBSERVATION)
        .filter_map(|m| match m {
            OwnedMessage::PadObservation(o) => Some(*o),
            _ => None,
        })
        .collect()
}

fn state(t_ns: u64, world_from_body: &Isometry3<f64>) -> VehicleState {
    let t = world_from_body.translation.vector;
    let q = world_from_body.rotation;
    VehicleState {
        msg: Header::captured_at(t_ns),
        world_from_body: Pose {
            translation: [t.x, t.y, t.z],
            rotation_xyzw: [q.i, q.j, q.k, q.w],
        },
        ..VehicleState::default()
    }
}

fn header(t_ns: u64) -> CameraFrameHeader {
    CameraFrameHeader {
        msg: Header::captured_at(t_ns),
        width: 640,
        height: 480,
        stride: 640,
        encoding: PixelEncoding::Mono8 as u32,
        ..CameraFrameHeader::default()
    }
}

fn feed(stage: &mut ArucoStage, out: &mut Collector, now_ns: u64, msg: Message<'_>) {
    let topic = match msg {
        Message::VehicleState(_) => topics::VEHICLE_STATE,
        _ => topics::CAMERA_FRAME,
    };
    stage.on_input(now_ns, Input { topic, msg }, out).unwrap();
}

/// A stage, the truth of one view, and its frame.
fn setup() -> (ArucoStage, Isometry3<f64>, Isometry3<f64>, Vec<u8>) {
    let mut cam = camera(FILE);
    let pad = pad_state();
    let view = View {
        height: 1.5,
        offset: [0.1, -0.05],
        roll_deg: 0.0,
        pitch_deg: 0.0,
        yaw_deg: 10.0,
    };
    let (world_from_body, _) = place(&cam, &pad, &view);
    let pixels = render(&mut cam, &pad, world_from_body);
    let stage = ArucoStage::new(estimator(FILE, &cam), 50 * MS);
    (stage, world_from_body, pad.world_from_pad, pixels)
}

#[test]
fn a_frame_ahead_of_the_telemetry_waits_for_the_next_state_and_is_placed_by_it() {
    let (mut stage, world_from_body, truth, pixels) = setup();
    let mut out = Collector::new();
    feed(
        &mut stage,
        &mut out,
        0,
        Message::VehicleState(&state(0, &world_from_body)),
    );
    // Exposed 200 ms after the newest state: beyond the 50 ms the stage extrapolates.
    feed(
        &mut stage,
        &mut out,
        201 * MS,
        Message::CameraFrame(&header(200 * MS), &pixels),
    );
    assert!(observations(&out).is_empty(), "held, not sent unplaced");
    // The late telemetry: a state from after the exposure places it.
    let later = state(210 * MS, &world_from_body);
    feed(
        &mut stage,
        &mut out,
        215 * MS,
        Message::VehicleState(&later),
    );
    let seen = observations(&out);
    assert_eq!(seen.len(), 1);
    let o = &seen[0];
    assert_eq!(o.world_valid, 1);
    assert_eq!(o.msg.capture_ns, 200 * MS);
    let p = o.world_from_pad.translation;
    let err = (nalgebra::Vector3::from(p) - truth.translation.vector).norm();
    assert!(err < 0.05, "{err} m off the pad");
    assert!(stage.counters().contains(&("held", 1)));
}

#[test]
fn a_held_frame_goes_out_unplaced_when_the_next_frame_comes_first() {
    let (mut stage, world_from_body, _, pixels) = setup();
    let mut out = Collector::new();
    feed(
        &mut stage,
        &mut out,
        0,
        Message::VehicleState(&state(0, &world_from_body)),
    );
    feed(
        &mut stage,
        &mut out,
        201 * MS,
        Message::CameraFrame(&header(200 * MS), &pixels),
    );
    feed(
        &mut stage,
        &mut out,
        234 * MS,
        Message::CameraFrame(&header(233 * MS), &pixels),
    );
    // The first in order, without a world pose; the second held in its turn.
    let seen = observations(&out);
    assert_eq!(seen.len(), 1);
    assert_eq!(seen[0].msg.capture_ns, 200 * MS);
    assert_eq!(seen[0].world_valid, 0);
    assert!(stage.counters().contains(&("no_state", 1)));
}
