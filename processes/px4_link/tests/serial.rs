#![allow(clippy::unwrap_used, clippy::expect_used)]
//! The `px4-link` process on a serial link, for real: a pseudo-terminal pair stands in
//! for the UART, px4-link opens the slave side as `serial:PATH:921600`, and this test
//! runs the simulator's autopilot (`sim::lockstep::Simulator`, paced on the wall clock)
//! behind the master side, speaking MAVLink as a byte stream. Driven through iceoryx2 as
//! fsm would: vehicle states arrive, garbage on the line is counted and skipped, an arm
//! request is acked. And a wrong baud rate or a missing device is one line, exit 2.

mod common;

use std::ffi::CStr;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use ipc_types::msg::{Header, LinkOutcomeKind, LinkRequest, LinkRequestKind, VehicleState};
use landing_tests::process::Running;
use mavlink::MavHeader;
use px4_protocol::codec::{Guard, StreamDecoder, encode};
use runtime::IpcPrefix;
use sim::lockstep::{PHYSICS_STEP_NS, Simulator};

/// A pseudo-terminal pair: (master, slave, slave path). The slave is made raw here so
/// nothing the test writes before px4-link has configured it is echoed or translated.
fn pty() -> (OwnedFd, OwnedFd, PathBuf) {
    let (mut master, mut slave) = (-1, -1);
    // SAFETY: openpty writes two descriptors; the null name/termios/winsize are allowed.
    let r = unsafe {
        libc::openpty(
            &mut master,
            &mut slave,
            std::ptr::null_mut(),
            std::ptr::null(),
            std::ptr::null(),
        )
    };
    assert_eq!(r, 0, "openpty: {}", std::io::Error::last_os_error());
    // SAFETY: both descriptors were just opened and are owned by nobody else.
    let (master, slave) = unsafe { (OwnedFd::from_raw_fd(master), OwnedFd::from_raw_fd(slave)) };
    let mut name = [0 as libc::c_char; 128];
    // SAFETY: the buffer is as long as we say; the fd is a valid tty.
    let r = unsafe { libc::ttyname_r(slave.as_raw_fd(), name.as_mut_ptr(), name.len()) };
    assert_eq!(r, 0, "ttyname_r");
    // SAFETY: ttyname_r wrote a NUL-terminated string into `name`.
    let path = unsafe { CStr::from_ptr(name.as_ptr()) };
    let path = PathBuf::from(path.to_str().unwrap());
    // SAFETY: valid fds; termios is filled by tcgetattr before use.
    unsafe {
        let mut t: libc::termios = std::mem::zeroed();
        assert_eq!(libc::tcgetattr(slave.as_raw_fd(), &mut t), 0);
        libc::cfmakeraw(&mut t);
        assert_eq!(libc::tcsetattr(slave.as_raw_fd(), libc::TCSANOW, &t), 0);
        let flags = libc::fcntl(master.as_raw_fd(), libc::F_GETFL);
        assert_eq!(
            libc::fcntl(master.as_raw_fd(), libc::F_SETFL, flags | libc::O_NONBLOCK),
            0
        );
    }
    (master, slave, path)
}

fn read_some(fd: &OwnedFd, buf: &mut [u8]) -> usize {
    // SAFETY: `buf` is valid for `buf.len()` bytes.
    let n = unsafe { libc::read(fd.as_raw_fd(), buf.as_mut_ptr().cast(), buf.len()) };
    n.max(0) as usize
}

fn write_all(fd: &OwnedFd, mut data: &[u8]) {
    let end = Instant::now() + Duration::from_millis(100);
    while !data.is_empty() && Instant::now() < end {
        // SAFETY: `data` is valid for `data.len()` bytes.
        let n = unsafe { libc::write(fd.as_raw_fd(), data.as_ptr().cast(), data.len()) };
        if n > 0 {
            data = &data[n as usize..];
        } else {
            std::thread::sleep(Duration::from_micros(200));
        }
    }
}

/// The autopilot behind the master side of the pty, paced on the wall clock.
struct Autopilot {
    sim: Simulator,
    master: OwnedFd,
    decoder: StreamDecoder,
    start: Instant,
    seq: u8,
    buf: Vec<u8>,
    frame: Vec<u8>,
    /// Bytes of garbage to put on the line before the next frames.
    garbage: Vec<u8>,
}

impl Autopilot {
    fn new(master: OwnedFd) -> Self {
        let deploy = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../deploy");
        let scn = sim::scenario::load("indoor-static", &deploy).unwrap();
        Self {
            sim: Simulator::new(&scn, 1).unwrap(),
            master,
            decoder: StreamDecoder::new(),
            start: Instant::now(),
            seq: 0,
            buf: vec![0; 4096],
            frame: Vec::new(),
            garbage: Vec::new(),
        }
    }

    /// Catches simulated time up with the wall clock, exchanging bytes on the way.
    fn pump(&mut self) {
        let mut msgs = Vec::new();
        loop {
            let n = read_some(&self.master, &mut self.buf);
            if n == 0 {
                break;
            }
            self.decoder
                .push(&self.buf[..n], 0, &mut Guard::open(), &mut msgs);
        }
        for (h, m) in &msgs {
            self.sim.handle_mavlink(h, m);
        }
        let target = self.start.elapsed().as_nanos() as u64;
        while self.sim.time_ns() + PHYSICS_STEP_NS <= target {
            self.sim.step().unwrap();
            let mut bytes = std::mem::take(&mut self.garbage);
            for m in self.sim.take_mavlink() {
                self.frame.clear();
                let h = MavHeader {
                    system_id: 1,
                    component_id: 1,
                    sequence: self.seq,
                };
                self.seq = self.seq.wrapping_add(1);
                encode(&mut self.frame, h, &m).unwrap();
                bytes.extend_from_slice(&self.frame);
            }
            write_all(&self.master, &bytes);
        }
    }
}

#[test]
fn px4_link_on_a_serial_line_reports_the_vehicle_and_gets_an_arm_acked() {
    let (master, _slave, path) = pty();
    let prefix = IpcPrefix::unique("px4serial");
    let mut link = Running::start(
        "px4-link",
        Command::new(env!("CARGO_BIN_EXE_px4-link"))
            .args(["--link", &format!("serial:{}:921600", path.display())])
            .args(["--ipc-prefix", prefix.as_str()])
            .env("LANDING_LOG", "warn"),
    );
    let common::FsmSide {
        ipc: _ipc,
        states,
        outcomes,
        mut requests,
    } = common::fsm_side(&prefix);
    let mut ap = Autopilot::new(master);

    let mut latest: Option<VehicleState> = None;
    let count = std::cell::Cell::new(0u32);
    let poll = |ap: &mut Autopilot, latest: &mut Option<VehicleState>| {
        ap.pump();
        while let Ok(Some(s)) = states.receive() {
            *latest = Some(*s.payload());
            count.set(count.get() + 1);
        }
        std::thread::sleep(Duration::from_millis(1));
    };

    // Connected: heartbeats and telemetry crossed the line.
    let end = Instant::now() + Duration::from_secs(10);
    while latest.is_none_or(|s| s.link.connected == 0) {
        assert!(
            Instant::now() < end,
            "no connected vehicle state over serial"
        );
        poll(&mut ap, &mut latest);
    }
    let s = latest.unwrap();
    assert!(s.world_from_body.translation[2].abs() < 0.1, "{s:?}");
    assert_eq!(s.link.parse_errors, 0);

    // Noise on the line: skipped and counted, the link carries on.
    ap.garbage = b"\x00\xfd\x13\x37 line noise \xfe\xfe\x01".to_vec();
    let end = Instant::now() + Duration::from_secs(3);
    while latest.is_none_or(|s| s.link.parse_errors == 0) {
        assert!(Instant::now() < end, "garbage not counted");
        poll(&mut ap, &mut latest);
    }

    let r = LinkRequest {
        msg: Header::default(),
        id: 7,
        kind: LinkRequestKind::Arm as u32,
        reserved: 0,
        altitude_m: 0.0,
    };
    requests.send(r.msg, &r).unwrap();
    let end = Instant::now() + Duration::from_secs(5);
    let answer = loop {
        assert!(Instant::now() < end, "no outcome for the arm request");
        poll(&mut ap, &mut latest);
        if let Ok(Some(o)) = outcomes.receive() {
            break *o.payload();
        }
    };
    assert_eq!(answer.id, 7);
    assert_eq!(answer.outcome, LinkOutcomeKind::Accepted as u32);
    assert!(ap.sim.commander().armed());
    // The stream keeps coming at the telemetry rates (position 30 Hz, attitude 50 Hz).
    let before = count.get();
    let end = Instant::now() + Duration::from_millis(1500);
    while Instant::now() < end {
        poll(&mut ap, &mut latest);
    }
    let n = count.get() - before;
    eprintln!("vehicle states over serial: {n} in 1.5 s");
    assert!(n >= 45, "{n} states in 1.5 s");
    assert_eq!(latest.unwrap().link.connected, 1);
    assert_eq!(latest.unwrap().armed, 1, "armed, per the 1 Hz HEARTBEAT");

    link.request_stop();
    let end = Instant::now() + Duration::from_secs(3);
    let status = loop {
        if let Some(s) = link.exited() {
            break s;
        }
        assert!(Instant::now() < end, "px4-link ignored SIGTERM");
        ap.pump();
        std::thread::sleep(Duration::from_millis(10));
    };
    assert!(status.success(), "{status}");
}

fn refused(link: &str) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_px4-link"))
        .args(["--link", link])
        .args(["--ipc-prefix", IpcPrefix::unique("px4bad").as_str()])
        .env("LANDING_LOG", "warn")
        .stdout(Stdio::null())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2), "{link}: {:?}", out);
    let err = String::from_utf8(out.stderr).unwrap();
    assert_eq!(err.trim().lines().count(), 1, "{link}: one line: {err}");
    err
}

#[test]
fn a_serial_link_with_a_bad_baud_rate_or_no_device_is_one_line_and_exit_2() {
    let e = refused("serial:/dev/ttyS0:12345");
    assert!(e.contains("12345") && e.contains("921600"), "{e}");
    let e = refused("serial:/dev/tty-does-not-exist:921600");
    assert!(e.contains("/dev/tty-does-not-exist"), "{e}");
    assert!(e.contains("No such file"), "{e}");
    let e = refused("serial:/dev/null:921600");
    assert!(e.contains("not a serial port"), "{e}");
}
