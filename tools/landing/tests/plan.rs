#![allow(clippy::unwrap_used, clippy::expect_used)]
//! `landing plan` and `landing bench planner` as a user meets them: the documented JSON,
//! a curve from the start to the goal around the paper's obstacle, one-line errors.

mod common;
use common::landing;

fn paper_map() -> String {
    concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../deploy/maps/paper-obstacle.json"
    )
    .to_string()
}

fn temp(name: &str, text: &str) -> String {
    let dir = std::env::temp_dir().join(format!("landing-plan-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p.to_str().unwrap().to_string()
}

/// The uniform cubic B-spline's position at the start or the end of its control points.
fn end_point(points: &[Vec<f64>], at_end: bool) -> [f64; 3] {
    let q = if at_end {
        &points[points.len() - 3..]
    } else {
        &points[..3]
    };
    let mut p = [0.0; 3];
    for (k, w) in [1.0 / 6.0, 4.0 / 6.0, 1.0 / 6.0].iter().enumerate() {
        for i in 0..3 {
            p[i] += w * q[k][i];
        }
    }
    p
}

#[test]
fn a_plan_around_the_papers_obstacle_prints_the_documented_json() {
    let map = paper_map();
    let o = landing(&[
        "plan", "--map", &map, "--start", "0,0,0.8", "--goal", "6,0,0.8", "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    assert_eq!(v["success"], true);
    let pts: Vec<Vec<f64>> = serde_json::from_value(v["control_points"].clone()).unwrap();
    assert!(pts.len() >= 7 && pts.iter().all(|p| p.len() == 3));
    let ts = v["knot_interval"].as_f64().unwrap();
    let dur = v["duration"].as_f64().unwrap();
    assert!(ts > 0.0 && (dur - ts * (pts.len() - 3) as f64).abs() < 1e-9);
    assert!(v["planning_time_ms"].as_f64().unwrap() > 0.0);
    assert!(v["iterations"].as_u64().is_some() && v["rebounds"].as_u64().is_some());
    let (s, e) = (end_point(&pts, false), end_point(&pts, true));
    for i in 0..3 {
        assert!((s[i] - [0.0, 0.0, 0.8][i]).abs() < 1e-6, "{s:?}");
        assert!((e[i] - [6.0, 0.0, 0.8][i]).abs() < 1e-6, "{e:?}");
    }
    // It goes around the box: some control point leaves the box's footprint (y in
    // -0.6..0.6 below 1.2 m) by the inflation.
    assert!(
        pts.iter().any(|p| p[1].abs() > 0.9 || p[2] > 1.5),
        "{pts:?}"
    );
}

#[test]
fn start_and_goal_velocities_are_accepted() {
    let map = paper_map();
    let o = landing(&[
        "plan",
        "--map",
        &map,
        "--start",
        "0,0,1",
        "--goal",
        "6,0.5,1",
        "--start-vel",
        "1,0,0",
        "--goal-vel",
        "-0.5,0,0",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["success"], true);
}

fn one_line_error(args: &[&str], needle: &str) {
    let o = landing(args);
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    assert!(err.contains(needle), "{args:?}: {err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn bad_maps_and_flags_are_one_line_errors() {
    one_line_error(
        &[
            "plan",
            "--map",
            "/nonexistent.json",
            "--start",
            "0,0,1",
            "--goal",
            "1,0,1",
        ],
        "cannot read",
    );
    let bad = temp("bad.json", "{\"bounds\": {\"min\": [0, 0, 0]}}");
    one_line_error(
        &["plan", "--map", &bad, "--start", "0,0,1", "--goal", "1,0,1"],
        "missing field `max`",
    );
    let inverted = temp(
        "inv.json",
        "{\"bounds\": {\"min\": [0, 0, 0], \"max\": [-1, 1, 1]}}",
    );
    one_line_error(
        &[
            "plan", "--map", &inverted, "--start", "0,0,1", "--goal", "1,0,1",
        ],
        "bounds",
    );
    let badbox = temp(
        "box.json",
        "{\"bounds\": {\"min\": [0, 0, 0], \"max\": [5, 5, 3]}, \"boxes\": [{\"min\": [2, 2, 0], \"max\": [1, 3, 1]}]}",
    );
    one_line_error(
        &[
            "plan", "--map", &badbox, "--start", "0,0,1", "--goal", "1,0,1",
        ],
        "boxes[0]",
    );
    let map = paper_map();
    one_line_error(
        &["plan", "--map", &map, "--start", "0,0", "--goal", "1,0,1"],
        "expected x,y,z",
    );
    one_line_error(
        &[
            "plan", "--map", &map, "--start", "0,0,nan", "--goal", "1,0,1",
        ],
        "not finite",
    );
}

#[test]
fn a_goal_outside_the_map_or_a_speed_beyond_the_limit_is_an_error_not_clamped() {
    let map = paper_map();
    one_line_error(
        &[
            "plan", "--map", &map, "--start", "0,0,1", "--goal", "1e9,0,1",
        ],
        "--goal 1e9,0,1: outside the map (allowed:",
    );
    one_line_error(
        &[
            "plan", "--map", &map, "--start", "0,0,-5", "--goal", "6,0,1",
        ],
        "--start 0,0,-5: outside the map",
    );
    one_line_error(
        &[
            "plan",
            "--map",
            &map,
            "--start",
            "0,0,1",
            "--goal",
            "6,0,1",
            "--start-vel",
            "30,0,0",
        ],
        "max_vel",
    );
}

#[test]
fn a_start_inside_the_obstacle_is_no_plan_with_exit_code_three() {
    let map = paper_map();
    let o = landing(&[
        "plan", "--map", &map, "--start", "3,0,0.5", "--goal", "6,0,0.8", "--json",
    ]);
    assert_eq!(o.status.code(), Some(3));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["success"], false);
    assert!(v["error"].as_str().unwrap().contains("inflation"));
    assert_eq!(v["control_points"].as_array().unwrap().len(), 0);
}

#[test]
fn the_planner_benchmark_prints_the_documented_json() {
    let o = landing(&["bench", "planner", "--json", "--maps", "3"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    for key in ["success_rate", "planning_ms_p50", "planning_ms_p99"] {
        assert!(v[key].as_f64().unwrap() > 0.0, "{key}");
    }
    // The headline is the random fields alone (4 densities x 3); the paper's scene is
    // its own row.
    assert_eq!(v["runs"].as_u64(), Some(12));
    for d in ["0.05", "0.10", "0.15", "0.20"] {
        assert_eq!(v["per_density"][d]["runs"].as_u64(), Some(3), "{d}");
    }
    assert_eq!(v["paper_obstacle"]["runs"].as_u64(), Some(3));
}
