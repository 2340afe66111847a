//! Timing decisions with the time passed in: when a log line may be written. The binary
//! reads the clock; this only decides. (When the next recorded frame is due and how long
//! to wait before reopening a camera are `runtime::capture`'s `Pacer` and `Backoff`,
//! which the capture thread uses.)

use std::time::Duration;

/// Lets a repeated log line through at most once per interval, so a stream of bad frames
/// costs one formatted line per second instead of one per frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RateLimit {
    interval_ns: u64,
    last_ns: Option<u64>,
}

impl RateLimit {
    /// At most one line per `interval`.
    pub fn new(interval: Duration) -> Self {
        Self {
            interval_ns: interval.as_nanos() as u64,
            last_ns: None,
        }
    }

    /// True when a line may be written at `now_ns` (and then not again for an interval).
    pub fn ready(&mut self, now_ns: u64) -> bool {
        match self.last_ns {
            Some(last) if now_ns.saturating_sub(last) < self.interval_ns => false,
            _ => {
                self.last_ns = Some(now_ns);
                true
            }
        }
    }
}

#[cfg(test)]
#[path = "pacing_test.rs"]
mod tests;
