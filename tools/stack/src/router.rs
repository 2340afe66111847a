//! A small MAVLink router, as mavlink-router or mavp2p sit on a vehicle between the
//! autopilot and its companions, and a second ground station behind it: to fly the
//! stack as one component among several (`landing run --processes --router`).
//!
//! The router has one UDP endpoint per peer (the autopilot, px4-link, the ground
//! station). Each datagram's frames are routed as mavlink-router routes them: a
//! message with a target system goes to the endpoints where that system (and component,
//! when given) was seen, or everywhere when it was never seen; one without a target
//! goes to every other endpoint, once that endpoint's peer has spoken (before, it is
//! not up). Every datagram is counted in and out, per endpoint.

use std::collections::HashMap;
use std::net::{SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use mavlink::dialects::common::{
    COMMAND_LONG_DATA, HEARTBEAT_DATA, MavAutopilot, MavCmd, MavMessage, MavModeFlag, MavState,
    MavType, PARAM_REQUEST_LIST_DATA,
};
use mavlink::{MavHeader, Message};
use px4_protocol::codec::{decode_datagram, encode};
use serde::Serialize;

/// The router's endpoints.
const SIM: usize = 0;
const LINK: usize = 1;
const GCS: usize = 2;

/// Datagrams through one endpoint.
#[derive(Debug, Default, Clone, Copy, Serialize, PartialEq, Eq)]
pub struct EndpointCounts {
    /// Datagrams received from the peer.
    pub datagrams_in: u64,
    /// Datagrams sent to the peer.
    pub datagrams_out: u64,
}

/// What went through the router.
#[derive(Debug, Default, Clone, Serialize)]
pub struct RouterCounts {
    /// From and to the autopilot.
    pub autopilot: EndpointCounts,
    /// From and to px4-link.
    pub px4_link: EndpointCounts,
    /// From and to the ground station.
    pub ground_station: EndpointCounts,
    /// Datagrams with nowhere to go (every frame for the endpoint it came from, or for
    /// peers not up yet).
    pub unrouted: u64,
    /// Datagrams that held no frame (not MAVLink).
    pub not_mavlink: u64,
    /// Datagrams received after [`Router::hold`] (the end of the run), not forwarded:
    /// whatever reached a peer was read by it before it stopped.
    pub held: u64,
}

#[derive(Default)]
struct Shared {
    counts: [EndpointCounts; 3],
    unrouted: u64,
    not_mavlink: u64,
    held: u64,
    /// (system, component) -> the endpoint it was last heard on.
    seen: HashMap<(u8, u8), usize>,
    /// The ground station's address, once it spoke.
    gcs_peer: Option<SocketAddr>,
    /// Which peers have spoken: one that has not is not up yet and gets nothing (as
    /// mavlink-router's UDP server endpoints learn their client from its first datagram).
    heard: [bool; 3],
}

/// A running router.
pub struct Router {
    sockets: [Arc<UdpSocket>; 3],
    shared: Arc<Mutex<Shared>>,
    stop: Arc<AtomicBool>,
    hold: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
}

impl Router {
    /// Routes between the autopilot at `autopilot` and px4-link at `link`; the
    /// ground station's endpoint takes whoever speaks to it first.
    pub fn start(autopilot: SocketAddr, link: SocketAddr) -> Result<Self> {
        let bind = || -> Result<Arc<UdpSocket>> {
            let s = UdpSocket::bind("127.0.0.1:0").context("router socket")?;
            s.set_read_timeout(Some(Duration::from_millis(100)))?;
            Ok(Arc::new(s))
        };
        let sockets = [bind()?, bind()?, bind()?];
        let shared = Arc::new(Mutex::new(Shared::default()));
        let stop = Arc::new(AtomicBool::new(false));
        let hold = Arc::new(AtomicBool::new(false));
        let peers = [Some(autopilot), Some(link), None];
        let mut threads = Vec::new();
        for from in [SIM, LINK, GCS] {
            let sockets = sockets.clone();
            let shared = Arc::clone(&shared);
            let stop = Arc::clone(&stop);
            let hold = Arc::clone(&hold);
            threads.push(
                std::thread::Builder::new()
                    .name(format!("router-{from}"))
                    .spawn(move || route_loop(from, &sockets, peers, &shared, [&stop, &hold]))?,
            );
        }
        Ok(Self {
            sockets,
            shared,
            stop,
            hold,
            threads,
        })
    }

    /// Where the autopilot must send (its companion address).
    pub fn autopilot_side(&self) -> SocketAddr {
        self.addr(SIM)
    }

    /// Where px4-link must send (its `remote`).
    pub fn link_side(&self) -> SocketAddr {
        self.addr(LINK)
    }

    /// Where a ground station sends.
    pub fn ground_station_side(&self) -> SocketAddr {
        self.addr(GCS)
    }

    fn addr(&self, k: usize) -> SocketAddr {
        self.sockets[k]
            .local_addr()
            .unwrap_or_else(|_| SocketAddr::from(([127, 0, 0, 1], 0)))
    }

    /// Forwards nothing more (counted as `held`): called before the peers stop, so that
    /// every datagram forwarded was one they were still reading.
    pub fn hold(&self) {
        self.hold.store(true, Ordering::Relaxed);
    }

    /// Stops the router and returns its counts.
    pub fn stop(mut self) -> RouterCounts {
        self.stop.store(true, Ordering::Relaxed);
        for t in std::mem::take(&mut self.threads) {
            let _ = t.join();
        }
        let s = self.shared.lock().unwrap_or_else(|p| p.into_inner());
        RouterCounts {
            autopilot: s.counts[SIM],
            px4_link: s.counts[LINK],
            ground_station: s.counts[GCS],
            unrouted: s.unrouted,
            not_mavlink: s.not_mavlink,
            held: s.held,
        }
    }
}

fn route_loop(
    from: usize,
    sockets: &[Arc<UdpSocket>; 3],
    peers: [Option<SocketAddr>; 3],
    shared: &Mutex<Shared>,
    [stop, hold]: [&AtomicBool; 2],
) {
    let mut buf = vec![0u8; 65_536];
    let mut frames = Vec::new();
    while !stop.load(Ordering::Relaxed) {
        let Ok((n, sender)) = sockets[from].recv_from(&mut buf) else {
            continue;
        };
        let data = buf.get(..n).unwrap_or_default();
        frames.clear();
        decode_datagram(data, &mut frames);
        let mut s = shared.lock().unwrap_or_else(|p| p.into_inner());
        s.counts[from].datagrams_in += 1;
        s.heard[from] = true;
        if from == GCS {
            s.gcs_peer = Some(sender);
        }
        if hold.load(Ordering::Relaxed) {
            s.held += 1;
            continue;
        }
        if frames.is_empty() {
            s.not_mavlink += 1;
            continue;
        }
        let mut to = [false; 3];
        for (h, m) in &frames {
            if let Ok(sys) = u8::try_from(h.system_id) {
                s.seen.insert((sys, h.component_id), from);
            }
            for k in destinations(&s.seen, from, m) {
                to[k] = true;
            }
        }
        let targets: Vec<(usize, SocketAddr)> = (0..3)
            .filter(|k| to[*k])
            .filter_map(|k| {
                let peer = if k == GCS { s.gcs_peer } else { peers[k] };
                peer.filter(|_| s.heard[k]).map(|p| (k, p))
            })
            .collect();
        if targets.is_empty() {
            s.unrouted += 1;
            continue;
        }
        for (k, peer) in targets {
            if sockets[k].send_to(data, peer).is_ok() {
                s.counts[k].datagrams_out += 1;
            }
        }
    }
}

/// The endpoints a frame from endpoint `from` goes to.
fn destinations(seen: &HashMap<(u8, u8), usize>, from: usize, m: &MavMessage) -> Vec<usize> {
    let others = (0..3).filter(|k| *k != from);
    let system = m.target_system_id().filter(|s| *s != 0);
    let Some(system) = system else {
        return others.collect();
    };
    let component = m.target_component_id().filter(|c| *c != 0);
    let of_system = |want: Option<u8>| -> Vec<usize> {
        let mut ks: Vec<usize> = seen
            .iter()
            .filter(|((s, c), k)| *s == system && **k != from && want.is_none_or(|w| w == *c))
            .map(|(_, k)| *k)
            .collect();
        ks.sort_unstable();
        ks.dedup();
        ks
    };
    if !seen.keys().any(|(s, _)| *s == system) {
        // A system never heard: everyone (it may be behind any endpoint).
        return others.collect();
    }
    // The component where it was seen; a component never heard: wherever its system was.
    let exact = of_system(component);
    if exact.is_empty() && component.is_some() {
        of_system(None)
    } else {
        exact
    }
}

impl Drop for Router {
    /// A run that failed before [`Router::stop`]: its threads end within a read timeout.
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// What the ground station sent and heard.
#[derive(Debug, Default, Clone, Copy, Serialize)]
pub struct GroundStationCounts {
    /// Datagrams it sent.
    pub datagrams_out: u64,
    /// Datagrams it received.
    pub datagrams_in: u64,
    /// COMMAND_ACKs addressed to it (answers to its own requests).
    pub acks: u64,
}

/// A second ground station (QGroundControl's ids, system 255, component 190): a
/// heartbeat every second, the parameter list once, and a request of the autopilot's
/// home position every two seconds, all through the router.
pub struct GroundStation {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<GroundStationCounts>>,
}

impl GroundStation {
    /// Starts talking to `router` (its ground-station endpoint).
    pub fn start(router: SocketAddr) -> Result<Self> {
        let socket = UdpSocket::bind("127.0.0.1:0").context("ground station socket")?;
        socket.set_read_timeout(Some(Duration::from_millis(50)))?;
        let stop = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&stop);
        let thread = std::thread::Builder::new()
            .name("ground-station".into())
            .spawn(move || ground_station(&socket, router, &flag))?;
        Ok(Self {
            stop,
            thread: Some(thread),
        })
    }

    /// Stops it and returns its counts.
    pub fn stop(mut self) -> GroundStationCounts {
        self.stop.store(true, Ordering::Relaxed);
        self.thread
            .take()
            .and_then(|t| t.join().ok())
            .unwrap_or_default()
    }
}

impl Drop for GroundStation {
    /// A run that failed before [`GroundStation::stop`]: its thread ends within a read
    /// timeout.
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

fn ground_station(
    socket: &UdpSocket,
    router: SocketAddr,
    stop: &AtomicBool,
) -> GroundStationCounts {
    let mut c = GroundStationCounts::default();
    let mut seq = 0u8;
    let mut send = |c: &mut GroundStationCounts, m: &MavMessage| {
        seq = seq.wrapping_add(1);
        let header = MavHeader {
            system_id: 255,
            component_id: 190,
            sequence: seq,
        };
        let mut buf = Vec::new();
        if encode(&mut buf, header, m).is_ok() && socket.send_to(&buf, router).is_ok() {
            c.datagrams_out += 1;
        }
    };
    let start = Instant::now();
    let (mut next_hb, mut next_req) = (start, start + Duration::from_millis(500));
    let mut listed = false;
    let mut buf = vec![0u8; 65_536];
    let mut frames = Vec::new();
    while !stop.load(Ordering::Relaxed) {
        let now = Instant::now();
        if now >= next_hb {
            next_hb += Duration::from_secs(1);
            send(
                &mut c,
                &MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                    custom_mode: 0,
                    mavtype: MavType::MAV_TYPE_GCS,
                    autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
                    base_mode: MavModeFlag::empty(),
                    system_status: MavState::MAV_STATE_ACTIVE,
                    mavlink_version: 3,
                }),
            );
        }
        if now >= next_req {
            next_req += Duration::from_secs(2);
            if !listed {
                listed = true;
                send(
                    &mut c,
                    &MavMessage::PARAM_REQUEST_LIST(PARAM_REQUEST_LIST_DATA {
                        target_system: 1,
                        target_component: 1,
                    }),
                );
            }
            send(
                &mut c,
                &MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
                    target_system: 1,
                    target_component: 1,
                    command: MavCmd::MAV_CMD_REQUEST_MESSAGE,
                    confirmation: 0,
                    // HOME_POSITION.
                    param1: 242.0,
                    param2: 0.0,
                    param3: 0.0,
                    param4: 0.0,
                    param5: 0.0,
                    param6: 0.0,
                    param7: 0.0,
                }),
            );
        }
        let Ok(n) = socket.recv(&mut buf) else {
            continue;
        };
        c.datagrams_in += 1;
        frames.clear();
        decode_datagram(buf.get(..n).unwrap_or_default(), &mut frames);
        c.acks += frames
            .iter()
            .filter(|(_, m)| matches!(m, MavMessage::COMMAND_ACK(a) if a.target_system == 255))
            .count() as u64;
    }
    c
}
