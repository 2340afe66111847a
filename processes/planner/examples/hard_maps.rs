//! Work counters per run on `landing bench planner`'s maps (the same generator, seeds
//! and densities): which maps restart or fail, and what each costs in L-BFGS iterations,
//! rebound rounds, A* expansions and occupancy queries. Counters, not clocks: they are
//! the same on a busy machine. `cargo run --release -p planner --example hard_maps -- 1 2 3`

use std::cell::Cell;
use std::time::Instant;

use nalgebra::Vector3;
use planner::fields::{FIELD_DENSITIES, FIELD_GOAL, FIELD_START, FieldRng, pillar_field};
use planner::{Goal, GridMap, OccupancyQuery, Planner, PlannerConfig, State};

type Error = Box<dyn std::error::Error>;

/// `value` parsed, or an error naming `what`.
fn parse<T: std::str::FromStr>(what: &str, value: &str) -> Result<T, Error> {
    value
        .parse()
        .map_err(|_| format!("{what} `{value}` is not a number of the right kind").into())
}

/// Overrides `field` with the environment variable `name` when it is set.
fn set_from_env<T: std::str::FromStr>(name: &str, field: &mut T) -> Result<(), Error> {
    if let Ok(v) = std::env::var(name) {
        *field = parse(name, &v)?;
    }
    Ok(())
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

fn main() -> Result<(), Error> {
    let seeds: Vec<u64> = std::env::args()
        .skip(1)
        .map(|s| parse("seed", &s))
        .collect::<Result<_, _>>()?;
    let seeds = if seeds.is_empty() { vec![1] } else { seeds };
    let mut cfg = PlannerConfig::default();
    let env = |name: &str| std::env::var(name).ok();
    set_from_env("STALL", &mut cfg.max_stalled_rounds)?;
    set_from_env("BUDGET", &mut cfg.work_budget)?;
    set_from_env("ROUNDS", &mut cfg.max_rebounds)?;
    set_from_env("GTOL", &mut cfg.g_tolerance)?;
    set_from_env("CPS", &mut cfg.control_point_spacing)?;
    set_from_env("RGTOL", &mut cfg.rebound_g_tolerance)?;
    set_from_env("MEM", &mut cfg.lbfgs_memory)?;
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
        State::at_rest(Vector3::from(FIELD_START)),
        State::at_rest(Vector3::from(FIELD_GOAL)),
    );
    let mut all_ms: Vec<f64> = Vec::new();
    let mut all_fail = 0usize;
    for seed in seeds {
        let mut rng = FieldRng::new(seed);
        let (mut it, mut ex, mut qu, mut fails, mut restarts) = (0u64, 0u64, 0u64, 0, 0);
        let mut ms = Vec::new();
        let (mut jerk, mut dur, mut nok) = (0.0, 0.0, 0.0);
        for d in FIELD_DENSITIES {
            for k in 0..50 {
                let map = pillar_field(&mut rng, d, cfg.resolution, cfg.inflation)?;
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
        all_ms.extend_from_slice(&ms);
        all_fail += fails;
        ms.sort_by(f64::total_cmp);
        if ms.len() < 200 {
            println!(
                "seed {seed}: failures {fails}, restarts {restarts}, iterations {it}, A* expansions {ex}, queries {qu}"
            );
            continue;
        }
        println!(
            "seed {seed}: failures {fails}/200, restarts {restarts}, iterations {it}, A* expansions {ex}, queries {qu}, ms total {:.1} p50 {:.3} p99 {:.3} top6 {:.2?}, mean jerk {:.0} duration {:.3} (random maps only)",
            ms.iter().sum::<f64>(),
            ms[100],
            ms[197],
            &ms[194..],
            jerk / nok,
            dur / nok
        );
    }
    if all_ms.len() >= 400 {
        all_ms.sort_by(f64::total_cmp);
        let q = |f: f64| all_ms[((all_ms.len() as f64 * f) as usize).min(all_ms.len() - 1)];
        println!(
            "all: {} maps, failures {all_fail}, ms p50 {:.3} p95 {:.3} p98 {:.3} p99 {:.3} max {:.3}",
            all_ms.len(),
            q(0.5),
            q(0.95),
            q(0.98),
            q(0.99),
            all_ms[all_ms.len() - 1]
        );
    }
    Ok(())
}
