#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test
//! `landing latency --live` on a bus this test publishes: setpoints whose headers carry
//! a known chain of stage stamps, as px4-link publishes them on px4/setpoint_sent.

use std::io::{BufRead, BufReader, Read};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use ipc_types::msg::{Header, Setpoint, Stage};
use ipc_types::services;
use runtime::{Ipc, IpcPrefix, monotonic_ns};

const MS: u64 = 1_000_000;

#[test]
fn latency_live_reports_the_chain_of_the_setpoints_on_the_bus_as_they_come() {
    let name = format!("lt_latlive_{}", std::process::id());
    let prefix = IpcPrefix::new(&name).unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_landing"))
        .args(["--ipc-prefix", &name, "latency", "--live", "--seconds", "3"])
        .args(["--period", "0.5", "--json"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Its first line says it watches: publishing starts then (a slow start on a loaded
    // machine must not find the publishing over).
    let mut stderr = BufReader::new(child.stderr.take().unwrap());
    let mut first = String::new();
    stderr.read_line(&mut first).unwrap();
    assert!(first.contains("watching the stack under prefix"), "{first}");
    let rest = std::thread::spawn(move || {
        let mut s = String::new();
        stderr.read_to_string(&mut s).unwrap();
        s
    });
    let ipc = Ipc::open("latency-live-test", &prefix).unwrap();
    let mut sent = ipc
        .publisher::<Setpoint>(services::PX4_SETPOINT_SENT)
        .unwrap();
    // Each frame delivered at t, then 0.5 ms in camera-ingest, 1 ms in aruco-pnp, 0.1 ms
    // in the fsm, 0.4 ms in px4-link: on the wire 2 ms after the camera delivered it.
    let start = Instant::now();
    let mut k = 0;
    while start.elapsed() < Duration::from_millis(2500) {
        k += 1;
        let t = monotonic_ns();
        let mut h = Header::captured_at(t - 30 * MS);
        h.push_stage(Stage::Sensor, t - 30 * MS, t);
        h.push_stage(Stage::CameraIngest, t, t + MS / 2);
        h.push_stage(Stage::ArucoPnp, t + MS / 2, t + 3 * MS / 2);
        h.push_stage(Stage::Fsm, t + 3 * MS / 2, t + 16 * MS / 10);
        h.push_stage(Stage::Px4Link, t + 16 * MS / 10, t + 2 * MS);
        let s = Setpoint {
            msg: h,
            ..Setpoint::default()
        };
        sent.send(h, &s).unwrap();
        std::thread::sleep(Duration::from_millis(20));
    }
    let out = child.wait_with_output().unwrap();
    let err = rest.join().unwrap();
    assert!(out.status.success(), "{err}");
    // A summary line every half second while it watched.
    assert!(
        err.lines().filter(|l| l.contains("end to end p50")).count() >= 2,
        "{err}"
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let e2e = &v["end_to_end_ms"];
    // Every setpoint sent after it subscribed, each exactly 2 ms.
    let n = e2e["count"].as_u64().unwrap();
    assert!(n >= 50 && n <= k, "{n} of {k}: {v}");
    for p in ["p50", "p99", "max"] {
        assert!((e2e[p].as_f64().unwrap() - 2.0).abs() < 1e-9, "{v}");
    }
    assert!(
        (v["stages"]["aruco-pnp"]["p50"].as_f64().unwrap() - 1.0).abs() < 1e-9,
        "{v}"
    );
    assert!(
        (v["capture_to_wire_ms"]["p50"].as_f64().unwrap() - 32.0).abs() < 1e-9,
        "{v}"
    );
    assert_eq!(v["drops"]["px4/setpoint_sent"], 0, "{v}");
}
