#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test
//! The `watchdog` binary against real processes of the stack (the planner, started on
//! its own): a SIGKILLed process is reported dead and, started again, alive (it
//! reconnects: the watchdog removed the dead node's resources); a SIGSTOPped one is
//! hung until SIGCONT; under systemd's notify protocol it says READY=1, WATCHDOG=1 and
//! STOPPING=1. Behaviour only: how fast is `landing bench faults`.

use std::os::unix::net::UnixDatagram;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use ipc_types::msg::{Liveness, WatchdogView};
use ipc_types::services;
use runtime::{Ipc, IpcPrefix, Subscriber};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// A stack binary built beside this one (`cargo build --workspace` builds them all).
fn bin(name: &str) -> PathBuf {
    let p = Path::new(env!("CARGO_BIN_EXE_watchdog")).with_file_name(name);
    assert!(
        p.exists(),
        "{} is not built: cargo build --release --workspace",
        p.display()
    );
    p
}

fn start(name: &str, prefix: &str, env: &[(&str, &str)]) -> Child {
    let deploy = root().join("deploy");
    Command::new(bin(name))
        .arg("--config")
        .arg(deploy.join("config/landing.toml"))
        .arg("--deploy-dir")
        .arg(&deploy)
        .args(["--ipc-prefix", prefix])
        .envs(env.iter().copied())
        .env("LANDING_LOG", "warn")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap()
}

fn signal(child: &Child, sig: libc::c_int) {
    // SAFETY: signalling our own child.
    unsafe { libc::kill(child.id() as i32, sig) };
}

fn stop(mut child: Child) {
    signal(&child, libc::SIGCONT);
    signal(&child, libc::SIGTERM);
    child.wait().unwrap();
}

/// The health the newest views give `process`, until one passes `want` (30 s at most).
fn wait_for(views: &Subscriber<WatchdogView>, process: &str, want: Liveness) -> WatchdogView {
    let end = Instant::now() + Duration::from_secs(30);
    let mut last = None;
    while Instant::now() < end {
        while let Some(v) = views.receive().unwrap() {
            last = Some(*v.payload());
        }
        if let Some(v) = &last {
            let p = v.processes[..v.count as usize]
                .iter()
                .find(|p| p.name.as_str() == process)
                .unwrap_or_else(|| panic!("the watchdog does not watch {process}"));
            if Liveness::from_raw(p.liveness) == want {
                return *v;
            }
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    panic!("{process} never {want:?}; last view: {last:?}");
}

fn health(v: &WatchdogView, process: &str) -> ipc_types::msg::ProcessHealth {
    *v.processes
        .iter()
        .find(|p| p.name.as_str() == process)
        .unwrap()
}

#[test]
fn a_killed_process_is_dead_to_the_watchdog_and_alive_again_once_restarted() {
    let prefix = format!("wdkill{}_", std::process::id());
    let ipc = Ipc::open("wdtest", &IpcPrefix::new(&prefix).unwrap()).unwrap();
    let views = ipc
        .subscriber::<WatchdogView>(services::WATCHDOG_VIEW)
        .unwrap();
    let dog = start("watchdog", &prefix, &[]);
    let mut planner = start("planner", &prefix, &[]);
    wait_for(&views, "planner", Liveness::Alive);
    signal(&planner, libc::SIGKILL);
    planner.wait().unwrap();
    let v = wait_for(&views, "planner", Liveness::Dead);
    assert!(health(&v, "planner").fault_ns > 0);
    assert_eq!(v.last_fault.as_str(), "planner died");
    assert_eq!(v.safe_land_ordered, 0, "on the ground nothing is ordered");
    // Restarted (as systemd would): it reconnects and beats again.
    let planner = start("planner", &prefix, &[]);
    wait_for(&views, "planner", Liveness::Alive);
    stop(planner);
    stop(dog);
}

#[test]
fn a_stopped_process_is_hung_to_the_watchdog_until_it_resumes() {
    let prefix = format!("wdstop{}_", std::process::id());
    let ipc = Ipc::open("wdtest", &IpcPrefix::new(&prefix).unwrap()).unwrap();
    let views = ipc
        .subscriber::<WatchdogView>(services::WATCHDOG_VIEW)
        .unwrap();
    let dog = start("watchdog", &prefix, &[]);
    let planner = start("planner", &prefix, &[]);
    wait_for(&views, "planner", Liveness::Alive);
    signal(&planner, libc::SIGSTOP);
    let v = wait_for(&views, "planner", Liveness::Hung);
    assert_eq!(health(&v, "planner").missed_deadlines, 1);
    assert_eq!(v.last_fault.as_str(), "planner hung");
    signal(&planner, libc::SIGCONT);
    wait_for(&views, "planner", Liveness::Alive);
    stop(planner);
    stop(dog);
}

#[test]
fn under_systemd_the_watchdog_says_ready_beats_its_unit_watchdog_and_says_stopping() {
    let prefix = format!("wdnotify{}_", std::process::id());
    let dir = std::env::temp_dir().join(format!("wdnotify-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("notify.sock");
    let _ = std::fs::remove_file(&path);
    let sock = UnixDatagram::bind(&path).unwrap();
    sock.set_read_timeout(Some(Duration::from_secs(20)))
        .unwrap();
    let dog = start(
        "watchdog",
        &prefix,
        &[
            ("NOTIFY_SOCKET", path.to_str().unwrap()),
            ("WATCHDOG_USEC", "1000000"),
        ],
    );
    let mut got = Vec::new();
    let mut buf = [0u8; 256];
    while !got.iter().any(|m: &String| m == "WATCHDOG=1") {
        let n = sock.recv(&mut buf).expect("a notification within 20 s");
        got.push(String::from_utf8_lossy(&buf[..n]).to_string());
    }
    assert_eq!(got[0], "READY=1", "{got:?}");
    stop(dog);
    let mut last = String::new();
    while let Ok(n) = sock.recv(&mut buf) {
        last = String::from_utf8_lossy(&buf[..n]).to_string();
        if last == "STOPPING=1" {
            break;
        }
    }
    assert_eq!(last, "STOPPING=1");
    let _ = std::fs::remove_dir_all(&dir);
}
