//! A serial port opened raw (8N1, no flow control, no line discipline) at a baud rate,
//! non-blocking, for the `px4-link` binary.
//!
//! Opened with libc termios rather than the `mavlink` crate's `serial` feature: that
//! feature brings the `serialport` crate and its dependency tree (nix, and libudev on
//! Linux by default for port enumeration we do not need) and a blocking connection that
//! owns the port and hides parse errors; we need a non-blocking descriptor our own loop
//! polls, and our own stream decoder that counts errors. libc is already in the tree
//! (iceoryx2, the tests), and raw mode is a handful of well-known calls.

use std::fs::{File, OpenOptions};
use std::io::{self, ErrorKind, Read, Write};
use std::os::fd::AsRawFd;
use std::os::unix::fs::OpenOptionsExt;
use std::path::Path;
use std::time::Duration;

/// What waiting on the port found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Readiness {
    /// Nothing within the time-out.
    Nothing,
    /// Bytes to read.
    Readable,
    /// The device is gone (unplugged, or the other end of a pseudo-terminal closed).
    HungUp,
}

/// An open, configured serial port.
#[derive(Debug)]
pub struct SerialPort {
    file: File,
}

fn check(ret: libc::c_int) -> io::Result<()> {
    if ret < 0 {
        Err(io::Error::last_os_error())
    } else {
        Ok(())
    }
}

impl SerialPort {
    /// Opens `path` raw at `baud`, exclusively (a second px4-link on the same port would
    /// interleave frames), discarding whatever was waiting in the buffers.
    pub fn open(path: &Path, baud: u32) -> io::Result<Self> {
        let speed = px4_link::config::serial_speed(baud)
            .ok_or_else(|| io::Error::new(ErrorKind::InvalidInput, format!("baud rate {baud}")))?;
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .custom_flags(libc::O_NOCTTY | libc::O_NONBLOCK | libc::O_CLOEXEC)
            .open(path)?;
        let fd = file.as_raw_fd();
        // SAFETY: `fd` is open for the whole block; termios is plain data that tcgetattr
        // fills before anything reads it.
        unsafe {
            let mut t: libc::termios = std::mem::zeroed();
            if libc::tcgetattr(fd, &mut t) < 0 {
                let e = io::Error::last_os_error();
                return Err(io::Error::new(e.kind(), format!("not a serial port ({e})")));
            }
            libc::cfmakeraw(&mut t);
            t.c_cflag |= libc::CLOCAL | libc::CREAD;
            t.c_cflag &= !(libc::CRTSCTS | libc::CSTOPB);
            t.c_cc[libc::VMIN] = 0;
            t.c_cc[libc::VTIME] = 0;
            check(libc::cfsetispeed(&mut t, speed))?;
            check(libc::cfsetospeed(&mut t, speed))?;
            check(libc::tcsetattr(fd, libc::TCSANOW, &t))?;
            check(libc::ioctl(fd, libc::TIOCEXCL))?;
            check(libc::tcflush(fd, libc::TCIOFLUSH))?;
        }
        Ok(Self { file })
    }

    /// Waits until bytes can be read, at most `timeout`.
    pub fn wait_readable(&self, timeout: Duration) -> io::Result<Readiness> {
        let revents = self.wait(libc::POLLIN, timeout)?;
        Ok(if revents & libc::POLLIN != 0 {
            Readiness::Readable
        } else if revents & (libc::POLLHUP | libc::POLLERR | libc::POLLNVAL) != 0 {
            Readiness::HungUp
        } else {
            Readiness::Nothing
        })
    }

    /// poll(2) on the port for `events`; the events that occurred (0 on time-out).
    fn wait(&self, events: libc::c_short, timeout: Duration) -> io::Result<libc::c_short> {
        let mut p = libc::pollfd {
            fd: self.file.as_raw_fd(),
            events,
            revents: 0,
        };
        let ms = libc::c_int::try_from(timeout.as_millis()).unwrap_or(libc::c_int::MAX);
        // SAFETY: one valid pollfd for the duration of the call.
        let n = unsafe { libc::poll(&mut p, 1, ms) };
        if n >= 0 {
            return Ok(if n > 0 { p.revents } else { 0 });
        }
        let e = io::Error::last_os_error();
        if e.kind() == ErrorKind::Interrupted {
            Ok(0)
        } else {
            Err(e)
        }
    }

    /// Reads what is there without blocking: `Ok(0)` (raw mode, VMIN = VTIME = 0) or
    /// `WouldBlock` when nothing is.
    pub fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        self.file.read(buf)
    }

    /// Writes all of `data`, waiting at most `stall` each time the output buffer is full.
    pub fn write_all(&mut self, mut data: &[u8], stall: Duration) -> io::Result<()> {
        while !data.is_empty() {
            match self.file.write(data) {
                Ok(0) => return Err(ErrorKind::WriteZero.into()),
                Ok(n) => data = data.get(n..).unwrap_or(&[]),
                Err(e) if e.kind() == ErrorKind::WouldBlock => {
                    if self.wait(libc::POLLOUT, stall)? & libc::POLLOUT == 0 {
                        return Err(io::Error::new(ErrorKind::TimedOut, "output stalled"));
                    }
                }
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }
}
