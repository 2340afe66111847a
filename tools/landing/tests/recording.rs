#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test
//! A recorded mission read back: `landing latency` on a lockstep recording, where every
//! stage's latency is the graph's model, and the readers on damaged files.

mod common;
use common::landing;
use std::path::PathBuf;

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("landing-recording-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// One lockstep paper-sim mission recorded (shared by the tests of this file) with the
/// shipped config, whose `[px4_link] new_setpoints_at_once` is on: the latency chain
/// without the stream's wait.
fn recording() -> PathBuf {
    static ONCE: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    ONCE.get_or_init(|| {
        let path = temp("paper-sim.mcap");
        assert!(common::shipped_config().contains("new_setpoints_at_once = true"));
        let o = landing(&[
            "run",
            "--scenario",
            "paper-sim",
            "--record",
            path.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        path
    })
    .clone()
}

#[test]
fn in_lockstep_a_frame_reaches_the_wire_after_exactly_its_stages_modelled_latency() {
    let path = recording();
    let o = landing(&["latency", "--json", path.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    // camera-ingest 0.3 + aruco-pnp 1.5 + fsm 0.1 + px4-link 0.1 ms (deploy/graph.toml):
    // the fsm answers the observation at once and px4-link (new_setpoints_at_once) sends
    // a new setpoint at once.
    // Waiting for the fsm's 50 Hz tick or the 25 Hz stream would add up to 20 or 40 ms.
    let e2e = &v["end_to_end_ms"];
    assert!(e2e["count"].as_u64().unwrap() > 200, "{e2e}");
    for p in ["p50", "p99"] {
        let ms = e2e[p].as_f64().unwrap();
        assert!((ms - 2.0).abs() < 0.05, "{p} {ms} ms: {e2e}");
    }
    assert!(e2e["max"].as_f64().unwrap() < 2.5, "{e2e}");
    for (stage, ms) in [
        ("camera-ingest", 0.3),
        ("aruco-pnp", 1.5),
        ("px4-link", 0.1),
    ] {
        let p50 = v["stages"][stage]["p50"].as_f64().unwrap();
        assert!((p50 - ms).abs() < 0.01, "{stage}: {p50} ms");
    }
    for (topic, n) in v["drops"].as_object().unwrap() {
        assert_eq!(n, 0, "{topic}");
    }
    let hz = v["rates_hz"]["camera/frame/header"].as_f64().unwrap();
    assert!((hz - 30.0).abs() < 1.0, "{hz}");
}

#[test]
fn latency_draws_the_end_to_end_histogram() {
    let path = recording();
    let dir = temp("plots");
    let o = landing(&[
        "latency",
        path.to_str().unwrap(),
        "--plot",
        dir.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let png = std::fs::read(dir.join("end_to_end_ms.png")).unwrap();
    assert!(png.starts_with(b"\x89PNG"), "a PNG");
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("end to end (frame -> wire)"), "{out}");
}

#[test]
fn a_cut_recording_is_reported_to_the_cut_and_the_cut_is_named_by_its_offset() {
    let path = recording();
    let bytes = std::fs::read(&path).unwrap();
    let cut = temp("cut.mcap");
    let at = bytes.len() / 2;
    std::fs::write(&cut, &bytes[..at]).unwrap();
    let o = landing(&["mcap", "info", cut.to_str().unwrap()]);
    let out = String::from_utf8_lossy(&o.stdout);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{out}");
    assert!(
        out.contains("/vehicle/state"),
        "what was read is reported: {out}"
    );
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(
        err.contains("truncated") && err.contains(&format!("of {at}")),
        "{err}"
    );
    let o = landing(&["latency", cut.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("truncated"), "{err}");
}

#[test]
fn a_file_that_is_not_mcap_is_one_line_saying_so() {
    let path = temp("random.mcap");
    std::fs::write(&path, b"not a recording at all, just words").unwrap();
    let out = temp("random-plots");
    let plot = ["plot", "--out", out.to_str().unwrap()];
    let replay = ["replay", "--stage", "fsm"];
    for cmd in [
        &["mcap", "info"][..],
        &["latency"][..],
        &plot[..],
        &replay[..],
    ] {
        let mut args = cmd.to_vec();
        args.push(path.to_str().unwrap());
        let o = landing(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{cmd:?}");
        assert_eq!(err.trim_end().lines().count(), 1, "{cmd:?}: {err}");
        assert!(err.contains("is not an MCAP file"), "{cmd:?}: {err}");
    }
}

#[test]
fn replaying_aruco_pnp_on_a_raw_recording_reproduces_every_observation_bit_for_bit() {
    let path = temp("indoor-static-raw.mcap");
    let p = path.to_str().unwrap();
    let o = landing(&[
        "run",
        "--scenario",
        "indoor-static",
        "--record",
        p,
        "--raw-images",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = landing(&["replay", p, "--stage", "aruco-pnp", "--json"]);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(o.status.success(), "{v}");
    assert!(v["recorded"].as_u64().unwrap() > 50, "{v}");
    assert_eq!(v["identical"], v["recorded"], "{v}");
    assert_eq!(v["replayed"], v["recorded"], "{v}");
    assert_eq!(v["different"], 0, "{v}");
    let _ = std::fs::remove_file(&path);
}

#[test]
fn replaying_aruco_pnp_on_jpeg_frames_is_refused_in_one_line() {
    let path = recording();
    let o = landing(&["replay", path.to_str().unwrap(), "--stage", "aruco-pnp"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.contains("--raw-images"), "{err}");
    let o = landing(&["replay", path.to_str().unwrap(), "--stage", "camera-ingest"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(
        err.contains("allowed: aruco-pnp, depth-map, planner, fsm"),
        "{err}"
    );
}

/// `landing replay --stage fsm --json` on `path` (with `extra` arguments): the report.
fn replay_fsm(path: &std::path::Path, extra: &[&str]) -> (bool, serde_json::Value) {
    let mut args = vec!["replay", path.to_str().unwrap(), "--stage", "fsm", "--json"];
    args.extend_from_slice(extra);
    let o = landing(&args);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout)
        .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&o.stderr)));
    (o.status.success(), v)
}

#[test]
fn replaying_the_fsm_reproduces_every_transition_of_the_flight_and_its_time() {
    let (ok, v) = replay_fsm(&recording(), &[]);
    assert!(ok, "{v}");
    // idle -> takeoff -> goto-preset -> track -> descend -> land -> landed.
    assert!(v["recorded"].as_u64().unwrap() >= 6, "{v}");
    assert_eq!(v["identical"], v["recorded"], "{v}");
    assert_eq!(v["replayed"], v["recorded"], "{v}");
    let flown = v["flown"].to_string();
    assert!(flown.contains("land -> landed"), "{v}");
}

#[test]
fn replaying_the_fsm_with_another_config_shows_the_transitions_it_changes() {
    // The same inputs, a tighter alignment before the descent: the fsm descends later.
    let text = common::shipped_config();
    let tighter = text.replace("\nalign_m = 0.3\n", "\nalign_m = 0.1\n");
    assert_ne!(
        text, tighter,
        "deploy/config/landing.toml has no `align_m = 0.3`"
    );
    let cfg = common::write_config(temp("x").parent().unwrap(), "tighter-align.toml", &tighter);
    let (ok, v) = replay_fsm(&recording(), &["--config", cfg.to_str().unwrap()]);
    assert!(!ok, "{v}");
    assert!(v["different"].as_u64().unwrap() >= 1, "{v}");
    let first = v["differences"][0].as_str().unwrap();
    assert!(first.contains("track -> descend"), "{v}");
}

/// One paper-sim flight with every stage its own process, aruco-pnp killed while
/// tracking, recorded (shared by the tests of this file): the inputs as iceoryx2
/// delivered them, and the watchdog's order.
fn processes_recording() -> PathBuf {
    static ONCE: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    ONCE.get_or_init(|| {
        let path = temp("killed-aruco.mcap");
        let o = landing(&[
            "run",
            "--scenario",
            "paper-sim",
            "--processes",
            "--inject",
            "kill:aruco-pnp@track",
            "--record",
            path.to_str().unwrap(),
        ]);
        // Not on the pad: the run says so in its exit status; the recording is what counts.
        let said = String::from_utf8_lossy(&o.stdout);
        assert!(said.contains("SAFE LANDING"), "{said}");
        path
    })
    .clone()
}

#[test]
fn replaying_the_fsm_of_a_flight_the_watchdog_ended_reproduces_its_safety_order() {
    let (ok, v) = replay_fsm(&processes_recording(), &[]);
    assert!(ok, "{v}");
    assert_eq!(v["identical"], v["recorded"], "{v}");
    assert_eq!(v["replayed"], v["recorded"], "{v}");
    let flown = v["flown"].to_string();
    assert!(flown.contains("-> safe-land"), "{v}");
    assert!(flown.contains("watchdog: aruco-pnp"), "{v}");
}

#[test]
fn latency_reports_each_supervised_processs_cpu_use_from_the_watchdogs_view() {
    let path = processes_recording();
    let o = landing(&["latency", "--json", path.to_str().unwrap()]);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let cpu = v["cpu_percent"].as_object().unwrap();
    // Every process the watchdog supervises; aruco-pnp until it was killed.
    for p in [
        "camera-ingest",
        "aruco-pnp",
        "depth-map",
        "planner",
        "fsm",
        "px4-link",
    ] {
        let c = &cpu.get(p).unwrap_or_else(|| panic!("no cpu for {p}: {v}"));
        let (mean, max) = (c["mean"].as_f64().unwrap(), c["max"].as_f64().unwrap());
        assert!(mean > 0.0 && mean <= 100.0, "{p}: {c}");
        assert!(max >= mean * 0.5 && max <= 200.0, "{p}: {c}");
    }
    // The camera path works every frame; the planner and the fsm do little.
    let mean = |p: &str| cpu[p]["mean"].as_f64().unwrap();
    assert!(mean("depth-map") > mean("fsm"), "{v}");
}

#[test]
fn plotting_a_recording_draws_the_plots_the_run_drew() {
    let path = temp("plotted.mcap");
    let (run_dir, rec_dir) = (temp("run-plots"), temp("recording-plots"));
    let o = landing(&[
        "run",
        "--scenario",
        "indoor-moving",
        "--record",
        path.to_str().unwrap(),
        "--plot",
        run_dir.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = landing(&[
        "plot",
        path.to_str().unwrap(),
        "--out",
        rec_dir.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("truth: "),
        "the truth file beside it was not read: {err}"
    );
    // The same referee on the same messages: the same pixels.
    for name in ["top.png", "3d.png"] {
        let from_run = std::fs::read(run_dir.join(name)).unwrap();
        let from_recording = std::fs::read(rec_dir.join(name)).unwrap();
        assert!(from_run.starts_with(b"\x89PNG"), "{name}");
        assert!(from_run == from_recording, "{name} differs");
    }

    // A flight without the simulator's truth (a real one): the stack's estimates.
    let alone = temp("alone");
    std::fs::create_dir_all(&alone).unwrap();
    let copy = alone.join("flight.mcap");
    std::fs::copy(&path, &copy).unwrap();
    let est_dir = temp("estimate-plots");
    let o = landing(&[
        "plot",
        copy.to_str().unwrap(),
        "--out",
        est_dir.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(!err.contains("truth: "), "{err}");
    let estimated = std::fs::read(est_dir.join("top.png")).unwrap();
    assert!(estimated.starts_with(b"\x89PNG"));
    assert!(estimated != std::fs::read(rec_dir.join("top.png")).unwrap());
    let printed = String::from_utf8_lossy(&o.stdout);
    assert_eq!(printed.lines().count(), 2, "{printed}");
}

/// `landing replay --stage STAGE --json` on `path`: whether it reproduced, the report.
fn replay(path: &std::path::Path, stage: &str) -> (bool, serde_json::Value) {
    let o = landing(&["replay", path.to_str().unwrap(), "--stage", stage, "--json"]);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout)
        .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&o.stderr)));
    (o.status.success(), v)
}

#[test]
fn replaying_depth_map_reproduces_every_map_cell_for_cell_in_lockstep_and_in_processes() {
    for path in [recording(), processes_recording()] {
        let (ok, v) = replay(&path, "depth-map");
        assert!(ok, "{}: {v}", path.display());
        // A map every depth frame, 30 Hz, over the flight.
        assert!(v["recorded"].as_u64().unwrap() > 100, "{v}");
        assert_eq!(v["different"], 0, "{v}");
        // The processes recorder can fall behind and lose maps (the test above); the
        // maps up to the first loss are compared, the rest counted.
        let compared = v["recorded"].as_u64().unwrap() - v["not_compared"].as_u64().unwrap();
        assert_eq!(v["identical"], compared, "{v}");
        assert_eq!(v["replayed"], compared, "{v}");
        if path == recording() {
            assert_eq!(v["lost"], 0, "lockstep loses nothing: {v}");
        } else {
            assert!(compared > 30, "a second of maps at least: {v}");
        }
    }
}

/// `from` copied to `to` as a recorder that fell behind would have written it: the maps
/// numbered as their publisher numbers them (lockstep leaves them 0) and the maps
/// numbered in `lost` missing, header and cells.
fn with_maps_lost(from: &std::path::Path, to: &std::path::Path, lost: &[u64]) {
    let bytes = std::fs::read(from).unwrap();
    let mut w =
        mcap::Writer::new(std::io::BufWriter::new(std::fs::File::create(to).unwrap())).unwrap();
    let (mut seq, mut skip) = (0, false);
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let mut m = m.unwrap();
        if m.channel.topic == "/map/occupancy/header" {
            seq += 1;
            skip = lost.contains(&seq);
            let mut v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
            v["msg"]["seq"] = seq.into();
            m.data = serde_json::to_vec(&v).unwrap().into();
        }
        // The cells follow their header.
        if !(skip && m.channel.topic.starts_with("/map/occupancy")) {
            w.write(&m).unwrap();
        }
    }
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    for i in &summary.metadata_indexes {
        w.write_metadata(&mcap::read::metadata(&bytes, i).unwrap())
            .unwrap();
    }
    w.finish().unwrap();
}

#[test]
fn a_map_the_recording_lost_is_counted_and_the_maps_after_it_are_not_compared() {
    // A recorder that falls behind loses maps (the buffer's oldest: 3 in a flight under
    // `make test`'s load). The map is a memory: a lost map's frame is in every map after
    // it, and which frame it was is not recorded. The maps before it still reproduce.
    let path = temp("lost-maps.mcap");
    with_maps_lost(&recording(), &path, &[121, 122, 300]);
    let (ok, v) = replay(&path, "depth-map");
    assert!(ok, "{v}");
    assert_eq!(v["lost"], 3, "{v}");
    assert_eq!(v["identical"], 120, "{v}");
    assert_eq!(v["different"], 0, "{v}");
    let after = v["recorded"].as_u64().unwrap() - 120;
    assert_eq!(v["not_compared"], after, "{v}");
    assert!(after > 100, "{v}");
    let o = landing(&["replay", path.to_str().unwrap(), "--stage", "depth-map"]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("the recording lost 3 maps"), "{out}");
    let _ = std::fs::remove_file(&path);
}

#[test]
fn replaying_the_planner_reproduces_every_trajectory_in_lockstep_and_in_processes() {
    // The lockstep flight plans the whole way (9-11 trajectories). The processes one is
    // cut short by the kill: its planner publishes until the pad is seen, which timing
    // moves (3-6 times in runs at the end of issue 18), and each is compared.
    for (path, least) in [(recording(), 6), (processes_recording(), 1)] {
        let (ok, v) = replay(&path, "planner");
        assert!(ok, "{}: {v}", path.display());
        assert!(
            v["recorded"].as_u64().unwrap() >= least,
            "{}: {v}",
            path.display()
        );
        assert_eq!(v["identical"], v["recorded"], "{v}");
        assert_eq!(v["replayed"], v["recorded"], "{v}");
    }
}

#[test]
fn a_recorded_touchdown_is_taken_apart_into_the_offset_at_the_drop_and_the_fall() {
    let path = recording();
    let o = landing(&["mcap", "touchdown", "--json", path.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let num = |k: &str| v[k].as_f64().unwrap_or_else(|| panic!("{k}: {v}"));
    let pair = |k: &str| [v[k][0].as_f64().unwrap(), v[k][1].as_f64().unwrap()];
    // The flare is 0.25 m over the pad and the drop falls at 0.8 m/s (landing.toml).
    let (height, lead) = (num("drop_height_m"), num("drop_lead_s"));
    assert!(
        (0.1..0.45).contains(&height),
        "dropped from {height} m: {v}"
    );
    assert!(
        (0.15..1.0).contains(&lead),
        "dropped {lead} s before contact: {v}"
    );
    // paper-sim's pad drives at 3.24 km/h.
    assert!((num("pad_speed_m_s") - 0.9).abs() < 0.2, "{v}");
    // The truth's state at contact and the referee's touchdown point agree.
    let norm = |p: [f64; 2]| p[0].hypot(p[1]);
    let (contact, referee) = (
        norm(pair("offset_at_contact_m")),
        norm(pair("touchdown_pad_m")),
    );
    assert!(
        (contact - referee).abs() < 0.01,
        "{contact} against {referee}: {v}"
    );
    // A calm fall drifts centimetres, and the stack read the offset at the drop within
    // the camera's calibration residual (centimetres).
    assert!(norm(pair("fall_drift_m")) < 0.04, "{v}");
    assert!(norm(pair("read_error_at_drop_m")) < 0.05, "{v}");
    assert!(norm(pair("lean_before_drop_m_s2")) < 2.0, "{v}");
    // The table names its rows.
    let o = landing(&["mcap", "touchdown", path.to_str().unwrap()]);
    let table = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success() && table.contains("drift through the fall"),
        "{table}"
    );

    // A real flight has no truth: one line says what is missing.
    let alone = temp("touchdown-alone");
    std::fs::create_dir_all(&alone).unwrap();
    let copy = alone.join("flight.mcap");
    std::fs::copy(&path, &copy).unwrap();
    let o = landing(&["mcap", "touchdown", copy.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.contains("flight.truth.mcap") && err.contains("--truth"),
        "{err}"
    );
}
