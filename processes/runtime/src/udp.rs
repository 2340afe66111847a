//! A UDP datagram link as the iceoryx2 driver's [`External`] I/O: each datagram that
//! arrives is one input on its `input` topic, handed over borrowed from the receive
//! buffer; each output on its `output` topic is one datagram. Both ends of the MAVLink
//! link use it: px4-link toward PX4 (or the simulator), and the simulator's autopilot
//! toward px4-link, as PX4 SITL's onboard link does.

use std::io::ErrorKind;
use std::net::{SocketAddr, UdpSocket};

use stage::{Counter, External, Flow, Input, Message, StageError};

/// The largest datagram (a sender may pack several MAVLink frames into one).
const DATAGRAM_MAX: usize = 65_536;

/// Whom a datagram goes to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reply {
    /// The configured remote only, both ways (px4-link toward the autopilot, the
    /// simulated autopilot toward px4-link): a datagram from any other address is
    /// counted (`foreign_datagrams`), handed over on the `foreign` topic when one is
    /// set (so the stage can count it where it reports), never on the input topic, and
    /// never takes the link over.
    OnlyRemote,
    /// The peer last heard from and the configured remote (PX4 SITL's onboard link keeps
    /// sending to its configured companion port even after another peer spoke).
    PeerAndRemote,
}

/// What went over the link.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct UdpStats {
    /// Datagrams received.
    pub datagrams_in: u64,
    /// Datagrams sent (once per destination).
    pub datagrams_out: u64,
    /// Receives or sends that failed (the link goes on).
    pub io_errors: u64,
    /// Datagrams from a sender other than the configured peer, not delivered as input.
    pub foreign_datagrams: u64,
    /// Datagrams the kernel dropped because the socket's receive buffer was full (any
    /// sender): with `datagrams_in`, every datagram that reached the socket is counted.
    pub kernel_drops: u64,
    /// Datagrams still in the socket when the process stopped, never read (counted at
    /// the stop).
    pub unread_at_stop: u64,
}

/// Why the link could not be opened.
#[derive(Debug, thiserror::Error)]
#[error("UDP {addr}: {source}")]
pub struct UdpError {
    /// The address involved.
    pub addr: SocketAddr,
    /// What the socket said.
    pub source: std::io::Error,
}

/// A bound UDP socket, its peer and its topics.
#[derive(Debug)]
pub struct UdpLink {
    socket: UdpSocket,
    local: SocketAddr,
    peer: Option<SocketAddr>,
    remote: Option<SocketAddr>,
    reply: Reply,
    /// The input, output and (when set) foreign topics.
    topics: [&'static str; 3],
    buf: Vec<u8>,
    stats: UdpStats,
    /// Descriptors that end a wait early (the stage's iceoryx2 inputs).
    wake: Vec<i32>,
    /// Where datagrams from a foreign address are handed over, if anywhere.
    foreign: Option<&'static str>,
}

impl UdpLink {
    /// Binds `listen`; arrivals are `input`, `output` is sent to the peer and/or `remote`.
    pub fn bind(
        listen: SocketAddr,
        remote: Option<SocketAddr>,
        reply: Reply,
        input: &'static str,
        output: &'static str,
    ) -> Result<Self, UdpError> {
        let err = |source| UdpError {
            addr: listen,
            source,
        };
        let socket = UdpSocket::bind(listen).map_err(err)?;
        // Reads never wait: `wait` waits in ppoll, then drains.
        socket.set_nonblocking(true).map_err(err)?;
        let local = socket.local_addr().map_err(err)?;
        Ok(Self {
            socket,
            local,
            peer: None,
            remote,
            reply,
            topics: [input, output, input],
            buf: vec![0; DATAGRAM_MAX],
            stats: UdpStats::default(),
            wake: Vec::new(),
            foreign: None,
        })
    }

    /// Hands datagrams from a foreign address over on `topic` (their bytes, for
    /// counting: a stage must not act on them) instead of dropping them silently.
    pub fn with_foreign_topic(mut self, topic: &'static str) -> Self {
        self.foreign = Some(topic);
        self.topics[2] = topic;
        self
    }

    /// The bound address (the port, when 0 was asked for).
    pub fn local_addr(&self) -> SocketAddr {
        self.local
    }

    /// The peer last heard from.
    pub fn peer(&self) -> Option<SocketAddr> {
        self.peer
    }

    /// What went over the link.
    pub fn stats(&self) -> UdpStats {
        UdpStats {
            kernel_drops: self.kernel_drops(),
            ..self.stats
        }
    }

    /// The socket's drop count (SO_MEMINFO's SK_MEMINFO_DROPS): datagrams that found
    /// its receive buffer full. 0 when the kernel does not say.
    fn kernel_drops(&self) -> u64 {
        use std::os::fd::AsRawFd;
        /// SO_MEMINFO (asm-generic/socket.h; the libc crate lacks it).
        const SO_MEMINFO: libc::c_int = 55;
        let mut info = [0u32; libc::SK_MEMINFO_DROPS as usize + 1];
        let mut len = std::mem::size_of_val(&info) as libc::socklen_t;
        // SAFETY: the socket is open while `self` lives; `info` is writable for `len`
        // bytes, and the kernel writes at most `len` bytes and says how many in `len`.
        let rc = unsafe {
            libc::getsockopt(
                self.socket.as_raw_fd(),
                libc::SOL_SOCKET,
                SO_MEMINFO,
                info.as_mut_ptr().cast(),
                &mut len,
            )
        };
        if rc != 0 || (len as usize) < std::mem::size_of_val(&info) {
            return 0;
        }
        u64::from(info[libc::SK_MEMINFO_DROPS as usize])
    }

    fn send_to(&mut self, to: SocketAddr, frame: &[u8]) {
        match self.socket.send_to(frame, to) {
            Ok(_) => self.stats.datagrams_out += 1,
            Err(e) => {
                self.stats.io_errors += 1;
                tracing::trace!(%to, error = %e, "UDP send failed");
            }
        }
    }
}

impl External for UdpLink {
    fn topics(&self) -> &[&'static str] {
        let n = if self.foreign.is_some() { 3 } else { 2 };
        self.topics.get(..n).unwrap_or(&[])
    }

    fn wait(
        &mut self,
        timeout_ns: u64,
        clock: &dyn Fn() -> u64,
        deliver: &mut dyn FnMut(Input<'_>, u64) -> Result<(), StageError>,
    ) -> Result<Flow, StageError> {
        // One wait, in ppoll (the kernel's timer precision), on the socket and on
        // whatever else may end it; then every datagram already there, without waiting.
        // (A socket read timeout would not do for the drain: the kernel rounds it up to
        // a jiffy, 4-10 ms, during which a setpoint arriving on another input waited.)
        use std::os::fd::AsRawFd;
        let mut fds = Vec::with_capacity(self.wake.len() + 1);
        fds.push(self.socket.as_raw_fd());
        fds.extend_from_slice(&self.wake);
        let ready = crate::ipc::wait_fds(&fds, timeout_ns);
        if !ready.first().copied().unwrap_or(false) {
            return Ok(Flow::Open);
        }
        loop {
            match self.socket.recv_from(&mut self.buf) {
                Ok((n, from)) => {
                    self.stats.datagrams_in += 1;
                    if self.reply == Reply::OnlyRemote && self.remote != Some(from) {
                        self.stats.foreign_datagrams += 1;
                        if let Some(topic) = self.foreign {
                            let input = Input {
                                topic,
                                msg: Message::Mavlink(self.buf.get(..n).unwrap_or(&[])),
                            };
                            deliver(input, clock())?;
                        }
                        continue;
                    }
                    self.peer = Some(from);
                    let input = Input {
                        topic: self.topics[0],
                        msg: Message::Mavlink(self.buf.get(..n).unwrap_or(&[])),
                    };
                    deliver(input, clock())?;
                }
                Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                    return Ok(Flow::Open);
                }
                // A signal (the stop) or an ICMP "port unreachable" from an earlier send
                // (the other end is not up yet): the driver looks at its flag, the link
                // goes on.
                Err(e) if e.kind() == ErrorKind::Interrupted => return Ok(Flow::Open),
                Err(e) => {
                    self.stats.io_errors += 1;
                    tracing::trace!(error = %e, "UDP receive failed");
                    return Ok(Flow::Open);
                }
            }
        }
    }

    fn wake_on(&mut self, fds: &[i32]) {
        self.wake = fds.to_vec();
    }

    fn finish(&mut self) {
        // Non-blocking reads until the queue is empty; a socket that cannot be made
        // non-blocking is left as it is (its count stays 0).
        if self.socket.set_nonblocking(true).is_err() {
            return;
        }
        while self.socket.recv_from(&mut self.buf).is_ok() {
            self.stats.unread_at_stop += 1;
        }
    }

    fn send(&mut self, _topic: &str, msg: Message<'_>) -> Result<(), StageError> {
        let Message::Mavlink(frame) = msg else {
            return Err(StageError::WrongType {
                topic: self.topics[1].to_string(),
                expected: "MAVLink bytes",
                got: msg.payload().type_name(),
            });
        };
        match (self.reply, self.peer, self.remote) {
            (Reply::OnlyRemote, _, Some(to)) => self.send_to(to, frame),
            (Reply::PeerAndRemote, peer, remote) => {
                if let Some(to) = peer {
                    self.send_to(to, frame);
                }
                if let Some(to) = remote.filter(|r| Some(*r) != peer) {
                    self.send_to(to, frame);
                }
            }
            (Reply::OnlyRemote, _, None) => {}
        }
        Ok(())
    }

    fn counters(&self) -> Vec<Counter> {
        vec![
            ("datagrams_in", self.stats.datagrams_in),
            ("datagrams_out", self.stats.datagrams_out),
            ("io_errors", self.stats.io_errors),
            ("foreign_datagrams", self.stats.foreign_datagrams),
            ("kernel_drops", self.kernel_drops()),
            ("unread_at_stop", self.stats.unread_at_stop),
        ]
    }
}
