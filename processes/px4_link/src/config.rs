//! The `[px4_link]` section of the stack configuration.

use std::net::SocketAddr;
use std::path::PathBuf;

use serde::Deserialize;

use crate::link::SetpointBounds;
use stack_config::{Invalid, Validate, check_range};

use crate::LinkSettings;

/// Where the autopilot is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LinkAddress {
    /// UDP: listen here; answer whoever the autopilot's datagrams come from.
    Udp(SocketAddr),
    /// A serial port (a Pixhawk TELEM port on a companion UART), raw 8N1 at this baud
    /// rate, no flow control.
    Serial {
        /// The device, e.g. `/dev/ttyTHS1`.
        path: PathBuf,
        /// Bits per second, one of [`SERIAL_SPEEDS`].
        baud: u32,
    },
}

/// Baud rates a serial link may use, with their termios speeds: the standard rates
/// PX4's `SER_TELx_BAUD` also offers, plus the higher ones companion UARTs run at. One
/// table, so the accepted rates and the rates the port can be set to cannot drift apart.
pub const SERIAL_SPEEDS: &[(u32, libc::speed_t)] = &[
    (9_600, libc::B9600),
    (19_200, libc::B19200),
    (38_400, libc::B38400),
    (57_600, libc::B57600),
    (115_200, libc::B115200),
    (230_400, libc::B230400),
    (460_800, libc::B460800),
    (500_000, libc::B500000),
    (921_600, libc::B921600),
    (1_000_000, libc::B1000000),
    (1_500_000, libc::B1500000),
    (2_000_000, libc::B2000000),
    (3_000_000, libc::B3000000),
];

/// The termios speed for `baud`, when it is one of [`SERIAL_SPEEDS`].
pub fn serial_speed(baud: u32) -> Option<libc::speed_t> {
    SERIAL_SPEEDS
        .iter()
        .find(|(b, _)| *b == baud)
        .map(|&(_, speed)| speed)
}

/// What px4-link reads from `landing.toml`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Px4LinkConfig {
    /// `udp:HOST:PORT` to listen on (PX4 SITL and the simulator send to 14540), or
    /// `serial:DEVICE:BAUD` (a Pixhawk on a companion UART, e.g. `serial:/dev/ttyTHS1:921600`).
    pub link: String,
    /// Where to send before the autopilot has been heard (the simulator and PX4 SITL
    /// listen on 14580); unused on a serial link.
    pub remote: String,
    /// Setpoint stream rate, Hz (PX4 needs more than 2 Hz).
    pub setpoint_rate_hz: f64,
    /// A new setpoint from the fsm goes out at once rather than at the stream's next
    /// period (up to 1 / setpoint_rate_hz later); the newest is repeated every period.
    /// On by default: camera -> wire p99 under 10 ms (docs/recording.md).
    pub new_setpoints_at_once: bool,
    /// Wait this long for a COMMAND_ACK before resending, ms.
    pub command_timeout_ms: u64,
    /// Sends of one command before it counts as timed out.
    pub command_attempts: u32,
    /// The autopilot counts as disconnected without a heartbeat this long, ms. PX4 beats
    /// at 1 Hz over a link that loses datagrams: the default lets two in a row go
    /// missing (a 5000-datagram flood at px4-link's port made the kernel drop one, and
    /// 1.5 s turned that into a safe landing). Silence is found sooner anyway: the
    /// watchdog, from the telemetry stream (`[watchdog.ride_through] telemetry_ms`).
    pub heartbeat_timeout_ms: u64,
    /// Setpoints asking more horizontal speed than this are refused, m/s.
    pub max_horizontal_speed_m_s: f64,
    /// Setpoints asking more vertical speed than this are refused, m/s.
    pub max_vertical_speed_m_s: f64,
    /// Setpoints asking more acceleration than this are refused, m/s^2.
    pub max_acceleration_m_s2: f64,
    /// Position setpoints farther than this from the take-off point are refused, m.
    pub geofence_radius_m: f64,
    /// Position setpoints higher than this above the take-off point are refused, m.
    pub geofence_height_m: f64,
    /// MAVLink 2 signing key file (32 raw bytes or 64 hex digits, owner-only
    /// permissions), relative to this config file; empty: the link is not signed.
    /// Install the same key on the autopilot with `landing link setup-signing`.
    pub signing_key: String,
    /// Forward `vio/odometry` to the autopilot as MAVLink ODOMETRY (a GPS-denied PX4 that
    /// fuses vision: `EKF2_EV_CTRL`, docs/px4-sitl.md). Off: the autopilot has its own
    /// estimate (the built-in simulator's, or PX4 with another source).
    pub forward_vio: bool,
}

impl Default for Px4LinkConfig {
    fn default() -> Self {
        Self {
            link: "udp:127.0.0.1:14540".into(),
            remote: "127.0.0.1:14580".into(),
            setpoint_rate_hz: 25.0,
            new_setpoints_at_once: true,
            command_timeout_ms: 500,
            command_attempts: 4,
            heartbeat_timeout_ms: 3500,
            max_horizontal_speed_m_s: SetpointBounds::default().max_horizontal_speed_m_s,
            max_vertical_speed_m_s: SetpointBounds::default().max_vertical_speed_m_s,
            max_acceleration_m_s2: SetpointBounds::default().max_acceleration_m_s2,
            geofence_radius_m: SetpointBounds::default().geofence_radius_m,
            geofence_height_m: SetpointBounds::default().geofence_height_m,
            signing_key: String::new(),
            forward_vio: false,
        }
    }
}

/// What the `px4-link` command line may override in `[px4_link]`.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct Px4LinkFlags {
    /// Link to open, overriding the config: udp:HOST:PORT to listen on, or
    /// serial:DEVICE:BAUD (e.g. serial:/dev/ttyTHS1:921600).
    #[arg(long)]
    pub link: Option<String>,
    /// Where to send before the autopilot is heard, HOST:PORT (UDP only).
    #[arg(long)]
    pub remote: Option<String>,
    /// Forward vio/odometry to the autopilot as ODOMETRY, whatever the config says
    /// (`landing run --autopilot px4-sitl` sets it: PX4 flies on the VIO).
    #[arg(long)]
    pub forward_vio: bool,
}

impl Px4LinkFlags {
    /// `cfg` with the flags applied, checked.
    pub fn apply(&self, mut cfg: Px4LinkConfig) -> Result<Px4LinkConfig, Invalid> {
        if let Some(l) = &self.link {
            cfg.link = l.clone();
        }
        if let Some(r) = &self.remote {
            cfg.remote = r.clone();
        }
        cfg.forward_vio |= self.forward_vio;
        cfg.validate()
            .map_err(|e| Invalid::new(e.key, format!("--link/--remote: {}", e.message)))?;
        Ok(cfg)
    }
}

/// Links this build can open.
pub const ALLOWED_LINKS: &str = "udp:HOST:PORT or serial:DEVICE:BAUD";

impl Px4LinkConfig {
    /// The link address, or what is wrong with it.
    pub fn address(&self) -> Result<LinkAddress, Invalid> {
        match self.link.split_once(':') {
            Some(("udp", addr)) => addr.parse().map(LinkAddress::Udp).map_err(|_| {
                Invalid::new(
                    "link",
                    format!("`{}`: not HOST:PORT (allowed: {ALLOWED_LINKS})", self.link),
                )
            }),
            Some(("serial", rest)) => {
                let bauds = || {
                    SERIAL_SPEEDS
                        .iter()
                        .map(|(b, _)| b.to_string())
                        .collect::<Vec<_>>()
                        .join(", ")
                };
                let Some((path, baud)) = rest.rsplit_once(':').filter(|(p, _)| p.starts_with('/'))
                else {
                    return Err(Invalid::new(
                        "link",
                        format!(
                            "`{}`: not serial:DEVICE:BAUD with an absolute device path (allowed: {ALLOWED_LINKS})",
                            self.link
                        ),
                    ));
                };
                match baud.parse::<u32>() {
                    Ok(b) if serial_speed(b).is_some() => Ok(LinkAddress::Serial {
                        path: PathBuf::from(path),
                        baud: b,
                    }),
                    _ => Err(Invalid::new(
                        "link",
                        format!(
                            "`{}`: baud rate `{baud}` is not allowed (allowed: {})",
                            self.link,
                            bauds()
                        ),
                    )),
                }
            }
            _ => Err(Invalid::new(
                "link",
                format!("`{}` is not allowed (allowed: {ALLOWED_LINKS})", self.link),
            )),
        }
    }

    /// The signing key file, resolved against `config_dir` (the config file's
    /// directory); `None` when the link is not signed.
    pub fn signing_key_path(&self, config_dir: &std::path::Path) -> Option<PathBuf> {
        (!self.signing_key.is_empty())
            .then(|| stack_config::resolve_path(config_dir, &self.signing_key))
    }

    /// The autopilot's address: where datagrams go and the only one they are taken from.
    pub fn remote_address(&self) -> Result<SocketAddr, Invalid> {
        self.remote
            .parse()
            .map_err(|_| Invalid::new("remote", format!("`{}`: not HOST:PORT", self.remote)))
    }

    /// The link settings these values give.
    pub fn settings(&self) -> LinkSettings {
        LinkSettings {
            setpoint_period_ns: (1e9 / self.setpoint_rate_hz.max(1.0)) as u64,
            new_setpoints_at_once: self.new_setpoints_at_once,
            command_timeout_ns: self.command_timeout_ms * 1_000_000,
            command_attempts: self.command_attempts,
            heartbeat_timeout_ns: self.heartbeat_timeout_ms * 1_000_000,
            bounds: SetpointBounds {
                max_horizontal_speed_m_s: self.max_horizontal_speed_m_s,
                max_vertical_speed_m_s: self.max_vertical_speed_m_s,
                max_acceleration_m_s2: self.max_acceleration_m_s2,
                geofence_radius_m: self.geofence_radius_m,
                geofence_height_m: self.geofence_height_m,
            },
            forward_vio: self.forward_vio,
            ..LinkSettings::default()
        }
    }
}

impl Validate for Px4LinkConfig {
    fn validate(&self) -> Result<(), Invalid> {
        self.address()?;
        self.remote_address()?;
        check_range("setpoint_rate_hz", self.setpoint_rate_hz, 5.0, 200.0)?;
        check_range("command_timeout_ms", self.command_timeout_ms, 50, 10_000)?;
        check_range("command_attempts", self.command_attempts, 1, 20)?;
        check_range(
            "heartbeat_timeout_ms",
            self.heartbeat_timeout_ms,
            300,
            60_000,
        )?;
        check_range(
            "max_horizontal_speed_m_s",
            self.max_horizontal_speed_m_s,
            0.5,
            60.0,
        )?;
        check_range(
            "max_vertical_speed_m_s",
            self.max_vertical_speed_m_s,
            0.2,
            20.0,
        )?;
        check_range(
            "max_acceleration_m_s2",
            self.max_acceleration_m_s2,
            1.0,
            100.0,
        )?;
        check_range("geofence_radius_m", self.geofence_radius_m, 5.0, 10_000.0)?;
        check_range("geofence_height_m", self.geofence_height_m, 2.0, 1_000.0)
    }
}

#[cfg(test)]
#[path = "config_test.rs"]
mod tests;
