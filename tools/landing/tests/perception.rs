//! The perception chain as real processes. Its own test binary: cargo runs test binaries
//! one at a time, so the other benchmarks' tests (cli.rs) do not share the 2 cores with
//! its five processes.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test

mod common;
use common::landing;
use std::process::Output;

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).to_string()
}

/// sim -> camera-ingest -> aruco-pnp (+ px4-link) as real processes over iceoryx2 (the binaries
/// `cargo test --workspace` builds next to `landing`): observations flow at the camera
/// rate, without gaps, each carrying the stage stamps of the processes it went through.
/// The latency figures themselves are the benchmark's to measure, not this test's.
#[test]
fn the_perception_chain_publishes_pad_observations_at_the_camera_rate() {
    let o = landing(&["bench", "perception", "--json", "--seconds", "3"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    let rate = v["rate_hz"].as_f64().unwrap_or(0.0);
    // 30 Hz camera; a loaded 2-core machine may drop a few frames, never most of them.
    assert!(rate > 20.0, "{v}");
    // px4-link's vehicle state reaches aruco-pnp: observations carry world poses.
    assert!(v["with_world_pose"].as_u64().unwrap_or(0) > 0, "{v}");
    for key in ["latency_ms_p50", "latency_ms_p99", "aruco_ms_p50"] {
        let x = v[key].as_f64().unwrap_or(-1.0);
        assert!(x > 0.0, "{key} = {x}");
    }
}
