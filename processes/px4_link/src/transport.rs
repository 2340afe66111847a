//! The autopilot's end of px4-link: a UDP socket or a serial port, as the iceoryx2
//! driver's [`External`] I/O. It delivers what the autopilot sent as `mavlink/from-px4`
//! (one datagram, or one chunk of the serial byte stream) and writes `mavlink/to-px4`;
//! everything those bytes mean is `px4_link::LinkStage`'s.

use std::io::ErrorKind;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{Context, Result};
use ipc_types::topics;
use px4_link::Framing;
use px4_link::config::LinkAddress;
use runtime::{Reply, UdpLink, monotonic_ns};
use stage::{Counter, External, Flow, Input, Message, StageError};

use crate::serial_port::{Readiness, SerialPort};

/// The longest wait for the autopilot in one call: the loop's period when it is quiet
/// (the driver asks for less when a tick or a beat is due sooner).
const RECV_TIMEOUT: Duration = Duration::from_millis(2);
/// How long a write may wait for room in a full serial output buffer.
const WRITE_STALL: Duration = Duration::from_millis(5);
/// How often a serial port that failed is reopened (a USB adapter unplugged and back).
const REOPEN_PERIOD_NS: u64 = 1_000_000_000;

/// Where MAVLink frames go and come from.
pub enum Transport {
    /// Datagrams (runtime's UDP link), to and from the configured autopilot address
    /// only.
    Udp(UdpLink),
    /// A byte stream; `port` is `None` while it is being reopened after a failure.
    Serial {
        /// The device.
        path: PathBuf,
        /// Its speed.
        baud: u32,
        /// The open port.
        port: Option<SerialPort>,
        /// When it last failed.
        failed_at_ns: u64,
        /// The read buffer.
        buf: Vec<u8>,
    },
}

impl Transport {
    /// Opens `address`; `remote` is the autopilot's UDP address: where datagrams go, and
    /// the only one they are taken from.
    pub fn open(address: &LinkAddress, remote: SocketAddr) -> Result<Self> {
        Ok(match address {
            LinkAddress::Udp(listen) => Self::Udp(
                UdpLink::bind(
                    *listen,
                    Some(remote),
                    Reply::OnlyRemote,
                    topics::MAVLINK_FROM_PX4,
                    topics::MAVLINK_TO_PX4,
                )?
                .with_foreign_topic(topics::MAVLINK_FOREIGN),
            ),
            LinkAddress::Serial { path, baud } => Self::Serial {
                path: path.clone(),
                baud: *baud,
                port: Some(open_serial(path, *baud)?),
                failed_at_ns: 0,
                buf: vec![0; 4096],
            },
        })
    }

    /// How the stage must frame what this delivers.
    pub fn framing(&self) -> Framing {
        match self {
            Self::Udp(_) => Framing::Datagram,
            Self::Serial { .. } => Framing::Stream,
        }
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

/// What the autopilot sent, as the stage's input.
fn from_px4(bytes: &[u8]) -> Input<'_> {
    Input {
        topic: topics::MAVLINK_FROM_PX4,
        msg: Message::Mavlink(bytes),
    }
}

impl External for Transport {
    fn topics(&self) -> &[&'static str] {
        &[topics::MAVLINK_FROM_PX4, topics::MAVLINK_TO_PX4]
    }

    fn counters(&self) -> Vec<Counter> {
        match self {
            Self::Udp(link) => link.counters(),
            Self::Serial { .. } => Vec::new(),
        }
    }

    fn wake_on(&mut self, fds: &[i32]) {
        if let Self::Udp(link) = self {
            link.wake_on(fds);
        }
    }

    fn wait(
        &mut self,
        timeout_ns: u64,
        clock: &dyn Fn() -> u64,
        deliver: &mut dyn FnMut(Input<'_>, u64) -> Result<(), StageError>,
    ) -> Result<Flow, StageError> {
        let timeout = Duration::from_nanos(timeout_ns)
            .min(RECV_TIMEOUT)
            .max(Duration::from_micros(1));
        match self {
            Self::Udp(link) => return link.wait(timeout_ns, clock, deliver),
            Self::Serial {
                path,
                baud,
                port,
                failed_at_ns,
                buf,
            } => {
                let Some(p) = port else {
                    std::thread::sleep(timeout);
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
                    return Ok(Flow::Open);
                };
                let failure = match p.wait_readable(timeout) {
                    Ok(Readiness::Nothing) => None,
                    Ok(Readiness::HungUp) => Some("hung up".to_string()),
                    Ok(Readiness::Readable) => loop {
                        match p.read(buf) {
                            Ok(0) => break None,
                            Ok(n) => deliver(from_px4(buf.get(..n).unwrap_or(&[])), clock())?,
                            Err(e) if e.kind() == ErrorKind::WouldBlock => break None,
                            Err(e) if e.kind() == ErrorKind::Interrupted => {}
                            Err(e) => break Some(e.to_string()),
                        }
                    },
                    Err(e) if e.kind() == ErrorKind::Interrupted => None,
                    Err(e) => Some(e.to_string()),
                };
                if let Some(why) = failure {
                    tracing::warn!(path = %path.display(), %why, "serial port failed; reopening every second");
                    *port = None;
                    *failed_at_ns = monotonic_ns();
                }
            }
        }
        Ok(Flow::Open)
    }

    fn send(&mut self, topic: &str, msg: Message<'_>) -> Result<(), StageError> {
        let Message::Mavlink(frame) = msg else {
            return Err(StageError::WrongType {
                topic: topics::MAVLINK_TO_PX4.to_string(),
                expected: "MAVLink bytes",
                got: msg.payload().type_name(),
            });
        };
        // A lost datagram or a failed write is the link's business (PX4 times out,
        // px4-link resends commands), never the process's end.
        match self {
            Self::Udp(link) => return link.send(topic, msg),
            Self::Serial { port: Some(p), .. } => {
                if let Err(e) = p.write_all(frame, WRITE_STALL) {
                    tracing::debug!(error = %e, "serial write failed");
                }
            }
            Self::Serial { port: None, .. } => {}
        }
        Ok(())
    }
}
