//! `landing plan`: one plan offline, on a map of boxes read from JSON.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::Args;
use nalgebra::Vector3;
use planner::{Aabb, Goal, GridMap, Planner, PlannerConfig, State};
use serde::Deserialize;
use serde_json::json;
use stack_config::load_process;

/// Exit code when the inputs were fine but no trajectory was found.
pub const NO_PLAN: u8 = 3;

/// Arguments of `landing plan`.
#[derive(Debug, Args)]
pub struct PlanArgs {
    /// Map JSON: {"bounds": {"min": [x, y, z], "max": [x, y, z]}, "boxes": [{"min": [..],
    /// "max": [..]}, ...], optional "resolution" and "inflation" (m; default: [planner]).
    #[arg(long)]
    map: PathBuf,
    /// Start position x,y,z (m).
    #[arg(long, allow_hyphen_values = true)]
    start: String,
    /// Goal position x,y,z (m).
    #[arg(long, allow_hyphen_values = true)]
    goal: String,
    /// Start velocity x,y,z (m/s; default 0,0,0).
    #[arg(long, allow_hyphen_values = true)]
    start_vel: Option<String>,
    /// Goal velocity x,y,z (m/s; default 0,0,0).
    #[arg(long, allow_hyphen_values = true)]
    goal_vel: Option<String>,
    /// Stack configuration for the [planner] section (default: the paper's parameters).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// Parses "x,y,z" into a finite vector.
pub fn parse_vec3(s: &str) -> Result<Vector3<f64>, String> {
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != 3 {
        return Err(format!("`{s}`: expected x,y,z"));
    }
    let mut v = Vector3::zeros();
    for (i, p) in parts.iter().enumerate() {
        v[i] = p
            .trim()
            .parse::<f64>()
            .map_err(|_| format!("`{s}`: `{p}` is not a number"))?;
        if !v[i].is_finite() {
            return Err(format!("`{s}`: `{p}` is not finite"));
        }
    }
    Ok(v)
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Corners {
    min: [f64; 3],
    max: [f64; 3],
}

/// The map file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MapFile {
    bounds: Corners,
    #[serde(default)]
    boxes: Vec<Corners>,
    resolution: Option<f64>,
    inflation: Option<f64>,
}

/// Reads a map file into an inflated grid and its bounds (min, max); errors name the
/// file and the problem.
pub fn load_map(path: &Path, cfg: &PlannerConfig) -> Result<(GridMap, [Vector3<f64>; 2])> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("map {}: cannot read", path.display()))?;
    let file: MapFile =
        serde_json::from_str(&text).map_err(|e| anyhow::anyhow!("map {}: {e}", path.display()))?;
    let v = |c: [f64; 3]| Vector3::from(c);
    let mut boxes = Vec::with_capacity(file.boxes.len());
    for (i, b) in file.boxes.iter().enumerate() {
        if !(b.min.iter().chain(&b.max).all(|x| x.is_finite()))
            || (0..3).any(|k| b.min[k] > b.max[k])
        {
            bail!(
                "map {}: boxes[{i}]: min must be finite and <= max",
                path.display()
            );
        }
        boxes.push(Aabb {
            min: v(b.min),
            max: v(b.max),
        });
    }
    let res = file.resolution.unwrap_or(cfg.resolution);
    let infl = file.inflation.unwrap_or(cfg.inflation);
    let bounds = [v(file.bounds.min), v(file.bounds.max)];
    let map = GridMap::from_boxes(bounds[0], bounds[1], res, infl, &boxes)
        .map_err(|e| anyhow::anyhow!("map {}: {e}", path.display()))?;
    Ok((map, bounds))
}

/// An error unless `p` (flag `--flag`) lies inside the map's `bounds`: the planner would
/// move such a point inside and plan to somewhere else than asked.
fn inside(flag: &str, raw: &str, p: &Vector3<f64>, bounds: &[Vector3<f64>; 2]) -> Result<()> {
    let [lo, hi] = bounds;
    if (0..3).all(|k| p[k] >= lo[k] && p[k] <= hi[k]) {
        return Ok(());
    }
    bail!(
        "--{flag} {raw}: outside the map (allowed: {:.2},{:.2},{:.2} to {:.2},{:.2},{:.2})",
        lo.x,
        lo.y,
        lo.z,
        hi.x,
        hi.y,
        hi.z
    )
}

/// An error unless the speed of `v` (flag `--flag`) is within `max` m/s.
fn within_speed(flag: &str, raw: &str, v: &Vector3<f64>, max: f64) -> Result<()> {
    if v.norm() <= max {
        return Ok(());
    }
    bail!(
        "--{flag} {raw}: {:.2} m/s (allowed: at most [planner] max_vel, {max} m/s)",
        v.norm()
    )
}

/// Loads the [planner] section, or the defaults.
pub fn planner_config(path: Option<&Path>) -> Result<PlannerConfig> {
    Ok(match path {
        Some(p) => load_process::<PlannerConfig>(p, "planner")?.1,
        None => PlannerConfig::default(),
    })
}

/// Runs `landing plan`; `Ok(false)` when no trajectory was found.
pub fn run(args: &PlanArgs) -> Result<bool> {
    let cfg = planner_config(args.config.as_deref())?;
    // Vectors are parsed here, not by clap, so that a bad one is one line like the rest.
    let vec = |flag: &str, v: Option<&String>| -> Result<Vector3<f64>> {
        match v {
            Some(s) => parse_vec3(s).map_err(|e| anyhow::anyhow!("--{flag} {e}")),
            None => Ok(Vector3::zeros()),
        }
    };
    let start = State {
        p: vec("start", Some(&args.start))?,
        v: vec("start-vel", args.start_vel.as_ref())?,
        a: Vector3::zeros(),
    };
    let goal = Goal {
        state: State {
            p: vec("goal", Some(&args.goal))?,
            v: vec("goal-vel", args.goal_vel.as_ref())?,
            a: Vector3::zeros(),
        },
        moving: false,
    };
    let (map, bounds) = load_map(&args.map, &cfg)?;
    inside("start", &args.start, &start.p, &bounds)?;
    inside("goal", &args.goal, &goal.state.p, &bounds)?;
    let raw = |v: Option<&String>| v.cloned().unwrap_or_default();
    within_speed(
        "start-vel",
        &raw(args.start_vel.as_ref()),
        &start.v,
        cfg.max_vel,
    )?;
    within_speed(
        "goal-vel",
        &raw(args.goal_vel.as_ref()),
        &goal.state.v,
        cfg.max_vel,
    )?;
    let mut planner = Planner::new(cfg);
    let t0 = Instant::now();
    let result = planner.plan(&map, &start, &goal);
    let ms = t0.elapsed().as_secs_f64() * 1e3;
    let stats = planner.stats();
    let (success, points, ts, duration, error, goal_used) = match &result {
        Ok(p) => (
            true,
            p.spline
                .points
                .iter()
                .map(|q| [q.x, q.y, q.z])
                .collect::<Vec<_>>(),
            p.spline.ts,
            p.spline.duration(),
            None,
            Some([p.goal.x, p.goal.y, p.goal.z]),
        ),
        Err(e) => (false, Vec::new(), 0.0, 0.0, Some(e.to_string()), None),
    };
    if args.json {
        let mut out = json!({
            "success": success,
            "control_points": points,
            "knot_interval": ts,
            "duration": duration,
            "planning_time_ms": ms,
            "iterations": stats.iterations,
            "rebounds": stats.rebounds,
        });
        if let Some(g) = goal_used {
            out["goal"] = json!(g);
        }
        if let Some(e) = &error {
            out["error"] = json!(e);
        }
        println!("{out}");
    } else if success {
        println!(
            "plan: {} control points, knot interval {:.4} s, duration {:.2} s, {:.3} ms, {} iterations, {} rebounds",
            points.len(),
            ts,
            duration,
            ms,
            stats.iterations,
            stats.rebounds
        );
        for p in &points {
            println!("  {:.3} {:.3} {:.3}", p[0], p[1], p[2]);
        }
    } else {
        println!("no plan: {}", error.unwrap_or_default());
    }
    Ok(success)
}
