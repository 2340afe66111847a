//! `landing doctor`: the preflight checks of a vehicle, one line each. The stack file;
//! the camera and the depth source it names, present and in the configured mode; the
//! autopilot answering on the link; the PX4 parameters the stack relies on, read over
//! MAVLink; the autopilot's clock against this computer's (TIMESYNC); the iceoryx2
//! prefix usable and clean; free disk for recordings.

use std::net::{SocketAddr, UdpSocket};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use mavlink::MavHeader;
use mavlink::dialects::common::{
    HEARTBEAT_DATA, MavAutopilot, MavMessage, MavModeFlag, MavParamType, MavState, MavType,
    PARAM_REQUEST_READ_DATA, TIMESYNC_DATA,
};
use px4_link::config::LinkAddress;
use px4_protocol::codec::{decode_datagram, encode};
use serde::Serialize;

use crate::config::StackConfig;

/// One check's outcome.
#[derive(Debug, Clone, Serialize)]
pub struct Check {
    /// What was checked (`link`, `param COM_OBL_RC_ACT`, `disk`, ...).
    pub name: String,
    /// Whether it passed.
    pub ok: bool,
    /// What was found; on a failure, what to change.
    pub detail: String,
}

impl Check {
    fn pass(name: &str, detail: impl Into<String>) -> Self {
        Self {
            name: name.to_string(),
            ok: true,
            detail: detail.into(),
        }
    }

    fn fail(name: &str, detail: impl Into<String>) -> Self {
        Self {
            name: name.to_string(),
            ok: false,
            detail: detail.into(),
        }
    }
}

/// What the checks need besides the stack file.
#[derive(Debug, Clone)]
pub struct DoctorOptions {
    /// Where recordings go.
    pub recordings: PathBuf,
    /// Least free space there, GB.
    pub min_free_gb: f64,
    /// How long to wait for the autopilot, each request.
    pub timeout: Duration,
    /// The iceoryx2 prefix of the stack.
    pub ipc_prefix: Option<String>,
}

/// A PX4 parameter the stack relies on and the values it accepts.
struct Expected {
    name: &'static str,
    ok: fn(f64) -> bool,
    want: &'static str,
    why: &'static str,
}

const EXPECTED: &[Expected] = &[
    Expected {
        name: "COM_OBL_RC_ACT",
        ok: |v| v == 4.0,
        want: "4 (Land)",
        why: "PX4 lands where it is when the stack's setpoints stop",
    },
    Expected {
        name: "COM_OF_LOSS_T",
        ok: |v| v > 0.0 && v <= 1.0,
        want: "at most 1 s",
        why: "the setpoints' loss is acted on within a second",
    },
    Expected {
        name: "EKF2_EV_CTRL",
        ok: |v| (v as i64) & 0b111 == 0b111,
        want: "15 (vision position, velocity and yaw)",
        why: "PX4's estimator fuses the stack's visual odometry",
    },
    Expected {
        name: "EKF2_HGT_REF",
        ok: |v| v == 3.0,
        want: "3 (Vision)",
        why: "height from vision, no GPS",
    },
    Expected {
        name: "MIS_TAKEOFF_ALT",
        ok: |v| (0.5..=10.0).contains(&v),
        want: "0.5 to 10 m",
        why: "a take-off the stack's search height can follow",
    },
];

/// Runs every check of `config_file`.
pub fn run(config_file: &Path, opts: &DoctorOptions) -> Vec<Check> {
    let mut checks = Vec::new();
    let cfg = match StackConfig::load(config_file) {
        Ok(c) => {
            checks.push(Check::pass(
                "config",
                format!("{} is valid", config_file.display()),
            ));
            c
        }
        Err(e) => {
            checks.push(Check::fail("config", format!("{e:#}")));
            return checks;
        }
    };
    checks.push(camera(&cfg));
    checks.push(depth(&cfg, config_file));
    checks.extend(autopilot(&cfg, opts));
    checks.push(ipc(&cfg, opts));
    checks.push(disk(opts));
    checks
}

fn camera(cfg: &StackConfig) -> Check {
    let source = cfg
        .camera_ingest
        .as_ref()
        .map_or_else(|| "sim".to_string(), |c| c.source.clone());
    let Some(device) = source.strip_prefix("v4l2:") else {
        return Check::pass(
            "camera",
            format!("[camera_ingest] source = \"{source}\" (no device to check)"),
        );
    };
    if !Path::new(device).exists() {
        return Check::fail(
            "camera",
            format!(
                "{device} not found: plug the camera in, or set [camera_ingest] source to the device it is"
            ),
        );
    }
    match std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(device)
    {
        Ok(_) => Check::pass("camera", format!("{device} present and opens")),
        Err(e) => Check::fail(
            "camera",
            format!(
                "{device}: {e}: add the landing user to the `video` group (or the unit's DeviceAllow=)"
            ),
        ),
    }
}

fn depth(cfg: &StackConfig, config_file: &Path) -> Check {
    if cfg.depth_map.input != depth_map::Input::DepthFrame {
        return Check::pass(
            "depth",
            "[depth_map] input = \"sim\" (the simulator's depth)",
        );
    }
    let Some(section) = cfg.depth_ingest.as_ref() else {
        return Check::fail(
            "depth",
            "[depth_map] input = \"depth-frame\" but no [depth_ingest] section: set its source",
        );
    };
    let dir = config_file.parent().unwrap_or(Path::new("."));
    let source = match depth_ingest::SourceFlags::default().resolve(section, dir) {
        Ok(s) => s,
        Err(e) => return Check::fail("depth", e),
    };
    let (w, h) = (cfg.depth_map.width, cfg.depth_map.height);
    let size = match &source.spec {
        depth_ingest::DepthSourceSpec::Bag(p)
        | depth_ingest::DepthSourceSpec::RealSense(depth_ingest::RealSenseTarget::Recording(p)) => {
            depth_ingest::RsBag::open(p)
                .map(|b| (b.info().width, b.info().height))
                .map_err(|e| e.to_string())
        }
        depth_ingest::DepthSourceSpec::V4l2(p) => {
            depth_ingest::V4l2Depth::open(p, source.mode, std::time::Duration::from_secs(1))
                .map(|d| d.size())
                .map_err(|e| e.to_string())
        }
        depth_ingest::DepthSourceSpec::RealSense(_) => realsense_on_usb()
            .map(|()| (source.mode[0], source.mode[1]))
            .map_err(|e| format!("{}: {e}", source.spec)),
        depth_ingest::DepthSourceSpec::File(d) => depth_ingest::PngDir::open(d)
            .and_then(|mut dir| {
                let mut image = depth_ingest::DepthImage::default();
                dir.next_image(&mut image)
                    .transpose()
                    .map(|_| (image.width, image.height))
            })
            .map_err(|e| e.to_string()),
    };
    match size {
        Ok(s) if s == (w, h) => {
            Check::pass("depth", format!("{}: {}x{} frames", source.spec, s.0, s.1))
        }
        Ok(s) => Check::fail(
            "depth",
            format!(
                "{} gives {}x{} frames but [depth_map] is {w}x{h}: set [depth_map] width and height to the stream's",
                source.spec, s.0, s.1
            ),
        ),
        Err(e) => Check::fail("depth", e),
    }
}

/// Intel's USB vendor id: every RealSense enumerates under it.
const INTEL_USB_VENDOR: &str = "8086";

/// Whether an Intel device is on the USB bus (sysfs), as a RealSense must be before
/// librealsense can open it. This build may lack librealsense: the doctor reads sysfs.
fn realsense_on_usb() -> Result<(), String> {
    let devices = std::fs::read_dir("/sys/bus/usb/devices")
        .map_err(|e| format!("cannot list USB devices (/sys/bus/usb/devices: {e})"))?;
    let found = devices.flatten().any(|d| {
        std::fs::read_to_string(d.path().join("idVendor"))
            .is_ok_and(|v| v.trim() == INTEL_USB_VENDOR)
    });
    if found {
        Ok(())
    } else {
        Err("no Intel RealSense on USB (no device of vendor 8086 in /sys/bus/usb/devices): plug it into a USB 3 port".into())
    }
}

/// The link, the parameters and the clock, over one UDP socket.
fn autopilot(cfg: &StackConfig, opts: &DoctorOptions) -> Vec<Check> {
    let link = match cfg.px4_link.address() {
        Ok(a) => a,
        Err(e) => {
            return vec![Check::fail(
                "link",
                format!("px4_link.{}: {}", e.key, e.message),
            )];
        }
    };
    let local = match link {
        LinkAddress::Udp(a) => a,
        LinkAddress::Serial { path: device, baud } => {
            // A live check over a serial port is not done yet: that it is there.
            return vec![match std::fs::metadata(&device) {
                Ok(_) => Check::pass(
                    "link",
                    format!(
                        "serial {} present ({baud} baud); the autopilot's answer over serial is not checked yet",
                        device.display()
                    ),
                ),
                Err(e) => Check::fail(
                    "link",
                    format!(
                        "serial {}: {e}: wire the autopilot's TELEM port, or set [px4_link] link",
                        device.display()
                    ),
                ),
            }];
        }
    };
    let remote: Option<SocketAddr> = cfg.px4_link.remote.parse().ok();
    let socket = match UdpSocket::bind(local) {
        Ok(s) => s,
        Err(e) => {
            return vec![Check::fail(
                "link",
                format!(
                    "udp {local}: {e}: is px4-link running (stop the stack first), or set [px4_link] link"
                ),
            )];
        }
    };
    let mut peer = Peer {
        socket,
        remote,
        seq: 0,
        from: None,
    };
    let started = Instant::now();
    let Some(hb) = peer.wait(opts.timeout, |m| matches!(m, MavMessage::HEARTBEAT(h) if h.autopilot != MavAutopilot::MAV_AUTOPILOT_INVALID)) else {
        return vec![Check::fail(
            "link",
            format!(
                "no heartbeat from an autopilot on udp {local} in {:.0} s (sending to {}): is PX4 running, and its MAVLink instance sending here?",
                opts.timeout.as_secs_f64(),
                remote.map_or_else(|| "nobody".into(), |r| r.to_string())
            ),
        )];
    };
    let mut checks = vec![Check::pass(
        "link",
        format!(
            "udp {local}: heartbeat of system {} component {} from {} in {} ms",
            hb.0.system_id,
            hb.0.component_id,
            peer.from.map_or_else(|| "?".into(), |a| a.to_string()),
            started.elapsed().as_millis()
        ),
    )];
    let target = (u8::try_from(hb.0.system_id).unwrap_or(1), hb.0.component_id);
    for e in EXPECTED {
        let name = format!("param {}", e.name);
        peer.send(&MavMessage::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA {
            param_index: -1,
            target_system: target.0,
            target_component: target.1,
            param_id: e.name.into(),
        }));
        let got = peer.wait(opts.timeout, |m| {
            matches!(m, MavMessage::PARAM_VALUE(v) if v.param_id.to_str().is_ok_and(|id| id == e.name))
        });
        let Some((_, MavMessage::PARAM_VALUE(v))) = got else {
            checks.push(Check::fail(
                &name,
                format!(
                    "the autopilot did not answer for {}: is it PX4 v1.14 or later?",
                    e.name
                ),
            ));
            continue;
        };
        let value = match v.param_type {
            MavParamType::MAV_PARAM_TYPE_INT32 => {
                f64::from(i32::from_ne_bytes(v.param_value.to_ne_bytes()))
            }
            _ => f64::from(v.param_value),
        };
        checks.push(if (e.ok)(value) {
            Check::pass(&name, format!("{value}"))
        } else {
            Check::fail(
                &name,
                format!("{} is {value}: set it to {} ({})", e.name, e.want, e.why),
            )
        });
    }
    checks.push(clock(&mut peer, target, opts.timeout));
    checks
}

/// The autopilot's clock: a TIMESYNC round trip, its time and the offset.
fn clock(peer: &mut Peer, target: (u8, u8), timeout: Duration) -> Check {
    let sent = runtime::monotonic_ns();
    peer.send(&MavMessage::TIMESYNC(TIMESYNC_DATA {
        tc1: 0,
        ts1: i64::try_from(sent).unwrap_or(i64::MAX),
        target_system: target.0,
        target_component: target.1,
    }));
    let got = peer.wait(timeout, |m| {
        matches!(m, MavMessage::TIMESYNC(t) if t.tc1 != 0 && u64::try_from(t.ts1).ok() == Some(sent))
    });
    let Some((_, MavMessage::TIMESYNC(t))) = got else {
        return Check::fail(
            "clock",
            "no TIMESYNC answer: the autopilot's time cannot be mapped onto this computer's (PX4 answers TIMESYNC on every MAVLink instance)",
        );
    };
    let now = runtime::monotonic_ns();
    let rtt_ms = now.saturating_sub(sent) as f64 * 1e-6;
    let offset_s = (t.tc1 as f64 - (sent as f64 + now as f64) / 2.0) * 1e-9;
    if rtt_ms > 50.0 {
        return Check::fail(
            "clock",
            format!(
                "TIMESYNC round trip {rtt_ms:.1} ms (at most 50): the link is too slow or loaded for the stack's timing"
            ),
        );
    }
    Check::pass(
        "clock",
        format!(
            "TIMESYNC round trip {rtt_ms:.2} ms; the autopilot's clock is {offset_s:+.3} s from this computer's"
        ),
    )
}

/// One MAVLink peer over UDP, as the doctor's own component.
struct Peer {
    socket: UdpSocket,
    remote: Option<SocketAddr>,
    seq: u8,
    from: Option<SocketAddr>,
}

/// The doctor's MAVLink identity: the companion's system, a component of its own.
const SYSTEM: u8 = 1;
const COMPONENT: u8 = 196;

impl Peer {
    fn send(&mut self, msg: &MavMessage) {
        let Some(to) = self.from.or(self.remote) else {
            return;
        };
        self.seq = self.seq.wrapping_add(1);
        let mut buf = Vec::new();
        let header = MavHeader {
            system_id: u32::from(SYSTEM),
            component_id: COMPONENT,
            sequence: self.seq,
        };
        if encode(&mut buf, header, msg).is_ok() {
            let _ = self.socket.send_to(&buf, to);
        }
    }

    /// Waits up to `timeout` for a message `wanted`, greeting the autopilot with a
    /// heartbeat every half second meanwhile.
    fn wait(
        &mut self,
        timeout: Duration,
        wanted: impl Fn(&MavMessage) -> bool,
    ) -> Option<(MavHeader, MavMessage)> {
        let end = Instant::now() + timeout;
        let mut next_hb = Instant::now();
        let mut buf = vec![0u8; 2048];
        let mut frames = Vec::new();
        while Instant::now() < end {
            if Instant::now() >= next_hb {
                next_hb += Duration::from_millis(500);
                self.send(&MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                    custom_mode: 0,
                    mavtype: MavType::MAV_TYPE_ONBOARD_CONTROLLER,
                    autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
                    base_mode: MavModeFlag::empty(),
                    system_status: MavState::MAV_STATE_ACTIVE,
                    mavlink_version: 3,
                }));
            }
            let _ = self
                .socket
                .set_read_timeout(Some(Duration::from_millis(50)));
            let Ok((n, from)) = self.socket.recv_from(&mut buf) else {
                continue;
            };
            frames.clear();
            decode_datagram(buf.get(..n).unwrap_or_default(), &mut frames);
            for (h, m) in frames.drain(..) {
                if matches!(m, MavMessage::HEARTBEAT(_)) && self.from.is_none() {
                    self.from = Some(from);
                }
                if wanted(&m) {
                    return Some((h, m));
                }
            }
        }
        None
    }
}

fn ipc(cfg: &StackConfig, opts: &DoctorOptions) -> Check {
    let prefix = match runtime::IpcPrefix::resolve(opts.ipc_prefix.as_deref(), &cfg.ipc.prefix) {
        Ok(p) => p,
        Err(e) => return Check::fail("ipc", e.to_string()),
    };
    match runtime::Ipc::open("landing-doctor", &prefix) {
        Ok(ipc) => {
            let dead = ipc
                .nodes()
                .map_or(0, |n| n.iter().filter(|n| !n.alive).count());
            if dead > 0 {
                Check::fail(
                    "ipc",
                    format!(
                        "{dead} dead processes of a stack left shared memory under `{}`: run `landing clean`",
                        prefix.as_str()
                    ),
                )
            } else {
                Check::pass(
                    "ipc",
                    format!(
                        "iceoryx2 under `{}`: a node opens, nothing stale",
                        prefix.as_str()
                    ),
                )
            }
        }
        Err(e) => Check::fail(
            "ipc",
            format!(
                "iceoryx2 under `{}`: {e}: run the stack as the user that owns /dev/shm/iox2_* and /tmp/iceoryx2 (the `landing` user)",
                prefix.as_str()
            ),
        ),
    }
}

fn disk(opts: &DoctorOptions) -> Check {
    let dir = &opts.recordings;
    let Ok(c) = std::ffi::CString::new(dir.to_string_lossy().as_bytes()) else {
        return Check::fail("disk", format!("{}: not a path", dir.display()));
    };
    // SAFETY: statvfs fills the zeroed struct from a NUL-terminated path it only reads.
    let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
    if unsafe { libc::statvfs(c.as_ptr(), &mut st) } != 0 {
        return Check::fail(
            "disk",
            format!(
                "{}: {}: create it, or give --recordings",
                dir.display(),
                std::io::Error::last_os_error()
            ),
        );
    }
    let free_gb = st.f_bavail as f64 * st.f_frsize as f64 / 1e9;
    if free_gb < opts.min_free_gb {
        Check::fail(
            "disk",
            format!(
                "{:.2} GB free under {} (at least {} GB for recordings: about 1 GB per 10 min with images): free space, or move --recordings",
                free_gb,
                dir.display(),
                opts.min_free_gb
            ),
        )
    } else {
        Check::pass(
            "disk",
            format!("{:.1} GB free under {}", free_gb, dir.display()),
        )
    }
}
