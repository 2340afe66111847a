//! Worker processes fed one run at a time over pipes: a worker gets its next run when it
//! reports the last one written, so the slow runs of one scenario do not hold the others
//! back. Which worker flies a run changes nothing in its file: its seed is the run's.

use std::io::{BufRead, BufReader, Write};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc;

use anyhow::{Context, Result, bail};

use crate::{Campaign, Task};

/// One run reported done.
#[derive(Debug, Clone, PartialEq)]
pub struct Done {
    /// The run.
    pub task: Task,
    /// Its outcome.
    pub outcome: String,
}

struct Slot {
    child: Child,
    stdin: Option<ChildStdin>,
    busy: Option<Task>,
}

impl Drop for Slot {
    fn drop(&mut self) {
        // A worker still running when the campaign ends early is stopped, not orphaned.
        self.stdin.take();
        if self.busy.is_some() {
            let _ = self.child.kill();
        }
        let _ = self.child.wait();
    }
}

fn give(slot: &mut Slot, campaign: &Campaign, task: Task) -> Result<()> {
    let plan = &campaign.scenarios[task.scenario];
    let stdin = slot.stdin.as_mut().context("a worker without its stdin")?;
    writeln!(
        stdin,
        "{}\t{}\t{}\t{}",
        task.index, task.seed, plan.hash, plan.spec
    )?;
    stdin.flush()?;
    slot.busy = Some(task);
    Ok(())
}

/// Flies `tasks` with `jobs` worker processes, each started by `worker(k)` (its stdin and
/// stdout are the pool's); `done` hears of each run as its file is written. A worker that
/// reports an error or dies ends the pool with that error.
pub fn run(
    campaign: &Campaign,
    tasks: Vec<Task>,
    jobs: usize,
    mut worker: impl FnMut(usize) -> Command,
    mut done: impl FnMut(&Done),
) -> Result<()> {
    let mut queue = tasks.into_iter();
    let (tx, rx) = mpsc::channel::<(usize, Option<String>)>();
    let mut slots = Vec::new();
    for k in 0..jobs {
        let Some(task) = queue.next() else { break };
        let mut cmd = worker(k);
        cmd.stdin(Stdio::piped()).stdout(Stdio::piped());
        let mut child = cmd.spawn().context("starting a worker process")?;
        let stdout = child.stdout.take().context("a worker without its stdout")?;
        let stdin = child.stdin.take();
        let tx = tx.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines() {
                let Ok(line) = line else { break };
                if tx.send((k, Some(line))).is_err() {
                    return;
                }
            }
            let _ = tx.send((k, None));
        });
        let mut slot = Slot {
            child,
            stdin,
            busy: None,
        };
        give(&mut slot, campaign, task)?;
        slots.push(slot);
    }
    drop(tx);
    while slots.iter().any(|s| s.busy.is_some()) {
        if runtime::shutdown::requested() {
            bail!("interrupted");
        }
        let (k, line) = match rx.recv_timeout(std::time::Duration::from_millis(200)) {
            Ok(m) => m,
            Err(mpsc::RecvTimeoutError::Timeout) => continue,
            Err(mpsc::RecvTimeoutError::Disconnected) => bail!("every worker is gone"),
        };
        let slot = &mut slots[k];
        let Some(line) = line else {
            if let Some(t) = slot.busy.take() {
                let status = slot.child.wait().ok();
                bail!(
                    "worker {k} died flying run {} (seed {}): {}",
                    t.index,
                    t.seed,
                    status.map_or("no exit status".to_string(), |s| s.to_string())
                );
            }
            continue;
        };
        let mut f = line.splitn(3, '\t');
        let (kind, rest) = (f.next().unwrap_or_default(), f.nth(1).unwrap_or_default());
        let Some(task) = slot.busy.take() else {
            bail!("worker {k} reported a run it was not given: {line:?}");
        };
        match kind {
            "ok" => done(&Done {
                task,
                outcome: rest.to_string(),
            }),
            _ => bail!(
                "worker {k} could not fly run {} of {} (seed {}): {rest}",
                task.index,
                campaign.scenarios[task.scenario].name,
                task.seed
            ),
        }
        match queue.next() {
            Some(next) => give(slot, campaign, next)?,
            None => {
                slot.stdin.take();
            }
        }
    }
    Ok(())
}
