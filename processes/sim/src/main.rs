//! `sim`: the simulator as its own process, standing in for the world and for PX4.
//!
//! Steps the scenario's world on the wall clock at 500 Hz, speaks MAVLink 2 on UDP as
//! PX4 SITL does toward px4-link, and publishes the evaluator-only ground-truth events.
//! Everything it does is library code (`sim::lockstep`, `sim::px4`); this file only
//! binds it to the clock, the socket and iceoryx2.

use std::net::SocketAddr;
use std::process::ExitCode;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use clap::Parser;
use ipc_types::msg::{
    CameraFrameHeader, DepthFrameHeader, Header, Intrinsics, PixelEncoding, Stage, TruthKind,
};
use ipc_types::services;
use runtime::ipc::SliceSample;
use runtime::{Ipc, IpcPrefix, monotonic_ns};
use runtime::{MessageHeader, SlicePublisher};
use sim::camera::PixelFormat;
use sim::lockstep::{PHYSICS_STEP_NS, Simulator, TRUTH_STATE_PERIOD_NS};
use sim::px4::endpoint::{EndpointConfig, SimVehicle};
use stack_config::deploy_dir;

/// The landing stack's simulator: quadrotor, PX4-like autopilot over MAVLink, moving pad.
#[derive(Debug, Parser)]
#[command(name = "sim", version, about)]
struct Args {
    /// Scenario name (from deploy/scenarios/) or TOML file.
    #[arg(long, default_value = "paper-sim")]
    scenario: String,
    /// Seed of every random process (default: the scenario's).
    #[arg(long)]
    seed: Option<u64>,
    /// The deploy directory (default: $LANDING_DEPLOY_DIR, else found above the current
    /// directory or the executable).
    #[arg(long)]
    deploy_dir: Option<std::path::PathBuf>,
    /// iceoryx2 prefix (default: $LANDING_IPC_PREFIX, else `landing_`).
    #[arg(long)]
    ipc_prefix: Option<String>,
    /// Where the simulated autopilot listens for MAVLink.
    #[arg(long, default_value = "127.0.0.1:14580")]
    mavlink_listen: SocketAddr,
    /// Where it sends MAVLink before a companion has spoken (px4-link's default port).
    #[arg(long, default_value = "127.0.0.1:14540")]
    mavlink_remote: SocketAddr,
    /// Simulated seconds per wall-clock second.
    #[arg(long, default_value_t = 1.0)]
    speed: f64,
    /// Stop after this many simulated seconds (default: the scenario's duration).
    #[arg(long)]
    duration_s: Option<f64>,
}

fn main() -> ExitCode {
    runtime::process_main("info", run)
}

fn run(args: &Args) -> Result<()> {
    if !(args.speed.is_finite() && args.speed > 0.0 && args.speed <= 100.0) {
        anyhow::bail!(
            "--speed {} is not allowed (allowed: above 0, at most 100)",
            args.speed
        );
    }
    let deploy = args.deploy_dir.clone().unwrap_or_else(deploy_dir);
    let scenario = sim::scenario::load(&args.scenario, &deploy)?;
    let seed = args.seed.unwrap_or(scenario.scenario.seed);
    let duration_s = args.duration_s.unwrap_or(scenario.scenario.duration_s);
    let simulator = Simulator::new(&scenario, seed)?;
    let config = EndpointConfig {
        listen: args.mavlink_listen,
        remote: Some(args.mavlink_remote),
        ..EndpointConfig::default()
    };
    let mut vehicle = SimVehicle::with_simulator(simulator, config)?;

    let prefix = IpcPrefix::from_flag_or_env(args.ipc_prefix.as_deref())?;
    let ipc = Ipc::open("sim", &prefix)?;
    let mut truth = ipc.publisher::<ipc_types::msg::TruthEvent>(services::SIM_TRUTH)?;
    let mut truth_state = ipc.publisher::<ipc_types::msg::TruthState>(services::SIM_TRUTH_STATE)?;
    let mut heartbeat = ipc.heartbeat(Duration::from_millis(500))?;
    let sim_ref = vehicle.simulator();
    let (cam_len, cam_geometry) = match sim_ref.down_camera() {
        Some(c) => (
            c.frame_len(),
            Some((
                c.calibration().width,
                c.calibration().height,
                c.params().format,
                (c.params().exposure_time_s * 1e9) as u64,
            )),
        ),
        None => (0, None),
    };
    let depth_geometry = sim_ref.depth_camera().map(|d| {
        let p = d.params();
        let (fx, fy) = p.focal_px();
        let (cx, cy) = p.principal_point_px();
        (
            d.frame_len(),
            p.width,
            p.height,
            Intrinsics { fx, fy, cx, cy },
        )
    });
    let mut camera =
        ipc.slice_publisher::<u8, CameraFrameHeader>(services::SIM_CAMERA, cam_len.max(1))?;
    let mut depth = ipc.slice_publisher::<u16, DepthFrameHeader>(
        services::SIM_DEPTH,
        depth_geometry.map(|g| g.0).unwrap_or(1),
    )?;
    // Rendered frames wait here for the sensor's exposure-to-publish latency.
    let mut pending_camera: Option<(SliceSample<u8, CameraFrameHeader>, u64)> = None;
    let mut pending_depth: Option<(SliceSample<u16, DepthFrameHeader>, u64)> = None;
    let mut dropped: u64 = 0;
    let (mut camera_sent, mut depth_sent, mut truth_events) = (0u64, 0u64, 0u64);
    tracing::info!(
        scenario = %scenario.scenario.name,
        seed,
        mavlink = %vehicle.endpoint().local_addr(),
        "simulator running"
    );

    let stop = AtomicBool::new(false);
    let speed = args.speed;
    let until = Instant::now() + Duration::from_secs_f64(duration_s / args.speed + 1.0);
    let end_ns = (duration_s * 1e9) as u64;
    let mut steps: u64 = 0;
    // The first publishing error (a sample or a heartbeat), reported after the loop.
    let mut failure: Option<anyhow::Error> = None;
    vehicle
        .run_realtime(until, &stop, args.speed, |sim, report| {
            for t in &report.truth {
                tracing::info!(kind = ?TruthKind::from_raw(t.kind), on_pad = t.on_pad, "ground truth");
                if let Err(e) = truth.send(t.msg, t) {
                    failure = Some(e.into());
                    return false;
                }
                truth_events += 1;
            }
            let now = monotonic_ns();
            // Frames whose latency has passed go out first; one still pending when the next
            // is due goes out now, in order, rather than being overwritten.
            camera_sent += u64::from(release(&mut pending_camera, &mut camera, now, report.camera_due));
            depth_sent += u64::from(release(&mut pending_depth, &mut depth, now, report.depth_due));
            if report.camera_due
                && let Some((width, height, format, exposure_ns)) = cam_geometry
            {
                match camera.loan(cam_len) {
                    Ok(mut sample) => match sim.render_camera_into(sample.payload_mut()) {
                        Ok(Some(shot)) => {
                            let (encoding, bpp) = match format {
                                PixelFormat::Mono8 => (PixelEncoding::Mono8, 1),
                                PixelFormat::Bgr8 => (PixelEncoding::Bgr8, 3),
                            };
                            *sample.user_header_mut() = CameraFrameHeader {
                                msg: Header::captured_at(now),
                                width,
                                height,
                                stride: width * bpp,
                                encoding: encoding as u32,
                                camera_id: 0,
                                undistorted: 0,
                                exposure_ns,
                            };
                            let wall_latency = ((shot.publish_ns - shot.capture_ns) as f64 / speed) as u64;
                            pending_camera = Some((sample, now + wall_latency));
                        }
                        Ok(None) => {}
                        Err(e) => tracing::warn!(error = %e, "camera frame not rendered"),
                    },
                    // A consumer holds every sample: drop this frame rather than queue latency.
                    Err(_) => dropped += 1,
                }
            }
            if report.depth_due
                && let Some((len, width, height, intrinsics)) = depth_geometry
            {
                match depth.loan(len) {
                    Ok(mut sample) => {
                        if let Some(shot) = sim.render_depth_into(sample.payload_mut()) {
                            *sample.user_header_mut() = DepthFrameHeader {
                                msg: Header::captured_at(now),
                                width,
                                height,
                                depth_scale_m: sim::depth::DEPTH_SCALE_M,
                                intrinsics,
                                camera_id: 0,
                                reserved: 0,
                            };
                            let wall_latency = ((shot.publish_ns - shot.capture_ns) as f64 / speed) as u64;
                            pending_depth = Some((sample, now + wall_latency));
                        }
                    }
                    Err(_) => dropped += 1,
                }
            }
            steps += 1;
            if steps.is_multiple_of(TRUTH_STATE_PERIOD_NS / PHYSICS_STEP_NS) {
                let s = sim::lockstep::truth_state(sim, now);
                if let Err(e) = truth_state.send(s.msg, &s) {
                    failure = Some(e.into());
                    return false;
                }
            }
            if steps.is_multiple_of(50) {
                if let Err(e) = heartbeat.beat() {
                    failure = Some(e.into());
                    return false;
                }
                // SIGINT/SIGTERM end the run cleanly.
                if ipc.shutdown_requested() {
                    tracing::info!("signal: stopping");
                    return false;
                }
            }
            sim.time_ns() < end_ns
        })
        .context("simulation")?;
    if dropped > 0 {
        tracing::warn!(
            dropped,
            "frames dropped because consumers held every sample"
        );
    }
    tracing::info!(
        steps,
        sim_time_s = vehicle.simulator().time_ns() as f64 * 1e-9,
        camera_frames = camera_sent,
        depth_frames = depth_sent,
        dropped,
        truth_events,
        "sim stopped"
    );
    if let Some(e) = failure {
        return Err(e).context("publishing");
    }
    Ok(())
}

/// Sends a held frame once its sensor latency has passed, or at once when `force` (the
/// next frame is due: frames go out in order, never overwritten). The sensor stage spans
/// capture to publication. Returns whether a frame went out.
fn release<T, H>(
    pending: &mut Option<(SliceSample<T, H>, u64)>,
    publisher: &mut SlicePublisher<T, H>,
    now: u64,
    force: bool,
) -> bool
where
    T: std::fmt::Debug + runtime::iceoryx2::prelude::ZeroCopySend + Copy + 'static,
    H: MessageHeader,
{
    if !pending.as_ref().is_some_and(|(_, at)| now >= *at || force) {
        return false;
    }
    let Some((mut sample, _)) = pending.take() else {
        return false;
    };
    let msg = sample.user_header_mut().msg_mut();
    msg.push_stage(Stage::Sensor, msg.capture_ns, monotonic_ns());
    match publisher.send(sample) {
        Ok(_) => true,
        Err(e) => {
            tracing::warn!(error = %e, service = publisher.service(), "frame not sent");
            false
        }
    }
}
