//! Stack binaries as child processes in tests: started with stderr collected, killed
//! when the test ends however it ends, stopped with SIGTERM as systemd does.

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// A child process that is killed when dropped; its stderr is collected line by line
/// (ANSI colours removed). A failure to start or to wait panics: these are tests.
pub struct Running {
    name: &'static str,
    child: Child,
    lines: Arc<Mutex<Vec<String>>>,
    reader: Option<JoinHandle<()>>,
}

impl Running {
    /// Starts `cmd` (stdout discarded, stderr collected) and names it `name` in messages.
    pub fn start(name: &'static str, cmd: &mut Command) -> Self {
        let mut child = match cmd
            .env("NO_COLOR", "1")
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
        {
            Ok(c) => c,
            Err(e) => panic!("start {name}: {e}"),
        };
        let lines = Arc::new(Mutex::new(Vec::new()));
        let sink = Arc::clone(&lines);
        let stderr = child.stderr.take();
        let reader = std::thread::spawn(move || {
            let Some(stderr) = stderr else { return };
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                sink.lock()
                    .unwrap_or_else(PoisonError::into_inner)
                    .push(strip_ansi(&line));
            }
        });
        Self {
            name,
            child,
            lines,
            reader: Some(reader),
        }
    }

    /// Everything the process wrote to stderr so far.
    pub fn log(&self) -> String {
        self.lines
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .join("\n")
    }

    /// Waits until a stderr line contains `needle`; panics with the log after `timeout`.
    pub fn wait_for(&self, needle: &str, timeout: Duration) {
        let end = Instant::now() + timeout;
        while Instant::now() < end {
            if self
                .lines
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .iter()
                .any(|l| l.contains(needle))
            {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        panic!("{} never said `{needle}`:\n{}", self.name, self.log());
    }

    /// True while the process has not exited.
    pub fn is_running(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }

    /// Waits for the process to exit on its own; panics with the log after `timeout`.
    pub fn wait_exit(&mut self, timeout: Duration) -> ExitStatus {
        let end = Instant::now() + timeout;
        loop {
            if let Some(status) = self.exited() {
                return status;
            }
            assert!(
                Instant::now() < end,
                "{} did not exit:\n{}",
                self.name,
                self.log()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// The exit status once the process has exited, without waiting.
    pub fn exited(&mut self) -> Option<ExitStatus> {
        match self.child.try_wait() {
            Ok(Some(status)) => {
                if let Some(r) = self.reader.take() {
                    let _ = r.join();
                }
                Some(status)
            }
            Ok(None) => None,
            Err(e) => panic!("waiting for {}: {e}", self.name),
        }
    }

    /// The process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Sends SIGTERM (a systemd stop) without waiting.
    pub fn request_stop(&self) {
        // SAFETY: signalling our own child, whose pid stays valid until it is waited for.
        unsafe { libc::kill(self.child.id() as i32, libc::SIGTERM) };
    }

    /// SIGTERM (a systemd stop), then waits for the exit.
    pub fn terminate(&mut self) -> ExitStatus {
        self.request_stop();
        self.wait_exit(Duration::from_secs(10))
    }
}

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `s` without ANSI escape sequences.
pub fn strip_ansi(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    let mut chars = s.chars();
    while let Some(c) = chars.next() {
        if c == '\u{1b}' {
            for c in chars.by_ref() {
                if c.is_ascii_alphabetic() {
                    break;
                }
            }
        } else {
            out.push(c);
        }
    }
    out
}

/// The `sim` binary next to the running test executable (see
/// [`crate::stack::stack_binary`]).
pub fn sim_binary() -> PathBuf {
    crate::stack::stack_binary("sim")
}

/// How many iceoryx2 nodes under `ipc`'s prefix are alive and how many died without
/// cleaning up (a process that crashed, or exited without dropping its node).
pub fn node_census(ipc: &runtime::Ipc) -> (usize, usize) {
    use iceoryx2::prelude::{CallbackProgression, Node, NodeState};
    let (mut alive, mut dead) = (0, 0);
    let listed = Node::<runtime::ipc::Svc>::list(ipc.node().config(), |state| {
        match state {
            NodeState::Alive(_) => alive += 1,
            NodeState::Dead(_) => dead += 1,
            _ => {}
        }
        CallbackProgression::Continue
    });
    if let Err(e) = listed {
        panic!("listing iceoryx2 nodes: {e:?}");
    }
    (alive, dead)
}
