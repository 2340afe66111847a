//! A listening TCP link as the iceoryx2 driver's [`External`] I/O: PX4 SITL connects to
//! its simulator as a TCP client (port 4560 + instance) and the simulator listens. Bytes
//! that arrive are inputs on the `input` topic (chunks of a stream: frames may span
//! them); each output on the `output` topic is written whole to the connected peer. One
//! peer at a time: a new connection replaces the old one (PX4 restarted).

use std::io::{ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::os::fd::AsRawFd;
use std::time::Duration;

use stage::{Counter, External, Flow, Input, Message, StageError};

/// The largest read at once.
const READ_MAX: usize = 65_536;

/// How long a write may block before the peer counts as gone: PX4 in lockstep reads
/// every step, so a full socket means it stopped.
const WRITE_TIMEOUT: Duration = Duration::from_millis(500);

/// Why the link could not be opened.
#[derive(Debug, thiserror::Error)]
#[error("TCP {addr}: {source}")]
pub struct TcpError {
    /// The address involved.
    pub addr: SocketAddr,
    /// What the socket said.
    pub source: std::io::Error,
}

/// What went over the link.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TcpStats {
    /// Peers accepted.
    pub connections: u64,
    /// Peers that closed or failed.
    pub disconnects: u64,
    /// Bytes received.
    pub bytes_in: u64,
    /// Bytes sent.
    pub bytes_out: u64,
    /// Outputs dropped because no peer was connected.
    pub unsent: u64,
}

/// A listening socket, its one peer and its topics.
#[derive(Debug)]
pub struct TcpServerLink {
    listener: TcpListener,
    local: SocketAddr,
    stream: Option<TcpStream>,
    /// The input and output topics.
    topics: [&'static str; 2],
    buf: Vec<u8>,
    stats: TcpStats,
    /// Descriptors that end a wait early (the stage's iceoryx2 inputs).
    wake: Vec<i32>,
    /// What a wait polls, reused (a wait every tick).
    fds: Vec<i32>,
}

impl TcpServerLink {
    /// Listens on `listen`; what a peer sends is `input`, `output` goes to the peer.
    pub fn bind(
        listen: SocketAddr,
        input: &'static str,
        output: &'static str,
    ) -> Result<Self, TcpError> {
        let err = |source| TcpError {
            addr: listen,
            source,
        };
        let listener = TcpListener::bind(listen).map_err(err)?;
        listener.set_nonblocking(true).map_err(err)?;
        let local = listener.local_addr().map_err(err)?;
        tracing::info!(%local, "TCP link listening for its peer");
        Ok(Self {
            listener,
            local,
            stream: None,
            topics: [input, output],
            buf: vec![0; READ_MAX],
            stats: TcpStats::default(),
            wake: Vec::new(),
            fds: Vec::new(),
        })
    }

    /// The bound address (the port, when 0 was asked for).
    pub fn local_addr(&self) -> SocketAddr {
        self.local
    }

    /// What went over the link.
    pub fn stats(&self) -> TcpStats {
        self.stats
    }

    fn accept(&mut self) {
        match self.listener.accept() {
            Ok((stream, from)) => {
                // Reads happen only after poll says readable; writes block at most
                // WRITE_TIMEOUT. Lockstep messages are small: no Nagle delay.
                let ok = stream.set_nonblocking(false).is_ok()
                    && stream.set_nodelay(true).is_ok()
                    && stream.set_write_timeout(Some(WRITE_TIMEOUT)).is_ok();
                if !ok {
                    return;
                }
                if self.stream.is_some() {
                    self.stats.disconnects += 1;
                }
                tracing::info!(%from, "simulator peer connected");
                self.stats.connections += 1;
                self.stream = Some(stream);
            }
            Err(e) if e.kind() == ErrorKind::WouldBlock => {}
            Err(e) => tracing::debug!(error = %e, "TCP accept failed"),
        }
    }

    fn drop_peer(&mut self, why: &str) {
        if self.stream.take().is_some() {
            self.stats.disconnects += 1;
            tracing::warn!(why, "simulator peer gone");
        }
    }
}

impl External for TcpServerLink {
    fn topics(&self) -> &[&'static str] {
        &self.topics
    }

    fn wait(
        &mut self,
        timeout_ns: u64,
        clock: &dyn Fn() -> u64,
        deliver: &mut dyn FnMut(Input<'_>, u64) -> Result<(), StageError>,
    ) -> Result<Flow, StageError> {
        // The listener, the peer (when there is one at the start of the wait: one accepted
        // below is read on the next), then the stage's wake descriptors.
        let peer = self.stream.as_ref().map(|s| s.as_raw_fd());
        self.fds.clear();
        self.fds.push(self.listener.as_raw_fd());
        self.fds.extend(peer);
        self.fds.extend_from_slice(&self.wake);
        let ready = crate::ipc::wait_fds(&self.fds, timeout_ns);
        if ready.first().copied().unwrap_or(false) {
            self.accept();
        }
        let readable = peer.is_some() && ready.get(1) == Some(&true);
        // Not the peer polled if `accept` replaced it.
        let Some(stream) = self
            .stream
            .as_mut()
            .filter(|s| readable && Some(s.as_raw_fd()) == peer)
        else {
            return Ok(Flow::Open);
        };
        match stream.read(&mut self.buf) {
            Ok(0) => self.drop_peer("closed"),
            Ok(n) => {
                self.stats.bytes_in += n as u64;
                let input = Input {
                    topic: self.topics[0],
                    msg: Message::Mavlink(self.buf.get(..n).unwrap_or(&[])),
                };
                deliver(input, clock())?;
            }
            Err(e) if matches!(e.kind(), ErrorKind::Interrupted | ErrorKind::WouldBlock) => {}
            Err(e) => self.drop_peer(&e.to_string()),
        }
        Ok(Flow::Open)
    }

    fn wake_on(&mut self, fds: &[i32]) {
        self.wake = fds.to_vec();
    }

    fn send(&mut self, _topic: &str, msg: Message<'_>) -> Result<(), StageError> {
        let Message::Mavlink(bytes) = msg else {
            return Err(StageError::WrongType {
                topic: self.topics[1].to_string(),
                expected: "MAVLink bytes",
                got: msg.payload().type_name(),
            });
        };
        let Some(stream) = self.stream.as_mut() else {
            self.stats.unsent += 1;
            return Ok(());
        };
        match stream.write_all(bytes) {
            Ok(()) => self.stats.bytes_out += bytes.len() as u64,
            Err(e) => self.drop_peer(&e.to_string()),
        }
        Ok(())
    }

    fn counters(&self) -> Vec<Counter> {
        vec![
            ("connections", self.stats.connections),
            ("disconnects", self.stats.disconnects),
            ("bytes_in", self.stats.bytes_in),
            ("bytes_out", self.stats.bytes_out),
            ("unsent", self.stats.unsent),
        ]
    }
}
