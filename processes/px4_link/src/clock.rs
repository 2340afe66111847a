//! The autopilot's boot clock mapped onto this machine's. Telemetry says when the
//! autopilot measured it (`time_boot_ms`); stamping it with its arrival instead puts every
//! delay of the link and of this machine's scheduler into the vehicle's pose history, and
//! a camera frame (stamped when it was exposed) is then matched with a pose from up to a
//! delay earlier: at 2 m/s, 100 ms is 20 cm of pad position.
//!
//! The mapping is a straight line, `local = boot + offset(boot)`, whose slope is how much
//! faster or slower the autopilot's clock runs than ours. That is not a crystal's few
//! ppm: a simulator's clock (PX4 SITL's SIH, Gazebo in lockstep) runs percents slower
//! or faster than the wall clock, and a mapping that only allowed a crystal's drift fell
//! behind by 10 ms a second until the mission called the telemetry lost (issue 34).
//!
//! A message cannot arrive before it was sent, so every message's point (boot time,
//! arrival minus boot time) lies on or above the line. The lowest point of each
//! [`BUCKET_NS`] of boot time is kept for the last [`BUCKETS`] buckets, and the line is
//! the edge of their lower convex hull above their mean boot time: the solution of the
//! linear programme of Moon, Skelly and Towsley (1999, "Estimation and removal of clock
//! skew from network delay measurements"). Late messages lie above the hull and never
//! pull it; the window follows a rate that changes. One-way, the path's fixed delay
//! stays in the offset (microseconds on a serial line or loopback UDP), as with
//! MAVROS's TIMESYNC.
//!
//! A clock that goes back (the autopilot or its simulator restarted), jumps ahead, or
//! stands still for a while (a paused simulator) is a new clock: the mapping starts
//! over, and the jump is logged and counted ([`AutopilotClock::jumps`]).

/// The boot time a kept point stands for, ns: the lowest point in each such span is kept.
pub const BUCKET_NS: u64 = 250_000_000;

/// How many buckets the line is fitted over (10 s at [`BUCKET_NS`]).
pub const BUCKETS: usize = 40;

/// A message this far below the line (its clock jumped ahead) is a new clock at once;
/// messages this far above it for [`JUMP_CONFIRM_NS`] (its clock stood still) are one
/// too, ns.
pub const JUMP_NS: i64 = 1_000_000_000;

/// How long messages must stay [`JUMP_NS`] late before the clock counts as jumped: a
/// burst of messages queued for a second by a stalled link is not a new clock, ns.
pub const JUMP_CONFIRM_NS: u64 = 500_000_000;

/// Messages may come this much out of their order of measurement, ns; a boot time
/// further back is a new clock.
pub const REORDER_NS: u64 = 100_000_000;

/// Buckets before a line is fitted (until then the lowest offset maps, at rate 1): one
/// late bucket among two would tilt the line.
const MIN_FIT: usize = 4;

/// The rate is logged once the window is full if it is this far from ours, then again
/// when it moved this far from the rate last logged...
const RATE_LOG_FIRST: f64 = 2e-3;
/// ...by this much,
const RATE_LOG_STEP: f64 = 5e-3;
/// ...and this long after the last line, ns: PX4 SITL's SIH wanders between 1 and 3.5 %
/// slow on a loaded machine, and a 0.2 % step logged 57 lines in 3.5 minutes.
const RATE_LOG_PERIOD_NS: u64 = 60_000_000_000;

/// `offset(boot) = offset0 + slope * (boot - boot0)`, ns.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Line {
    boot0: u64,
    offset0: i64,
    slope: f64,
}

impl Line {
    fn at(&self, boot_ns: u64) -> i64 {
        let dx = signed_diff(boot_ns, self.boot0) as f64;
        self.offset0.saturating_add((self.slope * dx) as i64)
    }
}

/// One kept point: the lowest offset seen in its bucket.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Point {
    bucket: u64,
    boot_ns: u64,
    offset_ns: i64,
}

/// The mapping; see the module docs. Fixed size: nothing is allocated per message.
#[derive(Debug, Clone, Copy)]
pub struct AutopilotClock {
    /// Closed buckets, oldest first, `len` of them from `head` round the ring.
    ring: [Point; BUCKETS],
    head: usize,
    len: usize,
    /// The bucket still filling.
    open: Option<Point>,
    /// The lowest offset since the last start: the mapping until a line is fitted.
    lowest: Option<i64>,
    line: Option<Line>,
    last_boot_ns: u64,
    /// Local time since which every message sat more than [`JUMP_NS`] above the line.
    late_since: Option<u64>,
    jumps: u64,
    /// The rate last logged, and the boot time it was logged at.
    logged: Option<(f64, u64)>,
}

impl Default for AutopilotClock {
    fn default() -> Self {
        Self {
            ring: [Point::default(); BUCKETS],
            head: 0,
            len: 0,
            open: None,
            lowest: None,
            line: None,
            last_boot_ns: 0,
            late_since: None,
            jumps: 0,
            logged: None,
        }
    }
}

impl AutopilotClock {
    /// The local time at which a message stamped `boot_ns` by the autopilot, arrived at
    /// `local_ns`, was sent; never after its arrival. An autopilot that does not fill the
    /// stamp (0) gets its arrival.
    pub fn local_time(&mut self, boot_ns: u64, local_ns: u64) -> u64 {
        if boot_ns == 0 {
            return local_ns;
        }
        let sample = clamp_i64(i128::from(local_ns) - i128::from(boot_ns));
        if boot_ns.saturating_add(REORDER_NS) < self.last_boot_ns {
            let back_ms = (self.last_boot_ns - boot_ns) / 1_000_000;
            tracing::warn!(
                back_ms,
                "the autopilot's clock went back (it restarted): its time mapping starts over"
            );
            self.start_over();
        } else if let Some(line) = self.line {
            let residual = sample.saturating_sub(line.at(boot_ns));
            if residual < -JUMP_NS {
                let ahead_ms = residual.unsigned_abs() / 1_000_000;
                tracing::warn!(
                    ahead_ms,
                    "the autopilot's clock jumped ahead: its time mapping starts over"
                );
                self.start_over();
            } else if residual > JUMP_NS {
                let since = *self.late_since.get_or_insert(local_ns);
                if local_ns.saturating_sub(since) >= JUMP_CONFIRM_NS {
                    let behind_ms = residual / 1_000_000;
                    tracing::warn!(
                        behind_ms,
                        "the autopilot's clock stood still or went back: its time mapping starts over"
                    );
                    self.start_over();
                }
            } else {
                self.late_since = None;
            }
        }
        self.last_boot_ns = self.last_boot_ns.max(boot_ns);
        self.take(boot_ns, sample);
        let offset = match (self.line, self.lowest) {
            (Some(l), _) => l.at(boot_ns),
            (None, Some(lowest)) => lowest,
            (None, None) => sample,
        };
        let t = clamp_i64(i128::from(boot_ns) + i128::from(offset));
        u64::try_from(t).unwrap_or(0).min(local_ns)
    }

    /// How many times the autopilot's clock jumped (restarted, jumped ahead, stood still).
    pub fn jumps(&self) -> u64 {
        self.jumps
    }

    /// The autopilot's clock rate against ours (boot seconds per local second) as
    /// estimated now; `None` until a line is fitted (a second of telemetry).
    pub fn rate(&self) -> Option<f64> {
        self.line.map(|l| 1.0 / (1.0 + l.slope))
    }

    fn start_over(&mut self) {
        *self = Self {
            jumps: self.jumps + 1,
            logged: self.logged,
            ..Self::default()
        };
    }

    /// Keeps the sample if it is the lowest of its bucket; a bucket that closes refits
    /// the line.
    fn take(&mut self, boot_ns: u64, offset_ns: i64) {
        self.lowest = Some(self.lowest.map_or(offset_ns, |l| l.min(offset_ns)));
        let point = Point {
            bucket: boot_ns / BUCKET_NS,
            boot_ns,
            offset_ns,
        };
        match self.open {
            None => self.open = Some(point),
            Some(open) if point.bucket == open.bucket => {
                if offset_ns < open.offset_ns {
                    self.open = Some(point);
                }
            }
            Some(open) if point.bucket > open.bucket => {
                self.push(open);
                self.open = Some(point);
                self.fit();
            }
            // A message from a bucket already closed (reordered): stamped, not kept.
            Some(_) => {}
        }
    }

    fn push(&mut self, p: Point) {
        if self.len == BUCKETS {
            self.ring[self.head] = p;
            self.head = (self.head + 1) % BUCKETS;
        } else {
            self.ring[(self.head + self.len) % BUCKETS] = p;
            self.len += 1;
        }
    }

    fn point(&self, i: usize) -> Point {
        self.ring[(self.head + i) % BUCKETS]
    }

    /// The lower hull's edge above the points' mean boot time.
    fn fit(&mut self) {
        if self.len < MIN_FIT {
            return;
        }
        let first = self.point(0);
        let xy = |p: Point| {
            (
                signed_diff(p.boot_ns, first.boot_ns) as f64,
                p.offset_ns.saturating_sub(first.offset_ns) as f64,
            )
        };
        // Andrew's monotone chain, lower half: the points are in boot order already.
        let mut hull = [(0.0f64, 0.0f64); BUCKETS];
        let mut n = 0usize;
        let mut mean = 0.0;
        for i in 0..self.len {
            let p = xy(self.point(i));
            mean += p.0;
            while n >= 2 && cross(hull[n - 2], hull[n - 1], p) <= 0.0 {
                n -= 1;
            }
            hull[n] = p;
            n += 1;
        }
        mean /= self.len as f64;
        let k = (1..n).find(|&k| hull[k].0 >= mean).unwrap_or(n - 1);
        let (a, b) = (hull[k - 1], hull[k]);
        let run = b.0 - a.0;
        if run.is_nan() || run <= 0.0 {
            return;
        }
        let slope = (b.1 - a.1) / run;
        if !slope.is_finite() {
            return;
        }
        self.line = Some(Line {
            boot0: first.boot_ns.saturating_add_signed(a.0 as i64),
            offset0: first.offset_ns.saturating_add(a.1 as i64),
            slope,
        });
        let now = self.point(self.len - 1).boot_ns;
        let due = |rate: f64| match self.logged {
            None => (rate - 1.0).abs() >= RATE_LOG_FIRST,
            Some((logged, at)) => {
                (rate - logged).abs() >= RATE_LOG_STEP
                    && now.saturating_sub(at) >= RATE_LOG_PERIOD_NS
            }
        };
        if let Some(rate) = self.rate()
            && self.len == BUCKETS
            && due(rate)
        {
            self.logged = Some((rate, now));
            let percent = (rate - 1.0) * 100.0;
            tracing::info!(
                percent,
                "the autopilot's clock runs at a rate other than ours (a simulator behind or ahead of real time?): mapped"
            );
        }
    }
}

/// `a - b` as a signed number, saturated.
fn signed_diff(a: u64, b: u64) -> i64 {
    clamp_i64(i128::from(a) - i128::from(b))
}

fn clamp_i64(x: i128) -> i64 {
    i64::try_from(x).unwrap_or(if x < 0 { i64::MIN } else { i64::MAX })
}

/// > 0 when o -> a -> b turns left (counter-clockwise).
fn cross(o: (f64, f64), a: (f64, f64), b: (f64, f64)) -> f64 {
    (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0)
}

#[cfg(test)]
#[path = "clock_test.rs"]
mod tests;
