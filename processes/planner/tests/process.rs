#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test
//! The `planner` binary as a real OS process under its own iceoryx2 prefix: this test
//! publishes a vehicle state, an occupancy map in the depth-map's wire format (the
//! paper's box) and a point goal, and reads the trajectory and statistics back through
//! shared memory as the controller would.

use std::path::PathBuf;
use std::process::Command;
use std::time::{Duration, Instant};

use ipc_types::msg::{
    CellState, GoalMode, Header, OccupancyMapHeader, PlannerGoal, PlannerStats, Pose, Trajectory,
    VehicleState,
};
use ipc_types::services;
use landing_tests::process::Running;
use nalgebra::Vector3;
use planner::{Aabb, BSpline, CellView, GridMap, OccupancyQuery};
use runtime::{Ipc, IpcPrefix, monotonic_ns};

/// The paper's 60 x 120 x 120 cm box, inflated as the depth-map would (0.15 m cells,
/// 0.299 m), as a `GridMap` for the occupancy and its wire cells.
fn scene() -> (GridMap, OccupancyMapHeader, Vec<u8>) {
    let b = Aabb {
        min: Vector3::new(2.7, -0.6, 0.0),
        max: Vector3::new(3.3, 0.6, 1.2),
    };
    let map = GridMap::from_boxes(
        Vector3::new(-1.0, -3.0, 0.0),
        Vector3::new(7.0, 3.0, 3.0),
        0.15,
        0.299,
        &[b],
    )
    .unwrap();
    let dims = map.dims();
    let (lo, _) = map.bounds();
    let mut cells = Vec::with_capacity(dims.iter().product());
    for z in 0..dims[2] {
        for y in 0..dims[1] {
            for x in 0..dims[0] {
                let c = lo + Vector3::new(x as f64 + 0.5, y as f64 + 0.5, z as f64 + 0.5) * 0.15;
                let state = if b.distance(&c) == 0.0 {
                    CellState::Occupied
                } else if map.is_occupied(&c) {
                    CellState::Inflated
                } else {
                    CellState::Free
                };
                cells.push(state as u8);
            }
        }
    }
    let header = OccupancyMapHeader {
        msg: Header::captured_at(monotonic_ns()),
        origin: [lo.x, lo.y, lo.z],
        resolution: 0.15,
        inflation: 0.299,
        dims: dims.map(|d| d as u32),
        reserved: 0,
        state_ns: 0,
    };
    (map, header, cells)
}

#[test]
fn a_state_a_map_and_a_goal_give_a_collision_free_trajectory_from_the_vehicle_and_its_stats() {
    let prefix = IpcPrefix::unique("plannerproc");
    let ipc = Ipc::open("planner-test", &prefix).unwrap();
    let trajectories = ipc
        .subscriber::<Trajectory>(services::PLANNER_TRAJECTORY)
        .unwrap();
    let stats = ipc
        .subscriber::<PlannerStats>(services::PLANNER_STATS)
        .unwrap();
    let mut states = ipc
        .publisher::<VehicleState>(services::VEHICLE_STATE)
        .unwrap();
    let mut goals = ipc
        .publisher::<PlannerGoal>(services::PLANNER_GOAL)
        .unwrap();
    let (map, header, cells) = scene();
    let mut maps = ipc
        .slice_publisher::<u8, OccupancyMapHeader>(services::MAP_OCCUPANCY, cells.len())
        .unwrap();
    let planner = Running::start(
        "planner",
        Command::new(env!("CARGO_BIN_EXE_planner"))
            .arg("--ipc-prefix")
            .arg(prefix.as_str()),
    );
    planner.wait_for("planner running", Duration::from_secs(30));

    let here = [0.0, 0.0, 0.8];
    let goal = PlannerGoal {
        msg: Header::captured_at(monotonic_ns()),
        position: [6.0, 0.0, 0.8],
        mode: GoalMode::Point as u32,
        ..PlannerGoal::default()
    };
    let (mut trajectory, mut stat) = (None, None);
    let end = Instant::now() + Duration::from_secs(30);
    // Inputs are sent again until the planner has answered: a subscriber that connects
    // after a sample was sent does not see it.
    while trajectory.is_none() || stat.is_none() {
        assert!(
            Instant::now() < end,
            "no trajectory and stats in 30 s:\n{}",
            planner.log()
        );
        let s = VehicleState {
            msg: Header::captured_at(monotonic_ns()),
            world_from_body: Pose {
                translation: here,
                rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
            },
            ..VehicleState::default()
        };
        states.send(s.msg, &s).unwrap();
        let mut sample = maps.loan(cells.len()).unwrap();
        sample.payload_mut().copy_from_slice(&cells);
        *sample.user_header_mut() = header;
        maps.send(sample).unwrap();
        goals.send(goal.msg, &goal).unwrap();
        std::thread::sleep(Duration::from_millis(50));
        while let Some(t) = trajectories.receive().unwrap() {
            trajectory = Some(*t.payload());
        }
        while let Some(s) = stats.receive().unwrap() {
            stat = Some(*s.payload());
        }
    }
    let (t, s) = (trajectory.unwrap(), stat.unwrap());
    assert_eq!((s.success, s.trajectory_id), (1, t.id), "{s:?}");
    // The process times the plan in the planner's stage stamp (the driver closes it when
    // the statistics leave, right after the plan).
    let stamp = s
        .msg
        .stages()
        .iter()
        .find(|st| st.stage == ipc_types::msg::Stage::Planner as u32)
        .copied()
        .unwrap();
    let ms = stamp.exit_ns.saturating_sub(stamp.enter_ns) as f64 * 1e-6;
    assert!(ms > 0.0 && ms < 1000.0, "the process times the plan: {s:?}");
    assert_eq!(t.emergency, 0);
    let spline = BSpline {
        points: t.points().iter().map(|p| Vector3::from(*p)).collect(),
        ts: t.knot_interval_s,
    };
    let start = spline.eval(0.0);
    assert!(
        (start.p - Vector3::from(here)).norm() < 1e-6,
        "{:?}",
        start.p
    );
    assert!(start.v.norm() < 1e-6);
    let view = CellView::new(&header, &cells).unwrap();
    let n = 2000;
    for k in 0..=n {
        let p = spline.eval(spline.duration() * k as f64 / n as f64).p;
        assert!(
            !view.is_occupied(&p),
            "{p} is in an occupied or inflated cell"
        );
        assert!(
            map.boxes()[0].distance(&p) >= 0.299 - 1e-6,
            "{p} is too close to the box"
        );
    }
    let last = spline.eval(spline.duration()).p;
    assert!((last - Vector3::new(6.0, 0.0, 0.8)).norm() < 1e-6, "{last}");
}

#[test]
fn a_bad_config_is_one_line_and_exit_code_2() {
    let dir = std::env::temp_dir().join(format!("planner_proc_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file: PathBuf = dir.join("bad.toml");
    std::fs::write(&file, "[planner]\nmax_vel = -1.0\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_planner"))
        .arg("--config")
        .arg(&file)
        .args(["--ipc-prefix", "lt_plannerbad_"])
        .output()
        .unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("planner.max_vel"), "{err}");
}
