//! Test peer: runs the runtime's wait loop (a subscriber, its own heartbeat, a tick) until
//! a signal ends it, then says how it ended. The `signals` test sends SIGTERM/SIGINT.
//!
//! Usage: `wait-loop-probe PREFIX [poll]` - with `poll`, the way the simulator and
//! camera-ingest look for a stop instead: a paced loop asking `Ipc::shutdown_requested`.

use std::io::Write;
use std::time::Duration;

use anyhow::{Result, bail};
use runtime::{Ipc, IpcPrefix, LoopExit, Wake, run_wait_loop};

fn main() -> Result<()> {
    let Some(prefix) = std::env::args().nth(1) else {
        bail!("usage: wait-loop-probe PREFIX");
    };
    let ipc = Ipc::open("wait-loop-probe", &IpcPrefix::new(&prefix)?)?;
    let sub = ipc.subscriber::<u64>("test/signals")?;
    let mut heartbeat = ipc.heartbeat(Duration::from_millis(500))?;
    println!("ready");
    std::io::stdout().flush()?;
    if std::env::args().nth(2).as_deref() == Some("poll") {
        while !ipc.shutdown_requested() {
            std::thread::sleep(Duration::from_millis(20));
        }
        println!("exit=signal");
        return Ok(());
    }
    let exit = run_wait_loop(
        &[sub.listener()],
        &[],
        Some(Duration::from_millis(50)),
        |wake| {
            if wake == Wake::Tick {
                let _ = heartbeat.beat();
            }
            true
        },
    )?;
    let name = match exit {
        LoopExit::Signal => "signal",
        LoopExit::Stopped => "stopped",
    };
    println!("exit={name}");
    Ok(())
}
