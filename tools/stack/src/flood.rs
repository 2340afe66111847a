//! Traffic at px4-link's MAVLink port from a port of its own, for `--inject`: a burst of
//! random bytes (`garbage:N`), or a steady flood (`flood:KIND:RATE`) of random bytes,
//! of valid autopilot frames with a few bytes mutated, or of valid but spoofed autopilot
//! heartbeats and positions (system 1, component 1, good checksums) until the run ends.
//! Each counts what it sent, so the run can hold px4-link's counters against it.

use std::net::UdpSocket;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use mavlink::MavHeader;
use mavlink::dialects::common::{
    ATTITUDE_QUATERNION_DATA, COMMAND_ACK_DATA, EXTENDED_SYS_STATE_DATA, HEARTBEAT_DATA,
    LOCAL_POSITION_NED_DATA, MavAutopilot, MavCmd, MavLandedState, MavMessage, MavModeFlag,
    MavResult, MavState, MavType,
};
use px4_protocol::codec::encode;

use crate::inject::FloodKind;

/// A small xorshift generator: noise, not cryptography.
struct Noise(u64);

impl Noise {
    fn new() -> Self {
        Self(runtime::monotonic_ns() | 1)
    }

    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// One datagram of `kind` into `buf`.
fn datagram(kind: FloodKind, rng: &mut Noise, seq: &mut u8, buf: &mut Vec<u8>) {
    buf.clear();
    match kind {
        FloodKind::Random => {
            let len = 1 + rng.below(280);
            buf.extend((0..len).map(|_| rng.next() as u8));
        }
        FloodKind::Mutated => {
            let msg = autopilot_message(rng);
            let _ = encode(buf, header(seq), &msg);
            match rng.below(4) {
                // Flip 1 to 4 bytes anywhere (checksum, header, payload).
                0 | 1 => {
                    for _ in 0..1 + rng.below(4) {
                        let i = rng.below(buf.len());
                        buf[i] ^= 1 << rng.below(8);
                    }
                }
                // Cut it short.
                2 => buf.truncate(rng.below(buf.len())),
                // Two frames glued, the second mutated.
                _ => {
                    let first = buf.clone();
                    let i = rng.below(first.len());
                    buf.extend_from_slice(&first);
                    let j = first.len() + i;
                    buf[j] = rng.next() as u8;
                }
            }
        }
        FloodKind::Spoofed => {
            // A heartbeat that says armed in OFFBOARD and a position 40 m away, both
            // well-formed, from the autopilot's ids.
            let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                custom_mode: 6 << 16,
                mavtype: MavType::MAV_TYPE_QUADROTOR,
                autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
                base_mode: MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED
                    | MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                system_status: MavState::MAV_STATE_ACTIVE,
                mavlink_version: 3,
            });
            let pos = MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
                time_boot_ms: (runtime::monotonic_ns() / 1_000_000) as u32,
                x: 40.0,
                y: -40.0,
                z: -15.0,
                vx: 5.0,
                ..LOCAL_POSITION_NED_DATA::default()
            });
            let _ = encode(buf, header(seq), &hb);
            let _ = encode(buf, header(seq), &pos);
        }
    }
}

fn header(seq: &mut u8) -> MavHeader {
    *seq = seq.wrapping_add(1);
    MavHeader {
        system_id: 1,
        component_id: 1,
        sequence: *seq,
    }
}

/// One of the messages the autopilot sends, with noisy values.
fn autopilot_message(rng: &mut Noise) -> MavMessage {
    let f = |rng: &mut Noise| (rng.next() % 2000) as f32 * 0.05 - 50.0;
    match rng.below(5) {
        0 => MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: (rng.next() as u32) & 0x0fff_0000,
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
            base_mode: MavModeFlag::from_bits_truncate(rng.next() as u8),
            system_status: MavState::MAV_STATE_ACTIVE,
            mavlink_version: 3,
        }),
        1 => MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
            time_boot_ms: rng.next() as u32,
            x: f(rng),
            y: f(rng),
            z: f(rng),
            ..LOCAL_POSITION_NED_DATA::default()
        }),
        2 => MavMessage::ATTITUDE_QUATERNION(ATTITUDE_QUATERNION_DATA {
            time_boot_ms: rng.next() as u32,
            q1: f(rng),
            q2: f(rng),
            q3: f(rng),
            q4: f(rng),
            ..ATTITUDE_QUATERNION_DATA::default()
        }),
        3 => MavMessage::EXTENDED_SYS_STATE(EXTENDED_SYS_STATE_DATA {
            landed_state: MavLandedState::MAV_LANDED_STATE_ON_GROUND,
            ..EXTENDED_SYS_STATE_DATA::default()
        }),
        _ => MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
            command: MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            result: MavResult::MAV_RESULT_ACCEPTED,
            ..COMMAND_ACK_DATA::default()
        }),
    }
}

/// `n` datagrams of random bytes at `to` as fast as they go; returns how many were sent.
pub fn burst(to: &str, n: u32) -> Result<u64> {
    let socket = UdpSocket::bind("127.0.0.1:0")?;
    let mut rng = Noise::new();
    let mut seq = 0u8;
    let mut buf = Vec::with_capacity(600);
    let mut sent = 0;
    for _ in 0..n {
        datagram(FloodKind::Random, &mut rng, &mut seq, &mut buf);
        // A full socket buffer on our side drops it, as a network would: not counted.
        if socket.send_to(&buf, to).is_ok() {
            sent += 1;
        }
    }
    Ok(sent)
}

/// A flood running on its own thread until [`Flood::stop`].
pub struct Flood {
    stop: Arc<AtomicBool>,
    sent: Arc<AtomicU64>,
    thread: Option<JoinHandle<()>>,
}

impl Flood {
    /// Starts sending `kind` datagrams at `to`, `rate` per second, from a port of its own.
    pub fn start(to: &str, kind: FloodKind, rate: f64) -> Result<Self> {
        let socket = UdpSocket::bind("127.0.0.1:0").context("flood socket")?;
        let to = to.to_string();
        let stop = Arc::new(AtomicBool::new(false));
        let sent = Arc::new(AtomicU64::new(0));
        let (stop2, sent2) = (stop.clone(), sent.clone());
        let thread = std::thread::Builder::new()
            .name("flood".into())
            .spawn(move || {
                let mut rng = Noise::new();
                let mut seq = 0u8;
                let mut buf = Vec::with_capacity(600);
                let start = Instant::now();
                let mut n = 0u64;
                while !stop2.load(Ordering::Relaxed) {
                    // Due by now at `rate`, sent in 1 ms batches.
                    let due = (start.elapsed().as_secs_f64() * rate) as u64;
                    while n < due {
                        datagram(kind, &mut rng, &mut seq, &mut buf);
                        if socket.send_to(&buf, &to).is_ok() {
                            sent2.fetch_add(1, Ordering::Relaxed);
                        }
                        n += 1;
                    }
                    std::thread::sleep(Duration::from_millis(1));
                }
            })
            .context("flood thread")?;
        Ok(Self {
            stop,
            sent,
            thread: Some(thread),
        })
    }

    /// Stops it; returns how many datagrams it sent.
    pub fn stop(mut self) -> u64 {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        self.sent.load(Ordering::Relaxed)
    }
}
