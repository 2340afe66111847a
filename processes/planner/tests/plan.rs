#![allow(clippy::unwrap_used, clippy::expect_used)]
#![allow(clippy::needless_range_loop)] // the basis matrix reads as written
//! Whole plans checked from outside the optimizer: the curve is re-evaluated here with
//! its own basis matrix and sampled densely against the raw boxes (distance >= the
//! inflation), the limits, and the requested end states.

use nalgebra::Vector3;
use planner::fields::{FieldRng, pillar_field};
use planner::{
    Aabb, BSpline, EXPANSIONS_PER_ITERATION, Goal, GridMap, LIMIT_TOLERANCE, OccupancyQuery,
    PlanError, Planner, PlannerConfig, State,
};

fn v(x: f64, y: f64, z: f64) -> Vector3<f64> {
    Vector3::new(x, y, z)
}

/// Position, velocity, acceleration at `t` from the uniform cubic B-spline matrix form.
fn sample(s: &BSpline, t: f64) -> [Vector3<f64>; 3] {
    let segs = s.points.len() - 3;
    let x = (t / s.ts).clamp(0.0, segs as f64);
    let i = (x as usize).min(segs - 1);
    let u = x - i as f64;
    let m = [
        [1.0, 4.0, 1.0, 0.0],
        [-3.0, 0.0, 3.0, 0.0],
        [3.0, -6.0, 3.0, 0.0],
        [-1.0, 3.0, -3.0, 1.0],
    ];
    let mut out = [Vector3::zeros(); 3];
    let pu = [
        [1.0, u, u * u, u * u * u],
        [0.0, 1.0, 2.0 * u, 3.0 * u * u],
        [0.0, 0.0, 2.0, 6.0 * u],
    ];
    for (d, row) in pu.iter().enumerate() {
        for k in 0..4 {
            let mut w = 0.0;
            for r in 0..4 {
                w += row[r] * m[r][k];
            }
            out[d] += s.points[i + k] * (w / 6.0 / s.ts.powi(d as i32));
        }
    }
    out
}

fn check(map: &GridMap, s: &BSpline, start: &State, goal: &State, cfg: &PlannerConfig) {
    let n = 4000;
    let vlim = cfg.max_vel.max(start.v.norm()).max(goal.v.norm());
    let alim = cfg.max_acc.max(start.a.norm()).max(goal.a.norm());
    for k in 0..=n {
        let t = s.duration() * k as f64 / n as f64;
        let [p, vel, acc] = sample(s, t);
        for b in map.boxes() {
            assert!(
                b.distance(&p) >= map.inflation() - 1e-6,
                "t {t}: {p} is {} m from a box",
                b.distance(&p)
            );
        }
        assert!(
            vel.norm() <= vlim * LIMIT_TOLERANCE,
            "t {t}: speed {}",
            vel.norm()
        );
        assert!(
            acc.norm() <= alim * LIMIT_TOLERANCE,
            "t {t}: acceleration {}",
            acc.norm()
        );
    }
    let [p0, v0, _] = sample(s, 0.0);
    let [p1, v1, _] = sample(s, s.duration());
    assert!(
        (p0 - start.p).norm() < 1e-6 && (v0 - start.v).norm() < 1e-6,
        "start {p0} {v0}"
    );
    assert!(
        (p1 - goal.p).norm() < 1e-6 && (v1 - goal.v).norm() < 1e-6,
        "end {p1} {v1}"
    );
}

fn paper_map(cfg: &PlannerConfig) -> GridMap {
    // The paper's 60 x 120 x 120 cm box, standing on the floor between start and goal.
    let b = Aabb {
        min: v(2.7, -0.6, 0.0),
        max: v(3.3, 0.6, 1.2),
    };
    GridMap::from_boxes(
        v(-1.0, -3.0, 0.0),
        v(7.0, 3.0, 3.0),
        cfg.resolution,
        cfg.inflation,
        &[b],
    )
    .unwrap()
}

fn at(p: Vector3<f64>) -> State {
    State::at_rest(p)
}

fn goal(s: State) -> Goal {
    Goal {
        state: s,
        moving: false,
    }
}

#[test]
fn the_papers_obstacle_is_bypassed_collision_free_within_limits() {
    let cfg = PlannerConfig::default();
    let map = paper_map(&cfg);
    let mut planner = Planner::new(cfg.clone());
    let (s, g) = (at(v(0.0, 0.0, 0.8)), at(v(6.0, 0.0, 0.8)));
    let plan = planner.plan(&map, &s, &goal(g)).unwrap();
    check(&map, &plan.spline, &s, &g, &cfg);
    assert!(planner.stats().iterations > 0);
}

#[test]
fn a_moving_start_and_goal_velocity_are_met_at_both_ends() {
    let cfg = PlannerConfig::default();
    let map = paper_map(&cfg);
    let mut planner = Planner::new(cfg.clone());
    let s = State {
        p: v(0.0, 0.3, 1.0),
        v: v(1.5, 0.0, 0.0),
        a: Vector3::zeros(),
    };
    let g = State {
        p: v(6.0, -0.5, 0.6),
        v: v(1.0, 0.5, 0.0),
        a: Vector3::zeros(),
    };
    let plan = planner.plan(&map, &s, &goal(g)).unwrap();
    check(&map, &plan.spline, &s, &g, &cfg);
}

#[test]
fn a_fast_chase_at_fifteen_metres_per_second_stays_within_the_limits() {
    let cfg = PlannerConfig {
        max_vel: 20.0,
        max_acc: 10.0,
        ..PlannerConfig::default()
    };
    let map = GridMap::new(
        v(-5.0, -10.0, 0.0),
        v(60.0, 10.0, 6.0),
        cfg.resolution,
        cfg.inflation,
    )
    .unwrap();
    let mut planner = Planner::new(cfg.clone());
    let s = State {
        p: v(0.0, 0.0, 3.0),
        v: v(10.0, 0.0, 0.0),
        a: Vector3::zeros(),
    };
    let g = State {
        p: v(40.0, 2.0, 1.0),
        v: v(14.0, 0.0, 0.0),
        a: Vector3::zeros(),
    };
    let plan = planner.plan(&map, &s, &goal(g)).unwrap();
    check(&map, &plan.spline, &s, &g, &cfg);
}

#[test]
fn a_rendezvous_aims_where_the_target_will_be_on_arrival() {
    let cfg = PlannerConfig::default();
    let map = GridMap::new(v(-2.0, -5.0, 0.0), v(20.0, 5.0, 4.0), 0.15, 0.3).unwrap();
    let mut planner = Planner::new(cfg.clone());
    let s = at(v(0.0, 0.0, 2.0));
    let pad = State {
        p: v(3.0, 0.0, 0.5),
        v: v(1.0, 0.0, 0.0),
        a: Vector3::zeros(),
    };
    let plan = planner
        .plan(
            &map,
            &s,
            &Goal {
                state: pad,
                moving: true,
            },
        )
        .unwrap();
    let end = sample(&plan.spline, plan.spline.duration());
    let predicted = pad.p + pad.v * plan.spline.duration();
    assert!(plan.goal.x > pad.p.x);
    assert!((end[1] - pad.v).norm() < 1e-6);
    // The stretch of time re-allocation may end later than predicted: within 1 s of travel.
    assert!((end[0] - predicted).norm() <= pad.v.norm() * plan.spline.duration() + 1e-6);
}

#[test]
fn a_goal_inside_an_obstacle_moves_to_the_nearest_free_point() {
    let cfg = PlannerConfig::default();
    let map = paper_map(&cfg);
    let mut planner = Planner::new(cfg.clone());
    let s = at(v(0.0, 0.0, 0.8));
    let plan = planner.plan(&map, &s, &goal(at(v(3.0, 0.0, 0.6)))).unwrap();
    assert!(plan.goal_adjusted);
    assert!((plan.goal - v(3.0, 0.0, 0.6)).norm() < 1.2, "{}", plan.goal);
    check(&map, &plan.spline, &s, &at(plan.goal), &cfg);
}

#[test]
fn a_goal_outside_the_map_is_clamped_into_it() {
    let cfg = PlannerConfig::default();
    let map = paper_map(&cfg);
    let mut planner = Planner::new(cfg.clone());
    let s = at(v(0.0, 0.0, 0.8));
    let plan = planner
        .plan(&map, &s, &goal(at(v(50.0, 0.0, 0.8))))
        .unwrap();
    assert!(
        plan.goal_adjusted && plan.goal.x < map.bounds().1.x,
        "{:?}",
        plan.goal
    );
    check(&map, &plan.spline, &s, &at(plan.goal), &cfg);
}

#[test]
fn a_start_inside_the_inflation_is_refused() {
    let cfg = PlannerConfig::default();
    let map = paper_map(&cfg);
    let mut planner = Planner::new(cfg);
    let r = planner.plan(&map, &at(v(2.5, 0.0, 0.8)), &goal(at(v(6.0, 0.0, 0.8))));
    assert_eq!(r.unwrap_err(), PlanError::StartOccupied);
}

#[test]
fn nan_states_are_refused() {
    let cfg = PlannerConfig::default();
    let map = paper_map(&cfg);
    let mut planner = Planner::new(cfg);
    let bad = State {
        v: v(f64::NAN, 0.0, 0.0),
        ..at(v(0.0, 0.0, 1.0))
    };
    assert_eq!(
        planner
            .plan(&map, &bad, &goal(at(v(6.0, 0.0, 1.0))))
            .unwrap_err(),
        PlanError::NotFinite
    );
    assert_eq!(
        planner
            .plan(
                &map,
                &at(v(0.0, 0.0, 1.0)),
                &goal(at(v(f64::INFINITY, 0.0, 1.0)))
            )
            .unwrap_err(),
        PlanError::NotFinite
    );
}

#[test]
fn an_empty_map_gives_a_direct_trajectory() {
    let cfg = PlannerConfig::default();
    let map = GridMap::new(v(0.0, 0.0, 0.0), v(10.0, 10.0, 3.0), 0.15, 0.3).unwrap();
    let mut planner = Planner::new(cfg.clone());
    let (s, g) = (at(v(1.0, 1.0, 1.0)), at(v(9.0, 8.0, 2.0)));
    let plan = planner.plan(&map, &s, &goal(g)).unwrap();
    check(&map, &plan.spline, &s, &g, &cfg);
    assert_eq!(planner.stats().rebounds, 0);
}

#[test]
fn a_wall_with_no_gap_fails_without_a_trajectory() {
    let cfg = PlannerConfig::default();
    let wall = Aabb {
        min: v(3.0, -10.0, -1.0),
        max: v(3.3, 10.0, 10.0),
    };
    let map = GridMap::from_boxes(v(0.0, -3.0, 0.0), v(6.0, 3.0, 3.0), 0.15, 0.3, &[wall]).unwrap();
    let mut planner = Planner::new(cfg);
    let r = planner.plan(&map, &at(v(1.0, 0.0, 1.0)), &goal(at(v(5.0, 0.0, 1.0))));
    assert!(r.is_err(), "{r:?}");
}

#[test]
fn random_pillar_fields_give_collision_free_plans() {
    let cfg = PlannerConfig::default();
    let mut planner = Planner::new(cfg.clone());
    let mut rng = FieldRng::new(7);
    let (s, g) = (at(v(0.0, 0.0, 1.0)), at(v(10.0, 0.0, 1.0)));
    let mut ok = 0;
    for _ in 0..20 {
        let map = pillar_field(&mut rng, 0.2, cfg.resolution, cfg.inflation).unwrap();
        if let Ok(plan) = planner.plan(&map, &s, &goal(g)) {
            check(&map, &plan.spline, &s, &g, &cfg);
            ok += 1;
        }
    }
    assert!(ok >= 17, "{ok} of 20");
}

#[test]
fn every_start_in_the_inflation_but_outside_the_box_fails_clearly_and_never_panics() {
    let cfg = PlannerConfig::default();
    let map = paper_map(&cfg);
    let mut planner = Planner::new(cfg.clone());
    let g = at(v(6.0, 0.0, 0.8));
    let mut refused = 0;
    // A ring of starts 0.05-0.28 m from the box's faces and edges (inside the 0.299 m
    // inflation, outside the box), some moving toward it.
    for k in 0..48 {
        let a = k as f64 * std::f64::consts::TAU / 48.0;
        let gap = 0.05 + 0.23 * (k % 4) as f64 / 3.0;
        let p = v(
            3.0 + (0.3 + gap) * a.cos(),
            (0.6 + gap) * a.sin(),
            0.6 + 0.1 * (k % 3) as f64,
        );
        let b = map.boxes()[0];
        if b.distance(&p) == 0.0 || b.distance(&p) >= map.inflation() {
            continue;
        }
        let s = State {
            p,
            v: v(-a.cos(), -a.sin(), 0.0) * (k % 2) as f64,
            a: Vector3::zeros(),
        };
        match planner.plan(&map, &s, &goal(g)) {
            Err(PlanError::StartOccupied) => refused += 1,
            Ok(plan) => check(&map, &plan.spline, &s, &g, &cfg),
            Err(e) => panic!("{p}: {e}"),
        }
    }
    assert!(refused >= 30, "{refused}");
}

/// A field dense enough that plans need rebound rounds (and some a restart).
/// A field of the benchmark's densest kind (0.2 floor-to-ceiling pillars per m^2).
fn dense_field(seed: u64) -> GridMap {
    let cfg = PlannerConfig::default();
    pillar_field(&mut FieldRng::new(seed), 0.2, cfg.resolution, cfg.inflation).unwrap()
}

#[test]
fn no_plan_spends_more_than_its_work_budget_and_a_spent_budget_is_an_error() {
    let (s, g) = (at(v(0.0, 0.0, 1.0)), at(v(10.0, 0.0, 1.0)));
    // With the default budget, every plan stays within it (plus the one optimization
    // under way when it ran out, itself capped at what was left).
    let cfg = PlannerConfig::default();
    let mut planner = Planner::new(cfg.clone());
    let mut ok = 0;
    for seed in 1..=30 {
        let map = dense_field(seed);
        let r = planner.plan(&map, &s, &goal(g));
        let st = planner.stats();
        let work = st.iterations as u64 + st.astar_expansions / EXPANSIONS_PER_ITERATION;
        assert!(work <= cfg.work_budget as u64 + 1, "seed {seed}: {st:?}");
        assert!(
            st.rebounds as usize <= cfg.max_rebounds + 2,
            "seed {seed}: {st:?}"
        );
        if let Ok(plan) = r {
            check(&map, &plan.spline, &s, &g, &cfg);
            ok += 1;
        }
    }
    assert!(ok >= 27, "{ok} of 30");
    // A budget too small for any rebound: the plans that need one fail as OverBudget (or
    // NoPath when A* itself ran out), never with a trajectory that was not checked.
    let tiny = PlannerConfig {
        work_budget: 10,
        ..PlannerConfig::default()
    };
    let mut planner = Planner::new(tiny.clone());
    let mut over = 0;
    for seed in 1..=30 {
        let map = dense_field(seed);
        match planner.plan(&map, &s, &goal(g)) {
            Ok(plan) => check(&map, &plan.spline, &s, &g, &tiny),
            Err(PlanError::OverBudget) => over += 1,
            Err(PlanError::NoPath | PlanError::Collides | PlanError::Infeasible(_)) => {}
            Err(e) => panic!("seed {seed}: {e}"),
        }
        let st = planner.stats();
        assert!(
            st.iterations as usize <= tiny.work_budget + 1,
            "seed {seed}: {st:?}"
        );
    }
    assert!(over > 0);
}

#[test]
fn time_reallocation_settles_in_one_pass_on_dense_fields() {
    // The optimizer aims 5% inside the limits, so a refinement does not come back beyond
    // them asking for another stretch (aimed at the limits themselves, plans on dense
    // fields ran the re-allocation loop to its limit of 5, each pass a refinement).
    let cfg = PlannerConfig::default();
    let mut planner = Planner::new(cfg.clone());
    let mut rng = FieldRng::new(1);
    let (s, g) = (at(v(0.0, 0.0, 1.0)), at(v(10.0, 0.0, 1.0)));
    let mut ok = 0;
    for k in 0..40 {
        let map = pillar_field(&mut rng, 0.2, cfg.resolution, cfg.inflation).unwrap();
        let r = planner.plan(&map, &s, &goal(g));
        let st = planner.stats();
        assert!(st.reallocations <= 1, "map {k}: {st:?}");
        if let Ok(plan) = r {
            check(&map, &plan.spline, &s, &g, &cfg);
            ok += 1;
        }
    }
    // The densest benchmark fields: 34 of these 40 succeed (the rest fail cleanly).
    assert!(ok >= 32, "{ok} of 40");
}
