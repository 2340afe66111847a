use super::*;
use crate::map::{Aabb, GridMap};

fn line() -> BSpline {
    BSpline {
        points: (0..10)
            .map(|i| Vector3::new(i as f64 * 0.5, 2.0, 1.0))
            .collect(),
        ts: 0.25,
    }
}

fn empty() -> GridMap {
    GridMap::new(Vector3::zeros(), Vector3::new(6.0, 4.0, 3.0), 0.15, 0.3).unwrap()
}

#[test]
fn a_missing_trajectory_a_new_goal_and_distance_travelled_each_ask_for_a_replan() {
    let map = empty();
    let mut p = ReplanPolicy::new(1.5, 0.3, 3.0, 1.0);
    let goal = (Vector3::new(4.0, 2.0, 1.0), 1);
    let here = Vector3::new(0.0, 2.0, 1.0);
    assert_eq!(
        p.decide(0.0, &here, goal, None, &map),
        Decision::Replan(Reason::NoTrajectory)
    );
    let t = line();
    assert_eq!(
        p.decide(0.0, &here, goal, Some(&t), &map),
        Decision::Replan(Reason::NewGoal)
    );
    p.planned(&here, goal);
    assert_eq!(p.decide(0.0, &here, goal, Some(&t), &map), Decision::Keep);
    let moved = (Vector3::new(4.0, 2.5, 1.0), 1);
    assert_eq!(
        p.decide(0.0, &here, moved, Some(&t), &map),
        Decision::Replan(Reason::NewGoal)
    );
    let there = Vector3::new(1.6, 2.0, 1.0);
    assert_eq!(
        p.decide(0.4, &there, goal, Some(&t), &map),
        Decision::Replan(Reason::Distance)
    );
}

#[test]
fn a_collision_ahead_asks_for_a_replan_and_a_failure_close_to_it_stops_the_drone() {
    let mut map = empty();
    map.add_box(&Aabb {
        min: Vector3::new(1.0, 1.5, 0.0),
        max: Vector3::new(1.2, 2.5, 3.0),
    });
    let mut p = ReplanPolicy::new(1.5, 0.3, 3.0, 1.0);
    let goal = (Vector3::new(4.0, 2.0, 1.0), 1);
    let here = Vector3::new(0.0, 2.0, 1.0);
    p.planned(&here, goal);
    let d = p.decide(0.0, &here, goal, Some(&line()), &map);
    let Decision::Replan(Reason::Collision(dt)) = d else {
        panic!("{d:?}");
    };
    assert!(dt > 0.0 && dt < 1.0, "{dt}");
    assert_eq!(
        p.on_failure(Reason::Collision(dt)),
        OnFailure::EmergencyStop
    );
    assert_eq!(p.on_failure(Reason::Collision(2.0)), OnFailure::KeepCurrent);
    assert_eq!(p.on_failure(Reason::Distance), OnFailure::KeepCurrent);
}
