//! MAVLink 2 signing on the simulated autopilot, as a process on a real UDP socket: a
//! peer without the key (even one at the companion's own address, as on a radio link
//! where addresses mean nothing) cannot arm it, switch its mode or steer it with
//! setpoints, and a signed command recorded earlier and played again is refused. The
//! peer with the key flies it.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::io::{BufRead, BufReader};
use std::net::{SocketAddr, UdpSocket};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use mavlink::MavHeader;
use mavlink::dialects::common::{
    HEARTBEAT_DATA, MavAutopilot, MavCmd, MavMessage, MavModeFlag, MavResult, MavState, MavType,
    PositionTargetTypemask, SET_POSITION_TARGET_LOCAL_NED_DATA,
};
use px4_protocol::codec::{Guard, StreamDecoder};
use px4_protocol::command_long;
use px4_protocol::signing::{Signer, SigningKey};
use runtime::IpcPrefix;

/// One end of the link: a socket, and how it signs and checks.
struct Peer {
    sock: UdpSocket,
    sim: SocketAddr,
    guard: Guard,
    seq: u8,
    start: Instant,
}

fn unix_at_zero() -> u64 {
    runtime::unix_ns_at_monotonic_zero()
}

impl Peer {
    fn new(sock: UdpSocket, sim: SocketAddr, key: Option<SigningKey>) -> Self {
        sock.set_read_timeout(Some(Duration::from_millis(20)))
            .unwrap();
        Self {
            sock,
            sim,
            // What it accepts: the autopilot's frames, signed with its key if it has one.
            guard: Guard::new(Some((1, 1)), key.map(|k| Signer::new(k, 3, unix_at_zero()))),
            seq: 0,
            start: Instant::now(),
        }
    }

    /// The bytes of `msg`, signed with this peer's key if it has one.
    fn frame(&mut self, msg: &MavMessage) -> Vec<u8> {
        let mut buf = Vec::new();
        let h = MavHeader {
            system_id: 1,
            component_id: 191,
            sequence: self.seq,
        };
        self.seq = self.seq.wrapping_add(1);
        self.guard
            .encode(&mut buf, h, msg, runtime::monotonic_ns())
            .unwrap();
        buf
    }

    fn send(&mut self, msg: &MavMessage) -> Vec<u8> {
        let f = self.frame(msg);
        self.sock.send_to(&f, self.sim).unwrap();
        f
    }

    /// What the autopilot sent this peer (and this peer's guard let through), for `for_`.
    fn receive(&mut self, for_: Duration) -> Vec<MavMessage> {
        let end = Instant::now() + for_;
        let mut out = Vec::new();
        let mut buf = [0u8; 2048];
        let mut d = StreamDecoder::new();
        while Instant::now() < end {
            if let Ok((n, _)) = self.sock.recv_from(&mut buf) {
                let mut msgs = Vec::new();
                d.push_datagram(
                    &buf[..n],
                    runtime::monotonic_ns(),
                    &mut self.guard,
                    &mut msgs,
                );
                out.extend(msgs.into_iter().map(|(_, m)| m));
            }
        }
        out
    }

    fn heartbeat(&mut self) {
        let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: 0,
            mavtype: MavType::MAV_TYPE_ONBOARD_CONTROLLER,
            autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
            base_mode: MavModeFlag::empty(),
            system_status: MavState::MAV_STATE_ACTIVE,
            mavlink_version: 3,
        });
        self.send(&hb);
    }

    /// The last autopilot heartbeat within `for_`, while answering with ours.
    fn last_heartbeat(&mut self, for_: Duration) -> Option<HEARTBEAT_DATA> {
        self.heartbeat();
        self.receive(for_).into_iter().rev().find_map(|m| match m {
            MavMessage::HEARTBEAT(h) => Some(h),
            _ => None,
        })
    }

    /// The COMMAND_ACKs for `cmd` within `for_`.
    fn acks(&mut self, cmd: MavCmd, for_: Duration) -> Vec<MavResult> {
        self.receive(for_)
            .into_iter()
            .filter_map(|m| match m {
                MavMessage::COMMAND_ACK(a) if a.command == cmd => Some(a.result),
                _ => None,
            })
            .collect()
    }

    fn elapsed_ms(&self) -> u32 {
        self.start.elapsed().as_millis() as u32
    }
}

fn armed(h: &HEARTBEAT_DATA) -> bool {
    h.base_mode
        .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED)
}

const ARM: [f32; 7] = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
const DISARM: [f32; 7] = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
/// DO_SET_MODE to OFFBOARD (custom mode flag, main mode 6).
const OFFBOARD: [f32; 7] = [1.0, 6.0, 0.0, 0.0, 0.0, 0.0, 0.0];

fn setpoint(time_boot_ms: u32) -> MavMessage {
    MavMessage::SET_POSITION_TARGET_LOCAL_NED(SET_POSITION_TARGET_LOCAL_NED_DATA {
        time_boot_ms,
        target_system: 1,
        target_component: 1,
        coordinate_frame: mavlink::dialects::common::MavFrame::MAV_FRAME_LOCAL_NED,
        type_mask: PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VX_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VY_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VZ_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AX_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AY_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AZ_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE,
        x: 30.0,
        y: 30.0,
        z: -20.0,
        ..SET_POSITION_TARGET_LOCAL_NED_DATA::default()
    })
}

/// The sim's counter `name` from its stop line.
fn counter(stop_line: &str, name: &str) -> u64 {
    stop_line
        .split_whitespace()
        .find_map(|kv| kv.strip_prefix(&format!("{name}=")))
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no {name} in {stop_line}"))
}

fn stop(mut child: Child) -> String {
    // SAFETY: the child's pid, alive until waited for below.
    unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
    let stderr = child.stderr.take().unwrap();
    let line = BufReader::new(stderr)
        .lines()
        .map_while(Result::ok)
        .find(|l| l.contains("sim stopped"))
        .unwrap_or_default();
    child.wait().unwrap();
    line
}

#[test]
fn a_peer_without_the_key_cannot_arm_switch_mode_or_steer_and_a_replayed_command_is_refused() {
    let dir = std::env::temp_dir().join(format!("landing-signing-sim-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let key_file = dir.join("autopilot.key");
    let key = SigningKey::from_bytes(core::array::from_fn(|i| (i * 7 + 3) as u8));
    key.save(&key_file).unwrap();

    let sim_addr: SocketAddr = {
        let s = UdpSocket::bind("127.0.0.1:0").unwrap();
        s.local_addr().unwrap()
    };
    // The companion's address: the only one the autopilot takes datagrams from. Every
    // peer below speaks from it, as anyone can on a radio link.
    let companion = UdpSocket::bind("127.0.0.1:0").unwrap();
    let prefix = IpcPrefix::unique("signing");
    let child = Command::new(env!("CARGO_BIN_EXE_sim"))
        .args(["--scenario", "indoor-static", "--duration-s", "120"])
        .args(["--mavlink-listen", &sim_addr.to_string()])
        .args([
            "--mavlink-remote",
            &companion.local_addr().unwrap().to_string(),
        ])
        .args(["--signing-key", key_file.to_str().unwrap()])
        .args(["--ipc-prefix", prefix.as_str()])
        .env("LANDING_LOG", "info")
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();

    // Without the key: the autopilot's frames do not check out, nothing it says is taken.
    let mut stranger = Peer::new(companion.try_clone().unwrap(), sim_addr, None);
    let mut wrong_key = Peer::new(
        companion.try_clone().unwrap(),
        sim_addr,
        Some(SigningKey::from_bytes([0x55; 32])),
    );
    std::thread::sleep(Duration::from_millis(500));
    assert!(
        wrong_key
            .last_heartbeat(Duration::from_millis(1500))
            .is_none()
    );
    assert!(
        wrong_key.guard.rejected().bad_signature > 0,
        "the sim's frames are signed"
    );

    let mut owner = Peer::new(companion, sim_addr, Some(key.clone()));
    let hb = owner
        .last_heartbeat(Duration::from_secs(3))
        .expect("signed heartbeats");
    assert!(!armed(&hb));

    // Unsigned and wrongly signed: arm, OFFBOARD and a setpoint stream far away, for 2 s.
    for attacker in [&mut stranger, &mut wrong_key] {
        for i in 0..40 {
            let t = attacker.elapsed_ms();
            attacker.send(&setpoint(t));
            if i % 10 == 0 {
                attacker.send(&command_long(
                    MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                    ARM,
                    (1, 1),
                ));
                attacker.send(&command_long(MavCmd::MAV_CMD_DO_SET_MODE, OFFBOARD, (1, 1)));
            }
            std::thread::sleep(Duration::from_millis(25));
        }
    }
    let hb = owner.last_heartbeat(Duration::from_millis(1500)).unwrap();
    assert!(!armed(&hb), "armed by a peer without the key");
    assert_ne!(
        (hb.custom_mode >> 16) & 0xff,
        6,
        "OFFBOARD by a peer without the key"
    );

    // The owner arms, disarms (that frame is recorded by an eavesdropper) and arms again.
    owner.send(&command_long(
        MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        ARM,
        (1, 1),
    ));
    let acks = owner.acks(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, Duration::from_secs(1));
    assert_eq!(acks, vec![MavResult::MAV_RESULT_ACCEPTED]);
    let recorded = owner.send(&command_long(
        MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        DISARM,
        (1, 1),
    ));
    let acks = owner.acks(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, Duration::from_secs(1));
    assert_eq!(acks, vec![MavResult::MAV_RESULT_ACCEPTED]);
    owner.send(&command_long(
        MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        ARM,
        (1, 1),
    ));
    let acks = owner.acks(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, Duration::from_secs(1));
    assert_eq!(acks, vec![MavResult::MAV_RESULT_ACCEPTED]);
    // The recorded disarm, played again: its timestamp is not newer than the stream's.
    stranger.sock.send_to(&recorded, sim_addr).unwrap();
    let acks = owner.acks(
        MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        Duration::from_millis(800),
    );
    assert!(
        acks.is_empty(),
        "the replayed disarm was answered: {acks:?}"
    );
    let hb = owner.last_heartbeat(Duration::from_millis(1500)).unwrap();
    assert!(armed(&hb), "the replayed disarm disarmed it");

    let line = stop(child);
    assert!(counter(&line, "unsigned") >= 40 + 8, "{line}");
    assert!(counter(&line, "bad_signature") >= 40 + 8, "{line}");
    assert_eq!(counter(&line, "replayed"), 1, "{line}");
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}
