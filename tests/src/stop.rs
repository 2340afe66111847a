//! Stop tests: a process is started, fed, and stopped with SIGTERM at a random moment
//! while busy loops load every core, as systemd stops it on a busy Jetson; it must exit
//! 0 every time, after logging its final counters.

use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use crate::process::Running;

/// Processes that spin on a core each until dropped (part of the test, not a CI setting).
pub struct BusyLoops(Vec<Child>);

impl BusyLoops {
    /// Starts `n` busy loops (`sh -c 'while :; do :; done'`).
    pub fn start(n: usize) -> Self {
        let children = (0..n)
            .map(|_| {
                Command::new("sh")
                    .args(["-c", "while :; do :; done"])
                    .stdout(Stdio::null())
                    .stderr(Stdio::null())
                    .spawn()
                    .unwrap_or_else(|e| panic!("start a busy loop: {e}"))
            })
            .collect();
        Self(children)
    }

    /// True while every loop still spins.
    pub fn all_running(&mut self) -> bool {
        self.0.iter_mut().all(|c| matches!(c.try_wait(), Ok(None)))
    }
}

impl Drop for BusyLoops {
    fn drop(&mut self) {
        for c in &mut self.0 {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// A small seeded generator (xorshift64*) for stop moments: the seed is printed, and
/// `STOP_TEST_SEED` replays a run.
pub struct Moments {
    state: u64,
    seed: u64,
}

impl Moments {
    /// Seeded from `STOP_TEST_SEED` if set, else from the clock.
    pub fn new() -> Self {
        let seed = std::env::var("STOP_TEST_SEED")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or_else(|| {
                std::time::SystemTime::now()
                    .duration_since(std::time::UNIX_EPOCH)
                    .map(|d| d.as_nanos() as u64)
                    .unwrap_or(1)
            });
        Self {
            state: seed | 1,
            seed,
        }
    }

    /// The seed (to replay with `STOP_TEST_SEED`).
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// A moment uniformly in `[0, max)`.
    pub fn up_to(&mut self, max: Duration) -> Duration {
        self.state ^= self.state >> 12;
        self.state ^= self.state << 25;
        self.state ^= self.state >> 27;
        let r = self.state.wrapping_mul(0x2545_F491_4F6C_DD1D);
        let unit = (r >> 11) as f64 / (1u64 << 53) as f64;
        max.mul_f64(unit)
    }
}

impl Default for Moments {
    fn default() -> Self {
        Self::new()
    }
}

/// The last line of `log` that contains `needle` (a process's final summary).
pub fn last_line_with<'a>(log: &'a str, needle: &str) -> Option<&'a str> {
    log.lines().rev().find(|l| l.contains(needle))
}

/// The number after `key=` in a `tracing` line, if any.
pub fn count_in(line: &str, key: &str) -> Option<u64> {
    line.split_whitespace()
        .find_map(|kv| kv.strip_prefix(key)?.strip_prefix('='))
        .and_then(|v| v.parse().ok())
}

/// How one stopped process ended.
#[derive(Debug)]
pub struct Stopped {
    /// Its exit status.
    pub status: ExitStatus,
    /// What it logged.
    pub log: String,
    /// How long after SIGTERM it was gone.
    pub took: Duration,
}

/// Sends SIGTERM to `process` and waits for it to exit (at most 10 s).
pub fn stop(mut process: Running) -> Stopped {
    let asked = Instant::now();
    let status = process.terminate();
    Stopped {
        status,
        log: process.log(),
        took: asked.elapsed(),
    }
}

/// True once process `pid` catches SIGTERM (its handler is installed: the process has
/// reached `main`), from the `SigCgt` mask in /proc/PID/status.
pub fn catches_sigterm(pid: u32) -> bool {
    let Ok(status) = std::fs::read_to_string(format!("/proc/{pid}/status")) else {
        return false;
    };
    status
        .lines()
        .find_map(|l| l.strip_prefix("SigCgt:"))
        .and_then(|mask| u64::from_str_radix(mask.trim(), 16).ok())
        .is_some_and(|mask| mask & (1 << (libc::SIGTERM - 1)) != 0)
}
