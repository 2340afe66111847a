//! Timing decisions with the time passed in: when the next recorded frame is due, how
//! long to wait before reopening a camera, when a log line may be written. The binary
//! reads the clock and sleeps; these types only decide.

use std::time::Duration;

/// Plays recorded frames at a fixed rate, the way the camera produced them.
///
/// A player that falls more than a period behind (the process was descheduled, a frame
/// took long to decode) resumes from now instead of bursting frames to catch up: a burst
/// would reach the pipeline as frames older than their rate implies.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Pacer {
    period_ns: u64,
    next_ns: Option<u64>,
}

impl Pacer {
    /// A pacer at `rate_hz`; `None` unless the rate is finite and positive.
    pub fn from_rate_hz(rate_hz: f64) -> Option<Self> {
        if !(rate_hz.is_finite() && rate_hz > 0.0) {
            return None;
        }
        let period_ns = (1e9 / rate_hz).round() as u64;
        (period_ns > 0).then_some(Self {
            period_ns,
            next_ns: None,
        })
    }

    /// The period, ns.
    pub fn period_ns(&self) -> u64 {
        self.period_ns
    }

    /// How long to wait at `now_ns` before the next frame is due (0: now).
    pub fn delay_ns(&self, now_ns: u64) -> u64 {
        self.next_ns.map_or(0, |next| next.saturating_sub(now_ns))
    }

    /// Records that a frame went out at `now_ns` and schedules the next one.
    pub fn emitted(&mut self, now_ns: u64) {
        let next = match self.next_ns {
            Some(due) if due + self.period_ns > now_ns => due + self.period_ns,
            _ => now_ns + self.period_ns,
        };
        self.next_ns = Some(next);
    }

    /// Forgets the schedule (after a rewind): the next frame is due at once.
    pub fn reset(&mut self) {
        self.next_ns = None;
    }
}

/// Exponential backoff between attempts to reopen a camera: quick at first (a USB
/// hiccup), then at most every `max` (a camera unplugged for good must not spin a core or
/// flood the log).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Backoff {
    initial: Duration,
    max: Duration,
    next: Duration,
}

impl Backoff {
    /// Starts at `initial`, doubles up to `max`.
    pub fn new(initial: Duration, max: Duration) -> Self {
        Self {
            initial,
            max: max.max(initial),
            next: initial,
        }
    }

    /// The delay before the next attempt; the one after is longer.
    pub fn next_delay(&mut self) -> Duration {
        let d = self.next;
        self.next = (self.next * 2).min(self.max);
        d
    }

    /// Back to the initial delay (after a success).
    pub fn reset(&mut self) {
        self.next = self.initial;
    }
}

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
