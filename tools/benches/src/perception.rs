//! `landing bench perception`: sim -> camera-ingest -> aruco-pnp as three OS processes
//! over iceoryx2, started from the graph as `landing run --processes` starts them;
//! observation rate and frame-to-observation latency.
//!
//! px4-link runs too, so aruco-pnp has the vehicle state and publishes world poses; the
//! vehicle is flown through px4-link's request topic (arm, take off to 2 m next to the
//! indoor pad) so the camera sees the pad. Once observations flow they are received here
//! for `--seconds` and timed from the stamps the processes leave in each header: the
//! frame's publication by camera-ingest to the observation's arrival at a consumer (this
//! one).

use std::process::Stdio;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use clap::Args;
use ipc_types::msg::{Header, LinkRequest, LinkRequestKind, PadObservation, Stage};
use ipc_types::services;
use runtime::ipc::{Wake, run_wait_loop};
use runtime::{Ipc, IpcPrefix, monotonic_ns};
use serde_json::json;

use stack_config::deploy_dir;

use evaluation::stats::percentile;
use stack::processes::{command, run_values};
use stack::procs::{Children, free_udp_port};

/// The graph's nodes this benchmark starts.
const NODES: [&str; 4] = ["sim", "px4-link", "camera-ingest", "aruco-pnp"];

/// Arguments of `landing bench perception`.
#[derive(Debug, Args)]
pub struct PerceptionArgs {
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
    /// Seconds of observations measured once they flow.
    #[arg(long, default_value_t = 10.0)]
    seconds: f64,
    /// Simulator scenario (the vehicle hovers at its take-off point; the pad must be in
    /// view from 2 m there).
    #[arg(long, default_value = "indoor-static")]
    scenario: String,
}

/// Runs the benchmark and prints the figures.
pub fn run(args: &PerceptionArgs, prefix: Option<&str>) -> Result<()> {
    if !(args.seconds.is_finite() && (1.0..=600.0).contains(&args.seconds)) {
        anyhow::bail!(
            "--seconds {} is not allowed (allowed: 1 to 600)",
            args.seconds
        );
    }
    let prefix = match prefix {
        Some(p) => IpcPrefix::new(p)?,
        None => IpcPrefix::unique("perception"),
    };
    let deploy = deploy_dir();
    let graph_path = graph::default_path(&deploy);
    let graph = graph::Graph::load(&graph_path)?;
    let scn = sim::scenario::load(&args.scenario, &deploy)?;
    // The graph's command lines, as `landing run --processes` starts them; the simulator
    // runs long enough for any --seconds.
    let values = run_values(
        &scn,
        scn.scenario.seed,
        600.0,
        &deploy.join("config").join("landing.toml"),
        &deploy,
        (free_udp_port()?, free_udp_port()?),
        "",
    )?;
    let ipc = Ipc::open("bench-perception", &prefix)?;
    let observations = ipc.subscriber::<PadObservation>(services::PAD_OBSERVATION)?;
    let mut requests = ipc.publisher::<LinkRequest>(services::PX4_REQUEST)?;
    eprintln!(
        "bench perception: starting {} from the graph: px4-link, camera-ingest, aruco-pnp, then sim...",
        args.scenario
    );
    let mut children = Children::default();
    for node in graph
        .start_order()
        .into_iter()
        .filter(|n| NODES.contains(&n.name.as_str()))
    {
        let child = command(node, &values, &prefix, &graph_path)?
            .env("LANDING_LOG", "warn")
            .stdout(Stdio::null())
            .spawn()
            .with_context(|| format!("starting {}", node.binary))?;
        children.push(&node.name, child);
    }
    std::thread::sleep(Duration::from_millis(1500));
    eprintln!("bench perception: arming and taking off to 2 m through px4-link...");
    for (id, kind) in [(1, LinkRequestKind::Arm), (2, LinkRequestKind::Takeoff)] {
        let r = LinkRequest {
            msg: Header::captured_at(monotonic_ns()),
            id,
            kind: kind as u32,
            reserved: 0,
            altitude_m: 2.0,
        };
        requests.send(r.msg, &r)?;
    }

    // Wait for the pad to come into view, then measure.
    let measure_ns = (args.seconds * 1e9) as u64;
    let give_up = Instant::now() + Duration::from_secs(30);
    let mut first: Option<(u64, u64)> = None; // (local time, seq)
    let (mut latency_ms, mut aruco_ms, mut capture_ms) = (Vec::new(), Vec::new(), Vec::new());
    let mut count = 0u64;
    let mut world = 0u64;
    let mut world_xyz: Vec<[f64; 3]> = Vec::new();
    let mut last_seq = 0u64;
    let mut timed_out = false;
    run_wait_loop(
        &[observations.listener()],
        &[],
        Some(Duration::from_millis(100)),
        |wake| {
            let now = monotonic_ns();
            if let Wake::Data(_) = wake {
                while let Ok(Some(s)) = observations.receive() {
                    let obs = *s.payload();
                    let got = monotonic_ns();
                    let first_ns = first.get_or_insert((got, obs.msg.seq)).0;
                    if got - first_ns > measure_ns {
                        break;
                    }
                    count += 1;
                    world += u64::from(obs.world_valid == 1);
                    if obs.world_valid == 1 {
                        world_xyz.push(obs.world_from_pad.translation);
                    }
                    last_seq = obs.msg.seq;
                    let stage = |st: Stage| {
                        obs.msg
                            .stages()
                            .iter()
                            .rev()
                            .find(|x| x.stage == st as u32)
                            .copied()
                    };
                    let published = stage(Stage::CameraIngest).or_else(|| stage(Stage::Sensor));
                    if let Some(p) = published {
                        latency_ms.push(got.saturating_sub(p.exit_ns) as f64 / 1e6);
                    }
                    if let Some(a) = stage(Stage::ArucoPnp) {
                        aruco_ms.push(a.exit_ns.saturating_sub(a.enter_ns) as f64 / 1e6);
                    }
                    capture_ms.push(got.saturating_sub(obs.msg.capture_ns) as f64 / 1e6);
                }
            }
            match first {
                Some((t0, _)) => now.saturating_sub(t0) <= measure_ns,
                None => {
                    timed_out = Instant::now() > give_up;
                    !timed_out
                }
            }
        },
    )?;
    drop(children);
    if timed_out || count == 0 {
        anyhow::bail!(
            "no pad observation within 30 s (is the pad in view in scenario {}?)",
            args.scenario
        );
    }
    let seconds = args.seconds;
    let rate = count as f64 / seconds;
    let skipped = last_seq.saturating_sub(first.map_or(0, |f| f.1) + count - 1);
    // The indoor pad stands still: the spread of its world position is the whole chain's
    // noise (detection, vehicle estimate, timing), per axis, 1 sigma.
    let spread = (0..3)
        .map(|k| {
            let n = world_xyz.len().max(1) as f64;
            let mean = world_xyz.iter().map(|p| p[k]).sum::<f64>() / n;
            (world_xyz.iter().map(|p| (p[k] - mean).powi(2)).sum::<f64>() / n).sqrt()
        })
        .fold(0.0f64, f64::max);
    let out = json!({
        "world_position_sigma_m": (spread * 1e4).round() / 1e4,
        "observations": count,
        "with_world_pose": world,
        "rate_hz": (rate * 100.0).round() / 100.0,
        "seq_gaps": skipped,
        "latency_ms_p50": percentile(&latency_ms, 50.0),
        "latency_ms_p99": percentile(&latency_ms, 99.0),
        "aruco_ms_p50": percentile(&aruco_ms, 50.0),
        "aruco_ms_p99": percentile(&aruco_ms, 99.0),
        "capture_to_observation_ms_p50": percentile(&capture_ms, 50.0),
    });
    if args.json {
        println!("{out}");
    } else {
        println!(
            "{count} observations in {seconds:.0} s ({rate:.1} Hz, {world} with a world pose); frame published -> observation received: p50 {:.3} ms, p99 {:.3} ms; aruco-pnp per frame p50 {:.3} ms, p99 {:.3} ms; capture -> observation p50 {:.1} ms (includes the simulated camera's exposure-to-publish latency)",
            percentile(&latency_ms, 50.0),
            percentile(&latency_ms, 99.0),
            percentile(&aruco_ms, 50.0),
            percentile(&aruco_ms, 99.0),
            percentile(&capture_ms, 50.0),
        );
    }
    Ok(())
}
