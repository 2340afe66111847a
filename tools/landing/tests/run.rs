#![allow(clippy::unwrap_used, clippy::expect_used)]
//! `landing run`: whole missions in the simulator, as a user runs them. Every scenario of
//! the paper lands on its pad within 10 cm (the simulator's ground truth measures it),
//! in one process and with every stage its own OS process; a refusing or silent
//! autopilot ends in a defined, logged landing in place; recordings and plots are files a
//! user can open.

mod common;
use std::process::Output;

use serde_json::Value;

/// A lockstep flight holds a share of the machine ([`common::beside_others`]): beside a
/// `--processes` flight (which holds all of it, [`common::one_stack`]) it took a whole core
/// of CI's two, and the wall-clock stack starved of it touched down 10.0 cm off at 0.21 m/s
/// sideways (a red CI run). Here, six beside one lockstep flight landed 2.0-3.7 cm off at
/// 0.03-0.07 m/s sideways, six beside two 1.2-6.2 cm, the 6.2 cm at 0.25 m/s.
fn landing(args: &[&str]) -> Output {
    let _machine = (!args.contains(&"--processes")).then(common::beside_others);
    common::landing_env(args, &[("LANDING_LOG", "warn")])
}

fn summary(out: &Output) -> Value {
    let stdout = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(stdout.trim()).unwrap_or_else(|e| {
        panic!(
            "not one JSON object ({e}): {stdout}\nstderr: {}",
            String::from_utf8_lossy(&out.stderr)
        )
    })
}

fn lands(args: &[&str]) -> Value {
    lands_within(args, 0.10)
}

/// `landed` by the referee (every foot on the board, at rest, disarmed) and the
/// centre within `max_m` of the pad's centre.
fn lands_within(args: &[&str], max_m: f64) -> Value {
    let out = landing(args);
    let s = summary(&out);
    let log = String::from_utf8_lossy(&out.stderr);
    assert_eq!(s["outcome"], "landed", "{s}\n{log}");
    assert!(out.status.success(), "{log}");
    let err = s["touchdown_error_m"].as_f64().unwrap();
    assert!(err <= max_m, "touchdown {err} m from the pad centre\n{log}");
    assert_eq!(s["collisions"].as_u64(), Some(0), "{s}");
    s
}

fn temp(name: &str, text: &str) -> String {
    let dir = std::env::temp_dir().join(format!("landing-run-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p.to_str().unwrap().to_string()
}

#[test]
fn paper_sim_lands_on_the_moving_pad_in_lockstep() {
    let s = lands(&["run", "--json"]);
    assert_eq!(s["scenario"], "paper-sim");
    // The paper's vehicle: 2.8 km/h.
    let v = s["target_speed_kmh"].as_f64().unwrap();
    assert!((v - 2.8).abs() < 0.1, "{v}");
    for key in [
        "seed",
        "touchdown_rel_speed_mps",
        "flight_time_s",
        "distance_m",
        "uav_max_speed_kmh",
        "uav_avg_speed_kmh",
        "planning_time_ms_p50",
        "planning_time_ms_max",
        "replans",
    ] {
        assert!(s[key].is_number(), "{key}: {s}");
    }
}

#[test]
fn indoor_static_lands() {
    lands(&["run", "--scenario", "indoor-static", "--json"]);
}

#[test]
fn indoor_moving_lands() {
    lands(&["run", "--scenario", "indoor-moving", "--json"]);
}

#[test]
fn outdoor_1_lands_in_wind() {
    lands(&["run", "--scenario", "outdoor-1", "--json"]);
}

#[test]
fn outdoor_2_lands_in_wind_on_seeds_1_to_5() {
    // The windiest scenario (3.2 m/s with 1 m/s gusts) under the full world of issue 16:
    // one seed's error says little, so five flights must all land within the issue's
    // 10 cm (2.4-7.0 cm today) and their median within 8 cm (5.7 cm today).
    let mut errors: Vec<f64> = (1..=5)
        .map(|seed| {
            let seed = seed.to_string();
            let s = lands(&["run", "--scenario", "outdoor-2", "--seed", &seed, "--json"]);
            s["touchdown_error_m"].as_f64().unwrap()
        })
        .collect();
    errors.sort_by(f64::total_cmp);
    assert!(errors[2] <= 0.08, "median of {errors:?}");
}

#[test]
fn obstacle_demo_lands_without_touching_the_box() {
    let s = lands(&["run", "--scenario", "obstacle-demo", "--json"]);
    assert!(s["replans"].as_u64().unwrap() >= 1, "{s}");
}

#[test]
fn a_pad_at_30_km_h_is_chased_and_landed_on_vision_only() {
    // The preset is 4 m up, where the 640x480 camera cannot read the pad's largest marker:
    // the mission searches from its ceiling (3.17 m), chases the pad as it passes and
    // lands on it at its speed (docs/highspeed.md).
    let s = lands(&["run", "--scenario", "highspeed-30", "--json"]);
    let v = s["target_speed_kmh"].as_f64().unwrap();
    assert!((v - 30.0).abs() < 0.5, "{v}");
    for (key, limit) in [
        ("touchdown_vertical_speed_mps", 1.0),
        ("touchdown_horizontal_speed_mps", 0.5),
        ("touchdown_tilt_deg", 15.0),
    ] {
        let x = s[key].as_f64().unwrap();
        assert!(x < limit, "{key} {x}: {s}");
    }
}

#[test]
fn a_pad_at_30_km_h_on_a_curve_is_chased_and_landed_on() {
    // A 60 m radius at 8.3 m/s: the pad turns under the vehicle the whole time. Within
    // 5 cm: the touchdown's relative-velocity term compared across the road (a setpoint
    // turning now against a vehicle velocity lagging the turn) pulled it 4.6 cm inside the
    // curve on average (6.3 cm off on this seed; 3.2 with the along-road part alone).
    lands_within(&["run", "--scenario", "highspeed-30-curve", "--json"], 0.05);
}

#[test]
fn a_pad_at_50_km_h_is_chased_and_landed_on_vision_only() {
    // Within 25 cm, every foot on the 84 cm board (the referee's `landed`).
    lands_within(&["run", "--scenario", "highspeed-50", "--json"], 0.25);
}

#[test]
fn paper_sim_lands_with_every_stage_its_own_process() {
    let _stack = common::one_stack();
    let logs = std::env::temp_dir().join(format!("landing-run-logs-{}", std::process::id()));
    let logs = logs.to_str().unwrap();
    let s = lands(&["run", "--processes", "--json", "--log-dir", logs]);
    assert_eq!(s["scenario"], "paper-sim");
    no_message_lost(logs);
}

/// No message lost between any publisher and any subscriber over the whole run: every
/// process's stop line counts the sequence gaps on every `queue` input (`lost_upstream`;
/// on a `newest` input an older frame dropped while the stage was busy is `skipped`,
/// as the policy says: the CI-loaded machine once stalled aruco-pnp past 4 frames), px4-link
/// the MAVLink sequence gaps; the watchdog of a healthy flight found nothing.
fn no_message_lost(logs: &str) {
    for p in [
        "sim",
        "camera-ingest",
        "aruco-pnp",
        "depth-map",
        "planner",
        "fsm",
        "px4-link",
        "watchdog",
    ] {
        let log = std::path::Path::new(logs).join(format!("{p}.log"));
        let text = std::fs::read_to_string(&log).unwrap_or_else(|e| panic!("{p}.log: {e}"));
        let stop = text
            .lines()
            .find(|l| l.contains(&format!("{p} stopped")))
            .unwrap_or_else(|| panic!("{p} logged no stop line:\n{text}"));
        assert!(stop.contains("lost_upstream=0"), "{stop}");
        if p == "px4-link" {
            assert!(stop.contains("messages_lost=0"), "{stop}");
        }
        if p == "watchdog" {
            // A healthy flight: every process beat within its deadline, every path
            // flowed, nothing was ordered.
            assert!(
                stop.contains(" faults=0 ") && stop.contains(" orders=0 "),
                "{stop}"
            );
            assert!(!stop.contains(" heartbeat_events=0 "), "{stop}");
        }
    }
}

#[test]
fn a_minute_of_flight_with_every_stage_its_own_process_loses_no_message() {
    let _stack = common::one_stack();
    // A world where the pad's vehicle waits 30 s, 19 m further away, then drives by: the
    // vehicle takes off, waits at the preset point for a minute of steady state (camera
    // and depth frames, states, maps, setpoints, status, the watchdog), then tracks the
    // pad and lands on it. (Two minutes until CI's time budget asked for one.)
    let paper = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../deploy/scenarios/paper-sim.toml"),
    )
    .unwrap();
    let world = paper
        .replace("name = \"paper-sim\"", "name = \"soak\"")
        .replace("duration_s = 120.0", "duration_s = 200.0")
        .replace("start_delay_s = 5.0", "start_delay_s = 30.0")
        .replace("start_m = [-6.0, -2.0]", "start_m = [-25.0, -2.0]");
    assert_ne!(world, paper);
    let file = temp("soak.toml", &world);
    let logs = std::env::temp_dir().join(format!("landing-soak-logs-{}", std::process::id()));
    let logs = logs.to_str().unwrap();
    let s = lands(&[
        "run",
        "--processes",
        "--json",
        "--scenario",
        &file,
        "--log-dir",
        logs,
    ]);
    let flown = s["flight_time_s"].as_f64().unwrap();
    assert!(flown >= 60.0, "a {flown} s flight");
    no_message_lost(logs);
}

#[test]
fn a_recording_and_the_plots_are_written_and_readable() {
    let dir = std::env::temp_dir().join(format!("landing-run-plots-{}", std::process::id()));
    let rec = dir.join("run.mcap");
    std::fs::create_dir_all(&dir).unwrap();
    let (dir_s, rec_s) = (dir.to_str().unwrap(), rec.to_str().unwrap());
    lands(&[
        "run",
        "--scenario",
        "indoor-moving",
        "--json",
        "--record",
        rec_s,
        "--plot",
        dir_s,
    ]);
    for f in ["top.png", "3d.png"] {
        let meta = std::fs::metadata(dir.join(f)).unwrap();
        assert!(meta.len() > 10_000, "{f}: {} bytes", meta.len());
    }
    let topics_of = |file: &std::path::Path| -> Vec<String> {
        let info = landing(&["mcap", "info", file.to_str().unwrap(), "--json"]);
        assert!(info.status.success());
        let v: Value = serde_json::from_slice(&info.stdout).unwrap();
        v["channels"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c["topic"].as_str().unwrap().to_string())
            .collect()
    };
    let pipeline = topics_of(&rec);
    for t in [
        "/vehicle/state",
        "/pad/observation",
        "/fsm/setpoint",
        "/fsm/status",
        "/px4/request",
        "/px4/outcome",
        "/camera/frame",
        "/tf",
    ] {
        assert!(pipeline.iter().any(|p| p == t), "{t} missing: {pipeline:?}");
    }
    // Ground truth in a file of its own, never in the pipeline's.
    assert!(
        !pipeline.iter().any(|p| p.starts_with("/sim/truth")),
        "{pipeline:?}"
    );
    let truth = topics_of(&dir.join("run.truth.mcap"));
    for t in ["/sim/truth", "/sim/truth_state", "/scene/truth"] {
        assert!(truth.iter().any(|p| p == t), "{t} missing: {truth:?}");
    }
}

/// indoor-static with a `[faults]` table added.
fn faulty(name: &str, faults: &str) -> String {
    let base = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../deploy/scenarios/indoor-static.toml"
    ))
    .unwrap();
    let text = base.replace("name = \"indoor-static\"", &format!("name = \"{name}\""))
        + "\n[faults]\n"
        + faults
        + "\n";
    temp(&format!("{name}.toml"), &text)
}

#[test]
fn an_autopilot_that_refuses_to_arm_ends_the_mission_on_the_ground() {
    let scn = faulty("no-arm", "reject_arming = true");
    let out = landing(&["run", "--scenario", &scn, "--json"]);
    let s = summary(&out);
    let log = String::from_utf8_lossy(&out.stderr);
    assert_eq!(s["outcome"], "safe_landed", "{s}\n{log}");
    assert_eq!(out.status.code(), Some(1));
    assert!(log.contains("Arm failed 3 times"), "{log}");
}

#[test]
fn an_autopilot_that_refuses_offboard_lands_in_place() {
    let scn = faulty("no-offboard", "reject_offboard = true");
    let out = landing(&["run", "--scenario", &scn, "--json"]);
    let s = summary(&out);
    let log = String::from_utf8_lossy(&out.stderr);
    assert_eq!(s["outcome"], "safe_landed", "{s}\n{log}");
    assert!(log.contains("Offboard failed 3 times"), "{log}");
}

#[test]
fn telemetry_that_stops_in_flight_ends_in_a_landing_in_place() {
    let scn = faulty("silent", "telemetry_stop_s = 6.0");
    let out = landing(&["run", "--scenario", &scn, "--json"]);
    let s = summary(&out);
    let log = String::from_utf8_lossy(&out.stderr);
    assert_eq!(s["outcome"], "safe_landed", "{s}\n{log}");
    // Both the fsm and the watchdog watch the telemetry (500 ms each): whichever sees
    // the silence first lands the vehicle, and says why.
    assert!(
        log.contains("telemetry lost") || log.contains("watchdog: vehicle/state silent"),
        "{log}"
    );
}

#[test]
fn an_unknown_scenario_is_one_line_and_exit_2() {
    let out = landing(&["run", "--scenario", "no-such-scenario"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    let lines: Vec<_> = err.lines().filter(|l| !l.starts_with("run:")).collect();
    assert_eq!(lines.len(), 1, "{err}");
    assert!(lines[0].contains("no-such-scenario"), "{err}");
}

#[test]
fn a_second_stack_on_a_prefix_in_use_refuses_to_start_in_one_line() {
    // The running stack's `landing run` node, held here: a whole second stack would load
    // the machine the flight tests beside this one run on.
    let name = format!("lt_twice_{}", std::process::id());
    let prefix = runtime::IpcPrefix::new(&name).unwrap();
    let running = runtime::Ipc::open_exclusive("landing-run", &prefix).unwrap();
    let second = landing(&[
        "--ipc-prefix",
        &name,
        "run",
        "--scenario",
        "paper-sim",
        "--processes",
    ]);
    let err = String::from_utf8_lossy(&second.stderr);
    assert!(!second.status.success(), "{err}");
    let line = err
        .lines()
        .find(|l| l.starts_with("error:"))
        .unwrap_or_default();
    assert!(
        line.contains(&format!("prefix `{name}`")) && line.contains("one stack per prefix"),
        "{err}"
    );
    assert!(
        line.contains(&format!("pid {}", std::process::id())),
        "{err}"
    );
    // It stopped before starting any process: nothing of it is on the prefix.
    let nodes = running.nodes().unwrap_or_default();
    assert!(
        nodes.iter().all(|n| !n.alive || n.name == "landing-run"),
        "{:?}",
        nodes.iter().map(|n| &n.name).collect::<Vec<_>>()
    );
}
