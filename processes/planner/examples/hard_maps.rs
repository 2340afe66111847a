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
    let cfg = PlannerConfig::default();
    let mut planner = Planner::new(cfg.clone());
    let (s, g) = (
        State::at_rest(Vector3::new(0.0, 0.0, 1.0)),
        State::at_rest(Vector3::new(10.0, 0.0, 1.0)),
    );
    for seed in seeds {
        let mut rng = Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1);
        let (mut it, mut ex, mut qu, mut fails, mut ms) = (0u64, 0u64, 0u64, 0, Vec::new());
        for d in [0.05, 0.1, 0.15, 0.2] {
            for k in 0..50 {
                let map = scene(&mut rng, d, &cfg);
                let cm = Counting {
                    map: &map,
                    queries: Cell::new(0),
                };
                let t0 = Instant::now();
                let r = planner.plan(
                    &cm,
                    &s,
                    &Goal {
                        state: g,
                        moving: false,
                    },
                );
                let t = t0.elapsed().as_secs_f64() * 1e3;
                ms.push(t);
                let st = planner.stats();
                it += st.iterations as u64;
                ex += st.astar_expansions;
                qu += cm.queries.get();
                fails += r.is_err() as usize;
                if r.is_err() || st.restarts > 0 || st.rebounds > 8 || t > 2.0 {
                    println!(
                        "seed {seed} density {d:.2} map {k}: {:?} {t:.2} ms it {} rb {} re {} realloc {} astar {} queries {}",
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
        println!(
            "seed {seed}: failures {fails}/200, iterations {it}, A* expansions {ex}, queries {qu}, ms p50 {:.3} p99 {:.3} (random maps only)",
            ms[100], ms[197]
        );
    }
}
