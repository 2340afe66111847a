//! Threads a process starts beside its main thread: told to stop, woken from their
//! sleeps, and joined within a bound before `main` returns.
//!
//! Returning from `main` runs the C and C++ exit handlers (OpenCV's static state among
//! them) while other threads still run; a thread inside OpenCV at that moment crashes the
//! process (camera-ingest did, one stop in four under load). So every thread is joined
//! first. A thread that cannot be joined in time (a camera read blocked in a driver) ends
//! the process with the exit code of its [`ThreadRole`] through `_exit`, which skips
//! those handlers: a defined exit, never a crash. See [`crate::process_main`].

use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How long a process waits for its threads to finish once told to stop. systemd's
/// `TimeoutStopSec` (deploy/systemd) must leave room for it.
pub const JOIN_TIMEOUT: Duration = Duration::from_secs(2);

/// Every thread a stack process starts besides its main thread, each with the exit code
/// the process ends with when that thread cannot be joined (80-89, clear of the usage
/// error 2 and the sysexits range 64-78).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum ThreadRole {
    /// camera-ingest's thread that reads, paces and reopens an OpenCV camera or file.
    CameraCapture = 80,
    /// depth-ingest's thread that reads and paces a depth recording.
    DepthCapture = 81,
}

impl ThreadRole {
    /// Every role, for documentation and tests.
    pub const ALL: [ThreadRole; 2] = [ThreadRole::CameraCapture, ThreadRole::DepthCapture];

    /// The thread's name (as `ps -L` and a debugger show it).
    pub fn name(self) -> &'static str {
        match self {
            Self::CameraCapture => "capture",
            Self::DepthCapture => "depth-capture",
        }
    }

    /// The process's exit code when this thread could not be joined.
    pub fn exit_code(self) -> u8 {
        self as u8
    }
}

/// Tells a thread to stop; its sleeps end early when it is set.
#[derive(Debug, Default)]
pub struct StopFlag {
    stopped: Mutex<bool>,
    changed: Condvar,
}

impl StopFlag {
    /// Sets the flag and wakes every [`StopFlag::sleep`].
    pub fn stop(&self) {
        *self.stopped.lock().unwrap_or_else(PoisonError::into_inner) = true;
        self.changed.notify_all();
    }

    /// True once [`StopFlag::stop`] was called.
    pub fn is_stopped(&self) -> bool {
        *self.stopped.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Sleeps for `duration` unless the flag is set first; returns false when it is set.
    pub fn sleep(&self, duration: Duration) -> bool {
        let guard = self.stopped.lock().unwrap_or_else(PoisonError::into_inner);
        let (stopped, _) = self
            .changed
            .wait_timeout_while(guard, duration, |stopped| !*stopped)
            .unwrap_or_else(PoisonError::into_inner);
        !*stopped
    }
}

/// Why a thread could not be started.
#[derive(Debug, thiserror::Error)]
#[error("cannot start the {} thread: {source}", role.name())]
pub struct SpawnError {
    /// The thread.
    pub role: ThreadRole,
    /// What the OS said.
    pub source: std::io::Error,
}

/// Why a thread did not end cleanly when told to stop.
#[derive(Debug, thiserror::Error)]
pub enum JoinError {
    /// It was still running when the bound passed (blocked in a read, most likely).
    #[error(
        "the {} thread did not stop within {} ms; exiting with code {}",
        role.name(),
        within.as_millis(),
        role.exit_code()
    )]
    Stuck {
        /// The thread.
        role: ThreadRole,
        /// How long it was given.
        within: Duration,
    },
    /// It panicked.
    #[error("the {} thread panicked; exiting with code {}", role.name(), role.exit_code())]
    Panicked {
        /// The thread.
        role: ThreadRole,
    },
}

impl JoinError {
    /// The exit code that names the thread.
    pub fn exit_code(&self) -> u8 {
        match self {
            Self::Stuck { role, .. } | Self::Panicked { role } => role.exit_code(),
        }
    }
}

/// A named thread with its stop flag; joined by [`Worker::stop_and_join`].
#[derive(Debug)]
pub struct Worker<T> {
    role: ThreadRole,
    stop: Arc<StopFlag>,
    handle: JoinHandle<T>,
}

impl<T: Send + 'static> Worker<T> {
    /// Starts `body` on a thread named after `role`; `body` gets the stop flag to watch.
    pub fn spawn(
        role: ThreadRole,
        body: impl FnOnce(&StopFlag) -> T + Send + 'static,
    ) -> Result<Self, SpawnError> {
        let stop = Arc::new(StopFlag::default());
        let flag = Arc::clone(&stop);
        let handle = std::thread::Builder::new()
            .name(role.name().into())
            .spawn(move || body(&flag))
            .map_err(|source| SpawnError { role, source })?;
        Ok(Self { role, stop, handle })
    }

    /// True once the thread's body has returned (or panicked).
    pub fn is_finished(&self) -> bool {
        self.handle.is_finished()
    }

    /// Tells the thread to stop and waits for it at most `within`; returns what it
    /// returned.
    pub fn stop_and_join(self, within: Duration) -> Result<T, JoinError> {
        self.stop.stop();
        let deadline = Instant::now() + within;
        // std has no timed join: poll the finished flag, a few ms at a time.
        while !self.handle.is_finished() {
            if Instant::now() >= deadline {
                return Err(JoinError::Stuck {
                    role: self.role,
                    within,
                });
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        self.handle
            .join()
            .map_err(|_| JoinError::Panicked { role: self.role })
    }
}

/// The exit code of the first [`JoinError`] in `error`'s chain of causes, if any.
pub fn exit_code_of(error: &(dyn std::error::Error + 'static)) -> Option<u8> {
    let mut next = Some(error);
    while let Some(e) = next {
        if let Some(j) = e.downcast_ref::<JoinError>() {
            return Some(j.exit_code());
        }
        next = e.source();
    }
    None
}

#[cfg(test)]
#[path = "threads_test.rs"]
mod tests;
