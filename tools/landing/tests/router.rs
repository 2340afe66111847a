#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test
//! The mission behind a MAVLink router (`landing run --processes --router`): the
//! simulated autopilot, px4-link and a second ground station (system 255, its own
//! heartbeats, a parameter list and a command every two seconds) each on an endpoint
//! of a router that routes as mavlink-router does. The vehicle lands as it does
//! alone, px4-link ignores the ground station's traffic without calling it an attack,
//! and every datagram is accounted for, per endpoint.

use std::process::Command;

use serde_json::Value;

/// The value of `key=N` in the last `stopped` line of a process log.
fn stopped(log: &str, key: &str) -> u64 {
    log.lines()
        .rev()
        .find(|l| l.contains(" stopped "))
        .and_then(|l| {
            l.split_whitespace()
                .find_map(|kv| kv.strip_prefix(&format!("{key}=")))
        })
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no {key} in the stop line of:\n{log}"))
}

#[test]
fn the_mission_behind_a_router_with_a_second_ground_station_lands_and_every_datagram_is_counted() {
    let logs = std::env::temp_dir().join(format!("router_run_{}", std::process::id()));
    let out = Command::new(env!("CARGO_BIN_EXE_landing"))
        .args(["run", "--processes", "--router", "--json", "--log-dir"])
        .arg(&logs)
        .env("LANDING_LOG", "warn")
        .output()
        .unwrap();
    let s: Value = serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&out.stderr)));
    println!("{}", s["router"]);
    assert_eq!(s["outcome"], "landed", "{s}");
    assert!(s["touchdown_error_m"].as_f64().unwrap() <= 0.10, "{s}");
    let r = &s["router"]["endpoints"];
    let g = &s["router"]["ground_station"];
    let n = |v: &Value| v.as_u64().unwrap();
    let sim = std::fs::read_to_string(logs.join("sim.log")).unwrap();
    let link = std::fs::read_to_string(logs.join("px4-link.log")).unwrap();
    // Everything each peer sent reached the router, and everything the router
    // forwarded reached its peer.
    assert_eq!(
        n(&r["autopilot"]["datagrams_in"]),
        stopped(&sim, "datagrams_out"),
        "{s}"
    );
    assert_eq!(
        n(&r["autopilot"]["datagrams_out"]),
        stopped(&sim, "datagrams_in"),
        "{s}"
    );
    assert_eq!(
        n(&r["px4_link"]["datagrams_in"]),
        stopped(&link, "datagrams_out"),
        "{s}"
    );
    assert_eq!(
        n(&r["px4_link"]["datagrams_out"]),
        stopped(&link, "datagrams_in"),
        "{s}"
    );
    assert_eq!(
        n(&r["ground_station"]["datagrams_in"]),
        n(&g["datagrams_out"]),
        "{s}"
    );
    assert_eq!(
        n(&r["ground_station"]["datagrams_out"]),
        n(&g["datagrams_in"]),
        "{s}"
    );
    for log in [&sim, &link] {
        assert_eq!(stopped(log, "kernel_drops"), 0);
        assert_eq!(stopped(log, "wrong_address"), 0);
    }
    // The ground station was answered (its requests acknowledged) and heard the
    // autopilot; px4-link saw its broadcasts and ignored them, not as attacks.
    assert!(n(&g["acks"]) >= 3, "{s}");
    assert!(n(&g["datagrams_in"]) > 500, "{s}");
    assert!(stopped(&link, "from_others") > 0, "{link}");
    for attack in ["unsigned", "bad_signature", "replayed"] {
        assert_eq!(stopped(&link, attack), 0, "{attack}");
    }
    let _ = std::fs::remove_dir_all(&logs);
}
