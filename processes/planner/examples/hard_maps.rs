//! Work counters per run on `landing bench planner`'s maps (the same generator, seeds
//! and densities): which maps restart or fail, and what each costs in L-BFGS iterations,
//! rebound rounds, A* expansions and occupancy queries. Counters, not clocks: they are
//! the same on a busy machine. `cargo run --release -p planner --example hard_maps -- 1 2 3`
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::cell::Cell;
use std::time::Instant;

use nalgebra::Vector3;
use planner::{Aabb, Goal, GridMap, OccupancyQuery, Planner, PlannerConfig, State};

struct Rng(u64);

impl Rng {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }
}

struct Counting<'a> {
    map: &'a GridMap,
    queries: Cell<u64>,
}

impl OccupancyQuery for Counting<'_> {
    fn resolution(&self) -> f64 {
        self.map.resolution()
    }
    fn is_occupied(&self, p: &Vector3<f64>) -> bool {
        self.queries.set(self.queries.get() + 1);
        self.map.is_occupied(p)
    }
    fn bounds(&self) -> (Vector3<f64>, Vector3<f64>) {
        self.map.bounds()
    }
}

fn scene(rng: &mut Rng, density: f64, cfg: &PlannerConfig) -> GridMap {
    let (start, goal) = (Vector3::new(0.0, 0.0, 1.0), Vector3::new(10.0, 0.0, 1.0));
    let count = (density * 64.0).round() as usize;
    let mut boxes = Vec::with_capacity(count);
    while boxes.len() < count {
        let c = Vector3::new(1.0 + 8.0 * rng.uniform(), -4.0 + 8.0 * rng.uniform(), 0.0);
        let flat = |p: Vector3<f64>| Vector3::new(p.x, p.y, 0.0);
        if (c - flat(start)).norm() < 1.0 || (c - flat(goal)).norm() < 1.0 {
            continue;
        }
        let w = 0.15;
        boxes.push(Aabb {
            min: Vector3::new(c.x - w, c.y - w, 0.0),
            max: Vector3::new(c.x + w, c.y + w, 3.0),
        });
    }
    GridMap::from_boxes(
        Vector3::new(-1.0, -5.0, 0.0),
        Vector3::new(11.0, 5.0, 3.0),
        cfg.resolution,
        cfg.inflation,
        &boxes,
    )
    .unwrap()
}

fn main() {
    let seeds: Vec<u64> = std::env::args()
        .skip(1)
        .map(|s| s.parse().unwrap())
        .collect();
    let seeds = if seeds.is_empty() { vec![1] } else { seeds };
    let mut cfg = PlannerConfig::default();
    let env = |name: &str| std::env::var(name).ok();
    if let Some(v) = env("STALL") {
        cfg.max_stalled_rounds = v.parse().unwrap();
    }
    if let Some(v) = env("BUDGET") {
        cfg.work_budget = v.parse().unwrap();
    }
    if let Some(v) = env("ROUNDS") {
        cfg.max_rebounds = v.parse().unwrap();
    }
    if let Some(v) = env("GTOL") {
        cfg.g_tolerance = v.parse().unwrap();
    }
    if let Some(v) = env("MEM") {
        cfg.lbfgs_memory = v.parse().unwrap();
    }
    let all = env("ALL").is_some();
    // ONLY="seed:density:map,...": plan only these maps (the others are still generated).
    let only: Vec<String> = env("ONLY")
        .map(|v| {
            v.split(',')
                .filter(|s| !s.is_empty())
                .map(str::to_string)
                .collect()
        })
        .unwrap_or_default();
    let quiet = env("QUIET").is_some();
    let mut planner = Planner::new(cfg.clone());
    let (s, g) = (
        State::at_rest(Vector3::new(0.0, 0.0, 1.0)),
        State::at_rest(Vector3::new(10.0, 0.0, 1.0)),
    );
    for seed in seeds {
        let mut rng = Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1);
        let (mut it, mut ex, mut qu, mut fails, mut restarts) = (0u64, 0u64, 0u64, 0, 0);
        let mut ms = Vec::new();
        let (mut jerk, mut dur, mut nok) = (0.0, 0.0, 0.0);
        for d in [0.05, 0.1, 0.15, 0.2] {
            for k in 0..50 {
                let map = scene(&mut rng, d, &cfg);
                if !only.is_empty() && !only.contains(&format!("{seed}:{d:.2}:{k}")) {
                    continue;
                }
                let cm = Counting {
                    map: &map,
                    queries: Cell::new(0),
                };
                let goal = Goal {
                    state: g,
                    moving: false,
                };
                let t0 = Instant::now();
                let r = planner.plan(&cm, &s, &goal);
                let t = t0.elapsed().as_secs_f64() * 1e3;
                ms.push(t);
                let st = planner.stats();
                it += st.iterations as u64;
                ex += st.astar_expansions;
                qu += cm.queries.get();
                fails += r.is_err() as usize;
                restarts += st.restarts;
                if let Ok(p) = &r {
                    let q = &p.spline.points;
                    let j: f64 = (0..q.len() - 3)
                        .map(|i| (q[i + 3] - q[i + 2] * 3.0 + q[i + 1] * 3.0 - q[i]).norm_squared())
                        .sum::<f64>()
                        / p.spline.ts.powi(5);
                    jerk += j;
                    dur += p.spline.duration();
                    nok += 1.0;
                }
                let hard = r.is_err() || st.restarts > 0 || st.rebounds > 8 || t > 2.0;
                if all || (!quiet && hard) {
                    println!(
                        "seed {seed} density {d:.2} map {k}: {:?} {t:.3} ms it {} rb {} re {} realloc {} astar {} queries {}",
                        r.as_ref().err(),
                        st.iterations,
                        st.rebounds,
                        st.restarts,
                        st.reallocations,
                        st.astar_expansions,
                        cm.queries.get()
                    );
                }
            }
        }
        ms.sort_by(f64::total_cmp);
        if ms.len() < 200 {
            println!(
                "seed {seed}: failures {fails}, restarts {restarts}, iterations {it}, A* expansions {ex}, queries {qu}"
            );
            continue;
        }
        println!(
            "seed {seed}: failures {fails}/200, restarts {restarts}, iterations {it}, A* expansions {ex}, queries {qu}, ms p50 {:.3} p99 {:.3} top6 {:.2?}, mean jerk {:.0} duration {:.3} (random maps only)",
            ms[100],
            ms[197],
            &ms[194..],
            jerk / nok,
            dur / nok
        );
    }
}
