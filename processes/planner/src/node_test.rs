use super::*;
use crate::map::{Aabb, GridMap};

fn goal(seq: u64, p: [f64; 3], mode: GoalMode) -> PlannerGoal {
    PlannerGoal {
        msg: Header {
            seq,
            ..Header::default()
        },
        position: p,
        mode: mode as u32,
        ..PlannerGoal::default()
    }
}

fn map() -> GridMap {
    let b = Aabb {
        min: Vector3::new(2.7, -0.6, 0.0),
        max: Vector3::new(3.3, 0.6, 1.2),
    };
    GridMap::from_boxes(
        Vector3::new(-1.0, -3.0, 0.0),
        Vector3::new(7.0, 3.0, 3.0),
        0.15,
        0.299,
        &[b],
    )
    .unwrap()
}

#[test]
fn a_goal_gives_one_trajectory_and_the_same_goal_no_second_one() {
    let mut node = PlannerNode::new(PlannerConfig::default());
    let m = map();
    let here = State::at_rest(Vector3::new(0.0, 0.0, 0.8));
    let g = goal(1, [6.0, 0.0, 0.8], GoalMode::Point);
    let out = node.step(1_000, &here, Some(&g), Some(&m), &Header::default());
    let t = out.trajectory.unwrap();
    assert_eq!((t.id, t.emergency, t.start_ns), (1, 0, 1_000));
    assert!(t.count >= 7 && t.points().iter().flatten().all(|v| v.is_finite()));
    assert_eq!(out.stats.unwrap().success, 1);
    let again = node.step(2_000, &here, Some(&g), Some(&m), &Header::default());
    assert!(again.trajectory.is_none() && again.stats.is_none());
}

#[test]
fn nothing_is_published_without_a_goal_a_map_or_a_finite_state() {
    let mut node = PlannerNode::new(PlannerConfig::default());
    let m = map();
    let here = State::at_rest(Vector3::new(0.0, 0.0, 0.8));
    let g = goal(1, [6.0, 0.0, 0.8], GoalMode::Point);
    assert!(
        node.step(0, &here, None, Some(&m), &Header::default())
            .trajectory
            .is_none()
    );
    assert!(
        node.step::<GridMap>(0, &here, Some(&g), None, &Header::default())
            .trajectory
            .is_none()
    );
    let nan = State::at_rest(Vector3::new(f64::NAN, 0.0, 0.8));
    assert!(
        node.step(0, &nan, Some(&g), Some(&m), &Header::default())
            .trajectory
            .is_none()
    );
}

#[test]
fn a_stop_goal_publishes_one_stop_trajectory() {
    let mut node = PlannerNode::new(PlannerConfig::default());
    let m = map();
    let moving = State {
        p: Vector3::new(0.0, 0.0, 1.0),
        v: Vector3::new(2.0, 0.0, 0.0),
        a: Vector3::zeros(),
    };
    let g = goal(5, [0.0; 3], GoalMode::Stop);
    let t = node
        .step(0, &moving, Some(&g), Some(&m), &Header::default())
        .trajectory
        .unwrap();
    assert_eq!(t.emergency, 0);
    assert!(
        node.step(10, &moving, Some(&g), Some(&m), &Header::default())
            .trajectory
            .is_none()
    );
}

#[test]
fn a_failed_plan_publishes_no_trajectory_but_its_statistics() {
    let mut node = PlannerNode::new(PlannerConfig::default());
    let wall = Aabb {
        min: Vector3::new(3.0, -10.0, -1.0),
        max: Vector3::new(3.3, 10.0, 10.0),
    };
    let m = GridMap::from_boxes(
        Vector3::new(0.0, -3.0, 0.0),
        Vector3::new(6.0, 3.0, 3.0),
        0.15,
        0.3,
        &[wall],
    )
    .unwrap();
    let here = State::at_rest(Vector3::new(1.0, 0.0, 1.0));
    let out = node.step(
        0,
        &here,
        Some(&goal(1, [5.0, 0.0, 1.0], GoalMode::Point)),
        Some(&m),
        &Header::default(),
    );
    assert!(out.trajectory.is_none());
    assert_eq!(out.stats.unwrap().success, 0);
}

#[test]
fn the_step_leaves_the_planning_time_to_the_caller_who_owns_the_clock() {
    let mut node = PlannerNode::new(PlannerConfig::default());
    let m = map();
    let here = State::at_rest(Vector3::new(0.0, 0.0, 0.8));
    let g = goal(1, [6.0, 0.0, 0.8], GoalMode::Point);
    let stats = node
        .step(0, &here, Some(&g), Some(&m), &Header::default())
        .stats
        .unwrap();
    assert_eq!((stats.success, stats.planning_ms), (1, 0.0));
}

#[test]
fn a_start_in_the_inflation_publishes_no_trajectory_and_reports_the_failure() {
    let mut node = PlannerNode::new(PlannerConfig::default());
    let m = map();
    let close = State::at_rest(Vector3::new(2.5, 0.0, 0.8));
    let g = goal(1, [6.0, 0.0, 0.8], GoalMode::Point);
    let out = node.step(0, &close, Some(&g), Some(&m), &Header::default());
    assert!(out.trajectory.is_none() && node.current().is_none());
    assert_eq!(out.stats.unwrap().success, 0);
}
