//! The supervision source: the liveness of the stack's processes as the runtime sees it,
//! delivered to the watchdog stage as `watchdog/liveness` messages. A heartbeat event of a
//! process is a beat; a node of the stack that is listed dead, or that was alive and is
//! no longer listed, is a death (whoever cleaned it up first). At its next wait, after the
//! death is delivered, the source removes the dead node's resources, so that the ports
//! of the others let go of it. The beats are read last in each wait, after a look at the
//! nodes or a cleanup however long: the deadlines are judged right after it.
//! Every [`CPU_PERIOD_NS`] it also reads each listed process's CPU time from
//! `/proc/<pid>/stat` (the node list names the pid), for the watchdog's view.

use std::time::Duration;

use iceoryx2::port::listener::Listener;
use ipc_types::msg::{Header, ProcessEvent, ProcessEventKind, Text};
use ipc_types::topics;
use stage::{Counter, External, Flow, Input, Message, StageError};

use crate::ipc::{Ipc, IpcPrefix, NodeError, ServiceError, Svc, wait_any_readable};

/// One watched process.
struct Watched {
    name: String,
    heartbeat: Listener<Svc>,
    /// Seen alive in the node list, with this node id.
    listed: Option<u128>,
    /// Reported dead since it was last seen alive.
    reported: bool,
    /// Its process, from the node list.
    pid: Option<u32>,
}

/// How often the CPU time of each watched process is read, ns.
pub const CPU_PERIOD_NS: u64 = 1_000_000_000;

/// The CPU time (user and system, every thread) process `pid` has used, ns, from
/// `/proc/<pid>/stat`; `None` when it cannot be read (gone, not Linux).
pub fn process_cpu_ns(pid: u32) -> Option<u64> {
    let stat = ProcStat::read(pid)?;
    let utime = stat.number(14)?;
    let stime = stat.number(15)?;
    // SAFETY: sysconf reads a constant of the system; no memory is touched.
    let ticks = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    let ticks = u64::try_from(ticks).ok().filter(|t| *t > 0)?;
    Some((utime + stime).saturating_mul(1_000_000_000) / ticks)
}

/// `/proc/<pid>/stat`, read once: its fields by their number in proc(5).
struct ProcStat(String);

impl ProcStat {
    fn read(pid: u32) -> Option<Self> {
        std::fs::read_to_string(format!("/proc/{pid}/stat"))
            .ok()
            .map(Self)
    }

    /// Field `n` (3 or more). The command name (field 2) is in parentheses and may hold
    /// spaces: fields are counted from the last ')'.
    fn field(&self, n: usize) -> Option<&str> {
        let rest = self.0.get(self.0.rfind(')')? + 1..)?;
        rest.split_whitespace().nth(n.checked_sub(3)?)
    }

    fn number(&self, n: usize) -> Option<u64> {
        self.field(n)?.parse().ok()
    }
}

/// Whether process `pid` is on its way out by a fault: a SIGKILL pending, or exiting (or
/// a zombie) with a status other than a clean exit 0 (`/proc/<pid>/stat` and `status`). A
/// killed process keeps its iceoryx2 node alive until it is reaped, which on a loaded
/// machine can come later than its heartbeat deadline: without this the watchdog called
/// a killed fsm hung (176 ms after the kill, in `make test`), and a hang is decided at once
/// where a death waits for its restart. A process stopping cleanly (SIGTERM, exit 0) is not
/// dying: its node goes as before. False when it cannot tell (no such process, not Linux):
/// the node list decides then.
pub fn process_is_dying(pid: u32) -> bool {
    /// `PF_EXITING` in the flags of `/proc/<pid>/stat` (include/linux/sched.h).
    const PF_EXITING: u64 = 0x4;
    /// SIGKILL's bit in the pending-signal masks of `/proc/<pid>/status`.
    const SIGKILL_BIT: u64 = 1 << (libc::SIGKILL - 1);
    let Some(stat) = ProcStat::read(pid) else {
        return false;
    };
    // The state is field 3, the flags field 9 and the exit status (as waitpid reports it,
    // Linux 3.5+) field 52.
    let exiting = matches!(stat.field(3), Some("Z" | "X" | "x"))
        || stat.number(9).is_some_and(|f| f & PF_EXITING != 0);
    if exiting && stat.number(52).is_some_and(|code| code != 0) {
        return true;
    }
    let Ok(status) = std::fs::read_to_string(format!("/proc/{pid}/status")) else {
        return false;
    };
    status.lines().any(|l| {
        let mask = |key: &str| {
            l.strip_prefix(key)
                .and_then(|v| u64::from_str_radix(v.trim(), 16).ok())
        };
        mask("ShdPnd:")
            .or_else(|| mask("SigPnd:"))
            .is_some_and(|m| m & SIGKILL_BIT != 0)
    })
}

/// Why the supervision source could not start.
#[derive(Debug, thiserror::Error)]
pub enum SupervisionError {
    /// Its iceoryx2 node.
    #[error(transparent)]
    Node(#[from] NodeError),
    /// A heartbeat service.
    #[error(transparent)]
    Service(#[from] ServiceError),
}

/// Heartbeats and node deaths of the watched processes, as an [`External`] source. It
/// has its own iceoryx2 node (`<process>-supervision`), listed alive beside the stage's.
pub struct Supervision {
    watched: Vec<Watched>,
    poll_ns: u64,
    next_poll_ns: u64,
    next_cpu_ns: u64,
    seq: u64,
    beats: u64,
    /// Beats read from a process reported dead and not listed since (sent before it
    /// died).
    stale_beats: u64,
    deaths: u64,
    cleaned: u64,
    /// Dead nodes were listed: their resources are removed at the start of the next
    /// wait, after the deaths are delivered (so the cleanup does not delay them).
    cleanup_due: bool,
    /// Last: fields drop in order, and the node must outlive the heartbeat listeners
    /// made from it. Dropped before them, its `Drop` still saw itself alive and left the
    /// prefix's node-counter segment behind when the stack stopped.
    ipc: Ipc,
}

impl Supervision {
    /// Watches `processes` (name, heartbeat deadline) of the stack under `prefix` for the
    /// process `owner`, listing its nodes every `poll`.
    pub fn open(
        owner: &str,
        prefix: &IpcPrefix,
        processes: &[(String, Duration)],
        poll: Duration,
    ) -> Result<Self, SupervisionError> {
        let ipc = Ipc::open(&format!("{owner}-supervision"), prefix)?;
        let mut watched = Vec::with_capacity(processes.len());
        for (name, deadline) in processes {
            watched.push(Watched {
                name: name.clone(),
                heartbeat: ipc.heartbeat_listener(name, *deadline)?,
                listed: None,
                reported: false,
                pid: None,
            });
        }
        Ok(Self {
            ipc,
            watched,
            poll_ns: u64::try_from(poll.as_nanos()).unwrap_or(u64::MAX).max(1),
            next_poll_ns: 0,
            next_cpu_ns: 0,
            seq: 0,
            beats: 0,
            stale_beats: 0,
            deaths: 0,
            cleaned: 0,
            cleanup_due: false,
        })
    }

    fn event(
        &mut self,
        k: usize,
        kind: ProcessEventKind,
        now_ns: u64,
        cpu_ns: u64,
    ) -> ProcessEvent {
        self.seq += 1;
        ProcessEvent {
            msg: Header {
                seq: self.seq,
                ..Header::captured_at(now_ns)
            },
            process: Text::new(&self.watched[k].name),
            kind: kind as u32,
            reserved: 0,
            cpu_ns,
        }
    }

    /// Lists the stack's nodes; the watched processes that died since the last look.
    fn poll_nodes(&mut self) -> Vec<usize> {
        let Some(nodes) = self.ipc.nodes() else {
            return Vec::new();
        };
        let mut died = Vec::new();
        for (k, w) in self.watched.iter_mut().enumerate() {
            // A node whose process is being killed is dead already.
            let node = nodes
                .iter()
                .find(|n| n.alive && n.name == w.name && !n.pid.is_some_and(process_is_dying));
            w.pid = node.and_then(|n| n.pid);
            let alive = node.map(|n| n.id);
            match (w.listed, alive) {
                // Restarted between two looks (systemd is quick): the node it had is
                // gone, another of its name is here. A death, and alive again.
                (Some(before), Some(now)) if before != now => {
                    w.listed = alive;
                    w.reported = false;
                    died.push(k);
                }
                (_, Some(_)) => {
                    w.listed = alive;
                    w.reported = false;
                }
                (Some(_), None) if !w.reported => {
                    w.listed = None;
                    w.reported = true;
                    died.push(k);
                }
                _ => {}
            }
        }
        self.cleanup_due = nodes.iter().any(|n| !n.alive);
        died
    }
}

impl External for Supervision {
    fn topics(&self) -> &[&'static str] {
        &[topics::WATCHDOG_LIVENESS]
    }

    fn wait(
        &mut self,
        timeout_ns: u64,
        clock: &dyn Fn() -> u64,
        deliver: &mut dyn FnMut(Input<'_>, u64) -> Result<(), StageError>,
    ) -> Result<Flow, StageError> {
        let mut timeout_ns = timeout_ns;
        if self.cleanup_due {
            // Found dead at the last look and reported then; cleaned up now, before the
            // beats of this wait are read (a cleanup took 180 ms on a loaded machine).
            self.cleanup_due = false;
            self.cleaned += self.ipc.cleanup_dead_nodes();
            timeout_ns = 0;
        }
        let now = clock();
        let until_poll = self.next_poll_ns.saturating_sub(now);
        let listeners: Vec<&Listener<Svc>> = self.watched.iter().map(|w| &w.heartbeat).collect();
        let ready = wait_any_readable(&listeners, timeout_ns.min(until_poll));
        let at = clock();
        let mut events = Vec::new();
        // A beat from a process reported dead is a restarted one only if its node is
        // listed again: look now rather than at the next poll.
        let beat_from_the_dead = ready
            .iter()
            .zip(&self.watched)
            .any(|(r, w)| *r && w.reported);
        if at >= self.next_poll_ns || beat_from_the_dead {
            self.next_poll_ns = at + self.poll_ns;
            // Stamped after the look: listing the nodes takes milliseconds, and a death
            // it finds may be younger than the wake-up.
            let died = self.poll_nodes();
            let seen = clock();
            for k in died {
                self.deaths += 1;
                events.push((k, ProcessEventKind::Died, seen, 0));
            }
        }
        // The beats are read after the look, however long it took: the watchdog's
        // deadlines are judged after this wait, and a beat that came meanwhile must
        // count. A beat of a process found dead and not listed since was sent before it
        // died: read late, it would count as a restart, which then hangs (in `make
        // test`, a killed fsm was called hung).
        for k in 0..self.watched.len() {
            let w = &self.watched[k];
            if w.heartbeat.try_wait(|_| {}).unwrap_or(0) == 0 {
                continue;
            }
            if w.reported {
                self.stale_beats += 1;
            } else {
                self.beats += 1;
                events.push((k, ProcessEventKind::Beat, clock(), 0));
            }
        }
        if at >= self.next_cpu_ns {
            self.next_cpu_ns = at + CPU_PERIOD_NS;
            for (k, w) in self.watched.iter().enumerate() {
                if let Some(cpu) = w.pid.and_then(process_cpu_ns) {
                    events.push((k, ProcessEventKind::Cpu, clock(), cpu));
                }
            }
        }
        for (k, kind, at, cpu) in events {
            let e = self.event(k, kind, at, cpu);
            let input = Input {
                topic: topics::WATCHDOG_LIVENESS,
                msg: Message::ProcessEvent(&e),
            };
            deliver(input, at)?;
        }
        Ok(Flow::Open)
    }

    fn send(&mut self, topic: &str, _msg: Message<'_>) -> Result<(), StageError> {
        Err(StageError::Transport(format!(
            "the supervision source takes nothing (`{topic}`)"
        )))
    }

    fn counters(&self) -> Vec<Counter> {
        vec![
            ("heartbeat_events", self.beats),
            ("stale_beats", self.stale_beats),
            ("nodes_gone", self.deaths),
            ("dead_nodes_cleaned", self.cleaned),
        ]
    }
}

#[cfg(test)]
#[path = "supervise_test.rs"]
mod tests;
