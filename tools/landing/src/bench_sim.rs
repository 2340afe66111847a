//! `landing bench sim`: how much faster than real time the simulator runs with both
//! cameras rendering at their rates, and what one render costs.
//!
//! The vehicle is flown as px4-link would fly it (arm + take-off over MAVLink messages to
//! the simulated autopilot), so the cameras see a real flight: the ground, the moving pad.
//! The headline real-time factor renders the camera on its worker thread between capture
//! and publish time, as the lockstep runner does; the single-thread figure is also given.
//! Render times are measured in the single-thread flights.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;
use serde_json::json;
use sim::camera_worker::CameraPipeline;
use sim::lockstep::Simulator;
use stack_config::deploy_dir;

use crate::stats::percentile;

/// Arguments of `landing bench sim`.
#[derive(Debug, Args)]
pub struct SimArgs {
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
    /// Simulated seconds flown per camera resolution.
    #[arg(long, default_value_t = 20.0)]
    seconds: f64,
    /// The deploy directory (default: found above the current directory or executable).
    #[arg(long)]
    deploy_dir: Option<PathBuf>,
}

/// What one flight measured.
struct Flight {
    /// Median over one-second windows of simulated time: this shared VM's
    /// neighbours steal whole bursts of CPU, which the median sets aside.
    realtime_factor: f64,
    /// Simulated time over wall time for the whole flight.
    realtime_factor_overall: f64,
    render_ms: Vec<f64>,
    depth_ms: Vec<f64>,
}

/// Flies `seconds` of `scenario`. Synchronous: every render on this thread, timed.
/// Pipelined: the camera renders on a [`CameraPipeline`] between capture and publish time,
/// as the lockstep runner does, while physics and depth run here.
fn fly(scenario: &str, seconds: f64, deploy: &std::path::Path, pipelined: bool) -> Result<Flight> {
    let scn = sim::scenario::load(scenario, deploy)?;
    let mut sim = Simulator::new(&scn, 1).context("building the simulator")?;
    // Home is reported from the first step on; the take-off altitude is AMSL.
    sim.step()?;
    let origin = sim
        .take_mavlink()
        .iter()
        .find_map(crate::companion::origin_amsl)
        .context("the simulated autopilot sent no HOME_POSITION")?;
    crate::companion::arm_and_take_off(&mut sim, origin, 2.0);
    let mut camera = if pipelined {
        CameraPipeline::from_simulator(&mut sim)?
    } else {
        None
    };
    let mut ready = Vec::new();
    let mut image = vec![0u8; sim.down_camera().map_or(0, |c| c.frame_len())];
    let mut depth = vec![0u16; sim.depth_camera().map_or(0, |c| c.frame_len())];
    let (mut render_ms, mut depth_ms) = (Vec::new(), Vec::new());
    let end_ns = (seconds * 1e9) as u64;
    let start = Instant::now();
    let (mut window_start, mut window_end_ns) = (start, WINDOW_NS);
    let mut window_factors = Vec::new();
    while sim.time_ns() < end_ns {
        if sim.time_ns() >= window_end_ns {
            let now = Instant::now();
            window_factors.push(1.0 / (now - window_start).as_secs_f64().max(1e-9));
            (window_start, window_end_ns) = (now, window_end_ns + WINDOW_NS);
        }
        let r = sim.step()?;
        let _ = sim.take_mavlink();
        if let Some(c) = camera.as_mut() {
            c.on_step(&sim, &r, &mut ready)?;
            for (buf, _) in ready.drain(..) {
                c.recycle(buf);
            }
        } else if r.camera_due {
            let t = Instant::now();
            sim.render_camera_into(&mut image)?;
            render_ms.push(t.elapsed().as_secs_f64() * 1e3);
        }
        if r.depth_due {
            let t = Instant::now();
            sim.render_depth_into(&mut depth);
            depth_ms.push(t.elapsed().as_secs_f64() * 1e3);
        }
    }
    if let Some(c) = camera.as_mut() {
        c.drain(&mut ready)?;
    }
    let wall = start.elapsed().as_secs_f64();
    Ok(Flight {
        // Too short a flight for windows: the whole flight is the one figure.
        realtime_factor: if window_factors.len() >= 3 {
            percentile(&window_factors, 50.0)
        } else {
            seconds / wall.max(1e-9)
        },
        realtime_factor_overall: seconds / wall.max(1e-9),
        render_ms,
        depth_ms,
    })
}

/// Simulated time per real-time-factor window.
const WINDOW_NS: u64 = 1_000_000_000;

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
    let deploy = args.deploy_dir.clone().unwrap_or_else(deploy_dir);
    let secs = args.seconds;
    eprintln!("bench sim: {secs} s of outdoor-1 (640x480 camera, depth), one thread...");
    let small = fly("outdoor-1", secs, &deploy, false)?;
    eprintln!("bench sim: the same with the camera on its render worker...");
    let small_piped = fly("outdoor-1", secs, &deploy, true)?;
    eprintln!("bench sim: {secs} s of paper-sim (1280x720 camera, depth), one thread...");
    let large = fly("paper-sim", secs, &deploy, false)?;
    eprintln!("bench sim: the same with the camera on its render worker...");
    let large_piped = fly("paper-sim", secs, &deploy, true)?;
    let mut depth_all = small.depth_ms.clone();
    depth_all.extend(&large.depth_ms);
    let out = json!({
        "realtime_factor": round3(small_piped.realtime_factor),
        "realtime_factor_single_thread": round3(small.realtime_factor),
        "realtime_factor_1280x720": round3(large_piped.realtime_factor),
        "realtime_factor_1280x720_single_thread": round3(large.realtime_factor),
        "realtime_factor_overall": round3(small_piped.realtime_factor_overall),
        "render_ms_p50_640x480": round3(percentile(&small.render_ms, 50.0)),
        "render_ms_p50_1280x720": round3(percentile(&large.render_ms, 50.0)),
        "depth_ms_p50": round3(percentile(&depth_all, 50.0)),
        "frames": small.render_ms.len() + large.render_ms.len(),
    });
    if args.json {
        println!("{out}");
    } else {
        println!(
            "real-time factor, physics 500 Hz + 640x480 camera 30 Hz + depth 30 Hz: {:.1} \
             (median of 1 s windows, camera on its render worker; {:.1} over the whole \
             flight; {:.1} all on one thread)",
            small_piped.realtime_factor, small_piped.realtime_factor_overall, small.realtime_factor
        );
        println!(
            "real-time factor with the 1280x720 camera: {:.1} ({:.1} on one thread)",
            large_piped.realtime_factor, large.realtime_factor
        );
        println!(
            "render p50: 640x480 {:.2} ms, 1280x720 {:.2} ms; depth 640x480 p50 {:.2} ms",
            percentile(&small.render_ms, 50.0),
            percentile(&large.render_ms, 50.0),
            percentile(&depth_all, 50.0)
        );
    }
    Ok(())
}
