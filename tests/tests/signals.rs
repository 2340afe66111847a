//! A process in the runtime's wait loop ends cleanly on SIGTERM (systemd stop) and SIGINT
//! (Ctrl-C): it returns from the loop, says why, drops its iceoryx2 resources and exits 0.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};

use runtime::IpcPrefix;

fn ends_cleanly_on(signal: i32, expected: &str) {
    let prefix = IpcPrefix::unique("signals");
    let mut child = Command::new(env!("CARGO_BIN_EXE_wait-loop-probe"))
        .arg(prefix.as_str())
        .stdout(Stdio::piped())
        .spawn()
        .expect("start probe");
    let mut out = BufReader::new(child.stdout.take().expect("stdout"));
    let mut line = String::new();
    out.read_line(&mut line).expect("ready line");
    assert_eq!(line.trim(), "ready");
    std::thread::sleep(std::time::Duration::from_millis(200));
    // SAFETY: sending a signal to our own child process, whose pid is valid until waited.
    let rc = unsafe { libc::kill(child.id() as i32, signal) };
    assert_eq!(rc, 0);
    line.clear();
    out.read_line(&mut line).expect("exit line");
    let status = child.wait().expect("exit status");
    assert_eq!(line.trim(), format!("exit={expected}"));
    assert!(status.success(), "{status}");
}

#[test]
fn the_wait_loop_ignores_a_harmless_signal() {
    let prefix = IpcPrefix::unique("sigchld");
    let mut child = Command::new(env!("CARGO_BIN_EXE_wait-loop-probe"))
        .arg(prefix.as_str())
        .stdout(Stdio::piped())
        .spawn()
        .expect("start probe");
    let mut out = BufReader::new(child.stdout.take().expect("stdout"));
    let mut line = String::new();
    out.read_line(&mut line).expect("ready line");
    std::thread::sleep(std::time::Duration::from_millis(100));
    // SAFETY: signalling our own child.
    unsafe { libc::kill(child.id() as i32, libc::SIGCHLD) };
    std::thread::sleep(std::time::Duration::from_millis(300));
    assert!(
        child.try_wait().expect("poll").is_none(),
        "SIGCHLD ended the loop"
    );
    // SAFETY: signalling our own child.
    unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
    line.clear();
    out.read_line(&mut line).expect("exit line");
    assert_eq!(line.trim(), "exit=signal");
    assert!(child.wait().expect("exit").success());
}

#[test]
fn the_wait_loop_ends_cleanly_on_sigterm() {
    ends_cleanly_on(libc::SIGTERM, "signal");
}

#[test]
fn the_wait_loop_ends_cleanly_on_sigint() {
    ends_cleanly_on(libc::SIGINT, "signal");
}

fn stop_then_sigcont(mode: &[&str]) {
    let prefix = IpcPrefix::unique("sigcont");
    let mut child = Command::new(env!("CARGO_BIN_EXE_wait-loop-probe"))
        .arg(prefix.as_str())
        .args(mode)
        .stdout(Stdio::piped())
        .spawn()
        .expect("start probe");
    let mut out = BufReader::new(child.stdout.take().expect("stdout"));
    let mut line = String::new();
    out.read_line(&mut line).expect("ready line");
    std::thread::sleep(std::time::Duration::from_millis(50));
    // SAFETY: signalling our own child, twice in a row.
    unsafe {
        libc::kill(child.id() as i32, libc::SIGTERM);
        libc::kill(child.id() as i32, libc::SIGCONT);
    }
    let started = std::time::Instant::now();
    while child.try_wait().expect("poll").is_none() {
        if started.elapsed() > std::time::Duration::from_secs(3) {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{mode:?}: SIGTERM followed by SIGCONT was lost");
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    line.clear();
    out.read_line(&mut line).expect("exit line");
    assert_eq!(line.trim(), "exit=signal");
}

#[test]
fn a_stop_followed_at_once_by_sigcont_still_ends_the_loop() {
    // systemd and `timeout` send SIGTERM then SIGCONT; iceoryx2 alone remembers only the
    // last signal, so the stop could be lost. Both ways processes wait for a stop.
    for _ in 0..5 {
        stop_then_sigcont(&[]);
        stop_then_sigcont(&["poll"]);
    }
}
