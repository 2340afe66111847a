#![allow(clippy::unwrap_used, clippy::expect_used)]

use ipc_types::msg::{LinkOutcomeKind, Text};
use mavlink::dialects::common::{
    ATTITUDE_QUATERNION_DATA, COMMAND_ACK_DATA, GLOBAL_POSITION_INT_DATA, HEARTBEAT_DATA,
    HOME_POSITION_DATA, LOCAL_POSITION_NED_DATA, MavAutopilot, MavCmd, MavModeFlag, MavState,
    MavType,
};

use super::*;

const PX4: MavHeader = MavHeader {
    system_id: 1,
    component_id: 1,
    sequence: 0,
};

fn request(id: u64, kind: u32) -> LinkRequest {
    LinkRequest {
        msg: Header::default(),
        id,
        kind,
        reserved: 0,
        altitude_m: 2.0,
    }
}

fn safety(action: SafetyAction) -> SafetyCommand {
    SafetyCommand {
        msg: Header::default(),
        action: action as u32,
        reserved: 0,
        source: Text::new("test"),
        reason: Text::new("test"),
    }
}

fn commands(msgs: &[MavMessage]) -> Vec<MavCmd> {
    msgs.iter()
        .filter_map(|m| match m {
            MavMessage::COMMAND_LONG(c) if c.command != MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL => {
                Some(c.command)
            }
            _ => None,
        })
        .collect()
}

fn heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
        base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
        system_status: MavState::MAV_STATE_STANDBY,
        mavlink_version: 3,
    })
}

/// HOME_POSITION: home at `alt_amsl` m, `up` m above the local origin.
fn home(alt_amsl: f64, up: f64) -> MavMessage {
    MavMessage::HOME_POSITION(HOME_POSITION_DATA {
        altitude: (alt_amsl * 1e3).round() as i32,
        z: -up as f32,
        ..Default::default()
    })
}

/// The param7 of the NAV_TAKEOFF among `msgs`.
fn takeoff_param7(msgs: &[MavMessage]) -> Option<f32> {
    msgs.iter().find_map(|m| match m {
        MavMessage::COMMAND_LONG(c) if c.command == MavCmd::MAV_CMD_NAV_TAKEOFF => Some(c.param7),
        _ => None,
    })
}

fn telemetry(node: &mut LinkNode, now_ns: u64) {
    node.on_message(
        now_ns,
        &PX4,
        &MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA::default()),
    );
    node.on_message(
        now_ns,
        &PX4,
        &MavMessage::ATTITUDE_QUATERNION(ATTITUDE_QUATERNION_DATA {
            q1: 1.0,
            ..Default::default()
        }),
    );
}

#[test]
fn an_unreadable_request_is_answered_invalid_with_its_id_at_once() {
    let mut node = LinkNode::new(LinkSettings::default());
    node.on_request(5, &request(7, 99));
    let mut takeoff = request(8, LinkRequestKind::Takeoff as u32);
    takeoff.altitude_m = f64::NAN;
    node.on_request(6, &takeoff);
    let got = node.take_outcomes();
    assert_eq!(got.len(), 2);
    assert_eq!((got[0].id, got[0].kind), (7, 99));
    assert_eq!(got[0].outcome, LinkOutcomeKind::Invalid as u32);
    assert_eq!(got[1].id, 8);
    assert_eq!(got[1].outcome, LinkOutcomeKind::Invalid as u32);
    assert!(commands(node.poll(10)).is_empty(), "nothing sent for them");
}

#[test]
fn outcomes_carry_the_ids_of_their_requests_in_order() {
    let mut node = LinkNode::new(LinkSettings::default());
    node.on_message(0, &PX4, &heartbeat());
    node.on_message(0, &PX4, &home(489.4, 0.0));
    node.on_request(0, &request(41, LinkRequestKind::Arm as u32));
    node.on_request(0, &request(42, LinkRequestKind::Takeoff as u32));
    assert_eq!(
        commands(node.poll(1)),
        vec![MavCmd::MAV_CMD_COMPONENT_ARM_DISARM]
    );
    let ack = |command| {
        MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
            command,
            result: MavResult::MAV_RESULT_ACCEPTED,
            ..Default::default()
        })
    };
    node.on_message(2, &PX4, &ack(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM));
    assert_eq!(commands(node.poll(3)), vec![MavCmd::MAV_CMD_NAV_TAKEOFF]);
    let mut denied = ack(MavCmd::MAV_CMD_NAV_TAKEOFF);
    if let MavMessage::COMMAND_ACK(a) = &mut denied {
        a.result = MavResult::MAV_RESULT_DENIED;
    }
    node.on_message(4, &PX4, &denied);
    let got = node.take_outcomes();
    assert_eq!(got.len(), 2);
    assert_eq!(
        (got[0].id, got[0].kind, got[0].outcome),
        (
            41,
            LinkRequestKind::Arm as u32,
            LinkOutcomeKind::Accepted as u32
        )
    );
    assert_eq!(
        (got[1].id, got[1].outcome, got[1].result),
        (
            42,
            LinkOutcomeKind::Rejected as u32,
            MavResult::MAV_RESULT_DENIED as u32
        )
    );
}

#[test]
fn the_takeoff_altitude_is_sent_above_mean_sea_level_from_the_home_position() {
    // PX4 reads NAV_TAKEOFF param7 as AMSL; the request's 2 m are a world height.
    for (h0, up) in [(488.0, 0.0), (0.0, 0.0), (-10.0, 0.0), (488.0, 0.6)] {
        let mut node = LinkNode::new(LinkSettings::default());
        node.on_message(0, &PX4, &heartbeat());
        node.on_message(0, &PX4, &home(h0 + up, up));
        node.on_request(0, &request(1, LinkRequestKind::Takeoff as u32));
        let p7 = takeoff_param7(node.poll(1)).expect("NAV_TAKEOFF sent");
        assert!((f64::from(p7) - (h0 + 2.0)).abs() < 1e-3, "home {h0}: {p7}");
    }
}

#[test]
fn without_home_the_global_position_gives_the_takeoff_altitude() {
    let mut node = LinkNode::new(LinkSettings::default());
    node.on_message(0, &PX4, &heartbeat());
    telemetry(&mut node, 0); // local z 0
    node.on_message(
        0,
        &PX4,
        &MavMessage::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
            alt: 488_300,
            ..Default::default()
        }),
    );
    node.on_request(0, &request(1, LinkRequestKind::Takeoff as u32));
    let p7 = takeoff_param7(node.poll(1)).expect("NAV_TAKEOFF sent");
    assert!((p7 - 490.3).abs() < 1e-3, "{p7}");
}

#[test]
fn a_takeoff_without_any_altitude_reference_is_not_sent() {
    // GPS-less PX4 sends neither HOME_POSITION nor GLOBAL_POSITION_INT and would fly
    // NAV_TAKEOFF towards its local origin.
    let mut node = LinkNode::new(LinkSettings::default());
    node.on_message(0, &PX4, &heartbeat());
    telemetry(&mut node, 0);
    node.on_request(0, &request(3, LinkRequestKind::Takeoff as u32));
    assert!(takeoff_param7(node.poll(1)).is_none());
    let got = node.take_outcomes();
    assert_eq!(
        (got[0].id, got[0].outcome),
        (3, LinkOutcomeKind::NoAltitudeReference as u32)
    );
}

#[test]
fn an_offboard_request_behind_a_stale_setpoint_is_answered_and_does_not_block_the_queue() {
    // The fsm that asked was stopped (or restarted) mid-request: its last setpoint ages
    // out, and the next fsm's requests must still be served.
    let settings = LinkSettings::default();
    let mut node = LinkNode::new(settings);
    node.on_message(0, &PX4, &heartbeat());
    node.on_setpoint(0, &Setpoint::default());
    node.on_request(0, &request(1, LinkRequestKind::Offboard as u32));
    let later = settings.setpoint_max_age_ns + 1;
    node.on_message(later, &PX4, &heartbeat());
    node.on_request(later, &request(2, LinkRequestKind::Arm as u32));
    let sent: Vec<MavCmd> = [later, later + 1]
        .iter()
        .flat_map(|t| commands(node.poll(*t)))
        .collect();
    assert_eq!(
        sent,
        vec![MavCmd::MAV_CMD_COMPONENT_ARM_DISARM],
        "the arm request goes out"
    );
    let got = node.take_outcomes();
    assert_eq!(got.len(), 1);
    assert_eq!(
        (got[0].id, got[0].outcome),
        (1, LinkOutcomeKind::NoSetpointStream as u32)
    );
}

#[test]
fn a_safety_land_cancels_every_queued_request_and_sends_nav_land_on_the_next_poll() {
    let mut node = LinkNode::new(LinkSettings::default());
    node.on_message(0, &PX4, &heartbeat());
    node.on_request(0, &request(1, LinkRequestKind::Arm as u32));
    node.on_request(0, &request(2, LinkRequestKind::Takeoff as u32));
    node.on_request(0, &request(3, LinkRequestKind::Offboard as u32));
    assert_eq!(
        commands(node.poll(1)),
        vec![MavCmd::MAV_CMD_COMPONENT_ARM_DISARM]
    );
    node.on_safety(2, &safety(SafetyAction::SafeLand));
    assert_eq!(commands(node.poll(3)), vec![MavCmd::MAV_CMD_NAV_LAND]);
    let got = node.take_outcomes();
    let ids: Vec<_> = got.iter().map(|o| o.id).collect();
    assert_eq!(ids, vec![1, 2, 3]);
    for o in &got {
        assert_eq!(o.outcome, LinkOutcomeKind::Rejected as u32);
        assert_eq!(o.result, MavResult::MAV_RESULT_CANCELLED as u32);
    }
    // The late ACK of the dropped ARM does not answer the LAND.
    node.on_message(
        4,
        &PX4,
        &MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
            command: MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            result: MavResult::MAV_RESULT_ACCEPTED,
            ..Default::default()
        }),
    );
    assert!(node.take_outcomes().is_empty());
    node.on_message(
        5,
        &PX4,
        &MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
            command: MavCmd::MAV_CMD_NAV_LAND,
            result: MavResult::MAV_RESULT_ACCEPTED,
            ..Default::default()
        }),
    );
    let got = node.take_outcomes();
    assert_eq!(got.len(), 1);
    assert_eq!(
        (got[0].id, got[0].kind, got[0].outcome),
        (
            SAFETY_REQUEST_ID,
            LinkRequestKind::Land as u32,
            LinkOutcomeKind::Accepted as u32
        )
    );
}

#[test]
fn a_repeated_safety_order_still_in_flight_is_not_restarted() {
    let mut node = LinkNode::new(LinkSettings::default());
    node.on_message(0, &PX4, &heartbeat());
    node.on_safety(0, &safety(SafetyAction::Abort));
    assert_eq!(commands(node.poll(1)), vec![MavCmd::MAV_CMD_NAV_LAND]);
    node.on_safety(2, &safety(SafetyAction::SafeLand));
    assert!(commands(node.poll(3)).is_empty(), "no second LAND at once");
    assert!(node.take_outcomes().is_empty(), "nothing cancelled");
    // A different order replaces it.
    node.on_safety(4, &safety(SafetyAction::Hold));
    assert_eq!(commands(node.poll(5)), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
    let got = node.take_outcomes();
    assert_eq!(got.len(), 1);
    assert_eq!(got[0].kind, LinkRequestKind::Land as u32);
    assert_eq!(got[0].result, MavResult::MAV_RESULT_CANCELLED as u32);
}

#[test]
fn a_cleared_safety_command_does_nothing() {
    let mut node = LinkNode::new(LinkSettings::default());
    node.on_request(0, &request(1, LinkRequestKind::Arm as u32));
    node.on_safety(0, &safety(SafetyAction::None));
    assert!(node.take_outcomes().is_empty());
    assert!(node.status(0).busy);
}

#[test]
fn the_state_is_handed_out_once_per_telemetry_then_again_when_stale_with_its_old_stamp() {
    let mut node = LinkNode::new(LinkSettings::default());
    assert!(node.vehicle_state(0).is_none(), "nothing heard yet");
    node.on_message(0, &PX4, &heartbeat());
    telemetry(&mut node, 10_000_000);
    let s = node.vehicle_state(10_000_000).expect("first state");
    assert_eq!(s.msg.capture_ns, 10_000_000);
    assert_eq!(s.link.connected, 1);
    assert!(node.vehicle_state(20_000_000).is_none(), "no new telemetry");
    telemetry(&mut node, 30_000_000);
    assert_eq!(
        node.vehicle_state(30_000_000).unwrap().msg.capture_ns,
        30_000_000
    );
    // Silence: the same state again after the stale period, its stamp unchanged.
    let later = 30_000_000 + STALE_STATE_PERIOD_NS;
    let s = node.vehicle_state(later).expect("republished");
    assert_eq!(s.msg.capture_ns, 30_000_000);
    assert_eq!(s.link.last_telemetry_ns, 30_000_000);
    // Past the heartbeat timeout: connected drops, and that is published at once.
    let lost = LinkSettings::default().heartbeat_timeout_ns + 1;
    let s = node.vehicle_state(lost).expect("connection change");
    assert_eq!(s.link.connected, 0);
    assert_eq!(s.msg.capture_ns, 30_000_000);
}

/// A small deterministic generator (xorshift64*), so the property test needs no crate.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    /// Mostly ordinary values, sometimes huge, beyond f32, NaN or infinite.
    fn value(&mut self) -> f64 {
        let u = (self.next() >> 11) as f64 / (1u64 << 53) as f64;
        match self.next() % 16 {
            0 => f64::NAN,
            1 => f64::INFINITY,
            2 => -1e39,
            3 => 1e6 * (u - 0.5),
            4..=6 => 400.0 * (u - 0.5),
            _ => 40.0 * (u - 0.5),
        }
    }
}

#[test]
fn no_setpoint_beyond_the_bounds_is_ever_sent_whatever_the_mission_asks() {
    let bounds = crate::SetpointBounds::default();
    let mut node = LinkNode::new(LinkSettings::default());
    telemetry(&mut node, 0);
    let home = node.link.home().unwrap();
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let (mut sent, mut inside) = (0, 0);
    for k in 1..20_000u64 {
        let now = k * 5_000_000;
        let mut v = || [rng.value(), rng.value(), rng.value()];
        let sp = Setpoint {
            position: v(),
            velocity: v(),
            acceleration: v(),
            yaw: rng.value(),
            valid: (rng.next() % 16) as u32,
            ..Setpoint::default()
        };
        if bounds.check(&sp, Some(home)).is_ok() {
            inside += 1;
        }
        node.on_setpoint(now, &sp);
        if k % 8 == 0 {
            telemetry(&mut node, now);
        }
        node.send_due(now, |_, m| {
            if let MavMessage::SET_POSITION_TARGET_LOCAL_NED(t) = m {
                sent += 1;
                let ignore = |bit| t.type_mask.contains(bit);
                use mavlink::dialects::common::PositionTargetTypemask as M;
                let wire = [t.x, t.y, t.z, t.vx, t.vy, t.vz, t.afx, t.afy, t.afz, t.yaw];
                assert!(wire.iter().all(|x| x.is_finite()), "{t:?}");
                if !ignore(M::POSITION_TARGET_TYPEMASK_X_IGNORE) {
                    // NED on the wire, home in ENU.
                    let (e, n, d) = (f64::from(t.y), f64::from(t.x), f64::from(t.z));
                    let horizontal = (e - home.x).hypot(n - home.y);
                    assert!(horizontal <= bounds.geofence_radius_m, "{t:?}");
                    assert!(-d - home.z <= bounds.geofence_height_m, "{t:?}");
                    assert!(-d - home.z >= -2.0, "{t:?}");
                }
                if !ignore(M::POSITION_TARGET_TYPEMASK_VX_IGNORE) {
                    let h = f64::from(t.vx).hypot(f64::from(t.vy));
                    assert!(h <= bounds.max_horizontal_speed_m_s + 1e-4, "{t:?}");
                    assert!(
                        f64::from(t.vz.abs()) <= bounds.max_vertical_speed_m_s + 1e-4,
                        "{t:?}"
                    );
                }
                if !ignore(M::POSITION_TARGET_TYPEMASK_AX_IGNORE) {
                    let a = (f64::from(t.afx).powi(2)
                        + f64::from(t.afy).powi(2)
                        + f64::from(t.afz).powi(2))
                    .sqrt();
                    assert!(a <= bounds.max_acceleration_m_s2 + 1e-4, "{t:?}");
                }
            }
            Ok::<(), ()>(())
        })
        .unwrap();
    }
    let (refused, _) = node.refused_setpoints();
    eprintln!("{sent} setpoints sent, {inside} of the random ones inside, {refused} refused");
    assert!(
        sent > 1_000 && inside > 1_000 && refused > 1_000,
        "the test must exercise both sides"
    );
}

#[test]
fn a_safety_order_the_autopilot_already_follows_sends_nothing() {
    let mut node = LinkNode::new(LinkSettings::default());
    // PX4 in AUTO.LAND (main mode 4, sub mode 6), armed.
    let landing = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: (6 << 24) | (4 << 16),
        base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            | MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED,
        ..match heartbeat() {
            MavMessage::HEARTBEAT(h) => h,
            _ => unreachable!(),
        }
    });
    node.on_message(0, &PX4, &landing);
    // The watchdog repeats its order every 200 ms: not one LAND goes out for it.
    for k in 1..5u64 {
        node.on_safety(k * 200_000_000, &safety(SafetyAction::SafeLand));
        assert!(
            commands(node.poll(k * 200_000_000 + 1)).is_empty(),
            "order {k}"
        );
    }
    // Hold is another mode: that one goes out.
    node.on_safety(1_000_000_000, &safety(SafetyAction::Hold));
    assert_eq!(
        commands(node.poll(1_000_000_001)),
        vec![MavCmd::MAV_CMD_DO_SET_MODE]
    );
}

fn setpoints_sent(msgs: &[MavMessage]) -> usize {
    msgs.iter()
        .filter(|m| matches!(m, MavMessage::SET_POSITION_TARGET_LOCAL_NED(_)))
        .count()
}

fn hold_at(x: f64, seq: u64) -> Setpoint {
    Setpoint {
        msg: Header {
            seq,
            capture_ns: 5_000,
            ..Header::default()
        },
        position: [x, 0.0, 2.0],
        valid: Setpoint::POSITION,
        ..Setpoint::default()
    }
}

#[test]
fn by_default_a_new_setpoint_goes_on_the_wire_at_once_and_the_newest_is_repeated_every_period() {
    let settings = LinkSettings::default();
    let mut node = LinkNode::new(settings);
    node.on_message(0, &PX4, &heartbeat());
    node.on_setpoint(1_000_000, &hold_at(1.0, 1));
    assert_eq!(setpoints_sent(node.poll(1_000_000)), 1);
    // Well inside the stream's period: a new setpoint still goes at once.
    node.on_setpoint(3_000_000, &hold_at(2.0, 2));
    assert_eq!(setpoints_sent(node.poll(3_000_000)), 1);
    // Nothing new: nothing until the period has passed since the last one sent.
    let period = settings.setpoint_period_ns;
    assert_eq!(setpoints_sent(node.poll(3_000_000 + period / 2)), 0);
    assert_eq!(setpoints_sent(node.poll(3_000_000 + period)), 1);
}

#[test]
fn not_at_once_a_new_setpoint_waits_for_the_streams_period() {
    let settings = LinkSettings {
        new_setpoints_at_once: false,
        ..LinkSettings::default()
    };
    let mut node = LinkNode::new(settings);
    node.on_message(0, &PX4, &heartbeat());
    node.on_setpoint(1_000_000, &hold_at(1.0, 1));
    assert_eq!(setpoints_sent(node.poll(1_000_000)), 1);
    node.on_setpoint(3_000_000, &hold_at(2.0, 2));
    assert_eq!(setpoints_sent(node.poll(3_000_000)), 0);
    assert_eq!(
        setpoints_sent(node.poll(1_000_000 + settings.setpoint_period_ns)),
        1
    );
    // It is reported sent when it went.
    let (taken, sp) = node.take_sent_setpoint().unwrap();
    assert_eq!((taken, sp.msg.seq), (3_000_000, 2));
}

#[test]
fn each_new_setpoint_is_reported_sent_once_with_when_it_was_taken_in() {
    let mut node = LinkNode::new(LinkSettings::default());
    node.on_message(0, &PX4, &heartbeat());
    assert!(node.take_sent_setpoint().is_none());
    node.on_setpoint(2_000_000, &hold_at(1.0, 7));
    node.poll(2_500_000);
    let (taken, sp) = node.take_sent_setpoint().unwrap();
    assert_eq!(taken, 2_000_000);
    assert_eq!(
        (sp.msg.seq, sp.msg.capture_ns),
        (7, 5_000),
        "its header goes on"
    );
    assert!(node.take_sent_setpoint().is_none(), "once");
    // A repeat of the same setpoint is not a new one.
    node.poll(2_500_000 + LinkSettings::default().setpoint_period_ns);
    assert!(node.take_sent_setpoint().is_none());
}

#[test]
fn two_lost_heartbeats_in_a_row_keep_the_link_connected_and_a_third_does_not() {
    // PX4 beats at 1 Hz over UDP: one datagram lost in a flood must not read as a lost
    // autopilot (the fsm would land at once).
    let mut node = LinkNode::new(LinkSettings::default());
    node.on_message(0, &PX4, &heartbeat());
    let s = 1_000_000_000;
    // The beats at 1 s and 2 s are lost; telemetry still flows.
    for t in (10_000_000..3 * s).step_by(10_000_000) {
        telemetry(&mut node, t);
    }
    assert!(node.status(3 * s).connected, "two beats lost");
    node.on_message(3 * s, &PX4, &heartbeat());
    // Then three lost: 3.5 s of silence is a lost link.
    assert!(node.status(6 * s).connected);
    assert!(
        !node.status(6 * s + s / 2 + 1).connected,
        "three beats lost"
    );
}

#[test]
fn a_restarted_link_that_hears_telemetry_asks_for_a_heartbeat_at_once() {
    // Restarted in the air, px4-link hears PX4's 50 Hz telemetry at once but its 1 Hz
    // heartbeat (mode, arming) up to a second later: it asks for one instead of waiting.
    let ms = 1_000_000;
    let mut node = LinkNode::new(LinkSettings::default());
    let asks = |out: &[MavMessage]| {
        out.iter()
            .filter(|m| {
                matches!(m, MavMessage::COMMAND_LONG(c)
                    if c.command == MavCmd::MAV_CMD_REQUEST_MESSAGE && c.param1 == 0.0)
            })
            .count()
    };
    assert_eq!(asks(node.poll(0)), 0, "nothing heard: nothing asked");
    telemetry(&mut node, 10 * ms);
    assert_eq!(asks(node.poll(10 * ms)), 1, "asked at once");
    assert_eq!(asks(node.poll(100 * ms)), 0, "not again within 200 ms");
    assert_eq!(asks(node.poll(210 * ms)), 1, "again after 200 ms");
    node.on_message(230 * ms, &PX4, &heartbeat());
    assert!(node.status(230 * ms).connected);
    for t in (240..2_000).step_by(10) {
        telemetry(&mut node, t * ms);
        assert_eq!(
            asks(node.poll(t * ms)),
            0,
            "connected: never asked at {t} ms"
        );
    }
}

#[test]
fn the_autopilots_home_centres_the_geofence_of_a_link_restarted_in_the_air() {
    let mut node = LinkNode::new(LinkSettings::default());
    node.on_message(
        0,
        &PX4,
        &MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
            x: 10.0,
            y: 20.0,
            z: -3.0,
            ..Default::default()
        }),
    );
    assert_eq!(
        node.home(),
        Some(nalgebra::Vector3::new(20.0, 10.0, 3.0)),
        "first heard"
    );
    node.on_message(1, &PX4, &home(500.0, 0.0));
    assert_eq!(
        node.home(),
        Some(nalgebra::Vector3::new(0.0, 0.0, 0.0)),
        "the autopilot's"
    );
}

#[test]
fn behind_a_router_an_ack_the_autopilot_sent_a_ground_station_does_not_settle_our_request() {
    let mut node = LinkNode::new(LinkSettings::default());
    node.on_message(0, &PX4, &heartbeat());
    node.on_message(0, &PX4, &home(489.4, 0.0));
    node.on_request(0, &request(41, LinkRequestKind::Arm as u32));
    assert_eq!(
        commands(node.poll(1)),
        vec![MavCmd::MAV_CMD_COMPONENT_ARM_DISARM]
    );
    // The same command, refused to QGroundControl (system 255, component 190).
    let ack = |system, component, result| {
        MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
            command: MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            result,
            target_system: system,
            target_component: component,
            ..Default::default()
        })
    };
    node.on_message(2, &PX4, &ack(255, 190, MavResult::MAV_RESULT_DENIED));
    assert!(node.take_outcomes().is_empty(), "not ours");
    node.on_message(3, &PX4, &ack(1, 191, MavResult::MAV_RESULT_ACCEPTED));
    let got = node.take_outcomes();
    assert_eq!(got.len(), 1);
    assert_eq!(
        (got[0].id, got[0].outcome),
        (41, LinkOutcomeKind::Accepted as u32)
    );
}
