//! `landing bench sim`: how fast `landing run` flies a mission in lockstep, and what the
//! simulator's part of it costs.
//!
//! Each flight is the real lockstep run: every stage of the graph on the lockstep driver
//! (the simulator, px4-link, camera-ingest, aruco-pnp, depth-map, planner, fsm), flying
//! the scenario's mission. The headline real-time factor is simulated time over wall
//! time for that whole pipeline, what a user of `landing run` gets. The simulator's
//! share is timed on its own (its stage wrapped in a timer): its real-time factor alone,
//! and the cost of a simulator call that rendered a camera frame or a depth frame (the
//! render dominates such a call: a physics step is microseconds).

use std::cell::RefCell;
use std::path::PathBuf;
use std::rc::Rc;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;
use serde_json::json;
use stack_config::deploy_dir;
use stage::lockstep::Lockstep;
use stage::{Counter, Input, Outbox, Stage, StageError};

use evaluation::stats::percentile;
use stack::StackConfig;
use stack::lockstep::{self as run_lockstep, Setup};

/// Arguments of `landing bench sim`.
#[derive(Debug, Args)]
pub struct SimArgs {
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
    /// Simulated seconds flown per scenario (the mission, then the vehicle on the pad).
    #[arg(long, default_value_t = 20.0)]
    seconds: f64,
    /// The deploy directory (default: found above the current directory or executable).
    #[arg(long)]
    deploy_dir: Option<PathBuf>,
    /// Threads OpenCV may use (the camera's remap, the detector): 1 is one core, as a
    /// campaign's worker runs; 0 is OpenCV's default (every core).
    #[arg(long, default_value_t = 1)]
    threads: i32,
}

/// What the timed simulator measured.
#[derive(Debug, Default)]
struct Timings {
    /// Wall time of all the simulator's calls, ns.
    total_ns: u64,
    /// Calls that rendered a camera frame (and no depth frame), ms.
    render_ms: Vec<f64>,
    /// Calls that rendered a depth frame (and no camera frame), ms.
    depth_ms: Vec<f64>,
}

/// The simulator's stage with each call timed, sorted by what the call rendered (the
/// driver owns the stage; the bench keeps the other handle on the timings).
struct Timed {
    inner: Box<dyn Stage>,
    timings: Rc<RefCell<Timings>>,
}

fn count(stage: &dyn Stage, key: &str) -> u64 {
    stage
        .counters()
        .into_iter()
        .find(|(k, _)| *k == key)
        .map_or(0, |(_, v)| v)
}

impl Stage for Timed {
    fn name(&self) -> &'static str {
        self.inner.name()
    }
    fn tick_period_ns(&self) -> Option<u64> {
        self.inner.tick_period_ns()
    }
    fn on_input(
        &mut self,
        now: u64,
        input: Input<'_>,
        out: &mut dyn Outbox,
    ) -> Result<(), StageError> {
        let t = Instant::now();
        let r = self.inner.on_input(now, input, out);
        self.timings.borrow_mut().total_ns += t.elapsed().as_nanos() as u64;
        r
    }
    fn on_tick(&mut self, now: u64, out: &mut dyn Outbox) -> Result<(), StageError> {
        let before = (
            count(&*self.inner, "renders"),
            count(&*self.inner, "depth_renders"),
        );
        let t = Instant::now();
        let r = self.inner.on_tick(now, out);
        let ns = t.elapsed().as_nanos() as u64;
        let rendered = (
            count(&*self.inner, "renders") - before.0,
            count(&*self.inner, "depth_renders") - before.1,
        );
        let mut timings = self.timings.borrow_mut();
        timings.total_ns += ns;
        match rendered {
            (1, 0) => timings.render_ms.push(ns as f64 * 1e-6),
            (0, 1) => timings.depth_ms.push(ns as f64 * 1e-6),
            _ => {}
        }
        r
    }
    fn on_inputs_done(&mut self, now: u64, out: &mut dyn Outbox) -> Result<(), StageError> {
        self.inner.on_inputs_done(now, out)
    }
    fn max_slice_len(&self, topic: &str) -> usize {
        self.inner.max_slice_len(topic)
    }
    fn counters(&self) -> Vec<Counter> {
        self.inner.counters()
    }
    fn finished(&self) -> bool {
        self.inner.finished()
    }
}

/// What one flight measured.
struct Flight {
    /// Median over one-second windows of simulated time: this shared VM's neighbours
    /// steal whole bursts of CPU, which the median sets aside.
    realtime_factor: f64,
    /// Simulated time over wall time for the whole flight.
    realtime_factor_overall: f64,
    /// Simulated time over the simulator's own wall time.
    sim_realtime_factor: f64,
    timings: Timings,
}

/// Simulated time per real-time-factor window.
const WINDOW_NS: u64 = 1_000_000_000;

/// Flies `seconds` of `scenario`'s mission as `landing run` does (seed 1).
fn fly(scenario: &str, seconds: f64, deploy: &std::path::Path) -> Result<Flight> {
    let cfg: StackConfig = stack_config::load(&deploy.join("config").join("landing.toml"))?;
    let scn = sim::scenario::load(scenario, deploy)?;
    let setup = Setup {
        scenario: &scn,
        seed: 1,
        config: &cfg,
        fsm: run_lockstep::mission(&cfg, &scn)?,
    };
    let graph = graph::Graph::load(&graph::default_path(deploy))?;
    let timings = Rc::new(RefCell::new(Timings::default()));
    let mut stages = Vec::new();
    for node in graph.step_order() {
        let mut stage = run_lockstep::stage_for(node, &setup)?
            .with_context(|| format!("no stage for {}", node.name))?;
        if node.name == "sim" {
            stage = Box::new(Timed {
                inner: stage,
                timings: Rc::clone(&timings),
            });
        }
        stages.push((node.spec(), stage));
    }
    let mut driver = Lockstep::new(stages)?;
    let end_ns = (seconds * 1e9) as u64;
    let start = Instant::now();
    let (mut window_start, mut window_end_ns) = (start, WINDOW_NS);
    let mut window_factors = Vec::new();
    while driver.now_ns() < end_ns {
        if driver.step(&mut |_| {})?.is_none() {
            break;
        }
        if driver.now_ns() >= window_end_ns {
            let now = Instant::now();
            window_factors.push(1.0 / (now - window_start).as_secs_f64().max(1e-9));
            (window_start, window_end_ns) = (now, window_end_ns + WINDOW_NS);
        }
    }
    let wall = start.elapsed().as_secs_f64();
    let simulated = driver.now_ns() as f64 * 1e-9;
    drop(driver);
    let timings = Rc::try_unwrap(timings)
        .map(RefCell::into_inner)
        .unwrap_or_default();
    Ok(Flight {
        // Too short a flight for windows: the whole flight is the one figure.
        realtime_factor: if window_factors.len() >= 3 {
            percentile(&window_factors, 50.0)
        } else {
            simulated / wall.max(1e-9)
        },
        realtime_factor_overall: simulated / wall.max(1e-9),
        sim_realtime_factor: simulated / (timings.total_ns as f64 * 1e-9).max(1e-9),
        timings,
    })
}

fn round3(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}

/// Runs the benchmark and prints the figures.
pub fn run(args: &SimArgs) -> Result<()> {
    if !(args.seconds.is_finite() && (1.0..=600.0).contains(&args.seconds)) {
        anyhow::bail!(
            "--seconds {} is not allowed (allowed: 1 to 600)",
            args.seconds
        );
    }
    if !(0..=256).contains(&args.threads) {
        anyhow::bail!(
            "--threads {} is not allowed (allowed: 0 to 256)",
            args.threads
        );
    }
    opencv::core::set_num_threads(if args.threads == 0 { -1 } else { args.threads })?;
    let threads = opencv::core::get_num_threads()?;
    let deploy = args.deploy_dir.clone().unwrap_or_else(deploy_dir);
    let secs = args.seconds;
    eprintln!("bench sim: {secs} s of the paper-sim mission in lockstep (1280x720 camera)...");
    let paper = fly("paper-sim", secs, &deploy)?;
    eprintln!("bench sim: {secs} s of the outdoor-1 mission in lockstep (640x480 camera)...");
    let small = fly("outdoor-1", secs, &deploy)?;
    let mut depth_all = small.timings.depth_ms.clone();
    depth_all.extend(&paper.timings.depth_ms);
    let p50 = |v: &[f64]| round3(percentile(v, 50.0));
    let out = json!({
        "realtime_factor": round3(paper.realtime_factor),
        "realtime_factor_overall": round3(paper.realtime_factor_overall),
        "realtime_factor_640x480": round3(small.realtime_factor),
        "sim_realtime_factor": round3(paper.sim_realtime_factor),
        "sim_realtime_factor_640x480": round3(small.sim_realtime_factor),
        "render_ms_p50_640x480": p50(&small.timings.render_ms),
        "render_ms_p50_1280x720": p50(&paper.timings.render_ms),
        "depth_ms_p50": p50(&depth_all),
        "frames": small.timings.render_ms.len() + paper.timings.render_ms.len(),
        "opencv_threads": threads,
    });
    if args.json {
        println!("{out}");
    } else {
        println!(
            "real-time factor of `landing run` (every stage in lockstep, OpenCV on {threads} \
             thread(s)), paper-sim: {:.1} (median of 1 s windows; {:.1} over the whole \
             flight); outdoor-1 (640x480): {:.1}",
            paper.realtime_factor, paper.realtime_factor_overall, small.realtime_factor
        );
        println!(
            "the simulator alone (physics 500 Hz, camera and depth 30 Hz) in those flights: \
             {:.1} (1280x720), {:.1} (640x480)",
            paper.sim_realtime_factor, small.sim_realtime_factor
        );
        println!(
            "simulator step with a render p50: camera 640x480 {:.2} ms, 1280x720 {:.2} ms; \
             depth 640x480 {:.2} ms",
            percentile(&small.timings.render_ms, 50.0),
            percentile(&paper.timings.render_ms, 50.0),
            percentile(&depth_all, 50.0)
        );
    }
    Ok(())
}
