//! The shipped graph (deploy/graph.toml) against what else the deploy directory and the
//! workspace say: it loads, its binaries exist, its topics carry the types the code
//! sends, landing.target starts exactly its vehicle nodes, and `landing run
//! --processes` gets the command lines it had before the graph existed.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use graph::{Graph, OBSERVER_BINARIES, RunValues, SENSOR_BINARIES, STACK_BINARIES};
use iceoryx2::prelude::ZeroCopySend;
use ipc_types::msg;
use ipc_types::services;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn shipped() -> Graph {
    Graph::load(&root().join("deploy/graph.toml")).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn the_shipped_graph_loads_with_the_eight_processes() {
    let g = shipped();
    let names: Vec<&str> = g.nodes.iter().map(|n| n.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "sim",
            "px4-link",
            "camera-ingest",
            "aruco-pnp",
            "depth-map",
            "planner",
            "fsm",
            "watchdog"
        ]
    );
    for n in &g.nodes {
        assert_eq!(n.name, n.binary, "each process is named for its binary");
        assert!(
            STACK_BINARIES.contains(&n.binary.as_str()),
            "the shipped graph runs the stack's binaries only: {}",
            n.binary
        );
    }
}

/// The `Wants=` of landing.target, in order.
fn wanted_units() -> Vec<String> {
    let text = std::fs::read_to_string(root().join("deploy/systemd/landing.target")).unwrap();
    text.lines()
        .filter_map(|l| l.trim().strip_prefix("Wants="))
        .flat_map(|l| l.split_whitespace().map(str::to_string))
        .collect()
}

#[test]
fn landing_target_wants_one_unit_per_vehicle_node_and_nothing_else() {
    let g = shipped();
    let expected: BTreeSet<String> = g
        .vehicle_nodes()
        .map(|n| format!("landing@{}.service", n.binary))
        .collect();
    let wanted = wanted_units();
    let found: BTreeSet<String> = wanted.iter().cloned().collect();
    assert_eq!(
        found.len(),
        wanted.len(),
        "a unit is wanted twice: {wanted:?}"
    );
    let missing: Vec<_> = expected.difference(&found).collect();
    let extra: Vec<_> = found.difference(&expected).collect();
    assert!(
        missing.is_empty() && extra.is_empty(),
        "landing.target and deploy/graph.toml disagree: missing {missing:?} (graph nodes with on_vehicle), extra {extra:?} (no such node in the graph)"
    );
    // The unit's instance is the binary it runs.
    let unit = std::fs::read_to_string(root().join("deploy/systemd/landing@.service")).unwrap();
    assert!(unit.contains("ExecStart=/usr/local/bin/%i "), "{unit}");
}

#[test]
fn every_stack_binary_is_a_binary_of_the_workspace() {
    let mut bins = BTreeSet::new();
    for entry in std::fs::read_dir(root().join("processes")).unwrap() {
        let manifest = entry.unwrap().path().join("Cargo.toml");
        let Ok(text) = std::fs::read_to_string(&manifest) else {
            continue;
        };
        for section in text.split("[[bin]]").skip(1) {
            let name = section
                .lines()
                .find_map(|l| l.trim().strip_prefix("name = "))
                .unwrap();
            bins.insert(name.trim_matches('"').to_string());
        }
    }
    let declared: BTreeSet<String> = STACK_BINARIES
        .iter()
        .chain(OBSERVER_BINARIES)
        .chain(SENSOR_BINARIES)
        .map(|b| b.to_string())
        .collect();
    assert_eq!(declared, bins);
}

/// The versioned type name iceoryx2 compares.
fn type_name<T: ZeroCopySend>() -> &'static str {
    // SAFETY: reading the name the derive declared; nothing is sent.
    unsafe { <T as ZeroCopySend>::type_name() }
}

#[test]
fn every_topic_names_the_type_its_service_carries() {
    // What the processes open each service with (their main.rs files).
    let carried: Vec<(&str, &str, Option<&str>)> = vec![
        (
            services::SIM_CAMERA,
            type_name::<msg::CameraFrameHeader>(),
            Some("u8"),
        ),
        (
            services::SIM_DEPTH,
            type_name::<msg::DepthFrameHeader>(),
            Some("u16"),
        ),
        (services::SIM_TRUTH, type_name::<msg::TruthEvent>(), None),
        (
            services::SIM_TRUTH_STATE,
            type_name::<msg::TruthState>(),
            None,
        ),
        (
            services::CAMERA_FRAME,
            type_name::<msg::CameraFrameHeader>(),
            Some("u8"),
        ),
        (
            services::PAD_OBSERVATION,
            type_name::<msg::PadObservation>(),
            None,
        ),
        (
            services::VEHICLE_STATE,
            type_name::<msg::VehicleState>(),
            None,
        ),
        (
            services::MAP_OCCUPANCY,
            type_name::<msg::OccupancyMapHeader>(),
            Some("u8"),
        ),
        (
            services::PLANNER_GOAL,
            type_name::<msg::PlannerGoal>(),
            None,
        ),
        (
            services::PLANNER_TRAJECTORY,
            type_name::<msg::Trajectory>(),
            None,
        ),
        (
            services::PLANNER_STATS,
            type_name::<msg::PlannerStats>(),
            None,
        ),
        (
            services::VIO_ODOMETRY,
            type_name::<msg::VioOdometry>(),
            None,
        ),
        (services::PX4_REQUEST, type_name::<msg::LinkRequest>(), None),
        (services::PX4_OUTCOME, type_name::<msg::LinkOutcome>(), None),
        (services::FSM_SETPOINT, type_name::<msg::Setpoint>(), None),
        (
            services::PX4_SETPOINT_SENT,
            type_name::<msg::Setpoint>(),
            None,
        ),
        (services::FSM_STATUS, type_name::<msg::FsmStatus>(), None),
        (
            services::SAFETY_COMMAND,
            type_name::<msg::SafetyCommand>(),
            None,
        ),
        (
            services::WATCHDOG_VIEW,
            type_name::<msg::WatchdogView>(),
            None,
        ),
    ];
    let g = shipped();
    for t in g.topics.iter().filter(|t| t.service.is_some()) {
        let service = t.service.as_deref().unwrap();
        let Some((_, ty, elements)) = carried.iter().find(|(s, _, _)| *s == service) else {
            panic!("topic {}: no type known for {service}", t.name);
        };
        assert_eq!(&t.type_name, ty, "topic {}", t.name);
        assert_eq!(t.elements.as_deref(), *elements, "topic {}", t.name);
    }
}

#[test]
fn landing_run_processes_starts_the_stack_as_it_did_before_the_graph() {
    let v = RunValues {
        config: "/d/config/landing.toml".into(),
        deploy: "/d".into(),
        calibration: "/d/config/camera_down_1280x720.yaml".into(),
        pad: "/d/config/pad.toml".into(),
        scenario: "/d/scenarios/paper-sim.toml".into(),
        seed: "1".into(),
        duration: "120".into(),
        sim_addr: "127.0.0.1:40001".into(),
        link_addr: "127.0.0.1:40002".into(),
        sim_remote: "127.0.0.1:40002".into(),
        link_remote: "127.0.0.1:40001".into(),
        preset: "-4,-2,4.5".into(),
        commit_height: "0.6".into(),
        search_height_max: "6.33".into(),
        signing_key: "/d/config/mavlink.key".into(),
    };
    // The list `landing run --processes` had hard-coded (tools/landing/src/run_processes.rs
    // before the graph), with the same values; the watchdog came later.
    let before: Vec<(&str, Vec<&str>)> = vec![
        (
            "px4-link",
            vec![
                "--config",
                &v.config,
                "--link",
                "udp:127.0.0.1:40002",
                "--remote",
                &v.sim_addr,
            ],
        ),
        (
            "camera-ingest",
            vec![
                "--config",
                &v.config,
                "--deploy-dir",
                &v.deploy,
                "--source",
                "sim",
                "--camera",
                &v.calibration,
            ],
        ),
        (
            "aruco-pnp",
            vec![
                "--config",
                &v.config,
                "--deploy-dir",
                &v.deploy,
                "--camera",
                &v.calibration,
                "--pad",
                &v.pad,
            ],
        ),
        ("depth-map", vec!["--config", &v.config, "--input", "sim"]),
        ("planner", vec!["--config", &v.config]),
        (
            "fsm",
            vec![
                "--config",
                &v.config,
                "--preset=-4,-2,4.5",
                "--commit-height=0.6",
                "--search-height-max=6.33",
            ],
        ),
        (
            "watchdog",
            vec!["--config", &v.config, "--deploy-dir", &v.deploy],
        ),
        (
            "sim",
            vec![
                "--scenario",
                &v.scenario,
                "--seed",
                "1",
                "--duration-s",
                "120",
                "--deploy-dir",
                &v.deploy,
                "--mavlink-listen",
                &v.sim_addr,
                "--mavlink-remote",
                &v.link_addr,
                // Added with MAVLink signing: the simulated autopilot holds the key.
                "--signing-key",
                &v.signing_key,
            ],
        ),
    ];
    let g = shipped();
    let now: Vec<(&str, Vec<String>)> = g
        .start_order()
        .into_iter()
        .map(|n| (n.binary.as_str(), n.command_args(&v)))
        .collect();
    let before: Vec<(&str, Vec<String>)> = before
        .into_iter()
        .map(|(b, a)| (b, a.into_iter().map(str::to_string).collect()))
        .collect();
    assert_eq!(now, before);
}

#[test]
fn every_topic_of_the_graph_is_the_topic_tables_with_its_service_and_type() {
    let g = shipped();
    for t in &g.topics {
        let row = ipc_types::topics::find(&t.name)
            .unwrap_or_else(|| panic!("`{}` is not in ipc_types::topics", t.name));
        assert_eq!(t.service.as_deref(), row.service, "{}", t.name);
        if row.service.is_some() {
            assert_eq!(t.type_name, row.payload.type_name(), "{}", t.name);
            assert_eq!(t.elements.as_deref(), row.payload.elements(), "{}", t.name);
        }
        assert_eq!(t.evaluator_only, row.evaluator_only, "{}", t.name);
    }
}

#[test]
fn the_architecture_page_shows_the_shipped_graph_as_landing_graph_prints_it() {
    let page = std::fs::read_to_string(root().join("docs/ARCHITECTURE.md")).unwrap();
    let block = page
        .split("<!-- landing graph -->\n```\n")
        .nth(1)
        .and_then(|rest| rest.split("```\n<!-- /landing graph -->").next())
        .expect("docs/ARCHITECTURE.md has a <!-- landing graph --> block");
    assert_eq!(
        block.trim_end(),
        graph::text(&shipped()).trim_end(),
        "docs/ARCHITECTURE.md's graph block is not what `landing graph` prints: paste its output"
    );
}
