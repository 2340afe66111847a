#![allow(clippy::unwrap_used, clippy::expect_used)]
//! The simulator as PX4 SITL's backend, driven as PX4 drives it (bytes in, bytes out):
//! time starts when PX4 speaks, PX4 boots on the ground before the world's clock starts
//! and the world starts when it arms, one HIL_SENSOR per answer, 4 ms apart on PX4's
//! clock throughout.

use std::path::PathBuf;

use ipc_types::topics;
use mavlink::MavHeader;
use mavlink::dialects::common::{
    HEARTBEAT_DATA, HIL_ACTUATOR_CONTROLS_DATA, HilActuatorControlsFlags, MavMessage, MavModeFlag,
};
use px4_protocol::codec::{Guard, StreamDecoder, encode};
use sim::stage::{Pace, SimStage};
use stage::testing::Collector;
use stage::{Input, Message, OwnedMessage, Stage};

fn stage() -> SimStage {
    let deploy = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../deploy");
    let scn = sim::scenario::load("paper-sim", &deploy)
        .unwrap()
        .with_airframe("iris")
        .unwrap();
    SimStage::from_config(&scn, 1, Pace::realtime(1.0), None)
        .unwrap()
        .with_px4_sitl(&scn)
}

fn px4_bytes(msg: &MavMessage) -> Vec<u8> {
    let mut buf = Vec::new();
    let header = MavHeader {
        system_id: 1,
        component_id: 1,
        sequence: 0,
    };
    encode(&mut buf, header, msg).unwrap();
    buf
}

fn answer(armed: bool) -> Vec<u8> {
    let mut mode = MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED;
    if armed {
        mode |= MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
    }
    let mut controls = [0.0; 16];
    controls[..4].copy_from_slice(&[0.3; 4]);
    px4_bytes(&MavMessage::HIL_ACTUATOR_CONTROLS(
        HIL_ACTUATOR_CONTROLS_DATA {
            time_usec: 0,
            controls,
            mode,
            flags: HilActuatorControlsFlags::HIL_ACTUATOR_CONTROLS_FLAGS_LOCKSTEP,
        },
    ))
}

/// The HIL_SENSOR times (us) the stage sent since the last call.
fn sensors(out: &mut Collector) -> Vec<u64> {
    let (mut decoder, mut guard, mut decoded) = (StreamDecoder::new(), Guard::open(), Vec::new());
    for (topic, m) in out.take() {
        if let (true, OwnedMessage::Mavlink(b)) = (topic == topics::HIL_TO_PX4, m) {
            decoder.push(&b, 0, &mut guard, &mut decoded);
        }
    }
    decoded
        .iter()
        .filter_map(|(_, m)| match m {
            MavMessage::HIL_SENSOR(s) => Some(s.time_usec),
            _ => None,
        })
        .collect()
}

fn input(stage: &mut SimStage, now: u64, bytes: &[u8], out: &mut Collector) {
    let input = Input {
        topic: topics::HIL_FROM_PX4,
        msg: Message::Mavlink(bytes),
    };
    stage.on_input(now, input, out).unwrap();
    stage.on_inputs_done(now, out).unwrap();
}

#[test]
fn px4_boots_on_the_ground_before_the_world_starts_and_steps_in_lockstep() {
    let mut s = stage();
    let mut out = Collector::new();
    let ms = 1_000_000u64;
    // Nothing goes out before PX4 speaks.
    for k in 0..10 {
        s.on_tick(k * 2 * ms, &mut out).unwrap();
    }
    assert!(sensors(&mut out).is_empty());
    let hb = px4_bytes(&MavMessage::HEARTBEAT(HEARTBEAT_DATA::default()));
    let mut now = 20 * ms;
    input(&mut s, now, &hb, &mut out);
    // Before PX4's first answer the simulator runs free, on the wall clock while booting.
    for _ in 0..5 {
        now += 4 * ms;
        s.on_tick(now, &mut out).unwrap();
    }
    let first = sensors(&mut out);
    assert!(first.len() >= 5, "{first:?}");
    assert!(first.windows(2).all(|w| w[1] - w[0] == 4000), "{first:?}");
    // Disarmed answers: PX4 boots, the world's clock stays at 0.
    for _ in 0..250 {
        now += 4 * ms;
        input(&mut s, now, &answer(false), &mut out);
    }
    assert_eq!(s.simulator().time_ns(), 0, "the world waits for PX4 to arm");
    let booting = sensors(&mut out);
    assert!(booting.len() >= 240, "{}", booting.len());
    // Lockstep: without an answer nothing more goes out.
    now += 4 * ms;
    s.on_tick(now, &mut out).unwrap();
    s.on_tick(now + 2 * ms, &mut out).unwrap();
    assert!(
        sensors(&mut out).is_empty(),
        "a step waits for PX4's answer"
    );
    // Armed: the world's clock starts; PX4's keeps its 4 ms steps.
    let mut after = Vec::new();
    for _ in 0..50 {
        now += 4 * ms;
        input(&mut s, now, &answer(true), &mut out);
        after.extend(sensors(&mut out));
    }
    assert!(
        s.simulator().time_ns() > 0,
        "the world's clock runs once PX4 armed"
    );
    let last_boot = *booting.last().unwrap();
    assert!(
        after.first().is_some_and(|t| *t == last_boot + 4000),
        "{after:?}"
    );
    assert!(after.windows(2).all(|w| w[1] - w[0] == 4000), "{after:?}");
    // PX4's clock is its boot (the last boot step included, where it armed) plus the
    // world's.
    let world_us = s.simulator().time_ns() / 1000;
    assert_eq!(*after.last().unwrap(), last_boot + 4000 + world_us);
}
