//! The MAVLink 2 UDP endpoint around the [`Commander`], like PX4 SITL's
//! onboard link, and [`SimVehicle`], a world flown by it.
//!
//! PX4 SITL sends its onboard link to the companion at UDP 14540. Here the
//! simulator listens on a configurable address (default 127.0.0.1:14580) and
//! sends to the peer it last heard from, plus a configured remote (default
//! 127.0.0.1:14540, where px4-link listens) so a companion that has not
//! spoken yet still gets heartbeats. System id 1, component id 1
//! (autopilot), one MAVLink 2 message per datagram.
//!
//! This is the only part of the crate that does I/O; [`SimVehicle::step`]
//! still takes time as an argument and never reads a clock, so a lockstep
//! runner can drive it. [`SimVehicle::run_realtime`] is the wall-clock loop.

use std::io::ErrorKind;
use std::net::{SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use mavlink::MavHeader;
use mavlink::dialects::common::{MavMessage, MavResult};
use px4_protocol::codec::decode_datagram;
use px4_protocol::raw::{UnknownCommand, command_ack_frame, unknown_commands};
use serde::Deserialize;
use thiserror::Error;

use super::commander::{Commander, Px4Params, VehicleStatus};
use crate::lockstep::{PHYSICS_STEP_NS, Simulator, StepReport};
use crate::params::ParamError;
use crate::world::{World, WorldError};

/// Largest datagram read; MAVLink 2 frames are at most 280 bytes, but a
/// sender may pack several into one datagram.
const MAX_DATAGRAM: usize = 65_536;

/// Where the endpoint listens and whom it talks to.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EndpointConfig {
    /// Local address to bind (default 127.0.0.1:14580; port 0 picks a free one).
    pub listen: SocketAddr,
    /// Where to send even before hearing from anyone (default
    /// 127.0.0.1:14540, the companion port of PX4 SITL); None sends only to
    /// the last peer heard from.
    pub remote: Option<SocketAddr>,
    /// Our MAVLink system id (PX4: 1).
    pub system_id: u8,
    /// Our MAVLink component id (PX4 autopilot: 1).
    pub component_id: u8,
}

impl Default for EndpointConfig {
    /// Listen on 127.0.0.1:14580, send to 127.0.0.1:14540, system 1, component 1.
    fn default() -> Self {
        Self {
            listen: SocketAddr::from(([127, 0, 0, 1], 14580)),
            remote: Some(SocketAddr::from(([127, 0, 0, 1], 14540))),
            system_id: 1,
            component_id: 1,
        }
    }
}

/// Counters of what went over the link, to see parse errors and drops.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct EndpointStats {
    /// Datagrams received.
    pub datagrams_received: u64,
    /// MAVLink messages decoded and handed to the commander.
    pub messages_received: u64,
    /// Frames that failed to decode, plus datagrams with no valid frame at all.
    pub parse_errors: u64,
    /// Messages sent (counted once per destination).
    pub messages_sent: u64,
    /// Sends or receives that failed (the link carries on).
    pub io_errors: u64,
}

/// Why the endpoint or the simulated vehicle failed.
#[derive(Debug, Error)]
pub enum EndpointError {
    /// The socket could not be set up or read.
    #[error("UDP socket {addr}: {source}")]
    Socket {
        /// The address involved.
        addr: SocketAddr,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A PX4 parameter is invalid.
    #[error("PX4 parameter {0}")]
    Params(#[from] ParamError),
    /// The world failed to step.
    #[error("world: {0}")]
    World(#[from] WorldError),
    /// The simulator failed to step.
    #[error("simulator: {0}")]
    Sim(#[from] crate::lockstep::SimError),
}

/// A non-blocking UDP MAVLink 2 endpoint: pure I/O; the [`Simulator`] owns the commander.
#[derive(Debug)]
pub struct Endpoint {
    socket: UdpSocket,
    local: SocketAddr,
    config: EndpointConfig,
    peer: Option<SocketAddr>,
    sequence: u8,
    stats: EndpointStats,
    buf: Vec<u8>,
    unknown: Vec<UnknownCommand>,
}

impl Endpoint {
    /// Binds the socket (non-blocking).
    pub fn bind(config: EndpointConfig) -> Result<Self, EndpointError> {
        let err = |source| EndpointError::Socket {
            addr: config.listen,
            source,
        };
        let socket = UdpSocket::bind(config.listen).map_err(err)?;
        socket.set_nonblocking(true).map_err(err)?;
        let local = socket.local_addr().map_err(err)?;
        Ok(Self {
            socket,
            local,
            config,
            peer: None,
            sequence: 0,
            stats: EndpointStats::default(),
            buf: vec![0; MAX_DATAGRAM],
            unknown: Vec::new(),
        })
    }

    /// The bound address (useful when the configured port was 0).
    pub fn local_addr(&self) -> SocketAddr {
        self.local
    }

    /// The companion address we last heard from, if any.
    pub fn peer(&self) -> Option<SocketAddr> {
        self.peer
    }

    /// Link counters.
    pub fn stats(&self) -> EndpointStats {
        self.stats
    }

    /// Every message that arrived since the last call (non-blocking); parse errors are
    /// counted and skipped.
    pub fn receive(&mut self) -> Result<Vec<(MavHeader, MavMessage)>, EndpointError> {
        let mut out = Vec::new();
        loop {
            match self.socket.recv_from(&mut self.buf) {
                Ok((len, from)) => {
                    self.stats.datagrams_received += 1;
                    self.peer = Some(from);
                    let before = out.len();
                    let errors = decode_datagram(&self.buf[..len], &mut out);
                    if errors > 0 {
                        self.unknown.extend(unknown_commands(&self.buf[..len]));
                    }
                    self.stats.parse_errors += errors;
                    let decoded = (out.len() - before) as u64;
                    self.stats.messages_received += decoded;
                    if decoded == 0 && errors == 0 && len > 0 {
                        self.stats.parse_errors += 1;
                    }
                }
                Err(e) if e.kind() == ErrorKind::WouldBlock => break,
                Err(e)
                    if matches!(
                        e.kind(),
                        ErrorKind::ConnectionRefused
                            | ErrorKind::ConnectionReset
                            | ErrorKind::Interrupted
                    ) =>
                {
                    // An ICMP "port unreachable" from an earlier send: the
                    // companion is not up yet. Keep going.
                    self.stats.io_errors += 1;
                }
                Err(source) => {
                    return Err(EndpointError::Socket {
                        addr: self.local,
                        source,
                    });
                }
            }
        }
        Ok(out)
    }

    /// The commands with a number the dialect lacks that arrived since the last call.
    pub fn take_unknown_commands(&mut self) -> Vec<UnknownCommand> {
        std::mem::take(&mut self.unknown)
    }

    /// Answers `cmd` MAV_RESULT_UNSUPPORTED as PX4's commander does, if it was sent to
    /// us (our system, component ours or 0); otherwise nothing, as PX4's receiver.
    pub fn answer_unsupported(&mut self, cmd: &UnknownCommand) {
        let ours = cmd.target_system == self.config.system_id
            && (cmd.target_component == 0 || cmd.target_component == self.config.component_id);
        if !ours {
            return;
        }
        let frame = command_ack_frame(
            self.sequence,
            self.config.system_id,
            self.config.component_id,
            cmd,
            MavResult::MAV_RESULT_UNSUPPORTED as u8,
        );
        self.sequence = self.sequence.wrapping_add(1);
        self.send_frame(&frame);
    }

    /// Sends one encoded frame to the last peer and to the configured remote.
    fn send_frame(&mut self, frame: &[u8]) {
        let mut targets: [Option<SocketAddr>; 2] = [self.peer, self.config.remote];
        if targets[0] == targets[1] {
            targets[1] = None;
        }
        for to in targets.iter().flatten() {
            match self.socket.send_to(frame, to) {
                Ok(_) => self.stats.messages_sent += 1,
                Err(e) => {
                    self.stats.io_errors += 1;
                    tracing::trace!(%to, error = %e, "MAVLink send failed");
                }
            }
        }
    }

    /// Sends `msgs` to the last peer and to the configured remote.
    pub fn send(&mut self, msgs: &[MavMessage]) {
        if self.peer.is_none() && self.config.remote.is_none() {
            return;
        }
        let mut frame = Vec::with_capacity(300);
        for msg in msgs {
            let header = MavHeader {
                system_id: u32::from(self.config.system_id),
                component_id: self.config.component_id,
                sequence: self.sequence,
            };
            self.sequence = self.sequence.wrapping_add(1);
            frame.clear();
            if mavlink::write_v2_msg(&mut frame, header, msg).is_err() {
                self.stats.io_errors += 1;
                continue;
            }
            self.send_frame(&frame);
        }
    }
}

/// A simulated PX4 vehicle reachable over UDP: the lockstep [`Simulator`] (world +
/// commander + sensor schedules) behind an [`Endpoint`].
#[derive(Debug)]
pub struct SimVehicle {
    sim: Simulator,
    endpoint: Endpoint,
}

impl SimVehicle {
    /// Builds the vehicle around `world`, validates the PX4 parameters, binds the socket.
    pub fn new(
        world: World,
        params: Px4Params,
        config: EndpointConfig,
    ) -> Result<Self, EndpointError> {
        let sim = Simulator::from_world(world, Commander::new(params)?, 30.0, 30.0, 0);
        Self::with_simulator(sim, config)
    }

    /// Puts an existing simulator behind a new endpoint.
    pub fn with_simulator(sim: Simulator, config: EndpointConfig) -> Result<Self, EndpointError> {
        Ok(Self {
            sim,
            endpoint: Endpoint::bind(config)?,
        })
    }

    /// The simulated world.
    pub fn world(&self) -> &World {
        self.sim.world()
    }

    /// The simulated world, mutably (scenario set-up, fault injection).
    pub fn world_mut(&mut self) -> &mut World {
        self.sim.world_mut()
    }

    /// The simulator.
    pub fn simulator(&self) -> &Simulator {
        &self.sim
    }

    /// The simulator, mutably (sensors, commander).
    pub fn simulator_mut(&mut self) -> &mut Simulator {
        &mut self.sim
    }

    /// The MAVLink endpoint (address, stats).
    pub fn endpoint(&self) -> &Endpoint {
        &self.endpoint
    }

    /// The MAVLink endpoint, mutably.
    pub fn endpoint_mut(&mut self) -> &mut Endpoint {
        &mut self.endpoint
    }

    /// What the commander sees of the world now: the estimate, never truth.
    pub fn status(&self) -> VehicleStatus {
        self.sim.status()
    }

    /// One physics step, clock-free: what arrived on the link goes to the commander, the
    /// simulator steps, what the commander produced goes out.
    pub fn step(&mut self) -> Result<StepReport, EndpointError> {
        for (header, msg) in self.endpoint.receive()? {
            self.sim.handle_mavlink(&header, &msg);
        }
        for cmd in self.endpoint.take_unknown_commands() {
            if !self.sim.autopilot_silent() {
                self.endpoint.answer_unsupported(&cmd);
            }
        }
        let report = self.sim.step()?;
        let out = self.sim.take_mavlink();
        self.endpoint.send(&out);
        Ok(report)
    }

    /// Runs on the wall clock (times `speed`) in the calling thread, stepping the world
    /// at 500 Hz, calling `on_step` after each step (sensors, truth), until `until`, until
    /// `stop` is set, or until `on_step` returns false. If the thread falls more than 100 ms behind (a loaded machine),
    /// simulated time skips ahead instead of racing to catch up.
    pub fn run_realtime(
        &mut self,
        until: Instant,
        stop: &AtomicBool,
        speed: f64,
        mut on_step: impl FnMut(&mut Simulator, &StepReport) -> bool,
    ) -> Result<(), EndpointError> {
        const MAX_LAG_NS: u64 = 100_000_000;
        let speed = if speed.is_finite() && speed > 0.0 {
            speed
        } else {
            1.0
        };
        let start = Instant::now();
        let world_start_ns = self.sim.time_ns();
        let mut skipped_ns: u64 = 0;
        loop {
            let wall = Instant::now();
            if wall >= until || stop.load(Ordering::Relaxed) {
                return Ok(());
            }
            let elapsed_ns = (wall.duration_since(start).as_nanos() as f64 * speed) as u64;
            let target_ns = world_start_ns
                .saturating_add(elapsed_ns)
                .saturating_sub(skipped_ns);
            let behind = target_ns.saturating_sub(self.sim.time_ns());
            if behind > MAX_LAG_NS {
                skipped_ns = skipped_ns.saturating_add(behind - PHYSICS_STEP_NS);
                tracing::debug!(behind_ms = behind / 1_000_000, "real-time loop fell behind");
            }
            while self.sim.time_ns().saturating_add(PHYSICS_STEP_NS)
                <= world_start_ns
                    .saturating_add(elapsed_ns)
                    .saturating_sub(skipped_ns)
            {
                let report = self.step()?;
                if !on_step(&mut self.sim, &report) {
                    return Ok(());
                }
            }
            std::thread::sleep(Duration::from_micros(500));
        }
    }
}
