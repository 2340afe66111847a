//! systemd's notify protocol (sd_notify(3)), without libsystemd: `READY=1` once a process
//! runs, `WATCHDOG=1` with every heartbeat when its unit has `WatchdogSec=` (systemd then
//! restarts a process whose loop stops beating), `STOPPING=1` on the way out. Outside
//! systemd (`NOTIFY_SOCKET` unset) every call does nothing.

use std::os::unix::net::{SocketAddr, UnixDatagram};

/// The notify socket of this process's unit, if it has one.
#[derive(Debug)]
pub struct Notifier {
    link: Option<(UnixDatagram, SocketAddr)>,
    watchdog: bool,
}

impl Notifier {
    /// From `NOTIFY_SOCKET` (a path, or `@name` for an abstract socket) and
    /// `WATCHDOG_USEC` / `WATCHDOG_PID` (whether systemd watches this very process).
    pub fn from_env() -> Self {
        let link = std::env::var_os("NOTIFY_SOCKET").and_then(|s| {
            let s = s.to_string_lossy().into_owned();
            let addr = match s.strip_prefix('@') {
                Some(name) => {
                    use std::os::linux::net::SocketAddrExt;
                    SocketAddr::from_abstract_name(name.as_bytes()).ok()?
                }
                None => SocketAddr::from_pathname(&s).ok()?,
            };
            Some((UnixDatagram::unbound().ok()?, addr))
        });
        let ours = std::env::var("WATCHDOG_PID")
            .ok()
            .and_then(|p| p.parse::<u32>().ok())
            .is_none_or(|p| p == std::process::id());
        let watchdog = ours
            && std::env::var("WATCHDOG_USEC")
                .ok()
                .and_then(|u| u.parse::<u64>().ok())
                .is_some_and(|u| u > 0);
        Self { link, watchdog }
    }

    /// Whether a unit listens at all.
    pub fn active(&self) -> bool {
        self.link.is_some()
    }

    fn send(&self, state: &str) {
        if let Some((sock, addr)) = &self.link {
            // A lost notification is systemd's to time out on; nothing to do here.
            let _ = sock.send_to_addr(state.as_bytes(), addr);
        }
    }

    /// The process is up (its ports are open).
    pub fn ready(&self) {
        self.send("READY=1");
    }

    /// The process's loop is alive (systemd's watchdog).
    pub fn alive(&self) {
        if self.watchdog {
            self.send("WATCHDOG=1");
        }
    }

    /// The process is stopping.
    pub fn stopping(&self) {
        self.send("STOPPING=1");
    }
}
