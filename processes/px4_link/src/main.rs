//! `px4-link`: the MAVLink link to PX4 as its own process.
//!
//! Reads fsm/setpoint, px4/request and safety/command; publishes vehicle/state and
//! px4/outcome. Everything the process decides is `px4_link::LinkNode`; this file owns
//! the UDP socket or serial port, the clock and the iceoryx2 ports.

mod serial_port;

use std::io::ErrorKind;
use std::net::{SocketAddr, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

use anyhow::{Context, Result};
use clap::Parser;
use ipc_types::msg::{LinkOutcome, LinkRequest, SafetyCommand, Setpoint, VehicleState};
use ipc_types::services;
use mavlink::MavHeader;
use mavlink::dialects::common::MavMessage;
use px4_link::LinkNode;
use px4_link::config::{LinkAddress, Px4LinkConfig};
use px4_protocol::codec::{StreamDecoder, decode_datagram, encode};
use runtime::{Ipc, IpcPrefix, monotonic_ns};
use stack_config::Validate;
use stack_config::{IpcConfig, load_process_or_default};

use serial_port::{Readiness, SerialPort};

/// The MAVLink link between the stack and PX4 (or the simulator).
#[derive(Debug, Parser)]
#[command(name = "px4-link", version, about)]
struct Args {
    /// Stack configuration (reads [ipc] and [px4_link]; defaults when absent).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Link to open, overriding the config: udp:HOST:PORT to listen on, or
    /// serial:DEVICE:BAUD (e.g. serial:/dev/ttyTHS1:921600).
    #[arg(long)]
    link: Option<String>,
    /// Where to send before the autopilot is heard, HOST:PORT (UDP only).
    #[arg(long)]
    remote: Option<String>,
    /// iceoryx2 prefix (default: $LANDING_IPC_PREFIX, else [ipc] prefix).
    #[arg(long)]
    ipc_prefix: Option<String>,
}

fn main() -> ExitCode {
    runtime::process_main("info", run)
}

/// How long one receive may block: the loop's period when the autopilot is quiet.
const RECV_TIMEOUT: Duration = Duration::from_millis(2);
/// How long a write may wait for room in a full serial output buffer.
const WRITE_STALL: Duration = Duration::from_millis(5);
/// How often a serial port that failed is reopened (a USB adapter unplugged and back).
const REOPEN_PERIOD_NS: u64 = 1_000_000_000;

/// Where MAVLink frames go and come from.
enum Transport {
    /// Datagrams; replies go to whoever spoke last.
    Udp { socket: UdpSocket, peer: SocketAddr },
    /// A byte stream; `port` is `None` while it is being reopened after a failure.
    Serial {
        path: PathBuf,
        baud: u32,
        port: Option<SerialPort>,
        decoder: StreamDecoder,
        failed_at_ns: u64,
    },
}

impl Transport {
    fn open(address: &LinkAddress, remote: SocketAddr) -> Result<Self> {
        Ok(match address {
            LinkAddress::Udp(listen) => {
                let socket =
                    UdpSocket::bind(listen).with_context(|| format!("binding {listen}"))?;
                socket.set_read_timeout(Some(RECV_TIMEOUT))?;
                Self::Udp {
                    socket,
                    peer: remote,
                }
            }
            LinkAddress::Serial { path, baud } => {
                let port = open_serial(path, *baud)?;
                Self::Serial {
                    path: path.clone(),
                    baud: *baud,
                    port: Some(port),
                    decoder: StreamDecoder::new(),
                    failed_at_ns: 0,
                }
            }
        })
    }

    /// Hands everything that arrived to `node` and says how many messages that was; the
    /// first wait may block briefly. `buf` and `msgs` are the caller's, reused from call
    /// to call.
    fn receive(
        &mut self,
        node: &mut LinkNode,
        buf: &mut [u8],
        msgs: &mut Vec<(MavHeader, MavMessage)>,
    ) -> Result<u64> {
        let mut delivered = 0u64;
        match self {
            Self::Udp { socket, peer } => {
                loop {
                    match socket.recv_from(buf) {
                        Ok((n, from)) => {
                            *peer = from;
                            msgs.clear();
                            let errors = decode_datagram(buf.get(..n).unwrap_or(&[]), msgs);
                            deliver(node, errors, msgs);
                            delivered += msgs.len() as u64;
                            socket.set_read_timeout(Some(Duration::from_micros(1)))?;
                        }
                        Err(e)
                            if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) =>
                        {
                            break;
                        }
                        Err(e) => {
                            tracing::warn!(error = %e, "UDP receive failed");
                            break;
                        }
                    }
                }
                socket.set_read_timeout(Some(RECV_TIMEOUT))?;
            }
            Self::Serial {
                path,
                baud,
                port,
                decoder,
                failed_at_ns,
            } => {
                let Some(p) = port else {
                    std::thread::sleep(RECV_TIMEOUT);
                    let now = monotonic_ns();
                    if now.saturating_sub(*failed_at_ns) >= REOPEN_PERIOD_NS {
                        *failed_at_ns = now;
                        match SerialPort::open(path, *baud) {
                            Ok(reopened) => {
                                tracing::info!(path = %path.display(), "serial port reopened");
                                *port = Some(reopened);
                            }
                            Err(e) => tracing::debug!(error = %e, "serial port still unavailable"),
                        }
                    }
                    return Ok(0);
                };
                let failure = match p.wait_readable(RECV_TIMEOUT) {
                    Ok(Readiness::Nothing) => return Ok(0),
                    Ok(Readiness::HungUp) => Some("hung up".to_string()),
                    Ok(Readiness::Readable) => loop {
                        match p.read(buf) {
                            Ok(0) => break None,
                            Ok(n) => {
                                msgs.clear();
                                let errors = decoder.push(buf.get(..n).unwrap_or(&[]), msgs);
                                deliver(node, errors, msgs);
                                delivered += msgs.len() as u64;
                            }
                            Err(e) if e.kind() == ErrorKind::WouldBlock => break None,
                            Err(e) if e.kind() == ErrorKind::Interrupted => {}
                            Err(e) => break Some(e.to_string()),
                        }
                    },
                    Err(e) => Some(e.to_string()),
                };
                if let Some(why) = failure {
                    tracing::warn!(path = %path.display(), %why, "serial port failed; reopening every second");
                    *port = None;
                    *failed_at_ns = monotonic_ns();
                }
            }
        }
        Ok(delivered)
    }

    fn send(&mut self, frame: &[u8]) {
        match self {
            Self::Udp { socket, peer } => {
                if let Err(e) = socket.send_to(frame, *peer) {
                    tracing::debug!(error = %e, "UDP send failed");
                }
            }
            Self::Serial { port: Some(p), .. } => {
                if let Err(e) = p.write_all(frame, WRITE_STALL) {
                    tracing::debug!(error = %e, "serial write failed");
                }
            }
            Self::Serial { port: None, .. } => {}
        }
    }
}

/// What one read decoded, handed to the node at the time it arrived.
fn deliver(node: &mut LinkNode, parse_errors: u64, msgs: &[(MavHeader, MavMessage)]) {
    node.on_parse_errors(parse_errors);
    let now = monotonic_ns();
    for (h, m) in msgs {
        node.on_message(now, h, m);
    }
}

fn open_serial(path: &Path, baud: u32) -> Result<SerialPort> {
    SerialPort::open(path, baud).with_context(|| {
        format!(
            "serial port {}: cannot open at {baud} baud (allowed: an existing serial device, e.g. serial:/dev/ttyTHS1:921600)",
            path.display()
        )
    })
}

fn run(args: &Args) -> Result<()> {
    let (ipc_cfg, mut cfg): (IpcConfig, Px4LinkConfig) =
        load_process_or_default(args.config.as_deref(), "px4_link")?;
    if let Some(l) = &args.link {
        cfg.link = l.clone();
    }
    if let Some(r) = &args.remote {
        cfg.remote = r.clone();
    }
    cfg.validate()
        .map_err(|e| anyhow::anyhow!("--link/--remote: {}", e.message))?;
    let address = cfg.address().map_err(|e| anyhow::anyhow!(e.message))?;
    let remote = cfg
        .remote_address()
        .map_err(|e| anyhow::anyhow!(e.message))?;
    let mut transport = Transport::open(&address, remote)?;

    let prefix = IpcPrefix::resolve(args.ipc_prefix.as_deref(), &ipc_cfg.prefix)?;
    let ipc = Ipc::open("px4-link", &prefix)?;
    let setpoints = ipc.subscriber::<Setpoint>(services::FSM_SETPOINT)?;
    let requests = ipc.subscriber::<LinkRequest>(services::PX4_REQUEST)?;
    let safety = ipc.subscriber::<SafetyCommand>(services::SAFETY_COMMAND)?;
    let mut states = ipc.publisher::<VehicleState>(services::VEHICLE_STATE)?;
    let mut outcomes = ipc.publisher::<LinkOutcome>(services::PX4_OUTCOME)?;
    let mut heartbeat = ipc.heartbeat(Duration::from_millis(ipc_cfg.heartbeat_deadline_ms))?;
    let beat_ns = ipc_cfg.heartbeat_period_ms * 1_000_000;

    let mut node = LinkNode::new(cfg.settings());
    let (mut buf, mut frame, mut msgs) = (vec![0u8; 65_536], Vec::new(), Vec::new());
    let mut last_beat = 0u64;
    let mut counts = Counts::default();
    let mut last_link = None;
    tracing::info!(link = %cfg.link, "px4-link running");
    while !ipc.shutdown_requested() {
        counts.received += transport.receive(&mut node, &mut buf, &mut msgs)?;
        let now = monotonic_ns();
        while let Ok(Some(s)) = setpoints.receive() {
            counts.setpoints += 1;
            node.on_setpoint(now, s.payload());
        }
        while let Ok(Some(r)) = requests.receive() {
            counts.requests += 1;
            node.on_request(now, r.payload());
        }
        while let Ok(Some(c)) = safety.receive() {
            counts.safety += 1;
            node.on_safety(now, c.payload());
        }
        node.send_due(now, |header, m| {
            frame.clear();
            encode(&mut frame, header, m)?;
            transport.send(&frame);
            counts.sent += 1;
            anyhow::Ok(())
        })?;
        for o in node.take_outcomes() {
            outcomes.send(o.msg, &o)?;
            counts.outcomes += 1;
        }
        if let Some(state) = node.vehicle_state(now) {
            states.send(state.msg, &state)?;
            counts.states += 1;
            last_link = Some(state.link);
        }
        if now.saturating_sub(last_beat) >= beat_ns {
            last_beat = now;
            heartbeat.beat()?;
        }
    }
    let link = last_link.unwrap_or_default();
    tracing::info!(
        received = counts.received,
        sent = counts.sent,
        parse_errors = link.parse_errors,
        messages_lost = link.messages_lost,
        states = counts.states,
        outcomes = counts.outcomes,
        setpoints = counts.setpoints,
        requests = counts.requests,
        safety = counts.safety,
        "px4-link stopped"
    );
    Ok(())
}

/// What went through the process, logged when it stops.
#[derive(Debug, Default)]
struct Counts {
    /// MAVLink messages decoded from the autopilot, and sent to it.
    received: u64,
    sent: u64,
    /// Published: vehicle states, request outcomes.
    states: u64,
    outcomes: u64,
    /// Taken in: setpoints, requests, safety orders.
    setpoints: u64,
    requests: u64,
    safety: u64,
}
