//! The autopilot's boot clock mapped onto this machine's. Telemetry says when the
//! autopilot measured it (`time_boot_ms`); stamping it with its arrival instead puts every
//! delay of the link and of this machine's scheduler into the vehicle's pose history, and
//! a camera frame (stamped when it was exposed) is then matched with a pose from up to a
//! delay earlier: at 2 m/s, 100 ms is 20 cm of pad position.
//!
//! The offset (local minus boot time) is the smallest seen, the message that came
//! quickest: later ones were late, not sent later. It rises toward later arrivals by
//! [`DRIFT`] at most (crystals drift by tens of ppm) and starts over when the boot time
//! goes back (the autopilot restarted) or the offset jumps by more than [`RESTART_NS`].
//! MAVROS does the same with TIMESYNC's round trips; one-way, the path's fixed delay
//! stays in the offset (microseconds on a serial line or loopback UDP).

/// How fast the offset may rise, s per s: ten times a poor crystal's drift.
pub const DRIFT: f64 = 1e-3;

/// An offset this far from the estimate is a new clock (the autopilot restarted), ns.
pub const RESTART_NS: i64 = 1_000_000_000;

/// Messages may come this much out of their order of measurement, ns; a boot time
/// further back is a new clock.
pub const REORDER_NS: u64 = 100_000_000;

/// The mapping; see the module docs.
#[derive(Debug, Clone, Copy, Default)]
pub struct AutopilotClock {
    offset_ns: Option<i64>,
    last_local_ns: u64,
    last_boot_ns: u64,
}

impl AutopilotClock {
    /// The local time at which a message stamped `boot_ns` by the autopilot, arrived at
    /// `local_ns`, was sent; never after its arrival. An autopilot that does not fill the
    /// stamp (0) gets its arrival.
    pub fn local_time(&mut self, boot_ns: u64, local_ns: u64) -> u64 {
        if boot_ns == 0 {
            return local_ns;
        }
        let sample = i64::try_from(local_ns)
            .unwrap_or(i64::MAX)
            .saturating_sub(i64::try_from(boot_ns).unwrap_or(i64::MAX));
        let elapsed = local_ns.saturating_sub(self.last_local_ns);
        self.last_local_ns = self.last_local_ns.max(local_ns);
        // Its clock went back: the autopilot started again (however short its last run,
        // so however close the new offset is to the old).
        let rebooted = boot_ns.saturating_add(REORDER_NS) < self.last_boot_ns;
        self.last_boot_ns = if rebooted {
            boot_ns
        } else {
            self.last_boot_ns.max(boot_ns)
        };
        let offset = match self.offset_ns {
            Some(o) if !rebooted && sample.abs_diff(o) <= RESTART_NS.unsigned_abs() => {
                let risen = o.saturating_add((elapsed as f64 * DRIFT) as i64);
                sample.min(risen)
            }
            _ => sample,
        };
        self.offset_ns = Some(offset);
        let t = i64::try_from(boot_ns)
            .unwrap_or(i64::MAX)
            .saturating_add(offset);
        u64::try_from(t).unwrap_or(0).min(local_ns)
    }
}

#[cfg(test)]
#[path = "clock_test.rs"]
mod tests;
