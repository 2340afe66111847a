//! The mapping demo (`landing map`): flies a short scripted path in the lockstep simulator, maps every depth
//! frame with the pose the autopilot *reports*, and draws the map (top and side views)
//! into a PNG.
//!
//! The stages are the pipeline's own, on the lockstep driver: the simulator, px4-link
//! (MAVLink through its wire encoding both ways) and depth-map as the graph declares
//! them, with a scripted companion (`map_pilot`) in the fsm's place that flies through
//! px4-link's requests and setpoints: OFFBOARD with the setpoint stream running, arm,
//! climb, then slow legs that look at the obstacle from the front, both sides and above.
//! The figure is the map depth-map *published* (what the planner reads). The truth
//! (where the obstacles really are, where the vehicle really went) is used only to lay
//! out the script's legs around the first obstacle (as an operator who can see it
//! would), for the printed comparison and for the outlines in the figure: this is an
//! evaluation tool; the map never sees it.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::Args;
use ipc_types::msg::{CellState, OccupancyMapHeader};
use nalgebra::{Point3, Vector3};
use opencv::core::{Mat, Point, Rect, Scalar, Vector};
use opencv::{core, imgcodecs, imgproc};
use sim::world::Aabb;
use stack_config::{self as cfgload, deploy_dir};
use stage::lockstep::{Lockstep, Published};
use stage::{Message, Stage};

use crate::config::StackConfig;
use crate::lockstep::{self as run_lockstep, Setup};
use crate::map_pilot::{self, MapPilot};

/// Arguments of `landing map`.
#[derive(Debug, Args)]
pub struct MapArgs {
    /// Scenario name (from deploy/scenarios/) or TOML file.
    #[arg(long, default_value = "obstacle-demo")]
    scenario: String,
    /// Where to write the figure (PNG).
    #[arg(long, value_name = "FILE.png")]
    png: PathBuf,
    /// Seed of every random process (default: the scenario's).
    #[arg(long)]
    seed: Option<u64>,
    /// Stack configuration (default: the deploy directory's config/landing.toml).
    #[arg(long)]
    config: Option<PathBuf>,
    /// The deploy directory (default: found above the current directory or executable).
    #[arg(long)]
    deploy_dir: Option<PathBuf>,
    /// Pixels per map cell in the figure (2 to 20).
    #[arg(long, default_value_t = 8)]
    cell_px: i32,
}

/// Cruise height of the script, m.
const HEIGHT_M: f64 = 1.0;
/// Speed along the legs, m/s.
const SPEED_M_S: f64 = 0.4;
/// Occupied cells whose centre is below this are the ground layer (the ground is z = 0
/// and the cells are 0.15 m): left out of the comparison.
const GROUND_CUT_M: f64 = 0.15;
/// The top view shows cells whose centre is at least this high: above the ground layer
/// and its inflation (two cells), which would otherwise cover the whole view.
const TOP_VIEW_FROM_M: f64 = 0.45;
/// Longest flight, simulated s.
const MAX_FLIGHT_S: f64 = 90.0;

/// The occupancy window as depth-map published it: header and one state byte per cell.
struct PublishedMap {
    dims: [usize; 3],
    resolution: f64,
    origin: Point3<f64>,
    cells: Vec<u8>,
}

impl PublishedMap {
    fn new(h: &OccupancyMapHeader, cells: &[u8]) -> Self {
        Self {
            dims: h.dims.map(|d| d as usize),
            resolution: h.resolution,
            origin: Point3::from(h.origin),
            cells: cells.to_vec(),
        }
    }

    fn dims(&self) -> [usize; 3] {
        self.dims
    }

    fn resolution(&self) -> f64 {
        self.resolution
    }

    fn origin(&self) -> Point3<f64> {
        self.origin
    }

    fn state_at_index(&self, [x, y, z]: [usize; 3]) -> CellState {
        let i = x + self.dims[0] * (y + self.dims[1] * z);
        self.cells
            .get(i)
            .map_or(CellState::Unknown, |c| CellState::from_raw(*c))
    }

    fn cell_centre(&self, [x, y, z]: [usize; 3]) -> Point3<f64> {
        let r = self.resolution;
        self.origin + Vector3::new(x as f64 + 0.5, y as f64 + 0.5, z as f64 + 0.5) * r
    }

    fn occupied(&self) -> usize {
        self.cells
            .iter()
            .filter(|c| CellState::from_raw(**c) == CellState::Occupied)
            .count()
    }
}

/// A counter of a stage on the driver.
fn counter(driver: &Lockstep, node: &str, key: &str) -> u64 {
    driver
        .stage(node)
        .and_then(|s| s.counters().into_iter().find(|(k, _)| *k == key))
        .map_or(0, |(_, v)| v)
}

/// Runs the flight, writes the PNG, prints the comparison.
pub fn run(args: &MapArgs) -> Result<()> {
    if !(2..=20).contains(&args.cell_px) {
        bail!(
            "--cell-px {} is not allowed (allowed: 2 to 20)",
            args.cell_px
        );
    }
    // Before a flight that takes seconds: can the figure be written there at all?
    let parent = match args.png.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    if !parent.is_dir() {
        bail!(
            "{}: the directory {} does not exist",
            args.png.display(),
            parent.display()
        );
    }
    let deploy = args.deploy_dir.clone().unwrap_or_else(deploy_dir);
    let cfg_path = args
        .config
        .clone()
        .unwrap_or_else(|| deploy.join("config").join("landing.toml"));
    let cfg: StackConfig = cfgload::load(&cfg_path)?;
    let scn = sim::scenario::load(&args.scenario, &deploy)?;
    let seed = args.seed.unwrap_or(scn.scenario.seed);
    let obstacles: Vec<Aabb> = scn.obstacles(seed);
    let look_at = obstacles
        .first()
        .map(|b| {
            Vector3::new(
                (b.min_m[0] + b.max_m[0]) / 2.0,
                (b.min_m[1] + b.max_m[1]) / 2.0,
                (b.min_m[2] + b.max_m[2]) / 2.0,
            )
        })
        .unwrap_or(Vector3::new(3.0, 0.0, 0.5));
    let graph = graph::Graph::load(&graph::default_path(&deploy))?;
    let setup = Setup {
        scenario: &scn,
        seed,
        config: &cfg,
        fsm: run_lockstep::mission(&cfg, &scn)?,
    };
    let mut stages = Vec::new();
    for name in ["sim", "px4-link"] {
        let node = graph
            .node(name)
            .with_context(|| format!("the graph has no {name}"))?;
        let stage = run_lockstep::stage_for(node, &setup)?.context("no stage")?;
        stages.push((node.spec(), stage));
    }
    stages.push((
        MapPilot::spec(),
        Box::new(MapPilot::new(HEIGHT_M, SPEED_M_S, look_at)) as Box<dyn Stage>,
    ));
    let node = graph
        .node("depth-map")
        .context("the graph has no depth-map")?;
    stages.push((
        node.spec(),
        run_lockstep::stage_for(node, &setup)?.context("no stage")?,
    ));
    let mut driver = Lockstep::new(stages)?;
    let depth = &scn.scenario.depth;
    eprintln!(
        "map: {} (seed {seed}), depth {}x{} at {} Hz, {} m cells",
        scn.scenario.name,
        depth.sensor.width,
        depth.sensor.height,
        depth.rate_hz,
        cfg.depth_map.resolution_m
    );

    let mut path: Vec<Vector3<f64>> = Vec::new();
    let mut truth_path: Vec<Vector3<f64>> = Vec::new();
    let mut map: Option<PublishedMap> = None;
    let mut next_progress_ns = 0u64;
    let end_ns = (MAX_FLIGHT_S * 1e9) as u64;
    while driver.now_ns() < end_ns && counter(&driver, map_pilot::NAME, "done") == 0 {
        driver.step(&mut |p: &Published<'_>| match p.msg {
            Message::VehicleState(v) => {
                let pos = Vector3::from(v.world_from_body.translation);
                if path.last().is_none_or(|l| (l - pos).norm() > 0.02) {
                    path.push(pos);
                }
            }
            Message::TruthState(t) => {
                let pos = Vector3::from(t.vehicle_position);
                if truth_path.last().is_none_or(|l| (l - pos).norm() > 0.02) {
                    truth_path.push(pos);
                }
            }
            Message::OccupancyMap(h, cells) => map = Some(PublishedMap::new(h, cells)),
            _ => {}
        })?;
        let now = driver.now_ns();
        let phase = usize::try_from(counter(&driver, map_pilot::NAME, "phase"))
            .ok()
            .and_then(|i| MapPilot::PHASES.get(i))
            .copied()
            .unwrap_or("?");
        if now >= next_progress_ns {
            next_progress_ns = now + 2_000_000_000;
            eprintln!(
                "map: t {:5.1} s  {:<16} frames {:4}  mapped {:4}  occupied cells {:5}",
                now as f64 * 1e-9,
                phase,
                counter(&driver, "depth-map", "frames"),
                counter(&driver, "depth-map", "integrated"),
                map.as_ref().map_or(0, PublishedMap::occupied)
            );
        }
    }
    if counter(&driver, map_pilot::NAME, "done") == 0 {
        bail!("the scripted flight did not finish in {MAX_FLIGHT_S} s");
    }
    let Some(map) = map else {
        bail!("depth-map published no map");
    };
    let est_end = path.last().copied().unwrap_or_default();
    let truth_end = truth_path.last().copied().unwrap_or_default();
    println!(
        "flight: {:.1} s, {} depth frames, {} mapped; estimate vs truth at the end: {:.3} m apart",
        driver.now_ns() as f64 * 1e-9,
        counter(&driver, "depth-map", "frames"),
        counter(&driver, "depth-map", "integrated"),
        (est_end - truth_end).norm()
    );
    let vehicle = vehicle_body_sweep(&scn, seed, driver.now_ns())?;
    compare(&map, &obstacles, vehicle.as_ref());
    draw(
        &map,
        &path,
        &truth_path,
        &obstacles,
        &scn.scenario.name,
        args,
    )?;
    println!("figure: {}", args.png.display());
    Ok(())
}

/// The box the pad vehicle's body swept through during the flight (its body is a real
/// obstacle the depth camera maps), so its cells are not counted as phantoms.
fn vehicle_body_sweep(
    scn: &sim::scenario::LoadedScenario,
    seed: u64,
    end_ns: u64,
) -> Result<Option<Aabb>> {
    let Some(params) = scn.world_params(seed).ground_vehicle else {
        return Ok(None);
    };
    let vehicle = sim::ground_vehicle::GroundVehicle::new(params)?;
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    let end_s = end_ns as f64 * 1e-9;
    let mut t = 0.0;
    while t <= end_s {
        for p in vehicle.body(&vehicle.state_at(t)).corners() {
            for i in 0..3 {
                lo[i] = lo[i].min(p[i]);
                hi[i] = hi[i].max(p[i]);
            }
        }
        t += 0.1;
    }
    Ok(lo[0].is_finite().then_some(Aabb {
        min_m: lo,
        max_m: hi,
    }))
}

/// Prints where each obstacle really is against where the map put it; cells at the pad
/// vehicle's body (`vehicle`, where it drove) are the vehicle's, not phantoms.
fn compare(map: &PublishedMap, obstacles: &[Aabb], vehicle: Option<&Aabb>) {
    let [nx, ny, nz] = map.dims();
    let r = map.resolution();
    let mut near = vec![(0usize, [f64::INFINITY; 3], [f64::NEG_INFINITY; 3]); obstacles.len()];
    let (mut phantoms, mut above_ground) = (0usize, 0usize);
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                if map.state_at_index([x, y, z]) != CellState::Occupied {
                    continue;
                }
                let c = map.cell_centre([x, y, z]);
                if c.z < GROUND_CUT_M {
                    continue;
                }
                above_ground += 1;
                let mut claimed = false;
                for (b, slot) in obstacles.iter().zip(near.iter_mut()) {
                    if distance(&c, b) <= 1.0 {
                        slot.0 += 1;
                        for i in 0..3 {
                            slot.1[i] = slot.1[i].min(c[i] - r / 2.0);
                            slot.2[i] = slot.2[i].max(c[i] + r / 2.0);
                        }
                    }
                    claimed |= distance(&c, b) <= 0.5;
                }
                claimed |= vehicle.is_some_and(|v| distance(&c, v) <= 0.5);
                if !claimed {
                    phantoms += 1;
                }
            }
        }
    }
    for (k, (b, (n, lo, hi))) in obstacles.iter().zip(&near).enumerate() {
        println!(
            "obstacle {k} truth: x [{:.2}, {:.2}]  y [{:.2}, {:.2}]  z [{:.2}, {:.2}]",
            b.min_m[0], b.max_m[0], b.min_m[1], b.max_m[1], b.min_m[2], b.max_m[2]
        );
        if *n == 0 {
            println!(
                "obstacle {k} map:   nothing occupied within 1 m (not seen, or outside the window)"
            );
            continue;
        }
        println!(
            "obstacle {k} map:   x [{:.2}, {:.2}]  y [{:.2}, {:.2}]  z [{:.2}, {:.2}]  ({n} occupied cells above {GROUND_CUT_M} m within 1 m of it; faces the camera never saw are missing)",
            lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]
        );
    }
    println!(
        "occupied cells above {GROUND_CUT_M} m: {above_ground}, of which {phantoms} farther than 0.5 m from every obstacle and from the pad vehicle's body"
    );
}

fn distance(p: &Point3<f64>, b: &Aabb) -> f64 {
    let mut d2 = 0.0;
    for i in 0..3 {
        let c = p[i].clamp(b.min_m[i], b.max_m[i]);
        d2 += (p[i] - c).powi(2);
    }
    d2.sqrt()
}

/// Colour of a cell state, BGR.
fn colour(s: CellState) -> Scalar {
    match s {
        CellState::Unknown => Scalar::new(200.0, 200.0, 200.0, 0.0),
        CellState::Free => Scalar::new(255.0, 255.0, 255.0, 0.0),
        CellState::Inflated => Scalar::new(90.0, 170.0, 255.0, 0.0),
        CellState::Occupied => Scalar::new(30.0, 30.0, 200.0, 0.0),
    }
}

/// Occupied over inflated over free over unknown: what a column shows.
fn rank(s: CellState) -> u8 {
    match s {
        CellState::Unknown => 0,
        CellState::Free => 1,
        CellState::Inflated => 2,
        CellState::Occupied => 3,
    }
}

fn black() -> Scalar {
    Scalar::new(0.0, 0.0, 0.0, 0.0)
}

fn text(img: &mut Mat, s: &str, at: Point, scale: f64) -> Result<()> {
    imgproc::put_text(
        img,
        s,
        at,
        imgproc::FONT_HERSHEY_SIMPLEX,
        scale,
        black(),
        1,
        imgproc::LINE_AA,
        false,
    )?;
    Ok(())
}

/// One view: a grid of columns, each the highest-ranked state along the hidden axis.
struct Panel {
    left: i32,
    top: i32,
    cols: usize,
    rows: usize,
    /// World coordinate of the left and bottom edges, m.
    origin: (f64, f64),
}

impl Panel {
    fn px(&self, u: f64, v: f64, res: f64, s: i32) -> Point {
        Point::new(
            self.left + ((u - self.origin.0) / res * f64::from(s)).round() as i32,
            self.top + self.rows as i32 * s
                - ((v - self.origin.1) / res * f64::from(s)).round() as i32,
        )
    }

    fn fill(&self, img: &mut Mat, cells: &[CellState], s: i32) -> Result<()> {
        for (k, st) in cells.iter().enumerate() {
            let (c, r) = ((k % self.cols) as i32, (k / self.cols) as i32);
            let rect = Rect::new(
                self.left + c * s,
                self.top + (self.rows as i32 - 1 - r) * s,
                s,
                s,
            );
            imgproc::rectangle(img, rect, colour(*st), imgproc::FILLED, imgproc::LINE_8, 0)?;
        }
        imgproc::rectangle(
            img,
            Rect::new(
                self.left,
                self.top,
                self.cols as i32 * s,
                self.rows as i32 * s,
            ),
            black(),
            1,
            imgproc::LINE_8,
            0,
        )?;
        Ok(())
    }

    /// Ticks and labels every metre along both axes.
    fn axes(&self, img: &mut Mat, res: f64, s: i32, labels: (&str, &str)) -> Result<()> {
        let w = self.cols as f64 * res;
        let h = self.rows as f64 * res;
        let mut m = self.origin.0.ceil();
        while m <= self.origin.0 + w + 1e-9 {
            let p = self.px(m, self.origin.1, res, s);
            imgproc::line(
                img,
                p,
                Point::new(p.x, p.y + 5),
                black(),
                1,
                imgproc::LINE_8,
                0,
            )?;
            // `+ 0.0` turns -0 into 0.
            text(
                img,
                &format!("{:.0}", m + 0.0),
                Point::new(p.x - 6, p.y + 18),
                0.4,
            )?;
            m += 1.0;
        }
        let mut m = self.origin.1.ceil();
        while m <= self.origin.1 + h + 1e-9 {
            let p = self.px(self.origin.0, m, res, s);
            imgproc::line(
                img,
                p,
                Point::new(p.x - 5, p.y),
                black(),
                1,
                imgproc::LINE_8,
                0,
            )?;
            text(
                img,
                &format!("{:.0}", m + 0.0),
                Point::new(p.x - 26, p.y + 4),
                0.4,
            )?;
            m += 1.0;
        }
        let bottom = self.top + self.rows as i32 * s;
        text(
            img,
            labels.0,
            Point::new(self.left + self.cols as i32 * s / 2 - 40, bottom + 34),
            0.45,
        )?;
        text(
            img,
            labels.1,
            Point::new(self.left - 60, self.top - 8),
            0.45,
        )?;
        Ok(())
    }

    fn path(
        &self,
        img: &mut Mat,
        pts: &[(f64, f64)],
        res: f64,
        s: i32,
        c: Scalar,
        thick: i32,
    ) -> Result<()> {
        for w in pts.windows(2) {
            let (a, b) = (
                self.px(w[0].0, w[0].1, res, s),
                self.px(w[1].0, w[1].1, res, s),
            );
            imgproc::line(img, a, b, c, thick, imgproc::LINE_AA, 0)?;
        }
        Ok(())
    }

    fn outline(
        &self,
        img: &mut Mat,
        lo: (f64, f64),
        hi: (f64, f64),
        res: f64,
        s: i32,
    ) -> Result<()> {
        let a = self.px(lo.0, hi.1, res, s);
        let b = self.px(hi.0, lo.1, res, s);
        imgproc::rectangle(img, Rect::from_points(a, b), black(), 1, imgproc::LINE_8, 0)?;
        Ok(())
    }
}

/// Writes the figure: top view (max over z above the ground layer) and side view (max
/// over y), cells coloured by state, axes in metres, a 1 m scale bar, the estimated
/// path, the obstacles' true outlines.
fn draw(
    map: &PublishedMap,
    path: &[Vector3<f64>],
    truth_path: &[Vector3<f64>],
    obstacles: &[Aabb],
    scenario: &str,
    args: &MapArgs,
) -> Result<()> {
    let s = args.cell_px;
    let [nx, ny, nz] = map.dims();
    let res = map.resolution();
    let o = map.origin();
    let mut top_cells = vec![CellState::Unknown; nx * ny];
    let mut side_cells = vec![CellState::Unknown; nx * nz];
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                let st = map.state_at_index([x, y, z]);
                let centre_z = o.z + (z as f64 + 0.5) * res;
                if centre_z >= TOP_VIEW_FROM_M && rank(st) > rank(top_cells[y * nx + x]) {
                    top_cells[y * nx + x] = st;
                }
                if rank(st) > rank(side_cells[z * nx + x]) {
                    side_cells[z * nx + x] = st;
                }
            }
        }
    }
    let left = 80;
    let width = left + nx as i32 * s + 30;
    let top = Panel {
        left,
        top: 80,
        cols: nx,
        rows: ny,
        origin: (o.x, o.y),
    };
    let side = Panel {
        left,
        top: top.top + ny as i32 * s + 100,
        cols: nx,
        rows: nz,
        origin: (o.x, o.z),
    };
    let height = side.top + nz as i32 * s + 120;
    let mut img =
        Mat::new_rows_cols_with_default(height, width, core::CV_8UC3, Scalar::all(255.0))?;
    text(
        &mut img,
        &format!("landing map --scenario {scenario}: depth frames + estimated pose"),
        Point::new(10, 22),
        0.48,
    )?;
    text(
        &mut img,
        &format!(
            "top view: max over z of the cells {TOP_VIEW_FROM_M} m and higher (above the ground and its inflation)"
        ),
        Point::new(10, top.top - 32),
        0.42,
    )?;
    text(
        &mut img,
        "side view: max over y",
        Point::new(10, side.top - 32),
        0.42,
    )?;
    top.fill(&mut img, &top_cells, s)?;
    side.fill(&mut img, &side_cells, s)?;
    for b in obstacles {
        top.outline(
            &mut img,
            (b.min_m[0], b.min_m[1]),
            (b.max_m[0], b.max_m[1]),
            res,
            s,
        )?;
        side.outline(
            &mut img,
            (b.min_m[0], b.min_m[2]),
            (b.max_m[0], b.max_m[2]),
            res,
            s,
        )?;
    }
    let grey = Scalar::new(120.0, 120.0, 120.0, 0.0);
    let blue = Scalar::new(200.0, 90.0, 20.0, 0.0);
    let tp: Vec<_> = truth_path.iter().map(|p| (p.x, p.y)).collect();
    let ts: Vec<_> = truth_path.iter().map(|p| (p.x, p.z)).collect();
    top.path(&mut img, &tp, res, s, grey, 1)?;
    side.path(&mut img, &ts, res, s, grey, 1)?;
    let ep: Vec<_> = path.iter().map(|p| (p.x, p.y)).collect();
    let es: Vec<_> = path.iter().map(|p| (p.x, p.z)).collect();
    top.path(&mut img, &ep, res, s, blue, 2)?;
    side.path(&mut img, &es, res, s, blue, 2)?;
    if let Some(last) = path.last() {
        for (panel, (u, v)) in [(&top, (last.x, last.y)), (&side, (last.x, last.z))] {
            imgproc::circle(
                &mut img,
                panel.px(u, v, res, s),
                5,
                blue,
                imgproc::FILLED,
                imgproc::LINE_AA,
                0,
            )?;
        }
    }
    top.axes(&mut img, res, s, ("x (m, east)", "y (m, north)"))?;
    side.axes(&mut img, res, s, ("x (m, east)", "z (m, up)"))?;
    // Legend and scale bar.
    let ly = side.top + nz as i32 * s + 60;
    let mut lx = left;
    for (st, name) in [
        (CellState::Unknown, "unknown"),
        (CellState::Free, "free"),
        (CellState::Occupied, "occupied"),
        (CellState::Inflated, "inflated (0.299 m)"),
    ] {
        imgproc::rectangle(
            &mut img,
            Rect::new(lx, ly - 11, 14, 14),
            colour(st),
            imgproc::FILLED,
            imgproc::LINE_8,
            0,
        )?;
        imgproc::rectangle(
            &mut img,
            Rect::new(lx, ly - 11, 14, 14),
            black(),
            1,
            imgproc::LINE_8,
            0,
        )?;
        text(&mut img, name, Point::new(lx + 20, ly), 0.42)?;
        lx += 40 + 9 * name.len() as i32;
    }
    let ly2 = ly + 26;
    imgproc::line(
        &mut img,
        Point::new(left, ly2 - 4),
        Point::new(left + 24, ly2 - 4),
        blue,
        2,
        imgproc::LINE_AA,
        0,
    )?;
    text(
        &mut img,
        "path (autopilot estimate)",
        Point::new(left + 30, ly2),
        0.42,
    )?;
    imgproc::line(
        &mut img,
        Point::new(left + 250, ly2 - 4),
        Point::new(left + 274, ly2 - 4),
        grey,
        1,
        imgproc::LINE_AA,
        0,
    )?;
    text(&mut img, "path (truth)", Point::new(left + 280, ly2), 0.42)?;
    imgproc::rectangle(
        &mut img,
        Rect::new(left + 400, ly2 - 11, 14, 14),
        black(),
        1,
        imgproc::LINE_8,
        0,
    )?;
    text(
        &mut img,
        "obstacle (truth)",
        Point::new(left + 420, ly2),
        0.42,
    )?;
    let bar = (1.0 / res * f64::from(s)).round() as i32;
    let bx = width - bar - 40;
    imgproc::line(
        &mut img,
        Point::new(bx, ly - 4),
        Point::new(bx + bar, ly - 4),
        black(),
        3,
        imgproc::LINE_8,
        0,
    )?;
    text(
        &mut img,
        "1 m",
        Point::new(bx + bar / 2 - 10, ly - 10),
        0.42,
    )?;
    write_png(&args.png, &img)
}

fn write_png(path: &Path, img: &Mat) -> Result<()> {
    let p = path
        .to_str()
        .with_context(|| format!("{}: not a UTF-8 path", path.display()))?;
    let ok = imgcodecs::imwrite(p, img, &Vector::new())
        .with_context(|| format!("writing {}", path.display()))?;
    if !ok {
        bail!("{}: OpenCV could not write the PNG", path.display());
    }
    Ok(())
}
