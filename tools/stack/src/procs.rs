//! Starting the stack's binaries as child processes (benchmarks, `landing run
//! --processes`): where they are, and stopping them as systemd would.

use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::process::Child;
use std::time::{Duration, Instant};

use anyhow::Result;

/// Child processes, stopped when dropped (also on error paths): SIGTERM, then SIGKILL
/// after 3 s, as systemd does; those marked [`Children::stop_first`] before the rest.
#[derive(Default)]
pub struct Children {
    list: Vec<(String, Child)>,
    first: Vec<String>,
}

impl Children {
    /// Adds a started child under `name`.
    pub fn push(&mut self, name: &str, child: Child) {
        self.list.push((name.to_string(), child));
    }

    /// Stops the child started as `name` (a supervisor) before the others, and waits for
    /// it: stopped together, the others' exits reach a watchdog still running as deaths
    /// (a faultless `make test` flight logged `px4-link died` 16 ms after the stop).
    pub fn stop_first(&mut self, name: &str) {
        self.first.push(name.to_string());
    }

    /// The first child that has exited, with its status.
    pub fn exited(&mut self) -> Option<(String, std::process::ExitStatus)> {
        self.newly_exited(&[])
    }

    /// The first child that has exited and is not among `seen`.
    pub fn newly_exited(&mut self, seen: &[String]) -> Option<(String, std::process::ExitStatus)> {
        self.list
            .iter_mut()
            .filter(|(n, _)| !seen.contains(n))
            .find_map(|(n, c)| match c.try_wait() {
                Ok(Some(s)) => Some((n.clone(), s)),
                _ => None,
            })
    }

    /// Puts `child` in the place of the one started as `name` (restarted), reaping the
    /// old one.
    pub fn replace(&mut self, name: &str, child: Child) {
        match self.list.iter_mut().find(|(n, _)| n == name) {
            Some((_, c)) => {
                let _ = c.wait();
                *c = child;
            }
            None => self.push(name, child),
        }
    }

    /// Waits for the child started as `name` to exit (after a kill): its iceoryx2 node is
    /// dead from then on, so the process started in its place may take the name.
    pub fn reap(&mut self, name: &str) {
        if let Some((_, c)) = self.list.iter_mut().find(|(n, _)| n == name) {
            let _ = c.wait();
        }
    }

    /// The process id of the child started as `name`.
    pub fn pid_of(&self, name: &str) -> Option<u32> {
        self.list
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, c)| c.id())
    }
}

impl Drop for Children {
    fn drop(&mut self) {
        let (first, rest): (Vec<_>, Vec<_>) = self
            .list
            .iter_mut()
            .partition(|(n, _)| self.first.contains(n));
        terminate(first.into_iter().map(|(_, c)| c));
        terminate(rest.into_iter().map(|(_, c)| c));
    }
}

/// SIGTERM to every one of `children`, then SIGKILL to those still running after 3 s.
fn terminate<'a>(children: impl Iterator<Item = &'a mut Child>) {
    let mut children: Vec<&mut Child> = children.collect();
    for c in &children {
        // SIGTERM first: the processes shut down cleanly and release shared memory;
        // SIGCONT after it, so a stopped (hung, injected) process can act on it.
        // SAFETY: signalling our own child.
        unsafe {
            libc::kill(c.id() as i32, libc::SIGTERM);
            libc::kill(c.id() as i32, libc::SIGCONT);
        }
    }
    let end = Instant::now() + Duration::from_secs(3);
    for c in &mut children {
        while Instant::now() < end {
            if let Ok(Some(_)) = c.try_wait() {
                break;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = c.kill();
        let _ = c.wait();
    }
}

/// The stack binary `name`, next to this executable.
pub fn binary(name: &str) -> Result<PathBuf> {
    let dir = std::env::current_exe()?
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_default();
    let p = dir.join(name);
    if !p.is_file() {
        anyhow::bail!(
            "{} not found next to landing (build the workspace: cargo build --release)",
            p.display()
        );
    }
    Ok(p)
}

/// The real-time scheduling the deployment gives `binary`: `CPUSchedulingPolicy=fifo`
/// and `CPUSchedulingPriority` of its systemd drop-ins in `deploy/systemd` (the camera ->
/// fsm -> px4-link path), so that a run on this machine schedules the path as the
/// vehicle does. CPU affinity is the Jetson's and is not applied here.
pub fn deploy_fifo_priority(deploy: &Path, binary: &str) -> Option<i32> {
    let dir = deploy
        .join("systemd")
        .join(format!("landing@{binary}.service.d"));
    let mut fifo = false;
    let mut priority = None;
    for entry in std::fs::read_dir(dir).ok()?.flatten() {
        let text = std::fs::read_to_string(entry.path()).unwrap_or_default();
        for line in text.lines().map(str::trim) {
            match line.split_once('=') {
                Some(("CPUSchedulingPolicy", v)) => fifo = v.trim() == "fifo",
                Some(("CPUSchedulingPriority", v)) => priority = v.trim().parse().ok(),
                _ => {}
            }
        }
    }
    priority.filter(|p| fifo && (1..=99).contains(p))
}

/// Puts process `pid` under SCHED_FIFO at `priority`; the OS's error when refused.
pub fn set_fifo(pid: u32, priority: i32) -> std::io::Result<()> {
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: `param` is valid for the call; `pid` is our child.
    let rc = unsafe { libc::sched_setscheduler(pid as i32, libc::SCHED_FIFO, &param) };
    if rc == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

/// A free local UDP port (bound and released).
pub fn free_udp_port() -> Result<u16> {
    Ok(UdpSocket::bind("127.0.0.1:0")?.local_addr()?.port())
}
