#![allow(clippy::unwrap_used, clippy::expect_used)]
//! px4-link as a process against the `sim` process over real UDP, driven through
//! iceoryx2 as fsm and the watchdog would: requests answered, the state climbing in ENU,
//! a safety order landing it at once, a clean stop on SIGTERM.
//!
//! The `sim` binary is found next to this test's executable (`target/release/sim`);
//! `cargo test --release --workspace` builds it.

mod common;

use std::net::UdpSocket;
use std::process::Command;
use std::time::{Duration, Instant};

use ipc_types::msg::{
    FlightMode, Header, LinkOutcome, LinkOutcomeKind, LinkRequest, LinkRequestKind, SafetyAction,
    SafetyCommand, Text, VehicleState,
};
use ipc_types::services;
use landing_tests::process::{Running, sim_binary};
use runtime::IpcPrefix;

fn free_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

#[test]
fn px4_link_flies_the_sim_process_on_requests_and_lands_it_on_a_safety_order() {
    let (sim_port, link_port) = (free_port(), free_port());
    let prefix = IpcPrefix::unique("px4link");
    let _sim = Running::start(
        "sim",
        Command::new(sim_binary())
            .args(["--scenario", "indoor-static", "--duration-s", "120"])
            .args(["--mavlink-listen", &format!("127.0.0.1:{sim_port}")])
            .args(["--mavlink-remote", &format!("127.0.0.1:{link_port}")])
            .args(["--ipc-prefix", prefix.as_str()])
            .env("LANDING_LOG", "warn"),
    );
    let mut link = Running::start(
        "px4-link",
        Command::new(env!("CARGO_BIN_EXE_px4-link"))
            .args(["--link", &format!("udp:127.0.0.1:{link_port}")])
            .args(["--remote", &format!("127.0.0.1:{sim_port}")])
            .args(["--ipc-prefix", prefix.as_str()])
            .env("LANDING_LOG", "warn"),
    );
    let common::FsmSide {
        ipc,
        states,
        outcomes,
        mut requests,
    } = common::fsm_side(&prefix);
    let mut safety = ipc
        .publisher::<SafetyCommand>(services::SAFETY_COMMAND)
        .unwrap();

    let latest = |timeout: Duration| -> Option<VehicleState> {
        let end = Instant::now() + timeout;
        let mut last = None;
        while Instant::now() < end {
            while let Ok(Some(s)) = states.receive() {
                last = Some(*s.payload());
            }
            if last.is_some() {
                return last;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        last
    };
    let state = latest(Duration::from_secs(10)).expect("vehicle state from px4-link");
    assert_eq!(state.link.connected, 1);

    let ask = |requests: &mut runtime::Publisher<LinkRequest>, id, kind: u32| {
        let r = LinkRequest {
            msg: Header::default(),
            id,
            kind,
            reserved: 0,
            altitude_m: 2.0,
        };
        requests.send(r.msg, &r).unwrap();
    };
    let answer = |id: u64| -> LinkOutcome {
        let end = Instant::now() + Duration::from_secs(5);
        while Instant::now() < end {
            while let Ok(Some(o)) = outcomes.receive() {
                if o.payload().id == id {
                    return *o.payload();
                }
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        panic!("no outcome for request {id}");
    };
    ask(&mut requests, 1, LinkRequestKind::Arm as u32);
    assert_eq!(answer(1).outcome, LinkOutcomeKind::Accepted as u32);
    ask(&mut requests, 2, LinkRequestKind::Takeoff as u32);
    assert_eq!(answer(2).outcome, LinkOutcomeKind::Accepted as u32);
    // An unreadable request is refused, not guessed.
    ask(&mut requests, 3, 99);
    assert_eq!(answer(3).outcome, LinkOutcomeKind::Invalid as u32);

    let end = Instant::now() + Duration::from_secs(15);
    let mut height = 0.0;
    while Instant::now() < end && height < 1.7 {
        if let Some(s) = latest(Duration::from_millis(200)) {
            height = s.world_from_body.translation[2];
        }
    }
    assert!(height >= 1.7, "climbed to {height} m (ENU up)");

    let order = SafetyCommand {
        msg: Header::default(),
        action: SafetyAction::SafeLand as u32,
        reserved: 0,
        source: Text::default(),
        reason: Text::default(),
    };
    safety.send(order.msg, &order).unwrap();
    let end = Instant::now() + Duration::from_secs(5);
    let mut mode = FlightMode::Unknown;
    while Instant::now() < end && mode != FlightMode::Land {
        if let Some(s) = latest(Duration::from_millis(200)) {
            mode = FlightMode::from_raw(s.flight_mode);
        }
    }
    assert_eq!(mode, FlightMode::Land);

    link.request_stop();
    let status = link.wait_exit(Duration::from_secs(3));
    assert!(status.success(), "{status}");
}
