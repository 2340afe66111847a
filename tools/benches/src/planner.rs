//! `landing bench planner`: success rate and planning time on seeded random pillar fields
//! (0.05 to 0.2 pillars per m^2, start and goal 10 m apart) and on the paper's obstacle
//! scene. A run succeeds when the trajectory passes a check independent of the planner:
//! the curve re-evaluated from its basis matrix, sampled every ~1 cm, at least the
//! inflation away from every raw box, inside the map, within the limits (5%), and at the
//! requested end states.

use std::time::Instant;

use anyhow::Result;
use clap::Args;
use nalgebra::Vector3;
use planner::fields::{FIELD_DENSITIES, FIELD_GOAL, FIELD_START, FieldRng, pillar_field};
use planner::{
    Aabb, BSpline, Goal, GridMap, LIMIT_TOLERANCE, OccupancyQuery, Planner, PlannerConfig, State,
};
use serde_json::json;

use evaluation::stats::percentile;

/// Arguments of `landing bench planner`.
#[derive(Debug, Args)]
pub struct PlannerArgs {
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
    /// Random maps per density.
    #[arg(long, default_value_t = 50)]
    maps: usize,
    /// Seed of the map generator.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Times each plan is run; its planning time is the median (the planner is
    /// deterministic, so repeats measure the same work and the median drops the machine's
    /// scheduling spikes, as criterion's samples do).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=99))]
    repeats: u32,
    /// Print each failed or slow (> 2 ms) run on stderr.
    #[arg(long)]
    verbose: bool,
}

/// One scene: map, boxes, start, goal.
struct Scene {
    map: GridMap,
    start: State,
    goal: State,
}

fn random_scene(rng: &mut FieldRng, density: f64, cfg: &PlannerConfig) -> Result<Scene> {
    Ok(Scene {
        map: pillar_field(rng, density, cfg.resolution, cfg.inflation)?,
        start: State::at_rest(Vector3::from(FIELD_START)),
        goal: State::at_rest(Vector3::from(FIELD_GOAL)),
    })
}

/// The paper's obstacle demo: a 60 x 120 x 120 cm box between start and goal.
pub fn paper_scene(cfg: &PlannerConfig) -> Result<GridMap> {
    let b = Aabb {
        min: Vector3::new(2.7, -0.6, 0.0),
        max: Vector3::new(3.3, 0.6, 1.2),
    };
    Ok(GridMap::from_boxes(
        Vector3::new(-1.0, -3.0, 0.0),
        Vector3::new(7.0, 3.0, 3.0),
        cfg.resolution,
        cfg.inflation,
        &[b],
    )?)
}

/// Position, velocity, acceleration at `t` from the B-spline basis matrix.
#[allow(clippy::needless_range_loop)] // the basis matrix reads as written
fn sample(s: &BSpline, t: f64) -> [Vector3<f64>; 3] {
    let segs = s.points.len() - 3;
    let x = (t / s.ts).clamp(0.0, segs as f64);
    let i = (x as usize).min(segs - 1);
    let u = x - i as f64;
    const M: [[f64; 4]; 4] = [
        [1.0, 4.0, 1.0, 0.0],
        [-3.0, 0.0, 3.0, 0.0],
        [3.0, -6.0, 3.0, 0.0],
        [-1.0, 3.0, -3.0, 1.0],
    ];
    let pu = [
        [1.0, u, u * u, u * u * u],
        [0.0, 1.0, 2.0 * u, 3.0 * u * u],
        [0.0, 0.0, 2.0, 6.0 * u],
    ];
    let mut out = [Vector3::zeros(); 3];
    for (d, row) in pu.iter().enumerate() {
        for k in 0..4 {
            let w: f64 = (0..4).map(|r| row[r] * M[r][k]).sum();
            out[d] += s.points[i + k] * (w / 6.0 / s.ts.powi(d as i32));
        }
    }
    out
}

/// The independent acceptance check.
pub fn verify(
    map: &GridMap,
    s: &BSpline,
    start: &State,
    goal: &State,
    cfg: &PlannerConfig,
) -> bool {
    if s.points.len() < 4 || s.ts.is_nan() || s.ts <= 0.0 {
        return false;
    }
    let (lo, hi) = map.bounds();
    let (vmax, _) = s.max_vel_acc();
    let n = ((s.duration() * vmax / 0.01).ceil() as usize).clamp(100, 200_000);
    let vlim = cfg.max_vel.max(start.v.norm()).max(goal.v.norm()) * LIMIT_TOLERANCE;
    let alim = cfg.max_acc.max(start.a.norm()).max(goal.a.norm()) * LIMIT_TOLERANCE;
    for k in 0..=n {
        let [p, v, a] = sample(s, s.duration() * k as f64 / n as f64);
        if (0..3).any(|i| !(lo[i] <= p[i] && p[i] <= hi[i])) || v.norm() > vlim || a.norm() > alim {
            return false;
        }
        if map
            .boxes()
            .iter()
            .any(|b| b.distance(&p) < map.inflation() - 1e-9)
        {
            return false;
        }
    }
    let [p0, v0, _] = sample(s, 0.0);
    let [p1, v1, _] = sample(s, s.duration());
    (p0 - start.p).norm() < 1e-6
        && (v0 - start.v).norm() < 1e-6
        && (p1 - goal.p).norm() < 1e-6
        && (v1 - goal.v).norm() < 1e-6
}

/// Results of one group of runs.
#[derive(Default)]
struct Group {
    ms: Vec<f64>,
    ok: usize,
    runs: usize,
    iterations: Vec<f64>,
    rebounds: Vec<f64>,
}

impl Group {
    fn record(
        &mut self,
        planner: &mut Planner,
        map: &GridMap,
        start: &State,
        goal: &State,
        repeats: u32,
        verbose: bool,
    ) {
        let goal_in = Goal {
            state: *goal,
            moving: false,
        };
        let t0 = Instant::now();
        let r = planner.plan(map, start, &goal_in);
        let mut times = vec![t0.elapsed().as_secs_f64() * 1e3];
        // The same plan again (deterministic: same work, same result), timed only.
        for _ in 1..repeats {
            let t0 = Instant::now();
            let _ = planner.plan(map, start, &goal_in);
            times.push(t0.elapsed().as_secs_f64() * 1e3);
        }
        times.sort_by(f64::total_cmp);
        self.ms.push(times[times.len() / 2]);
        self.runs += 1;
        let st = planner.stats();
        self.iterations.push(st.iterations as f64);
        self.rebounds.push(st.rebounds as f64);
        let ms = self.ms.last().copied().unwrap_or(0.0);
        // Judged at the goal asked for: a plan that ends at a goal the planner moved
        // (out of an obstacle, into the map) is not a success.
        let ok = match &r {
            Ok(p) => verify(map, &p.spline, start, goal, planner.config()),
            Err(_) => false,
        };
        if ok {
            self.ok += 1;
        }
        if verbose && (!ok || ms > 2.0) {
            eprintln!(
                "run {}: {ms:.3} ms, {st:?}, verified {ok}, {:?}",
                self.runs,
                r.as_ref().err()
            );
        }
    }

    fn json(&self) -> serde_json::Value {
        json!({
            "success_rate": round3(self.ok as f64 / self.runs.max(1) as f64),
            "planning_ms_p50": round3(percentile(&self.ms, 50.0)),
            "planning_ms_p99": round3(percentile(&self.ms, 99.0)),
            "iterations_p50": percentile(&self.iterations, 50.0),
            "rebounds_p50": percentile(&self.rebounds, 50.0),
            "runs": self.runs,
        })
    }
}

fn round3(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}

/// Runs the benchmark.
pub fn run(args: &PlannerArgs) -> Result<()> {
    let cfg = PlannerConfig::default();
    let mut planner = Planner::new(cfg.clone());
    let mut rng = FieldRng::new(args.seed);
    let mut all = Group::default();
    let mut per = serde_json::Map::new();
    for d in FIELD_DENSITIES {
        let mut g = Group::default();
        for _ in 0..args.maps {
            let s = random_scene(&mut rng, d, &cfg)?;
            g.record(
                &mut planner,
                &s.map,
                &s.start,
                &s.goal,
                args.repeats,
                args.verbose,
            );
        }
        per.insert(format!("{d:.2}"), g.json());
        merge(&mut all, g);
    }
    let paper = paper_scene(&cfg)?;
    let mut g = Group::default();
    let (s, e) = (
        State::at_rest(Vector3::new(0.0, 0.0, 0.8)),
        State::at_rest(Vector3::new(6.0, 0.0, 0.8)),
    );
    for _ in 0..args.maps {
        g.record(&mut planner, &paper, &s, &e, args.repeats, args.verbose);
    }
    let paper_json = g.json();
    // The headline is the random fields alone; the paper's scene is its own row.
    let mut out = all.json();
    out["per_density"] = serde_json::Value::Object(per);
    out["paper_obstacle"] = paper_json;
    out["repeats"] = json!(args.repeats);
    if args.json {
        println!("{out}");
    } else {
        println!(
            "planner: {} random fields (headline; the paper's scene is its own row), each plan timed {} times (median) (max_vel {} m/s, max_acc {} m/s^2)",
            all.runs, args.repeats, cfg.max_vel, cfg.max_acc
        );
        println!("{}", serde_json::to_string_pretty(&out)?);
    }
    Ok(())
}

fn merge(all: &mut Group, g: Group) {
    all.ms.extend(g.ms);
    all.iterations.extend(g.iterations);
    all.rebounds.extend(g.rebounds);
    all.ok += g.ok;
    all.runs += g.runs;
}
