//! Time sources. Stamps are nanoseconds of CLOCK_MONOTONIC, which every process on the
//! host shares, so stamps taken in different processes can be subtracted.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

/// Something that tells the time in monotonic nanoseconds.
///
/// The multi-process mode uses [`MonotonicClock`]; lockstep mode uses [`SimClock`], which
/// only moves when the simulator steps, so a run is deterministic and faster than real time.
pub trait Clock: Send + Sync {
    /// Now, in nanoseconds.
    fn now_ns(&self) -> u64;
}

/// CLOCK_MONOTONIC, now, in nanoseconds.
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec and CLOCK_MONOTONIC always exists on Linux;
    // clock_gettime writes only into it.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    if rc != 0 {
        return 0;
    }
    (ts.tv_sec as u64)
        .saturating_mul(1_000_000_000)
        .saturating_add(ts.tv_nsec as u64)
}

/// The host's monotonic clock.
#[derive(Debug, Clone, Copy, Default)]
pub struct MonotonicClock;

impl Clock for MonotonicClock {
    fn now_ns(&self) -> u64 {
        monotonic_ns()
    }
}

/// Simulated time, shared by clones; moved only by whoever steps the simulation.
#[derive(Debug, Clone, Default)]
pub struct SimClock {
    now: Arc<AtomicU64>,
}

impl SimClock {
    /// A clock at `start_ns`.
    pub fn new(start_ns: u64) -> Self {
        Self {
            now: Arc::new(AtomicU64::new(start_ns)),
        }
    }

    /// Sets the time; time never goes backwards, so an earlier value is ignored.
    pub fn set(&self, ns: u64) {
        self.now.fetch_max(ns, Ordering::AcqRel);
    }

    /// Moves the time forward by `dt_ns`.
    pub fn advance(&self, dt_ns: u64) {
        self.now.fetch_add(dt_ns, Ordering::AcqRel);
    }
}

impl Clock for SimClock {
    fn now_ns(&self) -> u64 {
        self.now.load(Ordering::Acquire)
    }
}

#[cfg(test)]
#[path = "clock_test.rs"]
mod tests;

/// The Unix time (ns) at CLOCK_MONOTONIC's zero: read once at start, it turns the
/// monotonic times stages get into wall-clock times where a protocol needs one (MAVLink
/// signing timestamps), without a stage reading a clock.
pub fn unix_ns_at_monotonic_zero() -> u64 {
    let unix = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX));
    unix.saturating_sub(monotonic_ns())
}
