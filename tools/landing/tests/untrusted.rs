#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Untrusted traffic on the autopilot link (issue 20): with every stage its own process
//! and the simulated autopilot on a real UDP socket, another local port floods
//! px4-link's MAVLink port for the whole flight, 1,000 datagrams/s (random bytes and
//! mutated autopilot frames) plus a burst of 50,000 while the fsm tracks the pad; in a
//! second flight, 1,000/s of valid but spoofed autopilot heartbeats (armed, OFFBOARD)
//! and positions 40 m off. The mission lands on the pad as without them (within the
//! 10 cm every flight test asks), and px4-link accounts for every datagram: each one it
//! was sent is either counted as from the wrong address or counted by the kernel as
//! dropped on a full receive buffer.

mod common;

use std::path::Path;

use serde_json::Value;

/// px4-link's counter `name` from the stop line of its log.
fn counter(log: &str, name: &str) -> u64 {
    let line = log
        .lines()
        .rev()
        .find(|l| l.contains("px4-link stopped"))
        .unwrap_or_else(|| panic!("no stop line in px4-link's log:\n{log}"));
    line.split_whitespace()
        .find_map(|kv| kv.strip_prefix(&format!("{name}=")))
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no {name} in {line}"))
}

/// Flies paper-sim with every stage a process and `injections`; returns the summary and
/// px4-link's log.
fn fly(name: &str, injections: &[&str]) -> (Value, String) {
    let _stack = common::one_stack();
    let logs =
        std::env::temp_dir().join(format!("landing-untrusted-{}-{name}", std::process::id()));
    let mut args = vec![
        "run",
        "--scenario",
        "paper-sim",
        "--processes",
        "--json",
        "--log-dir",
        logs.to_str().unwrap(),
    ];
    for i in injections {
        args.extend(["--inject", i]);
    }
    let out = common::landing_env(&args, &[("LANDING_LOG", "warn")]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let s: Value = serde_json::from_str(stdout.trim())
        .unwrap_or_else(|e| panic!("{e}: {stdout}\n{}", String::from_utf8_lossy(&out.stderr)));
    let log = std::fs::read_to_string(Path::new(&logs).join("px4-link.log")).unwrap();
    std::fs::remove_dir_all(&logs).unwrap_or_default();
    (s, log)
}

fn assert_landed(s: &Value, log: &str) {
    assert_eq!(s["outcome"], "landed", "{s}\n{log}");
    let err = s["touchdown_error_m"].as_f64().unwrap();
    assert!(err <= 0.10, "touchdown {err} m from the pad centre\n{s}");
}

/// Datagrams the injections sent, all of them.
fn sent(s: &Value) -> u64 {
    s["faults"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            f["datagrams_sent"]
                .as_u64()
                .unwrap_or_else(|| panic!("{f}"))
        })
        .sum()
}

#[test]
fn a_flood_of_random_and_mutated_datagrams_from_another_port_changes_nothing_and_is_counted() {
    let (s, log) = fly(
        "noise",
        &[
            "flood:random:500:px4-link@0",
            "flood:mutated:500:px4-link@0",
            "garbage:50000:px4-link@track",
        ],
    );
    assert_landed(&s, &log);
    let sent = sent(&s);
    assert!(sent > 50_000 + 10_000, "{s}");
    let (wrong, foreign, drops, lost) = (
        counter(&log, "wrong_address"),
        counter(&log, "foreign_datagrams"),
        counter(&log, "kernel_drops"),
        counter(&log, "messages_lost"),
    );
    // Every datagram the socket delivered from the wrong address reached the stage's count.
    assert_eq!(wrong, foreign);
    // Every one sent is counted, as from the wrong address or as dropped by the kernel
    // (whose count also holds the autopilot's datagrams lost in the burst, at most
    // `messages_lost`).
    assert!(wrong + drops >= sent, "{wrong} + {drops} < {sent}");
    assert!(
        wrong + drops <= sent + lost,
        "{wrong} + {drops} > {sent} + {lost}"
    );
    // None of it decoded: no frame from the noise reached the link's parser.
    assert_eq!(counter(&log, "parse_errors"), 0);
}

#[test]
fn spoofed_autopilot_heartbeats_and_positions_from_another_port_are_never_taken() {
    let (s, log) = fly("spoofed", &["flood:spoofed:1000:px4-link@0"]);
    assert_landed(&s, &log);
    let sent = sent(&s);
    assert!(sent > 10_000, "{s}");
    let (wrong, drops, lost) = (
        counter(&log, "wrong_address"),
        counter(&log, "kernel_drops"),
        counter(&log, "messages_lost"),
    );
    assert!(
        wrong + drops >= sent && wrong + drops <= sent + lost,
        "{wrong} {drops} {sent}"
    );
    assert_eq!(counter(&log, "from_others"), 0);
}
