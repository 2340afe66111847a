#![allow(clippy::unwrap_used, clippy::expect_used)]

use ipc_types::msg::VehicleState;
use mavlink::dialects::common::{
    ATTITUDE_QUATERNION_DATA, HEARTBEAT_DATA, LOCAL_POSITION_NED_DATA, MavAutopilot, MavModeFlag,
    MavState, MavType,
};
use px4_protocol::signing::SigningKey;
use stage::OwnedMessage;
use stage::testing::Collector;

use super::*;

/// The vehicle states the stage published, oldest first.
fn states(out: &Collector) -> Vec<VehicleState> {
    (out.published.iter())
        .filter_map(|(_, m)| match m {
            OwnedMessage::VehicleState(s) => Some(*s),
            _ => None,
        })
        .collect()
}

/// The MAVLink frames the stage sent, oldest first.
fn frames(out: &Collector) -> Vec<Vec<u8>> {
    (out.published.iter())
        .filter_map(|(_, m)| match m {
            OwnedMessage::Mavlink(b) => Some(b.clone()),
            _ => None,
        })
        .collect()
}

const UNIX: u64 = 1_795_000_000_000_000_000;

/// A heartbeat and a position (40 m east, 10 m up) from the autopilot (1, 1), signed by
/// `guard` when it signs.
fn telemetry(guard: &mut Guard, seq: u8, now_ns: u64) -> Vec<u8> {
    let h = |sequence| MavHeader {
        system_id: 1,
        component_id: 1,
        sequence,
    };
    let mut buf = Vec::new();
    let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
        base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
        system_status: MavState::MAV_STATE_STANDBY,
        mavlink_version: 3,
    });
    guard.encode(&mut buf, h(seq), &hb, now_ns).unwrap();
    let pos = MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
        time_boot_ms: (now_ns / 1_000_000) as u32,
        x: 0.0,
        y: 40.0,
        z: -10.0,
        ..LOCAL_POSITION_NED_DATA::default()
    });
    guard
        .encode(&mut buf, h(seq.wrapping_add(1)), &pos, now_ns)
        .unwrap();
    let att = MavMessage::ATTITUDE_QUATERNION(ATTITUDE_QUATERNION_DATA {
        time_boot_ms: (now_ns / 1_000_000) as u32,
        q1: 1.0,
        ..ATTITUDE_QUATERNION_DATA::default()
    });
    guard
        .encode(&mut buf, h(seq.wrapping_add(2)), &att, now_ns)
        .unwrap();
    buf
}

fn feed(stage: &mut LinkStage, bytes: &[u8], now_ns: u64, out: &mut Collector) {
    let input = Input {
        topic: topics::MAVLINK_FROM_PX4,
        msg: Message::Mavlink(bytes),
    };
    stage.on_input(now_ns, input, out).unwrap();
    stage.on_inputs_done(now_ns, out).unwrap();
}

#[test]
fn a_signed_link_takes_no_telemetry_but_the_autopilots_signed_frames_and_counts_the_rest() {
    let key = SigningKey::from_bytes([0x42; 32]);
    let signer = Signer::new(key.clone(), 1, UNIX);
    let mut stage = LinkStage::new(LinkSettings::default(), Framing::Datagram, Some(signer));
    let mut out = Collector::new();
    let ms = 1_000_000;

    // A spoofer: unsigned, then signed with another key, then as another system.
    let mut unsigned = Guard::open();
    let mut forger = Guard::new(
        None,
        Some(Signer::new(SigningKey::from_bytes([1; 32]), 1, UNIX)),
    );
    for i in 0..10u64 {
        feed(
            &mut stage,
            &telemetry(&mut unsigned, i as u8 * 3, i * 10 * ms),
            i * 10 * ms,
            &mut out,
        );
        feed(
            &mut stage,
            &telemetry(&mut forger, i as u8 * 3, i * 10 * ms + ms),
            i * 10 * ms + ms,
            &mut out,
        );
    }
    stage
        .on_input(
            101 * ms,
            Input {
                topic: topics::MAVLINK_FOREIGN,
                msg: Message::Mavlink(&[1, 2, 3]),
            },
            &mut out,
        )
        .unwrap();
    assert!(
        states(&out).is_empty(),
        "a vehicle state from spoofed telemetry"
    );
    // What px4-link sends on a signed link is signed.
    assert!(!frames(&out).is_empty());
    for f in &frames(&out) {
        assert_eq!(f[2] & 1, 1, "an unsigned frame sent on a signed link");
    }

    // The autopilot, with the key: taken, and the state shows what was dropped.
    let mut autopilot = Guard::new(None, Some(Signer::new(key, 0, UNIX)));
    feed(
        &mut stage,
        &telemetry(&mut autopilot, 100, 200 * ms),
        200 * ms,
        &mut out,
    );
    let s = states(&out)
        .last()
        .copied()
        .expect("a state from the signed telemetry");
    assert_eq!(s.link.connected, 1);
    assert!((s.world_from_body.translation[0] - 40.0).abs() < 1e-6);
    assert_eq!(s.link.signed, 1);
    assert_eq!(s.link.unsigned, 30);
    assert_eq!(s.link.bad_signature, 30);
    assert_eq!(s.link.wrong_address, 1);
    assert_eq!(s.link.replayed, 0);
}

#[test]
fn an_unsigned_link_acts_on_the_autopilot_only() {
    let mut stage = LinkStage::new(LinkSettings::default(), Framing::Datagram, None);
    let mut out = Collector::new();
    let mut g = Guard::open();
    // A system 7 claiming to be the autopilot's: counted, not acted on.
    let mut other = Vec::new();
    let h = MavHeader {
        system_id: 7,
        component_id: 1,
        sequence: 0,
    };
    let pos = MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
        x: 100.0,
        ..LOCAL_POSITION_NED_DATA::default()
    });
    g.encode(&mut other, h, &pos, 0).unwrap();
    feed(&mut stage, &other, 1_000_000, &mut out);
    feed(
        &mut stage,
        &telemetry(&mut g, 0, 2_000_000),
        2_000_000,
        &mut out,
    );
    let s = states(&out).last().copied().unwrap();
    assert!(
        (s.world_from_body.translation[0] - 40.0).abs() < 1e-6,
        "{s:?}"
    );
    assert_eq!((s.link.signed, s.link.wrong_source), (0, 1));
}

/// Random numbers for the property test: ordinary values, huge ones, NaN, infinities.
struct Wild(u64);

impl Wild {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    fn value(&mut self) -> f64 {
        let u = (self.next() % 1_000_000) as f64 / 1_000_000.0;
        match self.next() % 10 {
            0 => f64::NAN,
            1 => f64::INFINITY * if u < 0.5 { 1.0 } else { -1.0 },
            2 => (u - 0.5) * 2e9,
            3 => (u - 0.5) * 1e40, // beyond f32
            4 | 5 => (u - 0.5) * 600.0,
            _ => (u - 0.5) * 40.0,
        }
    }
}

#[test]
fn whatever_the_fsm_asks_no_setpoint_beyond_the_bounds_goes_on_the_wire() {
    let settings = LinkSettings::default();
    let b = settings.bounds;
    let mut stage = LinkStage::new(settings, Framing::Datagram, None);
    let mut out = Collector::new();
    let ms = 1_000_000u64;
    // The autopilot reports the vehicle 40 m east, 10 m up: the take-off point.
    let mut autopilot = Guard::open();
    feed(&mut stage, &telemetry(&mut autopilot, 0, ms), ms, &mut out);
    let home = [40.0f64, 0.0, 10.0];
    let mut rng = Wild(0x9e37_79b9_7f4a_7c15);
    let mut sent = 0;
    for i in 0..20_000u64 {
        let t = 2 * ms + i * 10 * ms;
        let mut sp = ipc_types::msg::Setpoint {
            msg: ipc_types::msg::Header::captured_at(t),
            valid: (rng.next() % 16) as u32,
            yaw: rng.value(),
            ..Default::default()
        };
        for (k, h) in home.iter().enumerate() {
            sp.position[k] = h + rng.value();
            sp.velocity[k] = rng.value();
            sp.acceleration[k] = rng.value();
        }
        out.take();
        stage
            .on_input(
                t,
                Input {
                    topic: topics::FSM_SETPOINT,
                    msg: Message::Setpoint(&sp),
                },
                &mut out,
            )
            .unwrap();
        // Telemetry keeps the link up; the stream goes out at its period.
        feed(
            &mut stage,
            &telemetry(&mut autopilot, (i % 200) as u8, t),
            t,
            &mut out,
        );
        stage.on_tick(t + 5 * ms, &mut out).unwrap();
        for f in &frames(&out) {
            let mut msgs = Vec::new();
            px4_protocol::codec::decode_datagram(f, &mut msgs);
            for (_, m) in msgs {
                let MavMessage::SET_POSITION_TARGET_LOCAL_NED(s) = m else {
                    continue;
                };
                sent += 1;
                let mask = s.type_mask.bits();
                let used = |bits: u16| mask & bits == 0;
                // NED on the wire: x north, y east, z down.
                if used(0b111) {
                    let (e, n, u) = (f64::from(s.y), f64::from(s.x), -f64::from(s.z));
                    assert!(e.is_finite() && n.is_finite() && u.is_finite(), "{s:?}");
                    let d = [e - home[0], n - home[1], u - home[2]];
                    assert!(d[0].hypot(d[1]) <= b.geofence_radius_m + 1e-3, "{s:?}");
                    assert!(
                        d[2] <= b.geofence_height_m + 1e-3 && d[2] >= -2.0 - 1e-3,
                        "{s:?}"
                    );
                }
                if used(0b111_000) {
                    let (vn, ve, vd) = (f64::from(s.vx), f64::from(s.vy), f64::from(s.vz));
                    assert!(vn.hypot(ve) <= b.max_horizontal_speed_m_s + 1e-3, "{s:?}");
                    assert!(vd.abs() <= b.max_vertical_speed_m_s + 1e-3, "{s:?}");
                }
                if used(0b111_000_000) {
                    let a = [s.afx, s.afy, s.afz].map(f64::from);
                    let norm = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
                    assert!(norm <= b.max_acceleration_m_s2 + 1e-3, "{s:?}");
                }
                assert!(s.yaw.is_finite() && s.yaw_rate == 0.0, "{s:?}");
            }
        }
    }
    // Many were in bounds and went out; the others were refused and counted.
    assert!(sent > 1_000, "{sent}");
    assert!(stage.node().refused_setpoints().0 > 1_000);
}
