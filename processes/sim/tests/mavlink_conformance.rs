//! The simulator's MAVLink endpoint seen from a companion computer: a plain
//! UDP socket, raw MAVLink 2 bytes, and the PX4 v1.16 behaviours a companion can
//! tell apart, one test each (docs/px4-conformance.md maps each to PX4's source).
//! Each test runs the `sim` node as its process does (the `SimStage` paced by the wall
//! clock behind a `runtime::UdpLink`, on the iceoryx2 driver) in its own thread on an
//! ephemeral port. Timing tolerances are generous (shared 2-core machine).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::net::{SocketAddr, UdpSocket};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use graph::Graph;
use ipc_types::topics;
use mavlink::dialects::common::{
    HEARTBEAT_DATA, MavAutopilot, MavCmd, MavFrame, MavLandedState, MavMessage, MavModeFlag,
    MavResult, MavState, MavType, PositionTargetTypemask, SET_POSITION_TARGET_LOCAL_NED_DATA,
};
use mavlink::{MavHeader, MavlinkVersion};
use px4_protocol::codec::decode_datagram;
use px4_protocol::command_long;
use px4_protocol::raw::renumber_command_long;
use runtime::{Beat, Ipc, IpcPrefix, Reply, UdpLink};
use sim::lockstep::Simulator;
use sim::px4::commander::{Commander, Px4Params};
use sim::stage::{Pace, SimStage};
use sim::world::{World, WorldParams};
use stage::{Counter, Input, Outbox, Stage, StageError};

const OFFBOARD: u32 = 6 << 16;
const POSCTL: u32 = 3 << 16;
const AUTO_TAKEOFF: u32 = (2 << 24) | (4 << 16);
const AUTO_LOITER: u32 = (3 << 24) | (4 << 16);
const AUTO_LAND: u32 = (6 << 24) | (4 << 16);
/// MAV_CMD_COMPONENT_ARM_DISARM's parameters for "arm".
const ARM: [f32; 7] = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];

/// The simulator stage, stopped from the test when its flag is set.
struct Stoppable {
    inner: SimStage,
    stop: Arc<AtomicBool>,
}

impl Stage for Stoppable {
    fn name(&self) -> &'static str {
        self.inner.name()
    }
    fn tick_period_ns(&self) -> Option<u64> {
        self.inner.tick_period_ns()
    }
    fn on_input(
        &mut self,
        now: u64,
        input: Input<'_>,
        out: &mut dyn Outbox,
    ) -> Result<(), StageError> {
        self.inner.on_input(now, input, out)
    }
    fn on_tick(&mut self, now: u64, out: &mut dyn Outbox) -> Result<(), StageError> {
        self.inner.on_tick(now, out)
    }
    fn max_slice_len(&self, topic: &str) -> usize {
        self.inner.max_slice_len(topic)
    }
    fn counters(&self) -> Vec<Counter> {
        self.inner.counters()
    }
    fn finished(&self) -> bool {
        self.stop.load(Ordering::Relaxed) || self.inner.finished()
    }
}

struct Sim {
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<(Stoppable, UdpLink)>>,
    addr: SocketAddr,
}

impl Sim {
    /// PX4 v1.16's defaults (SIH home at 489.4 m, COM_OBL_RC_ACT 0).
    fn start() -> Self {
        Self::start_with(Px4Params::default())
    }

    fn start_with(params: Px4Params) -> Self {
        let world = World::new(WorldParams::default()).unwrap();
        let sim = Simulator::from_world(world, Commander::new(params).unwrap(), 30.0, 30.0, 0);
        let mut link = UdpLink::bind(
            "127.0.0.1:0".parse().unwrap(),
            None,
            Reply::PeerAndRemote,
            topics::MAVLINK_TO_PX4,
            topics::MAVLINK_FROM_PX4,
        )
        .unwrap();
        let addr = link.local_addr();
        let stop = Arc::new(AtomicBool::new(false));
        let mut stage = Stoppable {
            inner: SimStage::paced(sim, Pace::realtime(1.0), Some(120_000_000_000)),
            stop: stop.clone(),
        };
        let graph =
            Graph::load(&PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../deploy/graph.toml"))
                .unwrap();
        let spec = graph.node("sim").unwrap().spec();
        let handle = std::thread::spawn(move || {
            let ipc = Ipc::open("sim", &IpcPrefix::unique("conformance")).unwrap();
            let beat = Beat {
                period: Duration::from_millis(100),
                deadline: Duration::from_millis(500),
            };
            runtime::driver::run(&ipc, &spec, &mut stage, Some(&mut link), beat).unwrap();
            (stage, link)
        });
        Self {
            stop,
            handle: Some(handle),
            addr,
        }
    }

    /// Stops the simulator; returns its stage and link to read their counters.
    fn finish(mut self) -> (Stoppable, UdpLink) {
        self.stop.store(true, Ordering::Relaxed);
        self.handle.take().unwrap().join().unwrap()
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// A stage counter by name.
fn counter(stage: &dyn Stage, key: &str) -> u64 {
    stage
        .counters()
        .iter()
        .find(|(k, _)| *k == key)
        .map(|(_, v)| *v)
        .unwrap_or_else(|| panic!("no counter {key}"))
}

/// A companion computer: system 1, component 191, like px4-link.
struct Companion {
    sock: UdpSocket,
    sim: SocketAddr,
    seq: u8,
    start: Instant,
}

impl Companion {
    fn connect(sim: &Sim) -> Self {
        Self::connect_to(sim.addr)
    }

    fn connect_to(addr: SocketAddr) -> Self {
        Self::connect_from(UdpSocket::bind("127.0.0.1:0").unwrap(), addr)
    }

    /// A companion on `sock` (bound already: a simulator that takes datagrams from its
    /// companion's address only must be told it first).
    fn connect_from(sock: UdpSocket, addr: SocketAddr) -> Self {
        sock.set_read_timeout(Some(Duration::from_millis(20)))
            .unwrap();
        let mut c = Self {
            sock,
            sim: addr,
            seq: 0,
            start: Instant::now(),
        };
        c.send(&MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: 0,
            mavtype: MavType::MAV_TYPE_ONBOARD_CONTROLLER,
            autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
            base_mode: MavModeFlag::empty(),
            system_status: MavState::MAV_STATE_ACTIVE,
            mavlink_version: 3,
        }));
        c
    }

    fn send(&mut self, msg: &MavMessage) {
        let header = MavHeader {
            system_id: 1,
            component_id: 191,
            sequence: self.seq,
        };
        self.seq = self.seq.wrapping_add(1);
        let mut buf = Vec::new();
        mavlink::write_v2_msg(&mut buf, header, msg).unwrap();
        self.sock.send_to(&buf, self.sim).unwrap();
    }

    fn send_raw(&self, bytes: &[u8]) {
        self.sock.send_to(bytes, self.sim).unwrap();
    }

    /// Sends a COMMAND_LONG with a command number the dialect lacks and returns the
    /// result of the COMMAND_ACK for that number (read from the raw frames).
    fn raw_command(&mut self, number: u16, timeout: Duration) -> Option<u8> {
        let mut frame = Vec::new();
        mavlink::write_v2_msg(
            &mut frame,
            MavHeader {
                system_id: 1,
                component_id: 191,
                sequence: 0,
            },
            &command_long(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, ARM, (1, 1)),
        )
        .unwrap();
        assert!(renumber_command_long(&mut frame, number));
        self.send_raw(&frame);
        let end = Instant::now() + timeout;
        let mut buf = [0u8; 2048];
        while Instant::now() < end {
            let Ok((len, _)) = self.sock.recv_from(&mut buf) else {
                continue;
            };
            // One frame per datagram: COMMAND_ACK is message 77.
            let d = &buf[..len];
            if len >= 13 && d[0] == 0xFD && d[7] == 77 && d[8] == 0 && d[9] == 0 {
                let mut p = [0u8; 10];
                let plen = usize::from(d[1]).min(10);
                p[..plen].copy_from_slice(&d[10..10 + plen]);
                if u16::from_le_bytes([p[0], p[1]]) == number {
                    assert_eq!((p[8], p[9]), (1, 191), "addressed to us");
                    return Some(p[2]);
                }
            }
        }
        None
    }

    /// The AMSL altitude of the local origin, from the autopilot's HOME_POSITION
    /// (altitude and local z of the same point), as px4-link computes it.
    fn origin_amsl(&mut self) -> f64 {
        self.wait_for(
            Duration::from_secs(4),
            |_| {},
            |m| match m {
                MavMessage::HOME_POSITION(h) => Some(f64::from(h.altitude) * 1e-3 + f64::from(h.z)),
                _ => None,
            },
        )
        .expect("no HOME_POSITION")
    }

    /// Everything received within `d`, with receive times.
    fn collect(&mut self, d: Duration) -> Vec<(Instant, MavMessage)> {
        let end = Instant::now() + d;
        let mut out = Vec::new();
        while Instant::now() < end {
            self.recv_into(&mut out);
        }
        out
    }

    fn recv_into(&mut self, out: &mut Vec<(Instant, MavMessage)>) {
        let mut buf = [0u8; 2048];
        if let Ok((n, _)) = self.sock.recv_from(&mut buf) {
            let mut msgs = Vec::new();
            decode_datagram(&buf[..n], &mut msgs);
            let now = Instant::now();
            for (h, m) in msgs {
                assert_eq!((h.system_id, h.component_id), (1, 1));
                out.push((now, m));
            }
        }
    }

    /// Waits up to `timeout` for a message matching `pred`, calling `tick`
    /// between receives (to keep a setpoint stream going).
    fn wait_for<T>(
        &mut self,
        timeout: Duration,
        mut tick: impl FnMut(&mut Self),
        mut pred: impl FnMut(&MavMessage) -> Option<T>,
    ) -> Option<T> {
        let end = Instant::now() + timeout;
        while Instant::now() < end {
            tick(self);
            let mut got = Vec::new();
            self.recv_into(&mut got);
            for (_, m) in &got {
                if let Some(t) = pred(m) {
                    return Some(t);
                }
            }
        }
        None
    }

    fn command(&mut self, command: MavCmd, params: [f32; 7]) -> MavResult {
        self.command_with(command, params, |_| {})
    }

    fn command_with(
        &mut self,
        command: MavCmd,
        p: [f32; 7],
        mut tick: impl FnMut(&mut Self),
    ) -> MavResult {
        self.send(&command_long(command, p, (1, 1)));
        self.wait_for(Duration::from_secs(3), &mut tick, |m| match m {
            MavMessage::COMMAND_ACK(a) if a.command == command => {
                assert_eq!((a.target_system, a.target_component), (1, 191));
                Some(a.result)
            }
            _ => None,
        })
        .expect("no COMMAND_ACK")
    }

    fn heartbeat(&mut self, pred: impl Fn(&HEARTBEAT_DATA) -> bool, timeout: Duration) -> bool {
        self.heartbeat_with(pred, timeout, |_| {})
    }

    fn heartbeat_with(
        &mut self,
        pred: impl Fn(&HEARTBEAT_DATA) -> bool,
        timeout: Duration,
        tick: impl FnMut(&mut Self),
    ) -> bool {
        self.wait_for(timeout, tick, |m| match m {
            MavMessage::HEARTBEAT(h) if pred(h) => Some(()),
            _ => None,
        })
        .is_some()
    }

    /// NED position from LOCAL_POSITION_NED once `pred` holds.
    fn position_until(
        &mut self,
        timeout: Duration,
        tick: impl FnMut(&mut Self),
        pred: impl Fn([f32; 3]) -> bool,
    ) -> Option<[f32; 3]> {
        self.wait_for(timeout, tick, |m| match m {
            MavMessage::LOCAL_POSITION_NED(p) if pred([p.x, p.y, p.z]) => Some([p.x, p.y, p.z]),
            _ => None,
        })
    }

    fn landed_state(&mut self, want: MavLandedState, timeout: Duration) -> bool {
        self.wait_for(
            timeout,
            |_| {},
            |m| match m {
                MavMessage::EXTENDED_SYS_STATE(s) if s.landed_state == want => Some(()),
                _ => None,
            },
        )
        .is_some()
    }

    fn position_setpoint(&mut self, ned: [f32; 3]) {
        // Position + yaw; velocity, acceleration and yaw rate ignored.
        let ignore = PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VX_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VY_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VZ_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AX_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AY_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AZ_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE;
        let t = self.start.elapsed().as_millis() as u32;
        self.send(&MavMessage::SET_POSITION_TARGET_LOCAL_NED(
            SET_POSITION_TARGET_LOCAL_NED_DATA {
                time_boot_ms: t,
                x: ned[0],
                y: ned[1],
                z: ned[2],
                vx: 0.0,
                vy: 0.0,
                vz: 0.0,
                afx: 0.0,
                afy: 0.0,
                afz: 0.0,
                yaw: std::f32::consts::FRAC_PI_2,
                yaw_rate: 0.0,
                type_mask: ignore,
                target_system: 1,
                target_component: 1,
                coordinate_frame: MavFrame::MAV_FRAME_LOCAL_NED,
            },
        ));
    }

    fn arm(&mut self) {
        assert_eq!(
            self.command(
                MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
            ),
            MavResult::MAV_RESULT_ACCEPTED
        );
    }

    /// NAV_TAKEOFF with `param7` as PX4 reads it: an altitude above mean sea level
    /// (NaN: MIS_TAKEOFF_ALT above the current altitude).
    fn takeoff_amsl(&mut self, param7: f32) {
        assert_eq!(
            self.command(
                MavCmd::MAV_CMD_NAV_TAKEOFF,
                [0.0, 0.0, 0.0, f32::NAN, f32::NAN, f32::NAN, param7]
            ),
            MavResult::MAV_RESULT_ACCEPTED
        );
    }

    /// NAV_TAKEOFF to `height` m above the local origin.
    fn takeoff(&mut self, height: f64) {
        let origin = self.origin_amsl();
        self.takeoff_amsl((origin + height) as f32);
    }

    /// DO_SET_MODE to PX4 custom mode (main, sub).
    fn set_mode(&mut self, main: f32, sub: f32) -> MavResult {
        self.command(
            MavCmd::MAV_CMD_DO_SET_MODE,
            [1.0, main, sub, 0.0, 0.0, 0.0, 0.0],
        )
    }
}

/// A setpoint streamer at ~20 Hz for `wait_for` ticks.
fn streamer(target: [f32; 3]) -> impl FnMut(&mut Companion) {
    let mut last: Option<Instant> = None;
    move |c: &mut Companion| {
        if last.is_none_or(|t| t.elapsed() >= Duration::from_millis(50)) {
            last = Some(Instant::now());
            c.position_setpoint(target);
        }
    }
}

fn armed(h: &HEARTBEAT_DATA) -> bool {
    h.base_mode
        .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED)
}

fn secs(s: u64) -> Duration {
    Duration::from_secs(s)
}

#[test]
fn heartbeat_reports_px4_custom_mode_at_1_hz() {
    let sim = Sim::start();
    let mut c = Companion::connect(&sim);
    let msgs = c.collect(Duration::from_millis(3500));
    let beats: Vec<_> = msgs
        .iter()
        .filter_map(|(t, m)| match m {
            MavMessage::HEARTBEAT(h) => Some((*t, h.clone())),
            _ => None,
        })
        .collect();
    assert!(
        (3..=5).contains(&beats.len()),
        "{} heartbeats in 3.5 s",
        beats.len()
    );
    for w in beats.windows(2) {
        let dt = w[1].0.duration_since(w[0].0).as_secs_f64();
        assert!((0.6..=1.4).contains(&dt), "heartbeat gap {dt} s");
    }
    let h = &beats[0].1;
    assert_eq!(h.mavtype, MavType::MAV_TYPE_QUADROTOR);
    assert_eq!(h.autopilot, MavAutopilot::MAV_AUTOPILOT_PX4);
    assert!(
        h.base_mode
            .contains(MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)
    );
    assert!(!armed(h));
    // PX4 v1.16 boots into Hold (AUTO.LOITER); base_mode CUSTOM|STAB|GUIDED|AUTO.
    assert_eq!(h.custom_mode, AUTO_LOITER);
    assert_eq!(h.base_mode.bits(), 29);
    assert_eq!(h.system_status, MavState::MAV_STATE_STANDBY);
    // Default telemetry is flowing too.
    let count = |id: u32| {
        msgs.iter()
            .filter(|(_, m)| mavlink::Message::message_id(m) == id)
            .count()
    };
    assert!(count(32) > 60, "LOCAL_POSITION_NED {}", count(32));
    assert!(count(31) > 100, "ATTITUDE_QUATERNION {}", count(31));
    assert!(count(245) > 8, "EXTENDED_SYS_STATE {}", count(245));
    assert!(count(33) > 8, "GLOBAL_POSITION_INT {}", count(33));
    assert!(
        (1..=3).contains(&count(242)),
        "HOME_POSITION {}",
        count(242)
    );
    sim.finish();
}

#[test]
fn unknown_commands_are_answered_unsupported_and_broadcast_ones_ignored() {
    let sim = Sim::start();
    let mut c = Companion::connect(&sim);
    // A command PX4's commander does not handle.
    assert_eq!(
        c.command(MavCmd::MAV_CMD_DO_REPOSITION, [0.0; 7]),
        MavResult::MAV_RESULT_UNSUPPORTED
    );
    // A command number no dialect has: still a COMMAND_ACK, UNSUPPORTED (3).
    assert_eq!(c.raw_command(31_999, secs(3)), Some(3));
    // Sent to every system (target_system 0): PX4's receiver drops it, no ACK.
    c.send(&command_long(
        MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        ARM,
        (0, 1),
    ));
    let got = c.collect(Duration::from_millis(1200));
    assert!(
        !got.iter()
            .any(|(_, m)| matches!(m, MavMessage::COMMAND_ACK(_))),
        "no ACK for a broadcast command"
    );
    assert!(
        got.iter()
            .all(|(_, m)| !matches!(m, MavMessage::HEARTBEAT(h) if armed(h)))
    );
    sim.finish();
}

#[test]
fn arm_is_acked_and_heartbeat_shows_armed() {
    let sim = Sim::start();
    let mut c = Companion::connect(&sim);
    c.arm();
    assert!(c.heartbeat(
        |h| armed(h) && h.system_status == MavState::MAV_STATE_ACTIVE && h.base_mode.bits() == 157,
        secs(3)
    ));
    assert_eq!(
        c.command(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, [0.0; 7]),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert!(c.heartbeat(|h| !armed(h), secs(3)));
    sim.finish();
}

#[test]
fn home_is_at_the_configured_altitude_above_mean_sea_level() {
    let sim = Sim::start_with(Px4Params {
        sih_loc_h0: 488.0,
        ..Px4Params::default()
    });
    let mut c = Companion::connect(&sim);
    let home = c
        .wait_for(
            secs(4),
            |_| {},
            |m| match m {
                MavMessage::HOME_POSITION(h) => Some(h.clone()),
                _ => None,
            },
        )
        .expect("HOME_POSITION");
    // On the ground at the origin (estimator noise: centimetres).
    assert!((home.altitude - 488_000).abs() < 100, "{}", home.altitude);
    assert!(home.z.abs() < 0.1);
    let g = c
        .wait_for(
            secs(2),
            |_| {},
            |m| match m {
                MavMessage::GLOBAL_POSITION_INT(g) => Some(g.clone()),
                _ => None,
            },
        )
        .expect("GLOBAL_POSITION_INT");
    assert!((g.alt - 488_000).abs() < 100, "alt {} mm", g.alt);
    assert!(
        g.relative_alt.abs() < 100,
        "relative_alt {} mm",
        g.relative_alt
    );
    assert!((g.lat - 473_977_420).abs() < 10 && (g.lon - 85_455_940).abs() < 10);
    sim.finish();
}

#[test]
fn nav_takeoff_param7_is_read_above_mean_sea_level() {
    // Home at 488 m: 490.0 m AMSL is 2 m up.
    let sim = Sim::start_with(Px4Params {
        sih_loc_h0: 488.0,
        ..Px4Params::default()
    });
    let mut c = Companion::connect(&sim);
    c.arm();
    c.takeoff_amsl(490.0);
    let p = c.position_until(secs(10), |_| {}, |p| p[2] < -1.7);
    assert!(p.is_some(), "did not climb to 2 m");
    assert!(c.heartbeat(|h| h.custom_mode == AUTO_LOITER && armed(h), secs(5)));
    let msgs = c.collect(Duration::from_millis(1500));
    for (_, m) in &msgs {
        if let MavMessage::LOCAL_POSITION_NED(p) = m {
            assert!((p.z + 2.0).abs() < 0.5, "holds 2 m: z {}", p.z);
        }
    }
    sim.finish();
}

#[test]
fn nav_takeoff_below_the_current_altitude_is_accepted_but_never_climbs_and_disarms() {
    // The bug real PX4 showed: param7 = 2.5 with home at 489.4 m AMSL. ACCEPTED
    // ("Already higher than takeoff altitude" in PX4's log), no climb, and the
    // pre-flight auto-disarm COM_SPOOLUP_TIME + COM_DISARM_PRFLT = 11 s after arming.
    let sim = Sim::start();
    let mut c = Companion::connect(&sim);
    c.arm();
    let armed_at = Instant::now();
    c.takeoff_amsl(2.5);
    assert!(c.heartbeat(|h| h.custom_mode == AUTO_TAKEOFF && armed(h), secs(3)));
    let msgs = c.collect(secs(4));
    for (_, m) in &msgs {
        if let MavMessage::LOCAL_POSITION_NED(p) = m {
            assert!(p.z > -0.2, "it climbed: z {}", p.z);
        }
    }
    assert!(c.heartbeat(|h| !armed(h), secs(10)), "no auto-disarm");
    let after = armed_at.elapsed().as_secs_f64();
    assert!(
        (10.0..13.0).contains(&after),
        "disarmed {after:.1} s after arming"
    );
    // Take-off does not prevent arming: it is still the mode.
    assert!(c.heartbeat(|h| h.custom_mode == AUTO_TAKEOFF, secs(2)));
    sim.finish();
}

#[test]
fn takeoff_climbs_to_takeoff_altitude_then_loiters() {
    let sim = Sim::start();
    let mut c = Companion::connect(&sim);
    c.arm();
    c.takeoff_amsl(f32::NAN); // MIS_TAKEOFF_ALT = 2.5 m above the current altitude
    assert!(c.landed_state(MavLandedState::MAV_LANDED_STATE_TAKEOFF, secs(3)));
    let p = c.position_until(secs(10), |_| {}, |p| p[2] < -2.3);
    assert!(p.is_some(), "did not climb to 2.5 m");
    assert!(c.heartbeat(|h| h.custom_mode == AUTO_LOITER && armed(h), secs(5)));
    // It holds there (z negative is up), without overshooting far.
    let msgs = c.collect(Duration::from_millis(1500));
    for (_, m) in &msgs {
        if let MavMessage::LOCAL_POSITION_NED(p) = m {
            assert!((p.z + 2.5).abs() < 0.5, "z {}", p.z);
            assert!(p.x.abs() < 0.5 && p.y.abs() < 0.5, "drift {} {}", p.x, p.y);
        }
    }
    assert!(c.landed_state(MavLandedState::MAV_LANDED_STATE_IN_AIR, secs(2)));
    sim.finish();
}

#[test]
fn offboard_needs_only_one_setpoint_younger_than_com_of_loss_t() {
    let sim = Sim::start();
    let mut c = Companion::connect(&sim);
    // Disarmed, the switch is accepted even without setpoints ...
    assert_eq!(c.set_mode(6.0, 0.0), MavResult::MAV_RESULT_ACCEPTED);
    assert!(c.heartbeat(
        |h| h.custom_mode == OFFBOARD && h.base_mode.bits() == 17,
        secs(3)
    ));
    // ... but arming in OFFBOARD needs the signal.
    assert_eq!(
        c.command(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        ),
        MavResult::MAV_RESULT_TEMPORARILY_REJECTED
    );
    // One setpoint is enough: no minimum stream length.
    c.position_setpoint([0.0, 0.0, 0.0]);
    c.arm();
    // Armed in Hold, with the last setpoint older than COM_OF_LOSS_T: refused; one
    // fresh setpoint: accepted.
    assert_eq!(c.set_mode(4.0, 3.0), MavResult::MAV_RESULT_ACCEPTED);
    c.collect(Duration::from_millis(1200));
    assert_eq!(
        c.set_mode(6.0, 0.0),
        MavResult::MAV_RESULT_TEMPORARILY_REJECTED
    );
    c.position_setpoint([0.0, 0.0, 0.0]);
    assert_eq!(c.set_mode(6.0, 0.0), MavResult::MAV_RESULT_ACCEPTED);
    sim.finish();
}

#[test]
fn temporarily_rejected_where_px4_answers_it() {
    let sim = Sim::start();
    let mut c = Companion::connect(&sim);
    // An AUTO sub mode PX4 does not have ("Unsupported auto mode").
    assert_eq!(
        c.set_mode(4.0, 10.0),
        MavResult::MAV_RESULT_TEMPORARILY_REJECTED
    );
    // LAND is forced even disarmed, and then arming is refused.
    assert_eq!(
        c.command(
            MavCmd::MAV_CMD_NAV_LAND,
            [0.0, 0.0, 0.0, f32::NAN, f32::NAN, f32::NAN, f32::NAN]
        ),
        MavResult::MAV_RESULT_ACCEPTED
    );
    let arm = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    assert_eq!(
        c.command(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, arm),
        MavResult::MAV_RESULT_TEMPORARILY_REJECTED
    );
    // In the air, a disarm that is not forced is refused.
    assert_eq!(c.set_mode(4.0, 3.0), MavResult::MAV_RESULT_ACCEPTED);
    c.arm();
    c.takeoff(2.0);
    assert!(c.position_until(secs(8), |_| {}, |p| p[2] < -1.5).is_some());
    assert_eq!(
        c.command(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, [0.0; 7]),
        MavResult::MAV_RESULT_TEMPORARILY_REJECTED
    );
    // An ARM param1 neither 0 nor 1: PX4 sends no ACK at all.
    c.send(&command_long(
        MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        [3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        (1, 1),
    ));
    let got = c.collect(Duration::from_millis(800));
    assert!(
        !got.iter()
            .any(|(_, m)| matches!(m, MavMessage::COMMAND_ACK(_)))
    );
    sim.finish();
}

#[test]
fn offboard_loss_switches_to_position_by_default_and_back_when_setpoints_resume() {
    // COM_OBL_RC_ACT = 0 (PX4's default): Position mode at once after COM_OF_LOSS_T,
    // RC or not; the failsafe clears when the setpoints come back.
    let sim = Sim::start();
    let mut c = Companion::connect(&sim);
    c.arm();
    c.takeoff(2.0);
    assert!(c.heartbeat(|h| h.custom_mode == AUTO_LOITER, secs(10)));
    let mut tick = streamer([0.0, 0.0, -2.0]);
    tick(&mut c);
    assert_eq!(
        c.command_with(
            MavCmd::MAV_CMD_DO_SET_MODE,
            [1.0, 6.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            &mut tick,
        ),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert!(c.heartbeat_with(|h| h.custom_mode == OFFBOARD, secs(3), &mut tick));
    let stopped = Instant::now();
    assert!(
        c.heartbeat(
            |h| h.custom_mode == POSCTL && h.system_status == MavState::MAV_STATE_CRITICAL,
            secs(4)
        ),
        "no Position mode after the loss"
    );
    assert!(stopped.elapsed() >= Duration::from_millis(900));
    assert!(
        c.heartbeat_with(
            |h| h.custom_mode == OFFBOARD && h.system_status == MavState::MAV_STATE_ACTIVE,
            secs(4),
            &mut tick
        ),
        "not back in OFFBOARD"
    );
    sim.finish();
}

#[test]
fn offboard_move_then_stream_loss_lands_and_disarms() {
    // COM_OBL_RC_ACT = 4 (Land), as the stack's deployment sets it.
    let sim = Sim::start_with(Px4Params {
        com_obl_rc_act: 4,
        ..Px4Params::default()
    });
    let mut c = Companion::connect(&sim);
    c.arm();
    c.takeoff(2.0);
    assert!(
        c.heartbeat(|h| h.custom_mode == AUTO_LOITER, secs(10)),
        "takeoff did not finish"
    );

    // Stream the current hover point for > 1 s at 20 Hz, then switch.
    let hover = [0.0, 0.0, -2.0];
    let mut tick = streamer(hover);
    let end = Instant::now() + Duration::from_millis(1300);
    while Instant::now() < end {
        tick(&mut c);
        std::thread::sleep(Duration::from_millis(5));
    }
    let r = c.command_with(
        MavCmd::MAV_CMD_DO_SET_MODE,
        [1.0, 6.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        &mut tick,
    );
    assert_eq!(r, MavResult::MAV_RESULT_ACCEPTED);
    assert!(c.heartbeat_with(
        |h| h.custom_mode == OFFBOARD && armed(h),
        secs(3),
        &mut tick
    ));

    // 5 m north (NED x), same altitude.
    let target = [5.0, 0.0, -2.0];
    let mut tick = streamer(target);
    let p = c.position_until(secs(12), &mut tick, |p| {
        (p[0] - 5.0).abs() < 0.3 && p[1].abs() < 0.3 && (p[2] + 2.0).abs() < 0.3
    });
    assert!(p.is_some(), "did not reach (5, 0, -2) NED");

    // Stop streaming: COM_OF_LOSS_T later PX4 lands (COM_OBL_RC_ACT = 4).
    let stopped = Instant::now();
    assert!(
        c.heartbeat(|h| h.custom_mode == AUTO_LAND, secs(4)),
        "no AUTO.LAND after loss"
    );
    assert!(stopped.elapsed() >= Duration::from_millis(900));
    assert!(c.landed_state(MavLandedState::MAV_LANDED_STATE_LANDING, secs(2)));
    assert!(
        c.landed_state(MavLandedState::MAV_LANDED_STATE_ON_GROUND, secs(10)),
        "did not land"
    );
    // Disarmed after landing, it shows the mode asked for last again: OFFBOARD (a
    // failsafe does not change PX4's user intention).
    assert!(
        c.heartbeat(|h| !armed(h) && h.custom_mode == OFFBOARD, secs(5)),
        "did not disarm"
    );
    // It landed where it was, not back home.
    let p = c.position_until(secs(2), |_| {}, |_| true).unwrap();
    assert!((p[0] - 5.0).abs() < 0.7 && p[2].abs() < 0.3, "{p:?}");
    sim.finish();
}

#[test]
fn land_command_lands_and_disarms() {
    let sim = Sim::start();
    let mut c = Companion::connect(&sim);
    c.arm();
    c.takeoff(1.5);
    assert!(c.position_until(secs(8), |_| {}, |p| p[2] < -1.3).is_some());
    assert_eq!(
        c.command(
            MavCmd::MAV_CMD_NAV_LAND,
            [0.0, 0.0, 0.0, f32::NAN, f32::NAN, f32::NAN, f32::NAN]
        ),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert!(c.heartbeat(|h| h.custom_mode == AUTO_LAND && armed(h), secs(3)));
    // Descends at about MPC_LAND_SPEED.
    let v = c
        .wait_for(
            secs(3),
            |_| {},
            |m| match m {
                MavMessage::LOCAL_POSITION_NED(p) if p.z < -0.5 && p.vz > 0.4 => Some(p.vz),
                _ => None,
            },
        )
        .expect("not descending");
    assert!((0.4..1.0).contains(&v), "vz {v}");
    assert!(c.landed_state(MavLandedState::MAV_LANDED_STATE_ON_GROUND, secs(8)));
    let down = Instant::now();
    // Still AUTO.LAND while armed on the ground ...
    assert!(c.heartbeat(|h| armed(h) && h.custom_mode == AUTO_LAND, secs(2)));
    // ... disarmed COM_DISARM_LAND (2 s) after the land detector, then the last mode
    // asked for that does not prevent arming: Hold, here.
    assert!(
        c.heartbeat(|h| !armed(h) && h.custom_mode == AUTO_LOITER, secs(5)),
        "did not disarm after landing"
    );
    let after = down.elapsed().as_secs_f64();
    assert!(
        (1.0..5.0).contains(&after),
        "disarmed {after:.1} s after touchdown"
    );
    sim.finish();
}

#[test]
fn set_message_interval_changes_local_position_rate() {
    let sim = Sim::start();
    let mut c = Companion::connect(&sim);
    let count = |msgs: &[(Instant, MavMessage)]| {
        msgs.iter()
            .filter(|(_, m)| matches!(m, MavMessage::LOCAL_POSITION_NED(_)))
            .count()
    };
    // 10 Hz.
    let r = c.command(
        MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
        [32.0, 100_000.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    );
    assert_eq!(r, MavResult::MAV_RESULT_ACCEPTED);
    let n = count(&c.collect(secs(2)));
    assert!(
        (14..=26).contains(&n),
        "{n} LOCAL_POSITION_NED in 2 s at 10 Hz"
    );
    // Disabled.
    let r = c.command(
        MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
        [32.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    );
    assert_eq!(r, MavResult::MAV_RESULT_ACCEPTED);
    c.collect(Duration::from_millis(200));
    assert_eq!(count(&c.collect(secs(1))), 0);
    // Back to the default (30 Hz).
    let r = c.command(
        MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
        [32.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    );
    assert_eq!(r, MavResult::MAV_RESULT_ACCEPTED);
    let n = count(&c.collect(secs(2)));
    assert!(
        (45..=75).contains(&n),
        "{n} LOCAL_POSITION_NED in 2 s at 30 Hz"
    );
    // A message it cannot stream.
    let r = c.command(
        MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
        [12345.0, 1000.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    );
    assert_eq!(r, MavResult::MAV_RESULT_FAILED);
    sim.finish();
}

#[test]
fn garbage_datagrams_do_not_crash_it() {
    let sim = Sim::start();
    let mut c = Companion::connect(&sim);
    c.send_raw(b"hello, not mavlink");
    c.send_raw(&[0xFD; 300]);
    c.send_raw(&[0xFD, 9, 0, 0, 1, 1, 1, 0, 0]); // truncated header
    // A valid frame with its CRC broken.
    let mut buf = Vec::new();
    let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_ONBOARD_CONTROLLER,
        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
        base_mode: MavModeFlag::empty(),
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    });
    mavlink::write_v2_msg(
        &mut buf,
        MavHeader {
            system_id: 1,
            component_id: 191,
            sequence: 0,
        },
        &hb,
    )
    .unwrap();
    let n = buf.len();
    buf[n - 1] ^= 0xFF;
    c.send_raw(&buf);
    c.send_raw(&[]);
    // MAVLink 1 framing is still understood.
    let mut v1 = Vec::new();
    mavlink::write_versioned_msg(
        &mut v1,
        MavlinkVersion::V1,
        MavHeader {
            system_id: 1,
            component_id: 191,
            sequence: 1,
        },
        &hb,
    )
    .unwrap();
    c.send_raw(&v1);
    // Still alive and answering.
    assert!(c.heartbeat(|_| true, secs(3)));
    c.arm();
    let (stage, link) = sim.finish();
    assert!(
        counter(&stage, "parse_errors") >= 3,
        "{:?}",
        stage.counters()
    );
    assert!(counter(&stage, "mavlink_in") >= 3, "{:?}", stage.counters());
    assert!(link.stats().datagrams_in >= 7, "{:?}", link.stats());
}

/// The `sim` binary as systemd would start it: a companion flies it over UDP, and the
/// evaluator-only truth topic reports the liftoff and the touchdown over iceoryx2.
#[test]
fn the_sim_process_flies_over_mavlink_and_publishes_camera_depth_and_ground_truth() {
    use ipc_types::msg::{TruthEvent, TruthKind};

    let port = UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let addr: SocketAddr = format!("127.0.0.1:{port}").parse().unwrap();
    let prefix = IpcPrefix::unique("simproc");
    let ipc = Ipc::open("evaluator", &prefix).unwrap();
    let truth = ipc
        .subscriber::<TruthEvent>(ipc_types::services::SIM_TRUTH)
        .unwrap();
    let camera = ipc
        .slice_subscriber::<u8, ipc_types::msg::CameraFrameHeader>(ipc_types::services::SIM_CAMERA)
        .unwrap();
    let depth = ipc
        .slice_subscriber::<u16, ipc_types::msg::DepthFrameHeader>(ipc_types::services::SIM_DEPTH)
        .unwrap();
    let started = Instant::now();
    let companion = UdpSocket::bind("127.0.0.1:0").unwrap();
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_sim"))
        .args(["--scenario", "indoor-static", "--duration-s", "60"])
        .args(["--mavlink-listen", &addr.to_string()])
        .args([
            "--mavlink-remote",
            &companion.local_addr().unwrap().to_string(),
        ])
        .args(["--ipc-prefix", prefix.as_str()])
        .env("LANDING_LOG", "warn")
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(500));
    let mut c = Companion::connect_from(companion, addr);
    assert!(
        c.heartbeat(|_| true, secs(5)),
        "no heartbeat from the sim process"
    );
    c.arm();
    c.takeoff(1.5);
    assert!(c.position_until(secs(8), |_| {}, |p| p[2] < -1.3).is_some());
    // In the air, the forward depth camera sees the ground ahead.
    std::thread::sleep(Duration::from_millis(200));
    let d = depth.latest().unwrap().expect("depth frames");
    assert_eq!(
        (d.user_header().width * d.user_header().height) as usize,
        d.payload().len()
    );
    assert!(
        d.payload().iter().any(|&mm| mm > 0),
        "the ground is in view"
    );
    drop(d);
    assert_eq!(
        c.command(
            MavCmd::MAV_CMD_NAV_LAND,
            [0.0, 0.0, 0.0, f32::NAN, f32::NAN, f32::NAN, f32::NAN]
        ),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert!(c.landed_state(MavLandedState::MAV_LANDED_STATE_ON_GROUND, secs(10)));
    let elapsed = started.elapsed().as_secs_f64();
    let frame = camera.latest().unwrap().expect("camera frames");
    let h = *frame.user_header();
    assert_eq!(h.expected_len(), Some(frame.payload().len()), "{h:?}");
    assert!(
        h.msg.seq as f64 > 30.0 * elapsed * 0.5,
        "{} camera frames in {elapsed:.1} s",
        h.msg.seq
    );
    drop(frame);
    let mut kinds = Vec::new();
    while let Ok(Some(t)) = truth.receive() {
        kinds.push(TruthKind::from_raw(t.kind));
    }
    // SAFETY: signalling our own child process.
    unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
    let status = child.wait().unwrap();
    assert!(status.success(), "sim exited with {status}");
    assert!(kinds.contains(&Some(TruthKind::Liftoff)), "{kinds:?}");
    assert!(kinds.contains(&Some(TruthKind::Touchdown)), "{kinds:?}");
}
