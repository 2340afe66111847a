//! A device read on a thread of its own, for the ingest processes (camera-ingest,
//! depth-ingest): the thread reads, paces a recorded source at its rate, waits out a
//! device that is gone, and hands over only the newest frame, so the driver keeps
//! publishing and beating the heartbeat while a read blocks or a device is unplugged.
//! A frame a newer one replaced before the driver took it is counted, never queued.

use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::Duration;

use crate::threads::SpawnError;
use crate::{JoinError, StopFlag, ThreadRole, Worker, monotonic_ns};

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

/// Exponential backoff between attempts to reopen a device: quick at first (a USB
/// hiccup), then at most every `max` (a device unplugged for good must not spin a core or
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

/// What one read of a device did.
pub enum Step<T> {
    /// A frame, with the monotonic time it was taken.
    Frame(T, u64),
    /// Nothing to publish this time (a rewind, an undecodable video frame).
    Skip,
    /// A frame's slot in the recording went by without a frame (an unreadable file).
    Missed,
    /// Wait this long before trying again (a device to reopen).
    Retry(Duration),
    /// The recording ended (`Ok`), or the device cannot go on (`Err`, one line).
    End(Result<(), String>),
}

/// Losses a device counts while it reads, handed over with the next frame.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Losses {
    /// Recorded frames that could not be decoded.
    pub unreadable: u64,
    /// Reads that failed (disconnections), each followed by a reopen.
    pub source_errors: u64,
}

/// A source of frames read on the capture thread.
pub trait Device: Send + 'static {
    /// A frame (or a buffer to read one into).
    type Frame: Send + 'static;

    /// One read; `spare` may hold a buffer the publishing side gave back, to take and
    /// read into. Losses go into `losses`.
    fn step(&mut self, spare: &mut Option<Self::Frame>, losses: &mut Losses) -> Step<Self::Frame>;
}

/// What the capture thread handed over since the last look.
pub struct Taken<T> {
    /// The newest frame and its capture time.
    pub frame: Option<(T, u64)>,
    /// The end, once: `Ok` at the end of a recording, `Err` when the device failed.
    pub end: Option<Result<(), String>>,
}

struct Slot<T> {
    frame: Option<(T, u64)>,
    spare: Option<T>,
    overwritten: u64,
    losses: Losses,
    end: Option<Result<(), String>>,
}

struct Shared<T> {
    slot: Mutex<Slot<T>>,
    ready: Condvar,
}

impl<T> Shared<T> {
    fn lock(&self) -> MutexGuard<'_, Slot<T>> {
        self.slot.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn update(&self, f: impl FnOnce(&mut Slot<T>)) {
        f(&mut self.lock());
        self.ready.notify_one();
    }
}

/// The capture thread of one device and the newest frame it handed over.
pub struct CaptureThread<T: Send + 'static> {
    shared: Arc<Shared<T>>,
    worker: Worker<()>,
}

impl<T: Send + 'static> CaptureThread<T> {
    /// Starts reading `device` on a thread in `role`, paced by `pacer` when the source is
    /// a recording.
    pub fn start<D: Device<Frame = T>>(
        device: D,
        pacer: Option<Pacer>,
        role: ThreadRole,
    ) -> Result<Self, SpawnError> {
        let shared = Arc::new(Shared {
            slot: Mutex::new(Slot {
                frame: None,
                spare: None,
                overwritten: 0,
                losses: Losses::default(),
                end: None,
            }),
            ready: Condvar::new(),
        });
        let worker_shared = Arc::clone(&shared);
        let worker = Worker::spawn(role, move |stop| {
            capture_loop(device, pacer, &worker_shared, stop);
        })?;
        Ok(Self { shared, worker })
    }

    /// Waits up to `timeout` for a frame or the end; returns everything new.
    pub fn take(&self, timeout: Duration) -> Taken<T> {
        let guard = self.shared.lock();
        let (mut s, _) = self
            .shared
            .ready
            .wait_timeout_while(guard, timeout, |s| s.frame.is_none() && s.end.is_none())
            .unwrap_or_else(|p| p.into_inner());
        Taken {
            frame: s.frame.take(),
            end: s.end.take(),
        }
    }

    /// What was lost before a frame was taken, since the start, for the process's stop
    /// line: frames a newer one replaced, unreadable recorded frames, failed reads.
    pub fn counters(&self) -> Vec<stage::Counter> {
        let s = self.shared.lock();
        vec![
            ("overwritten", s.overwritten),
            ("dropped_unreadable", s.losses.unreadable),
            ("source_errors", s.losses.source_errors),
        ]
    }

    /// Gives a frame's buffer back for the thread to read the next frame into.
    pub fn give_back(&self, spare: T) {
        self.shared.lock().spare = Some(spare);
    }

    /// Whether the thread has ended (at the end of a recording, or it panicked).
    pub fn is_finished(&self) -> bool {
        self.worker.is_finished()
    }

    /// What the driver is told after a look that returned `end`: the recording ended,
    /// the device failed (its line), the thread is gone (it panicked: the join names
    /// it), or more may come.
    pub fn flow(&self, end: Option<Result<(), String>>) -> Result<stage::Flow, stage::StageError> {
        match end {
            Some(Ok(())) => {
                tracing::info!("end of the recording");
                Ok(stage::Flow::Ended)
            }
            Some(Err(e)) => Err(stage::StageError::Failed(e)),
            None if self.is_finished() => Ok(stage::Flow::Ended),
            None => Ok(stage::Flow::Open),
        }
    }

    /// Stops the thread and joins it within `timeout`: a read blocked for longer (a
    /// device stuck in its driver) is the thread's exit code (runtime::threads).
    pub fn stop(self, timeout: Duration) -> Result<(), JoinError> {
        self.worker.stop_and_join(timeout)
    }
}

/// The capture thread: reads, paces recorded sources, waits out a device that is gone,
/// and hands each frame over. Never publishes itself (iceoryx2 ports stay on one thread).
fn capture_loop<D: Device>(
    mut device: D,
    mut pacer: Option<Pacer>,
    shared: &Shared<D::Frame>,
    stop: &StopFlag,
) {
    while !stop.is_stopped() {
        if let Some(p) = &pacer {
            let delay = p.delay_ns(monotonic_ns());
            // A slow rate (0.1 Hz) must not hold a stop for seconds.
            if delay > 0 && !stop.sleep(Duration::from_nanos(delay)) {
                break;
            }
        }
        let mut spare = shared.lock().spare.take();
        let mut losses = Losses::default();
        let step = device.step(&mut spare, &mut losses);
        if let Some(unused) = spare {
            shared.lock().spare.get_or_insert(unused);
        }
        if losses != Losses::default() {
            shared.update(|s| {
                s.losses.unreadable += losses.unreadable;
                s.losses.source_errors += losses.source_errors;
            });
        }
        match step {
            Step::Frame(frame, capture_ns) => {
                if let Some(p) = pacer.as_mut() {
                    p.emitted(capture_ns);
                }
                shared.update(|s| {
                    if let Some((old, _)) = s.frame.replace((frame, capture_ns)) {
                        s.overwritten += 1;
                        s.spare = Some(old);
                    }
                });
            }
            Step::Skip => {}
            Step::Missed => {
                if let Some(p) = pacer.as_mut() {
                    p.emitted(monotonic_ns());
                }
            }
            Step::Retry(delay) => {
                stop.sleep(delay);
            }
            Step::End(result) => {
                shared.update(|s| s.end = Some(result));
                return;
            }
        }
    }
}

#[cfg(test)]
#[path = "capture_test.rs"]
mod tests;
