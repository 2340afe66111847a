//! Tests of `commander`.

use std::f64::consts::FRAC_PI_2;

use mavlink::dialects::common::MavCmd;
use nalgebra::UnitQuaternion;

use super::*;

const MS: u64 = 1_000_000;
const S: u64 = 1_000_000_000;
const COMPANION: MavHeader = MavHeader {
    system_id: 1,
    component_id: 191,
    sequence: 0,
};

fn status(z: f64, landed: bool) -> VehicleStatus {
    VehicleStatus {
        estimate: EstimatedState {
            position: Vector3::new(1.0, 2.0, z),
            velocity: Vector3::zeros(),
            world_from_body: UnitQuaternion::identity(),
            body_rates: Vector3::zeros(),
            landed,
        },
        crashed: false,
    }
}

fn ground() -> VehicleStatus {
    status(0.0, true)
}

fn cmd(command: MavCmd, p: [f32; 7]) -> MavMessage {
    px4_protocol::command_long(command, p, (1, 1))
}

/// Sends a command and returns its ACK result (and drops other output).
fn command(c: &mut Commander, now: u64, msg: &MavMessage, v: &VehicleStatus) -> MavResult {
    c.take_outgoing();
    c.handle_message(now, &COMPANION, msg, v);
    let acks: Vec<_> = c
        .take_outgoing()
        .into_iter()
        .filter_map(|m| match m {
            MavMessage::COMMAND_ACK(a) => Some(a),
            _ => None,
        })
        .collect();
    assert_eq!(acks.len(), 1, "one ACK per command");
    assert_eq!((acks[0].target_system, acks[0].target_component), (1, 191));
    acks[0].result
}

/// Sends a command; returns every ACK it produced (PX4 sends none for some).
fn acks(c: &mut Commander, now: u64, msg: &MavMessage, v: &VehicleStatus) -> Vec<MavResult> {
    c.take_outgoing();
    c.handle_message(now, &COMPANION, msg, v);
    c.take_outgoing()
        .into_iter()
        .filter_map(|m| match m {
            MavMessage::COMMAND_ACK(a) => Some(a.result),
            _ => None,
        })
        .collect()
}

/// NAV_TAKEOFF with `param7` (AMSL, or NaN).
fn takeoff_msg(param7: f32) -> MavMessage {
    cmd(
        MavCmd::MAV_CMD_NAV_TAKEOFF,
        [0.0, 0.0, 0.0, f32::NAN, f32::NAN, f32::NAN, param7],
    )
}

/// The AMSL altitude of local height `z` with the default SIH origin.
fn amsl(z: f64) -> f32 {
    (Px4Params::default().sih_loc_h0 + z) as f32
}

fn arm_msg(arm: bool) -> MavMessage {
    cmd(
        MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        [f32::from(u8::from(arm)), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    )
}

fn set_mode_msg(main: f32, sub: f32) -> MavMessage {
    cmd(
        MavCmd::MAV_CMD_DO_SET_MODE,
        [1.0, main, sub, 0.0, 0.0, 0.0, 0.0],
    )
}

fn sp_msg(type_mask: u16, frame: MavFrame, v: [f32; 11]) -> MavMessage {
    MavMessage::SET_POSITION_TARGET_LOCAL_NED(SET_POSITION_TARGET_LOCAL_NED_DATA {
        time_boot_ms: 0,
        x: v[0],
        y: v[1],
        z: v[2],
        vx: v[3],
        vy: v[4],
        vz: v[5],
        afx: v[6],
        afy: v[7],
        afz: v[8],
        yaw: v[9],
        yaw_rate: v[10],
        type_mask: PositionTargetTypemask::from_bits_retain(type_mask),
        target_system: 1,
        target_component: 1,
        coordinate_frame: frame,
    })
}

/// Position-only setpoint at NED (x, y, z).
fn pos_sp(x: f32, y: f32, z: f32) -> MavMessage {
    sp_msg(
        0x0DF8,
        MavFrame::MAV_FRAME_LOCAL_NED,
        [x, y, z, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    )
}

/// Motors at idle on the ground: xy held, pressed down, no height.
fn ground_idle(sp: &Setpoint) -> bool {
    sp.position[2].is_none() && sp.velocity[2].is_some_and(|vz| vz < 0.0)
}

fn new() -> Commander {
    Commander::new(Px4Params::default()).unwrap()
}

/// Streams setpoints at 20 Hz from `from` for `dur`, updating at 500 Hz.
fn stream(c: &mut Commander, from: u64, dur: u64, v: &VehicleStatus) -> u64 {
    let mut t = from;
    while t < from + dur {
        if (t - from).is_multiple_of(50 * MS) {
            c.handle_message(t, &COMPANION, &pos_sp(0.0, 0.0, -2.0), v);
        }
        c.update(t, v);
        t += 2 * MS;
    }
    t
}

#[test]
fn params_parse_with_px4_names_and_validate() {
    let p: Px4Params = toml::from_str("COM_OF_LOSS_T = 0.5\nCOM_OBL_RC_ACT = 5").unwrap();
    assert_eq!(p.com_of_loss_t, 0.5);
    assert_eq!(p.com_obl_rc_act, 5);
    assert_eq!(p.mis_takeoff_alt, 2.5);
    assert!(toml::from_str::<Px4Params>("COM_FOO = 1").is_err());
    let bad = Px4Params {
        com_obl_rc_act: 3,
        ..Px4Params::default()
    };
    assert!(bad.validate().is_err());
    // PX4 v1.16's defaults: Position on offboard loss, SIH home at 489.4 m.
    let d = Px4Params::default();
    assert_eq!(
        (d.com_obl_rc_act, d.sih_loc_h0, d.nav_mc_alt_rad),
        (0, 489.4, 0.8)
    );
    assert_eq!(
        (d.com_disarm_prflt, d.com_spoolup_time, d.com_disarm_land),
        (10.0, 1.0, 2.0)
    );
    let bad = Px4Params {
        mpc_land_speed: f64::NAN,
        ..Px4Params::default()
    };
    assert!(Commander::new(bad).is_err());
    assert!(Px4Params::default().validate().is_ok());
}

#[test]
fn custom_mode_packing() {
    assert_eq!(FlightMode::Offboard.custom_mode(), 6 << 16);
    assert_eq!(FlightMode::AutoLand.custom_mode(), (6 << 24) | (4 << 16));
    assert_eq!(FlightMode::AutoLoiter.custom_mode(), (3 << 24) | (4 << 16));
    assert_eq!(FlightMode::AutoTakeoff.custom_mode(), (2 << 24) | (4 << 16));
    assert_eq!(FlightMode::Posctl.custom_mode(), 3 << 16);
    for m in [
        FlightMode::Posctl,
        FlightMode::AutoTakeoff,
        FlightMode::AutoLoiter,
        FlightMode::AutoLand,
        FlightMode::Offboard,
    ] {
        let (main, sub) = m.main_sub();
        assert_eq!(
            ModeRequest::from_main_sub(main, sub),
            ModeRequest::Simulated(m)
        );
    }
    assert_eq!(ModeRequest::from_main_sub(4, 5), ModeRequest::NotSimulated);
    assert_eq!(
        ModeRequest::from_main_sub(4, 10),
        ModeRequest::UnsupportedAuto
    );
    assert_eq!(
        ModeRequest::from_main_sub(4, 1),
        ModeRequest::UnsupportedAuto
    );
    assert_eq!(
        ModeRequest::from_main_sub(3, 1),
        ModeRequest::Simulated(FlightMode::Posctl)
    );
    assert_eq!(ModeRequest::from_main_sub(1, 0), ModeRequest::NotSimulated);
    assert_eq!(ModeRequest::from_main_sub(0, 6), ModeRequest::Unknown);
    assert_eq!(ModeRequest::from_main_sub(42, 0), ModeRequest::Unknown);
}

#[test]
fn heartbeat_at_1_hz_with_px4_identity() {
    let mut c = new();
    let v = ground();
    let mut beats = Vec::new();
    for i in 0..1500 {
        c.update(i * 2 * MS, &v);
        beats.extend(c.take_outgoing().into_iter().filter_map(|m| match m {
            MavMessage::HEARTBEAT(h) => Some(h),
            _ => None,
        }));
    }
    assert_eq!(beats.len(), 3, "t = 0, 1, 2 s");
    let h = &beats[0];
    assert_eq!(h.mavtype, MavType::MAV_TYPE_QUADROTOR);
    assert_eq!(h.autopilot, MavAutopilot::MAV_AUTOPILOT_PX4);
    assert!(
        h.base_mode
            .contains(MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)
    );
    assert!(
        !h.base_mode
            .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED)
    );
    assert_eq!(h.system_status, MavState::MAV_STATE_STANDBY);
    // PX4 v1.16 boots into Hold; an AUTO mode's base_mode is 29 disarmed.
    assert_eq!(h.custom_mode, FlightMode::AutoLoiter.custom_mode());
    assert_eq!(h.base_mode.bits(), 29);
    assert_eq!(
        command(&mut c, 3 * S, &arm_msg(true), &v),
        MavResult::MAV_RESULT_ACCEPTED
    );
    let h = c.heartbeat();
    assert_eq!(h.base_mode.bits(), 157, "AUTO armed");
    assert_eq!(h.system_status, MavState::MAV_STATE_ACTIVE);
}

#[test]
fn heartbeat_base_mode_per_mode_is_px4s() {
    let mut c = new();
    let g = ground();
    c.handle_message(0, &COMPANION, &pos_sp(0.0, 0.0, 0.0), &g);
    command(&mut c, 0, &set_mode_msg(6.0, 0.0), &g);
    assert_eq!(c.heartbeat().base_mode.bits(), 17, "OFFBOARD");
    command(&mut c, 0, &set_mode_msg(3.0, 0.0), &g);
    assert_eq!(c.heartbeat().base_mode.bits(), 81, "POSCTL");
}

#[test]
fn telemetry_default_rates_and_frames() {
    let mut c = new();
    let mut v = status(3.0, false);
    v.estimate.velocity = Vector3::new(1.0, 0.0, 0.5);
    v.estimate.body_rates = Vector3::new(0.1, 0.2, 0.3);
    let mut out = Vec::new();
    for i in 0..500 {
        c.update(i * 2 * MS, &v);
        out.extend(c.take_outgoing());
    }
    let n = |id| {
        out.iter()
            .filter(|m| mavlink::Message::message_id(*m) == id)
            .count()
    };
    assert_eq!(n(msg_id::ATTITUDE_QUATERNION), 50);
    assert!((29..=31).contains(&n(msg_id::LOCAL_POSITION_NED)));
    assert_eq!(n(msg_id::EXTENDED_SYS_STATE), 5);
    assert_eq!(n(msg_id::GLOBAL_POSITION_INT), 5);
    assert_eq!(n(msg_id::HOME_POSITION), 1, "0.5 Hz");
    assert_eq!(n(msg_id::ODOMETRY), 0);
    for m in &out {
        match m {
            MavMessage::LOCAL_POSITION_NED(p) => {
                assert_eq!([p.x, p.y, p.z], [2.0, 1.0, -3.0]);
                assert_eq!([p.vx, p.vy, p.vz], [0.0, 1.0, -0.5]);
            }
            MavMessage::ATTITUDE_QUATERNION(q) => {
                assert_eq!([q.rollspeed, q.pitchspeed, q.yawspeed], [0.1, -0.2, -0.3]);
                let h = 0.5f32.sqrt();
                assert!((q.q1 - h).abs() < 1e-6 && (q.q4 - h).abs() < 1e-6);
            }
            MavMessage::EXTENDED_SYS_STATE(s) => {
                // Disarmed counts as on the ground.
                assert_eq!(s.landed_state, MavLandedState::MAV_LANDED_STATE_ON_GROUND);
            }
            MavMessage::GLOBAL_POSITION_INT(g) => {
                // AMSL in mm; home was set at the first update (here, at 3 m).
                assert_eq!(g.alt, 492_400);
                assert_eq!(g.relative_alt, 0);
                assert_eq!([g.vx, g.vy, g.vz], [0, 100, -50]);
                // 2 m north, 1 m east of the SIH origin.
                let lat = 47.397742 + (2.0f64 / 6_371_000.0).to_degrees();
                assert!((f64::from(g.lat) * 1e-7 - lat).abs() < 2e-7);
                assert!(f64::from(g.lon) * 1e-7 > 8.545594);
            }
            MavMessage::HOME_POSITION(h) => {
                assert_eq!(h.altitude, 492_400);
                assert_eq!([h.x, h.y, h.z], [2.0, 1.0, -3.0]);
            }
            _ => {}
        }
    }
}

#[test]
fn set_message_interval_and_request_message() {
    let mut c = new();
    let v = ground();
    let req = |id: f32, us: f32| {
        cmd(
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            [id, us, 0.0, 0.0, 0.0, 0.0, 0.0],
        )
    };
    assert_eq!(
        command(&mut c, 0, &req(32.0, 100_000.0), &v),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert_eq!(
        command(&mut c, 0, &req(331.0, 20_000.0), &v),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert_eq!(
        command(&mut c, 0, &req(31.0, -1.0), &v),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert_eq!(
        command(&mut c, 0, &req(9999.0, 1000.0), &v),
        MavResult::MAV_RESULT_FAILED
    );
    assert_eq!(
        command(&mut c, 0, &req(32.0, -5.0), &v),
        MavResult::MAV_RESULT_DENIED
    );
    assert_eq!(
        command(&mut c, 0, &req(f32::NAN, 5.0), &v),
        MavResult::MAV_RESULT_DENIED
    );
    let mut out = Vec::new();
    for i in 0..500 {
        c.update(i * 2 * MS, &v);
        out.extend(c.take_outgoing());
    }
    let n = |id| {
        out.iter()
            .filter(|m| mavlink::Message::message_id(*m) == id)
            .count()
    };
    assert_eq!(n(msg_id::LOCAL_POSITION_NED), 10);
    assert_eq!(n(msg_id::ODOMETRY), 50);
    assert_eq!(n(msg_id::ATTITUDE_QUATERNION), 0);
    let odom = out.iter().find_map(|m| match m {
        MavMessage::ODOMETRY(o) => Some(o.clone()),
        _ => None,
    });
    let odom = odom.unwrap();
    assert_eq!(odom.frame_id, MavFrame::MAV_FRAME_LOCAL_NED);
    assert_eq!(odom.child_frame_id, MavFrame::MAV_FRAME_BODY_FRD);
    assert_eq!([odom.x, odom.y, odom.z], [2.0, 1.0, -0.0]);
    // Interval 0 restores the default.
    assert_eq!(
        command(&mut c, S, &req(31.0, 0.0), &v),
        MavResult::MAV_RESULT_ACCEPTED
    );
    // REQUEST_MESSAGE: ACK, then the message once.
    c.take_outgoing();
    c.handle_message(
        S,
        &COMPANION,
        &cmd(
            MavCmd::MAV_CMD_REQUEST_MESSAGE,
            [245.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        ),
        &v,
    );
    let out = c.take_outgoing();
    assert!(
        matches!(&out[0], MavMessage::COMMAND_ACK(a) if a.result == MavResult::MAV_RESULT_ACCEPTED)
    );
    assert!(matches!(&out[1], MavMessage::EXTENDED_SYS_STATE(_)));
    let r = command(
        &mut c,
        S,
        &cmd(
            MavCmd::MAV_CMD_REQUEST_MESSAGE,
            [77.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        ),
        &v,
    );
    assert_eq!(r, MavResult::MAV_RESULT_FAILED);
}

#[test]
fn arm_disarm_results() {
    let mut c = new();
    let g = ground();
    assert_eq!(
        command(&mut c, 0, &arm_msg(true), &g),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert!(c.armed());
    // Already armed: accepted.
    assert_eq!(
        command(&mut c, 0, &arm_msg(true), &g),
        MavResult::MAV_RESULT_ACCEPTED
    );
    // param1 neither 0 nor 1 (rounded): PX4 sends no ACK at all.
    let bad = cmd(
        MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        [2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    );
    assert!(acks(&mut c, 0, &bad, &g).is_empty());
    // Disarm in the air refused unless forced.
    let air = status(3.0, false);
    c.update(10 * MS, &air);
    assert_eq!(
        command(&mut c, 20 * MS, &arm_msg(false), &air),
        MavResult::MAV_RESULT_TEMPORARILY_REJECTED
    );
    assert!(c.armed());
    let force = cmd(
        MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        [0.0, FORCE_DISARM_MAGIC, 0.0, 0.0, 0.0, 0.0, 0.0],
    );
    assert_eq!(
        command(&mut c, 30 * MS, &force, &air),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert!(!c.armed());
    // Crashed: arming refused, as every arming refusal, TEMPORARILY_REJECTED.
    let mut crashed = ground();
    crashed.crashed = true;
    c.update(40 * MS, &crashed);
    assert_eq!(
        command(&mut c, 50 * MS, &arm_msg(true), &crashed),
        MavResult::MAV_RESULT_TEMPORARILY_REJECTED
    );
    assert!(!c.armed());
    assert_eq!(c.heartbeat().system_status, MavState::MAV_STATE_EMERGENCY);
}

#[test]
fn crash_disarms() {
    let mut c = new();
    let air = status(3.0, false);
    command(&mut c, 0, &arm_msg(true), &air);
    let mut crashed = air;
    crashed.crashed = true;
    c.update(2 * MS, &crashed);
    assert!(!c.armed());
    assert_eq!(c.take_events(), vec![CommanderEvent::DisarmCrash]);
}

#[test]
fn commands_for_other_systems_are_ignored_and_unknown_ones_unsupported() {
    let mut c = new();
    let g = ground();
    let mut m = arm_msg(true);
    if let MavMessage::COMMAND_LONG(d) = &mut m {
        d.target_system = 2;
    }
    c.handle_message(0, &COMPANION, &m, &g);
    assert!(c.take_outgoing().is_empty());
    assert!(!c.armed());
    // Broadcast (target_system 0): PX4's receiver drops it too.
    if let MavMessage::COMMAND_LONG(d) = &mut m {
        d.target_system = 0;
    }
    assert!(acks(&mut c, 0, &m, &g).is_empty());
    assert!(!c.armed());
    let r = command(&mut c, 0, &cmd(MavCmd::MAV_CMD_DO_REPOSITION, [0.0; 7]), &g);
    assert_eq!(r, MavResult::MAV_RESULT_UNSUPPORTED);
}

#[test]
fn takeoff_climbs_at_tko_speed_then_loiters() {
    let mut c = new();
    let g = ground();
    command(&mut c, 0, &arm_msg(true), &g);
    let r = command(&mut c, 0, &takeoff_msg(f32::NAN), &g);
    assert_eq!(r, MavResult::MAV_RESULT_ACCEPTED);
    assert_eq!(c.mode(), FlightMode::AutoTakeoff);
    c.update(0, &g);
    // COM_SPOOLUP_TIME (1 s) after arming: motors at idle, no climb yet.
    c.update(500 * MS, &g);
    assert!(ground_idle(&c.setpoint()), "{:?}", c.setpoint());
    c.update(S, &g);
    c.update(2 * S, &status(1.0, false));
    assert_eq!(c.landed_state(), LandedState::Takeoff);
    let sp = c.setpoint();
    assert_eq!(sp.position[0], Some(1.0));
    assert_eq!(sp.position[1], Some(2.0));
    assert!(
        (sp.position[2].unwrap() - 1.5).abs() < 1e-9,
        "ramp at 1.5 m/s"
    );
    assert_eq!(sp.velocity[2], Some(1.5));
    // Within NAV_MC_ALT_RAD (0.8 m) of MIS_TAKEOFF_ALT (2.5 m): AUTO.LOITER there.
    c.update(3 * S, &status(1.6, false));
    assert_eq!(c.mode(), FlightMode::AutoTakeoff);
    c.update(3 * S + 100 * MS, &status(1.8, false));
    assert_eq!(c.mode(), FlightMode::AutoLoiter);
    assert_eq!(c.landed_state(), LandedState::InAir);
    let sp = c.setpoint();
    assert_eq!(sp.position, [Some(1.0), Some(2.0), Some(2.5)]);
    // param7 gives the altitude, above mean sea level.
    let r = command(&mut c, 3 * S, &takeoff_msg(amsl(6.0)), &status(2.5, false));
    assert_eq!(r, MavResult::MAV_RESULT_ACCEPTED);
    c.update(3 * S, &status(2.5, false));
    c.update(4 * S, &status(3.0, false));
    assert_eq!(c.mode(), FlightMode::AutoTakeoff);
    c.update(5 * S, &status(5.3, false));
    assert_eq!(c.mode(), FlightMode::AutoLoiter);
    let z = c.setpoint().position[2].unwrap();
    assert!(
        (z - 6.0).abs() < 1e-4,
        "loiters at the takeoff altitude: {z}"
    );
}

#[test]
fn takeoff_below_the_current_altitude_is_clamped_and_the_vehicle_stays_down() {
    // The bug PX4 showed the stack: param7 = 2.5 read as 2.5 m AMSL, home at
    // 489.4 m. ACCEPTED, "Already higher than takeoff altitude", no climb, and
    // the pre-flight auto-disarm 11 s after arming.
    let mut c = new();
    let g = ground();
    command(&mut c, 0, &arm_msg(true), &g);
    assert_eq!(
        command(&mut c, 0, &takeoff_msg(2.5), &g),
        MavResult::MAV_RESULT_ACCEPTED
    );
    let mut t = 0;
    while t < 11 * S - 10 * MS {
        c.update(t, &g);
        assert!(ground_idle(&c.setpoint()), "no climb: {:?}", c.setpoint());
        t += 10 * MS;
    }
    assert!(c.armed());
    assert_eq!(c.mode(), FlightMode::AutoTakeoff);
    c.update(11 * S, &g);
    assert!(!c.armed());
    assert_eq!(
        c.take_events(),
        vec![
            CommanderEvent::AlreadyHigher,
            CommanderEvent::AutoDisarmPreflight
        ]
    );
    // Takeoff does not prevent arming: it stays the mode after the disarm.
    assert_eq!(c.mode(), FlightMode::AutoTakeoff);
}

#[test]
fn takeoff_param7_is_amsl_whatever_the_home_altitude() {
    for h0 in [488.0, 0.0, -10.0] {
        let mut c = Commander::new(Px4Params {
            sih_loc_h0: h0,
            ..Px4Params::default()
        })
        .unwrap();
        let g = ground();
        c.update(0, &g);
        assert_eq!(c.home().unwrap().alt_amsl, h0);
        command(&mut c, 0, &arm_msg(true), &g);
        command(&mut c, 0, &takeoff_msg((h0 + 4.0) as f32), &g);
        c.update(0, &g);
        c.update(S, &status(1.5, false));
        assert!(c.take_events().is_empty(), "home {h0}: no clamp");
        c.update(4 * S, &status(3.5, false));
        assert_eq!(c.mode(), FlightMode::AutoLoiter, "home {h0}");
        let z = c.setpoint().position[2].unwrap();
        assert!((z - 4.0).abs() < 1e-3, "home {h0}: {z}");
    }
}

#[test]
fn takeoff_while_disarmed_waits_for_arming() {
    let mut c = new();
    let g = ground();
    let to = takeoff_msg(f32::NAN);
    assert_eq!(command(&mut c, 0, &to, &g), MavResult::MAV_RESULT_ACCEPTED);
    c.update(S, &g);
    assert_eq!(c.mode(), FlightMode::AutoTakeoff);
    assert_eq!(c.landed_state(), LandedState::OnGround);
    command(&mut c, 2 * S, &arm_msg(true), &g);
    c.update(2 * S, &g);
    c.update(3 * S, &g);
    c.update(3 * S + 500 * MS, &g);
    let z = c.setpoint().position[2].unwrap();
    assert!(
        (z - 0.75).abs() < 1e-9,
        "ramp starts after the spool-up: {z}"
    );
}

#[test]
fn land_descends_then_disarms_after_com_disarm_land() {
    let mut c = new();
    let air = status(3.0, false);
    command(&mut c, 0, &arm_msg(true), &ground());
    c.update(0, &air);
    let r = command(&mut c, 0, &cmd(MavCmd::MAV_CMD_NAV_LAND, [0.0; 7]), &air);
    assert_eq!(r, MavResult::MAV_RESULT_ACCEPTED);
    c.update(2 * MS, &air);
    assert_eq!(c.mode(), FlightMode::AutoLand);
    assert_eq!(c.landed_state(), LandedState::Landing);
    let sp = c.setpoint();
    assert_eq!(sp.position, [Some(1.0), Some(2.0), None]);
    assert_eq!(sp.velocity, [None, None, Some(-0.7)]);
    // The land detector (the autopilot's, through the estimate) reports landed from
    // t = 1 s: on the ground at once, disarmed COM_DISARM_LAND (2 s) after that.
    c.update(S, &ground());
    assert_eq!(c.landed_state(), LandedState::OnGround);
    let mut t = S + 2 * MS;
    while t < S + 2 * S - 10 * MS {
        c.update(t, &ground());
        t += 2 * MS;
    }
    assert_eq!(c.landed_state(), LandedState::OnGround);
    assert!(c.armed());
    assert_eq!(
        c.mode(),
        FlightMode::AutoLand,
        "LAND while armed on the ground"
    );
    c.update(S + 2 * S + 2 * MS, &ground());
    assert!(!c.armed());
    // After the disarm: the last mode asked for that does not prevent arming
    // (here the boot mode, Hold); LAND never sticks.
    assert_eq!(c.mode(), FlightMode::AutoLoiter);
    assert_eq!(c.take_events(), vec![CommanderEvent::AutoDisarmLanded]);
}

#[test]
fn preflight_auto_disarm() {
    let mut c = new();
    let g = ground();
    command(&mut c, 0, &arm_msg(true), &g);
    // COM_SPOOLUP_TIME + COM_DISARM_PRFLT = 11 s.
    let mut t = 0;
    while t < 11 * S - 10 * MS {
        c.update(t, &g);
        t += 10 * MS;
    }
    assert!(c.armed());
    c.update(11 * S, &g);
    assert!(!c.armed());
    assert_eq!(c.take_events(), vec![CommanderEvent::AutoDisarmPreflight]);
}

#[test]
fn offboard_needs_only_a_setpoint_younger_than_com_of_loss_t() {
    let mut c = new();
    let g = ground();
    // Disarmed: the mode change is always accepted, even with no setpoint.
    assert_eq!(
        command(&mut c, 0, &set_mode_msg(6.0, 0.0), &g),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert_eq!(c.mode(), FlightMode::Offboard);
    // Arming needs the offboard signal: refused without, accepted after one setpoint.
    assert_eq!(
        command(&mut c, 0, &arm_msg(true), &g),
        MavResult::MAV_RESULT_TEMPORARILY_REJECTED
    );
    c.handle_message(10 * MS, &COMPANION, &pos_sp(0.0, 0.0, -2.0), &g);
    assert!(c.offboard_available(10 * MS + 999 * MS));
    assert!(!c.offboard_available(10 * MS + S));
    assert_eq!(
        command(&mut c, 20 * MS, &arm_msg(true), &g),
        MavResult::MAV_RESULT_ACCEPTED
    );
    // After the spool-up, the setpoint (NED z -2 = ENU z 2) applies.
    let t = stream(&mut c, 20 * MS, 1100 * MS, &g);
    c.update(t, &g);
    assert_eq!(c.setpoint().position, [Some(0.0), Some(0.0), Some(2.0)]);
}

#[test]
fn armed_offboard_without_a_fresh_setpoint_is_temporarily_rejected() {
    let mut c = new();
    let g = ground();
    command(&mut c, 0, &arm_msg(true), &g);
    assert_eq!(
        command(&mut c, 0, &set_mode_msg(6.0, 0.0), &g),
        MavResult::MAV_RESULT_TEMPORARILY_REJECTED
    );
    assert_eq!(c.mode(), FlightMode::AutoLoiter);
    // One setpoint is enough (no 1 s stream), and setpoints do not move the
    // vehicle outside OFFBOARD.
    c.handle_message(S, &COMPANION, &pos_sp(0.0, 0.0, -2.0), &g);
    c.update(S, &g);
    assert!(ground_idle(&c.setpoint()), "{:?}", c.setpoint());
    assert_eq!(
        command(&mut c, S, &set_mode_msg(6.0, 0.0), &g),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert_eq!(c.heartbeat().custom_mode, 6 << 16);
}

#[test]
fn arming_in_offboard_without_stream_is_rejected() {
    let mut c = new();
    let g = ground();
    let t = stream(&mut c, 0, 200 * MS, &g);
    command(&mut c, t, &set_mode_msg(6.0, 0.0), &g);
    assert_eq!(c.mode(), FlightMode::Offboard);
    // Stream stops; disarmed, so no failsafe, but arming is refused.
    c.update(t + 3 * S, &g);
    assert_eq!(c.mode(), FlightMode::Offboard);
    assert_eq!(
        command(&mut c, t + 3 * S, &arm_msg(true), &g),
        MavResult::MAV_RESULT_TEMPORARILY_REJECTED
    );
}

fn offboard_loss(action: u8) -> (FlightMode, u64, Vec<CommanderEvent>) {
    let mut c = Commander::new(Px4Params {
        com_obl_rc_act: action,
        ..Px4Params::default()
    })
    .unwrap();
    let air = status(2.0, false);
    let t = stream(&mut c, 0, 200 * MS, &air);
    command(&mut c, t, &arm_msg(true), &air);
    command(&mut c, t, &set_mode_msg(6.0, 0.0), &air);
    assert_eq!(c.mode(), FlightMode::Offboard);
    let last = t - 50 * MS;
    let mut now = t;
    while c.mode() == FlightMode::Offboard && now < t + 5 * S {
        c.update(now, &air);
        now += 2 * MS;
    }
    (c.mode(), now - 2 * MS - last, c.take_events())
}

#[test]
fn offboard_loss_switches_to_position_by_default_after_com_of_loss_t() {
    let (mode, after, events) = offboard_loss(0);
    assert_eq!(mode, FlightMode::Posctl);
    assert!((1000 * MS..=1010 * MS).contains(&after), "after {after} ns");
    assert_eq!(
        events,
        vec![CommanderEvent::OffboardLost(FlightMode::Posctl)]
    );
}

#[test]
fn offboard_comes_back_when_setpoints_resume_after_a_loss() {
    let mut c = new();
    let air = status(2.0, false);
    let t = stream(&mut c, 0, 200 * MS, &air);
    command(&mut c, t, &arm_msg(true), &air);
    command(&mut c, t, &set_mode_msg(6.0, 0.0), &air);
    let mut now = t;
    while now < t + 2 * S {
        c.update(now, &air);
        now += 2 * MS;
    }
    assert_eq!(c.mode(), FlightMode::Posctl);
    assert_eq!(c.heartbeat().system_status, MavState::MAV_STATE_CRITICAL);
    stream(&mut c, now, 100 * MS, &air);
    assert_eq!(c.mode(), FlightMode::Offboard);
    assert_eq!(c.heartbeat().system_status, MavState::MAV_STATE_ACTIVE);
    assert_eq!(
        c.take_events(),
        vec![
            CommanderEvent::OffboardLost(FlightMode::Posctl),
            CommanderEvent::OffboardRegained
        ]
    );
}

#[test]
fn offboard_loss_lands_after_com_of_loss_t_with_com_obl_rc_act_4() {
    let (mode, after, events) = offboard_loss(4);
    assert_eq!(mode, FlightMode::AutoLand);
    assert!((1000 * MS..=1010 * MS).contains(&after), "after {after} ns");
    assert_eq!(
        events,
        vec![CommanderEvent::OffboardLost(FlightMode::AutoLand)]
    );
}

#[test]
fn offboard_loss_holds_with_com_obl_rc_act_5() {
    let (mode, _, events) = offboard_loss(5);
    assert_eq!(mode, FlightMode::AutoLoiter);
    assert_eq!(
        events,
        vec![CommanderEvent::OffboardLost(FlightMode::AutoLoiter)]
    );
}

#[test]
fn do_set_mode_results() {
    let mut c = new();
    let air = status(2.0, false);
    command(&mut c, 0, &arm_msg(true), &ground());
    // Hold was the boot mode; from POSCTL, entering it holds where the vehicle is.
    command(&mut c, 0, &set_mode_msg(3.0, 0.0), &air);
    assert_eq!(
        command(&mut c, 0, &set_mode_msg(4.0, 3.0), &air),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert_eq!(c.mode(), FlightMode::AutoLoiter);
    assert_eq!(c.heartbeat().custom_mode, (3 << 24) | (4 << 16));
    c.update(0, &air);
    assert_eq!(c.setpoint().position, [Some(1.0), Some(2.0), Some(2.0)]);
    assert_eq!(
        command(&mut c, 0, &set_mode_msg(4.0, 6.0), &air),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert_eq!(c.mode(), FlightMode::AutoLand);
    assert_eq!(
        command(&mut c, 0, &set_mode_msg(3.0, 0.0), &air),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert_eq!(c.mode(), FlightMode::Posctl);
    // Real PX4 modes the simulator does not fly.
    assert_eq!(
        command(&mut c, 0, &set_mode_msg(4.0, 5.0), &air),
        MavResult::MAV_RESULT_UNSUPPORTED
    );
    assert_eq!(
        command(&mut c, 0, &set_mode_msg(1.0, 0.0), &air),
        MavResult::MAV_RESULT_UNSUPPORTED
    );
    assert_eq!(c.mode(), FlightMode::Posctl);
    // Wrongly packed: ACKed, nothing happens (as PX4).
    assert_eq!(
        command(&mut c, 0, &set_mode_msg(0.0, 6.0), &air),
        MavResult::MAV_RESULT_ACCEPTED
    );
    let no_flag = cmd(
        MavCmd::MAV_CMD_DO_SET_MODE,
        [0.0, 4.0, 6.0, 0.0, 0.0, 0.0, 0.0],
    );
    assert_eq!(
        command(&mut c, 0, &no_flag, &air),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert_eq!(c.mode(), FlightMode::Posctl);
    assert_eq!(
        command(&mut c, 0, &set_mode_msg(f32::NAN, 0.0), &air),
        MavResult::MAV_RESULT_ACCEPTED,
        "no mode: nothing changes"
    );
    assert_eq!(c.mode(), FlightMode::Posctl);
    // An AUTO sub mode PX4 does not have: "Unsupported auto mode".
    assert_eq!(
        command(&mut c, 0, &set_mode_msg(4.0, 10.0), &air),
        MavResult::MAV_RESULT_TEMPORARILY_REJECTED
    );
    // DO_SET_MODE to AUTO.TAKEOFF uses MIS_TAKEOFF_ALT.
    assert_eq!(
        command(&mut c, 0, &set_mode_msg(4.0, 2.0), &air),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert_eq!(c.mode(), FlightMode::AutoTakeoff);
}

#[test]
#[allow(deprecated)]
fn set_mode_message_is_acked_as_do_set_mode() {
    let mut c = new();
    let g = ground();
    let m = MavMessage::SET_MODE(SET_MODE_DATA {
        custom_mode: (3 << 24) | (4 << 16),
        target_system: 1,
        base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
    });
    c.handle_message(0, &COMPANION, &m, &g);
    let out = c.take_outgoing();
    assert!(matches!(&out[0], MavMessage::COMMAND_ACK(a)
        if a.command == MavCmd::MAV_CMD_DO_SET_MODE && a.result == MavResult::MAV_RESULT_ACCEPTED));
    assert_eq!(c.mode(), FlightMode::AutoLoiter);
}

#[test]
fn setpoint_conversion_ned_to_enu() {
    let all = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 0.0, 0.5];
    let sp = setpoint_from_local_ned(&match sp_msg(0, MavFrame::MAV_FRAME_LOCAL_NED, all) {
        MavMessage::SET_POSITION_TARGET_LOCAL_NED(d) => d,
        _ => unreachable!(),
    })
    .unwrap();
    assert_eq!(sp.position, [Some(2.0), Some(1.0), Some(-3.0)]);
    assert_eq!(sp.velocity, [Some(5.0), Some(4.0), Some(-6.0)]);
    assert_eq!(sp.acceleration, [Some(8.0), Some(7.0), Some(-9.0)]);
    assert!(
        (sp.yaw.unwrap() - FRAC_PI_2).abs() < 1e-9,
        "NED yaw 0 = north = ENU pi/2"
    );
    assert_eq!(sp.yaw_rate, Some(-0.5));
}

fn convert(mask: u16, frame: MavFrame, v: [f32; 11]) -> Option<Setpoint> {
    match sp_msg(mask, frame, v) {
        MavMessage::SET_POSITION_TARGET_LOCAL_NED(d) => setpoint_from_local_ned(&d),
        _ => None,
    }
}

#[test]
fn setpoint_type_mask_frames_and_non_finite() {
    let v = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 0.0, 0.5];
    // Ignore NED x position (bit 1): ENU y is absent.
    let sp = convert(1, MavFrame::MAV_FRAME_LOCAL_NED, v).unwrap();
    assert_eq!(sp.position, [Some(2.0), None, Some(-3.0)]);
    // Velocity only (the usual 0x0DC7) with yaw rate.
    let sp = convert(0x05C7, MavFrame::MAV_FRAME_LOCAL_NED, v).unwrap();
    assert_eq!(sp.position, [None; 3]);
    assert_eq!(sp.velocity, [Some(5.0), Some(4.0), Some(-6.0)]);
    assert_eq!(sp.acceleration, [None; 3]);
    assert_eq!(sp.yaw, None);
    assert_eq!(sp.yaw_rate, Some(-0.5));
    // NaN counts as ignored.
    let mut nan = v;
    nan[2] = f32::NAN;
    nan[9] = f32::INFINITY;
    let sp = convert(0, MavFrame::MAV_FRAME_LOCAL_NED, nan).unwrap();
    assert_eq!(sp.position[2], None);
    assert_eq!(sp.yaw, None);
    // Everything ignored, body frames and force: not a setpoint.
    assert!(convert(0x01FF, MavFrame::MAV_FRAME_LOCAL_NED, v).is_none());
    assert!(convert(0, MavFrame::MAV_FRAME_BODY_FRD, v).is_none());
    assert!(convert(0, MavFrame::MAV_FRAME_LOCAL_OFFSET_NED, v).is_none());
    assert!(convert(0x0200, MavFrame::MAV_FRAME_LOCAL_NED, v).is_none());
}

#[test]
fn rejected_setpoints_do_not_count_as_a_stream() {
    let mut c = new();
    let g = ground();
    let body = sp_msg(0x0DF8, MavFrame::MAV_FRAME_BODY_FRD, [0.0; 11]);
    let mut t = 0;
    while t < 1500 * MS {
        c.handle_message(t, &COMPANION, &body, &g);
        c.update(t, &g);
        t += 50 * MS;
    }
    assert!(!c.offboard_available(t));
}

#[test]
fn enu_from_local_ned_inverts_the_report() {
    let p = enu_from_local_ned(2.0, 1.0, -3.0);
    assert_eq!(p, Vector3::new(1.0, 2.0, 3.0));
}

fn with_faults(f: Faults) -> Commander {
    let mut c = new();
    c.set_faults(f).unwrap();
    c
}

#[test]
fn the_reject_arming_fault_refuses_every_arm() {
    let mut c = with_faults(Faults {
        reject_arming: true,
        ..Faults::default()
    });
    for t in 0..3 {
        let r = command(&mut c, t * S, &arm_msg(true), &ground());
        assert_eq!(r, MavResult::MAV_RESULT_TEMPORARILY_REJECTED);
    }
    assert!(!c.armed());
}

#[test]
fn the_reject_arming_times_fault_rejects_temporarily_then_arms() {
    let mut c = with_faults(Faults {
        reject_arming_times: 2,
        ..Faults::default()
    });
    let v = ground();
    assert_eq!(
        command(&mut c, 0, &arm_msg(true), &v),
        MavResult::MAV_RESULT_TEMPORARILY_REJECTED
    );
    assert_eq!(
        command(&mut c, S, &arm_msg(true), &v),
        MavResult::MAV_RESULT_TEMPORARILY_REJECTED
    );
    assert_eq!(
        command(&mut c, 2 * S, &arm_msg(true), &v),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert!(c.armed());
}

#[test]
fn the_reject_offboard_fault_refuses_offboard_even_with_a_stream() {
    let mut c = with_faults(Faults {
        reject_offboard: true,
        ..Faults::default()
    });
    let v = ground();
    let t = stream(&mut c, 0, 2 * S, &v);
    assert!(c.offboard_available(t));
    assert_eq!(
        command(&mut c, t, &set_mode_msg(6.0, 0.0), &v),
        MavResult::MAV_RESULT_TEMPORARILY_REJECTED
    );
    assert_ne!(c.mode(), FlightMode::Offboard);
    // Other modes still switch.
    assert_eq!(
        command(&mut c, t, &set_mode_msg(4.0, 3.0), &v),
        MavResult::MAV_RESULT_ACCEPTED
    );
}

#[test]
fn the_telemetry_stop_fault_silences_everything_but_commands_still_act() {
    let mut c = with_faults(Faults {
        telemetry_stop_s: Some(1.0),
        ..Faults::default()
    });
    let v = ground();
    c.update(0, &v);
    assert!(!c.take_outgoing().is_empty(), "talks before");
    c.update(S, &v);
    assert!(c.take_outgoing().is_empty(), "silent from 1 s");
    c.handle_message(S + MS, &COMPANION, &arm_msg(true), &v);
    assert!(c.take_outgoing().is_empty(), "not even the ACK");
    assert!(c.armed(), "the command still acted");
    c.update(5 * S, &v);
    assert!(c.take_outgoing().is_empty());
}

#[test]
fn contradictory_arming_faults_are_refused() {
    let e = new()
        .set_faults(Faults {
            reject_arming: true,
            reject_arming_times: 2,
            ..Faults::default()
        })
        .unwrap_err();
    assert_eq!(e.field, "reject_arming_times");
}

#[test]
fn a_landed_vehicle_stays_at_idle_until_a_setpoint_asks_it_to_climb() {
    // PX4's take-off state machine: a position more than 0.2 m up or a climb faster
    // than 0.3 m/s starts a take-off; anything less keeps the motors at idle.
    let mut c = new();
    let g = ground();
    c.handle_message(0, &COMPANION, &pos_sp(0.0, 0.0, -0.1), &g);
    command(&mut c, 0, &set_mode_msg(6.0, 0.0), &g);
    command(&mut c, 0, &arm_msg(true), &g);
    let mut t = 0;
    while t < 1200 * MS {
        c.handle_message(t, &COMPANION, &pos_sp(0.0, 0.0, -0.1), &g);
        c.update(t, &g);
        t += 20 * MS;
    }
    assert!(ground_idle(&c.setpoint()), "10 cm up: idle");
    c.handle_message(t, &COMPANION, &pos_sp(0.0, 0.0, -0.5), &g);
    c.update(t, &g);
    assert_eq!(c.setpoint().position[2], Some(0.5), "50 cm up: take-off");
}

#[test]
fn the_autopilot_clock_runs_at_its_rate_from_its_boot_offset_and_jumps() {
    let mut c = new();
    // Keeps time by default: the boot clock is simulated time, to the nanosecond.
    assert_eq!(c.boot_ns(123_456_789), 123_456_789);
    c.set_clock(AutopilotClock {
        rate: 0.98,
        boot_offset_s: 40.0,
        jump_at_s: Some(100.0),
        jump_s: -130.0,
    })
    .unwrap();
    let s = 1_000_000_000u64;
    assert_eq!(c.boot_ns(0), 40 * s);
    assert_eq!(c.boot_ns(50 * s), 40 * s + 49 * s);
    // Restarted at 100 s: its clock went back from 138 s to 8 s, and counts on.
    assert_eq!(c.boot_ns(100 * s), 8 * s);
    assert_eq!(c.boot_ns(200 * s), 40 * s + 196 * s - 130 * s);
    // The telemetry carries it.
    let v = status(1.0, false);
    c.update(60 * s, &v);
    let stamp = c
        .take_outgoing()
        .into_iter()
        .find_map(|m| match m {
            MavMessage::ATTITUDE_QUATERNION(a) => Some(a.time_boot_ms),
            _ => None,
        })
        .unwrap();
    assert_eq!(stamp, 40_000 + 58_800);
}

#[test]
fn a_clock_rate_out_of_range_is_refused_naming_it() {
    let mut c = new();
    let e = c
        .set_clock(AutopilotClock {
            rate: 0.0,
            ..AutopilotClock::default()
        })
        .unwrap_err();
    assert_eq!(e.field, "autopilot_clock.rate");
}
