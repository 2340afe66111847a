//! `px4-link`: the MAVLink link to PX4 as its own process.
//!
//! Reads fsm/setpoint, px4/request and safety/command; publishes vehicle/state and
//! px4/outcome. The protocol is `px4_link::Px4Link`; this file owns the UDP socket, the
//! clock and the iceoryx2 ports.

use std::collections::VecDeque;
use std::io::ErrorKind;
use std::net::{SocketAddr, UdpSocket};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::{Context, Result};
use clap::Parser;
use ipc_types::msg::{
    Header, LinkOutcome, LinkOutcomeKind, LinkRequest, LinkRequestKind, SafetyAction,
    SafetyCommand, Setpoint, Stage, VehicleState,
};
use ipc_types::runtime::config::{IpcConfig, load_process_or_default};
use ipc_types::runtime::{Ipc, IpcPrefix, Validate, logging, monotonic_ns};
use ipc_types::services;
use mavlink::dialects::common::MavResult;
use px4_link::codec::{decode_datagram, encode};
use px4_link::config::{LinkAddress, Px4LinkConfig};
use px4_link::{Outcome, Px4Link, Request};

/// The MAVLink link between the stack and PX4 (or the simulator).
#[derive(Debug, Parser)]
#[command(name = "px4-link", version, about)]
struct Args {
    /// Stack configuration (reads [ipc] and [px4_link]; defaults when absent).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Link to open, overriding the config: udp:HOST:PORT to listen on.
    #[arg(long)]
    link: Option<String>,
    /// Where to send before the autopilot is heard, HOST:PORT.
    #[arg(long)]
    remote: Option<String>,
    /// iceoryx2 prefix (default: $LANDING_IPC_PREFIX, else [ipc] prefix).
    #[arg(long)]
    ipc_prefix: Option<String>,
}

fn main() -> ExitCode {
    let args = Args::parse();
    logging::init("info");
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

/// How long one receive may block: the loop's period when the autopilot is quiet.
const RECV_TIMEOUT: Duration = Duration::from_millis(2);

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
    let LinkAddress::Udp(listen) = cfg.address().map_err(|e| anyhow::anyhow!(e.message))?;
    let mut peer: SocketAddr = cfg
        .remote_address()
        .map_err(|e| anyhow::anyhow!(e.message))?;
    let socket = UdpSocket::bind(listen).with_context(|| format!("binding {listen}"))?;
    socket.set_read_timeout(Some(RECV_TIMEOUT))?;

    let prefix = IpcPrefix::resolve(args.ipc_prefix.as_deref(), &ipc_cfg.prefix)?;
    let ipc = Ipc::open("px4-link", &prefix)?;
    let setpoints = ipc.subscriber::<Setpoint>(services::FSM_SETPOINT)?;
    let requests = ipc.subscriber::<LinkRequest>(services::PX4_REQUEST)?;
    let safety = ipc.subscriber::<SafetyCommand>(services::SAFETY_COMMAND)?;
    let mut states = ipc.publisher::<VehicleState>(services::VEHICLE_STATE)?;
    let mut outcomes = ipc.publisher::<LinkOutcome>(services::PX4_OUTCOME)?;
    let mut heartbeat = ipc.heartbeat(Duration::from_millis(ipc_cfg.heartbeat_deadline_ms))?;
    let beat_ns = ipc_cfg.heartbeat_period_ms * 1_000_000;

    let mut link = Px4Link::new(cfg.settings());
    // Ids of the requests in flight, in order (the link answers them in order).
    let mut ids: VecDeque<(u64, u32)> = VecDeque::new();
    let (mut buf, mut frame, mut msgs) = (vec![0u8; 65_536], Vec::new(), Vec::new());
    let (mut seq, mut last_beat, mut last_state_ns) = (0u8, 0u64, 0u64);
    tracing::info!(%listen, %peer, "px4-link running");
    while !ipc.shutdown_requested() {
        let now = monotonic_ns();
        // Everything the autopilot sent; the first receive may block briefly.
        loop {
            match socket.recv_from(&mut buf) {
                Ok((n, from)) => {
                    peer = from;
                    msgs.clear();
                    for _ in 0..decode_datagram(buf.get(..n).unwrap_or(&[]), &mut msgs) {
                        link.parse_error();
                    }
                    for (h, m) in &msgs {
                        link.on_message(monotonic_ns(), h, m);
                    }
                    socket.set_read_timeout(Some(Duration::from_micros(1)))?;
                }
                Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => break,
                Err(e) => {
                    tracing::warn!(error = %e, "UDP receive failed");
                    break;
                }
            }
        }
        socket.set_read_timeout(Some(RECV_TIMEOUT))?;
        let now = now.max(monotonic_ns());
        while let Ok(Some(s)) = setpoints.receive() {
            link.set_setpoint(now, s.payload());
        }
        while let Ok(Some(r)) = requests.receive() {
            let r = *r.payload();
            let request = match LinkRequestKind::from_raw(r.kind) {
                Some(LinkRequestKind::Arm) => Some(Request::Arm),
                Some(LinkRequestKind::Disarm) => Some(Request::Disarm),
                Some(LinkRequestKind::Takeoff)
                    if r.altitude_m.is_finite() && r.altitude_m > 0.0 =>
                {
                    Some(Request::Takeoff {
                        altitude_m: r.altitude_m as f32,
                    })
                }
                Some(LinkRequestKind::Offboard) => Some(Request::Offboard),
                Some(LinkRequestKind::Land) => Some(Request::Land),
                Some(LinkRequestKind::Hold) => Some(Request::Hold),
                _ => None,
            };
            match request {
                Some(q) => {
                    ids.push_back((r.id, r.kind));
                    link.request(q);
                }
                None => {
                    tracing::warn!(kind = r.kind, "unreadable request refused");
                    let o = outcome(r.id, r.kind, LinkOutcomeKind::Invalid, 0);
                    outcomes.send(o.msg, &o)?;
                }
            }
        }
        while let Ok(Some(c)) = safety.receive() {
            let c = *c.payload();
            let request = match SafetyAction::from_raw(c.action) {
                SafetyAction::None => continue,
                SafetyAction::Hold => Request::Hold,
                SafetyAction::SafeLand | SafetyAction::Abort => Request::Land,
            };
            // At once: nothing queued may delay a safety order.
            tracing::warn!(?request, "safety command");
            link.clear_requests();
            ids.clear();
            ids.push_back((0, 0));
            link.request(request);
        }
        let header = link.header(0);
        for m in link.poll(now) {
            frame.clear();
            encode(
                &mut frame,
                mavlink::MavHeader {
                    sequence: seq,
                    ..header
                },
                m,
            )?;
            seq = seq.wrapping_add(1);
            if let Err(e) = socket.send_to(&frame, peer) {
                tracing::debug!(error = %e, "UDP send failed");
            }
        }
        for (_, o) in link.take_outcomes() {
            let (id, kind) = ids.pop_front().unwrap_or((0, 0));
            let (code, result) = match o {
                Outcome::Accepted => (
                    LinkOutcomeKind::Accepted,
                    MavResult::MAV_RESULT_ACCEPTED as u32,
                ),
                Outcome::Rejected(r) => (LinkOutcomeKind::Rejected, r as u32),
                Outcome::TimedOut => (LinkOutcomeKind::TimedOut, 0),
                Outcome::NoSetpointStream => (LinkOutcomeKind::NoSetpointStream, 0),
            };
            let msg = outcome(id, kind, code, result);
            outcomes.send(msg.msg, &msg)?;
        }
        if let Some(mut state) = link.vehicle_state(now)
            && state.msg.capture_ns != last_state_ns
        {
            last_state_ns = state.msg.capture_ns;
            state
                .msg
                .push_stage(Stage::Px4Link, state.msg.capture_ns, monotonic_ns());
            states.send(state.msg, &state)?;
        }
        if now.saturating_sub(last_beat) >= beat_ns {
            last_beat = now;
            heartbeat.beat()?;
        }
    }
    tracing::info!("px4-link stopped");
    Ok(())
}

fn outcome(id: u64, kind: u32, code: LinkOutcomeKind, result: u32) -> LinkOutcome {
    LinkOutcome {
        msg: Header::captured_at(monotonic_ns()),
        id,
        kind,
        outcome: code as u32,
        result,
        reserved: 0,
    }
}
