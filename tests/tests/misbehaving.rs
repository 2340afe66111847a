//! Misbehaving stages (`landing_tests::misbehaving`) under the iceoryx2 driver, watched by
//! the watchdog as the shipped graph's aruco-pnp: a panic and an error end the process
//! (exit code 101, and 2 with one line naming the error) and the watchdog reports it
//! dead; a stage that never returns stops beating and is reported hung; NaN in its pad
//! observations is reported as garbage on the path. Behaviour only.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test

use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use ipc_types::msg::{FaultOrder, Liveness, PortFault, Text, WatchdogView};
use ipc_types::services;
use landing_tests::stack::{deploy_dir, stack_binary};
use runtime::{Ipc, IpcPrefix, Subscriber};

fn start(bin: &std::path::Path, prefix: &str, extra: &[&str]) -> Child {
    let deploy = deploy_dir();
    Command::new(bin)
        .env("LANDING_FAULT_INJECTION", "1")
        .arg("--config")
        .arg(deploy.join("config/landing.toml"))
        .arg("--deploy-dir")
        .arg(&deploy)
        .args(["--ipc-prefix", prefix])
        .args(extra)
        .env("LANDING_LOG", "warn")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// The first view that passes `want`, 20 s at most.
fn wait_for(views: &Subscriber<WatchdogView>, what: &str, want: impl Fn(&WatchdogView) -> bool) {
    let end = Instant::now() + Duration::from_secs(20);
    let mut last = None;
    while Instant::now() < end {
        while let Some(v) = views.receive().unwrap() {
            last = Some(*v.payload());
        }
        if last.as_ref().is_some_and(&want) {
            return;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    panic!("never {what}; last view: {last:?}");
}

fn liveness(v: &WatchdogView, process: &str) -> Option<Liveness> {
    v.processes[..v.count as usize]
        .iter()
        .find(|p| p.name.as_str() == process)
        .map(|p| Liveness::from_raw(p.liveness))
}

/// The watchdog and a stage misbehaving by `mode`; `check` on the watchdog's views.
/// Returns the stage's exit code and stderr (it is stopped if it still runs).
fn misbehave(mode: &str, check: impl Fn(&Ipc, &Subscriber<WatchdogView>)) -> (Option<i32>, String) {
    let tag = format!("mis{}{}", &mode[..1], std::process::id());
    let prefix = IpcPrefix::new(&format!("{tag}_")).unwrap();
    let ipc = Ipc::open("misbehaving-test", &prefix).unwrap();
    let views = ipc
        .subscriber::<WatchdogView>(services::WATCHDOG_VIEW)
        .unwrap();
    let mut watchdog = start(&stack_binary("watchdog"), prefix.as_str(), &[]);
    let mut stage = start(
        std::path::Path::new(env!("CARGO_BIN_EXE_misbehaving")),
        prefix.as_str(),
        &["--mode", mode],
    );
    wait_for(&views, "aruco-pnp alive", |v| {
        liveness(v, "aruco-pnp") == Some(Liveness::Alive)
    });
    check(&ipc, &views);
    for c in [&stage, &watchdog] {
        // SAFETY: signalling our own children.
        unsafe { libc::kill(c.id() as i32, libc::SIGTERM) };
    }
    let end = Instant::now() + Duration::from_secs(5);
    while stage.try_wait().unwrap().is_none() && Instant::now() < end {
        std::thread::sleep(Duration::from_millis(20));
    }
    if stage.try_wait().unwrap().is_none() {
        // A hung stage does not hear SIGTERM: its driver thread never returns.
        stage.kill().unwrap();
    }
    let status = stage.wait_with_output().unwrap();
    watchdog.wait().unwrap();
    (
        status.status.code(),
        String::from_utf8_lossy(&status.stderr).to_string(),
    )
}

#[test]
fn a_stage_that_panics_ends_its_process_and_is_reported_dead() {
    let (code, err) = misbehave("panic", |_, views| {
        wait_for(views, "aruco-pnp dead", |v| {
            liveness(v, "aruco-pnp") == Some(Liveness::Dead)
        });
    });
    assert_eq!(code, Some(101), "{err}");
    assert!(err.contains("misbehaving stage: panic"), "{err}");
}

#[test]
fn a_stage_that_fails_ends_its_process_with_one_line_and_is_reported_dead() {
    let (code, err) = misbehave("fail", |_, views| {
        wait_for(views, "aruco-pnp dead", |v| {
            liveness(v, "aruco-pnp") == Some(Liveness::Dead)
        });
    });
    assert_eq!(code, Some(2), "{err}");
    let lines: Vec<&str> = err.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(lines.len(), 1, "{err}");
    assert!(lines[0].contains("misbehaving stage: error"), "{err}");
}

#[test]
fn a_stage_that_never_returns_stops_beating_and_is_reported_hung() {
    misbehave("hang", |_, views| {
        wait_for(views, "aruco-pnp hung", |v| {
            liveness(v, "aruco-pnp") == Some(Liveness::Hung)
        });
    });
}

#[test]
fn a_stage_that_publishes_nan_is_reported_as_garbage_on_its_path() {
    misbehave("nan", |_, views| {
        wait_for(views, "garbage on pad/observation", |v| {
            v.last_fault.as_str().contains("garbage on pad/observation")
        });
    });
}

#[test]
fn a_delay_fault_makes_data_late_but_never_makes_the_process_look_hung() {
    // Three outputs per round, each held 100 ms: a round lasts over 300 ms, beyond the
    // 250 ms heartbeat deadline, yet the process is alive and must be seen so.
    misbehave("burst", |ipc, views| {
        let observations = ipc
            .subscriber_with_depth::<ipc_types::msg::PadObservation>(services::PAD_OBSERVATION, 16)
            .unwrap();
        let mut orders = ipc.publisher::<FaultOrder>(services::FAULT_INJECT).unwrap();
        let order = FaultOrder {
            process: Text::new("aruco-pnp"),
            fault: PortFault::Delay as u32,
            value: 100.0,
            ..FaultOrder::default()
        };
        orders.send(order.msg, &order).unwrap();
        let end = Instant::now() + Duration::from_secs(4);
        let mut views_seen = 0;
        let mut published = 0;
        while Instant::now() < end {
            while observations.receive().unwrap().is_some() {
                published += 1;
            }
            while let Some(v) = views.receive().unwrap() {
                views_seen += 1;
                let l = liveness(v.payload(), "aruco-pnp");
                assert_ne!(l, Some(Liveness::Hung), "{:?}", v.payload().last_fault);
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        assert!(views_seen > 5, "{views_seen} views");
        // The delay held: 150 in 4 s without it, at most 40 with it.
        assert!((1..=45).contains(&published), "{published} observations");
    });
}
