//! The stack's shared memory belongs to the user that runs it (issue 20): another user
//! on the host can neither publish into the stack nor read it, and every iceoryx2
//! resource of the stack is readable and writable by its owner only, but for the one
//! iceoryx2 makes world-writable itself (docs/security.md says which and why it is
//! left).
//!
//! The other user is `nobody` (65534): a copy of this test binary started as that user
//! tries to open the stack's pad-observation service and publish on it.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::os::unix::process::CommandExt;
use std::process::Command;
use std::time::Duration;

use ipc_types::msg::{Header, PadObservation};
use ipc_types::services;
use runtime::{Ipc, IpcPrefix};

/// Set in the copy of this binary that plays the other process.
const CHILD: &str = "LANDING_TEST_INTRUDER_PREFIX";
const NAME: &str = "another_user_can_neither_publish_into_nor_read_the_stack";

/// The other process: opens the service and publishes, or says why it could not.
fn intruder(prefix: &str) {
    let outcome = IpcPrefix::new(prefix)
        .map_err(|e| e.to_string())
        .and_then(|p| Ipc::open("intruder", &p).map_err(|e| e.to_string()))
        .and_then(|ipc| {
            let mut p = ipc
                .publisher::<PadObservation>(services::PAD_OBSERVATION)
                .map_err(|e| e.to_string())?;
            // The owner's subscriber connects to a new publisher on its next look.
            std::thread::sleep(Duration::from_millis(300));
            p.send(Header::captured_at(7), &PadObservation::default())
                .map_err(|e| e.to_string())?;
            std::thread::sleep(Duration::from_millis(500));
            Ok(())
        });
    match outcome {
        Ok(()) => println!("INTRUDER published"),
        Err(e) => println!("INTRUDER refused: {e}"),
    }
}

/// Runs the intruder; returns what it said and the capture times of the samples `sub`
/// took while it ran.
fn run_intruder(
    prefix: &IpcPrefix,
    as_nobody: bool,
    sub: &runtime::Subscriber<PadObservation>,
) -> (String, Vec<u64>) {
    let mut cmd = Command::new(std::env::current_exe().unwrap());
    cmd.args(["--exact", NAME, "--nocapture", "--test-threads", "1"])
        .env(CHILD, prefix.as_str())
        .stdout(std::process::Stdio::piped());
    if as_nobody {
        cmd.uid(65534).gid(65534);
    }
    let mut child = cmd.spawn().unwrap();
    let mut got = Vec::new();
    while child.try_wait().unwrap().is_none() {
        while let Some(s) = sub.receive().unwrap() {
            got.push(s.user_header().capture_ns);
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let o = child.wait_with_output().unwrap();
    (String::from_utf8_lossy(&o.stdout).to_string(), got)
}

#[test]
fn another_user_can_neither_publish_into_nor_read_the_stack() {
    if let Ok(prefix) = std::env::var(CHILD) {
        intruder(&prefix);
        return;
    }
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        eprintln!(
            "not root: cannot start a process as another user; the permission check below still runs"
        );
    }
    let prefix = IpcPrefix::unique("seconduser");
    let ipc = Ipc::open("owner", &prefix).unwrap();
    let sub = ipc
        .subscriber::<PadObservation>(services::PAD_OBSERVATION)
        .unwrap();
    let mut own = ipc
        .publisher::<PadObservation>(services::PAD_OBSERVATION)
        .unwrap();
    own.send(Header::captured_at(1), &PadObservation::default())
        .unwrap();

    // Another process of the same user gets in (the test of the test).
    let (same, got) = run_intruder(&prefix, false, &sub);
    assert!(same.contains("INTRUDER published"), "{same}");
    assert_eq!(got, vec![1, 7], "the same user's second process");

    // SAFETY: as above.
    if unsafe { libc::geteuid() } == 0 {
        let (other, got) = run_intruder(&prefix, true, &sub);
        assert!(other.contains("INTRUDER refused"), "nobody got in: {other}");
        assert!(got.is_empty(), "samples from nobody arrived: {got:?}");
    }

    // Every resource of this prefix: owner-only, but iceoryx2's global management
    // segment (a node counter), which it creates world-writable.
    let mut checked = 0;
    let mut open = Vec::new();
    for dir in [
        "/dev/shm",
        "/tmp/iceoryx2",
        "/tmp/iceoryx2/services",
        "/tmp/iceoryx2/nodes",
    ] {
        let Ok(entries) = std::fs::read_dir(dir) else {
            continue;
        };
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().to_string();
            if !name.starts_with(prefix.as_str()) {
                continue;
            }
            let m = std::fs::symlink_metadata(e.path()).unwrap();
            checked += 1;
            // SAFETY: as above.
            assert_eq!(m.uid(), unsafe { libc::geteuid() }, "{name}");
            let mode = m.permissions().mode() & 0o777;
            if mode & 0o077 != 0 {
                open.push(format!("{dir}/{name} {mode:o}"));
            }
        }
    }
    assert!(
        checked >= 4,
        "{checked} resources found for {}",
        prefix.as_str()
    );
    assert!(
        open.iter().all(|o| o.contains(".global_mgmt ")),
        "resources others may read or write: {open:?}"
    );
}
