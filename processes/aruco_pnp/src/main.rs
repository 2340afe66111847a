//! `aruco-pnp`: the pad estimator as its own process.
//!
//! Reads camera frames (landing/camera/frame) and the vehicle state
//! (landing/vehicle/state), publishes pad observations (landing/pad/observation).
//! Everything it computes is `aruco_pnp::PadEstimator`; this file binds it to iceoryx2.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::{Context, Result};
use aruco_pnp::{ArucoConfig, Frame, PadEstimator, down_camera_from_body};
use clap::Parser;
use ipc_types::msg::{
    CameraFrameHeader, Header, PadObservation, PixelEncoding, Stage, VehicleState,
};
use ipc_types::services;
use optics::{CameraCalibration, PadModel};
use runtime::ipc::{Wake, run_wait_loop};
use runtime::{Ipc, IpcPrefix, monotonic_ns};
use stack_config::{IpcConfig, deploy_dir, load_process_or_default};
use state_history::{StateHistory, TimedPose};

/// Finds the landing pad in camera frames and publishes its pose.
#[derive(Debug, Parser)]
#[command(name = "aruco-pnp", version, about)]
struct Args {
    /// Stack configuration (reads [ipc] and [aruco_pnp]; defaults when absent).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Camera calibration, OpenCV YAML (default: [aruco_pnp] camera, in the deploy
    /// config directory).
    #[arg(long)]
    camera: Option<PathBuf>,
    /// Pad layout (default: [aruco_pnp] pad, in the deploy config directory).
    #[arg(long)]
    pad: Option<PathBuf>,
    /// The deploy directory (default: $LANDING_DEPLOY_DIR, else found above the current
    /// directory or the executable).
    #[arg(long)]
    deploy_dir: Option<PathBuf>,
    /// iceoryx2 prefix (default: $LANDING_IPC_PREFIX, else [ipc] prefix).
    #[arg(long)]
    ipc_prefix: Option<String>,
}

fn main() -> ExitCode {
    runtime::process_main("info", run)
}

/// How many vehicle states are kept (2 s at 50 Hz).
const STATE_HISTORY: usize = 100;

fn run(args: &Args) -> Result<()> {
    let deploy = args.deploy_dir.clone().unwrap_or_else(deploy_dir);
    let (ipc_cfg, cfg): (IpcConfig, ArucoConfig) =
        load_process_or_default(args.config.as_deref(), "aruco_pnp")?;
    let in_config = |name: &str| {
        let p = PathBuf::from(name);
        if p.is_absolute() {
            p
        } else {
            deploy.join("config").join(p)
        }
    };
    let camera_path = args
        .camera
        .clone()
        .unwrap_or_else(|| in_config(&cfg.camera));
    let pad_path = args.pad.clone().unwrap_or_else(|| in_config(&cfg.pad));
    let calibration = CameraCalibration::load(&camera_path)?;
    let pad = PadModel::load(&pad_path)?;
    let mut estimator = PadEstimator::new(
        calibration,
        pad,
        down_camera_from_body(cfg.camera_position_in_body_m),
        cfg.settings(),
    )?;
    let prefix = IpcPrefix::resolve(args.ipc_prefix.as_deref(), &ipc_cfg.prefix)?;
    let ipc = Ipc::open("aruco-pnp", &prefix)?;
    let frames = ipc
        .slice_subscriber::<u8, CameraFrameHeader>(services::CAMERA_FRAME)
        .context("camera frames")?;
    let states = ipc
        .subscriber::<VehicleState>(services::VEHICLE_STATE)
        .context("vehicle state")?;
    let mut observations = ipc
        .publisher::<PadObservation>(services::PAD_OBSERVATION)
        .context("pad observations")?;
    let mut heartbeat = ipc.heartbeat(Duration::from_millis(ipc_cfg.heartbeat_deadline_ms))?;
    let mut history = StateHistory::new(STATE_HISTORY, cfg.max_state_age_ms * 1_000_000);
    tracing::info!(camera = %camera_path.display(), "aruco-pnp running");

    let mut counters = Counts::default();
    let mut last_report = monotonic_ns();
    let mut failure = None;
    let exit = run_wait_loop(
        &[frames.listener(), states.listener()],
        &[],
        Some(Duration::from_millis(ipc_cfg.heartbeat_period_ms)),
        |wake| {
            match wake {
                Wake::Data(1) => drain_states(&states, &mut history, &mut counters),
                Wake::Data(_) => {
                    // States first: the frame's capture time may need the newest one.
                    drain_states(&states, &mut history, &mut counters);
                    // Only the newest frame: when this process lags, an older frame
                    // would only add latency to the pose the fsm steers by.
                    let mut newest = None;
                    loop {
                        match frames.receive() {
                            Ok(Some(s)) => {
                                if newest.replace(s).is_some() {
                                    counters.skipped += 1;
                                }
                            }
                            Ok(None) => break,
                            Err(e) => {
                                failure = Some(anyhow::Error::from(e));
                                return false;
                            }
                        }
                    }
                    if let Some(sample) = newest {
                        let enter = monotonic_ns();
                        let header = *sample.user_header();
                        let Some(frame) = frame_of(&header, sample.payload()) else {
                            counters.bad_frames += 1;
                            tracing::debug!("frame with an inconsistent header dropped");
                            return true;
                        };
                        let body = history.at(header.msg.capture_ns).ok();
                        if body.is_none() {
                            counters.no_state += 1;
                        }
                        match estimator.process(&frame, header.msg.capture_ns, body.as_ref()) {
                            Ok(Some(est)) => {
                                let mut msg = Header::derived_from(&header.msg);
                                msg.push_stage(Stage::ArucoPnp, enter, monotonic_ns());
                                if let Some(obs) = est.observation(msg) {
                                    if let Err(e) = observations.send(obs.msg, &obs) {
                                        failure = Some(anyhow::Error::from(e));
                                        return false;
                                    }
                                } else {
                                    counters.non_finite += 1;
                                }
                            }
                            Ok(None) => counters.no_pad += 1,
                            Err(e) => {
                                counters.bad_frames += 1;
                                tracing::debug!(error = %e, "frame dropped");
                            }
                        }
                    }
                }
                Wake::Tick | Wake::DeadlineMissed(_) => {
                    if let Err(e) = heartbeat.beat() {
                        failure = Some(anyhow::Error::from(e));
                        return false;
                    }
                    let now = monotonic_ns();
                    if now.saturating_sub(last_report) > 5_000_000_000 {
                        last_report = now;
                        report(&estimator, &counters, frames.gaps(), "aruco-pnp");
                    }
                }
            }
            true
        },
    )?;
    if let Some(e) = failure {
        return Err(e);
    }
    report(&estimator, &counters, frames.gaps(), "aruco-pnp stopped");
    tracing::info!(?exit, "aruco-pnp exiting");
    Ok(())
}

/// Logs every counter under `what` (periodically, and once at the end).
fn report(estimator: &PadEstimator, counters: &Counts, missed_frames: u64, what: &'static str) {
    let c = estimator.counters();
    tracing::info!(
        frames = c.frames,
        poses = c.poses,
        region_searches = c.region_searches,
        fallbacks = c.fallbacks,
        no_pad = counters.no_pad,
        skipped = counters.skipped,
        bad_frames = counters.bad_frames,
        no_state = counters.no_state,
        bad_states = counters.bad_states,
        non_finite = counters.non_finite,
        missed_frames,
        "{what}"
    );
}

/// What the process counts besides the estimator's own counters.
#[derive(Debug, Default)]
struct Counts {
    /// Frames passed over because a newer one was already waiting.
    skipped: u64,
    no_pad: u64,
    bad_frames: u64,
    no_state: u64,
    bad_states: u64,
    non_finite: u64,
}

fn drain_states(
    states: &runtime::Subscriber<VehicleState>,
    history: &mut StateHistory,
    counters: &mut Counts,
) {
    while let Ok(Some(s)) = states.receive() {
        let v = s.payload();
        let t = v.world_from_body.translation;
        let [x, y, z, w] = v.world_from_body.rotation_xyzw;
        let q = nalgebra::Quaternion::new(w, x, y, z);
        let ok = q.norm() > 0.5
            && history.push(TimedPose {
                time_ns: v.msg.capture_ns,
                world_from_body: nalgebra::Isometry3::from_parts(
                    nalgebra::Translation3::new(t[0], t[1], t[2]),
                    nalgebra::UnitQuaternion::from_quaternion(q),
                ),
                velocity: nalgebra::Vector3::from(v.velocity),
            });
        if !ok {
            counters.bad_states += 1;
        }
    }
}

/// The frame a sample holds, if its header agrees with its bytes.
fn frame_of<'a>(header: &CameraFrameHeader, payload: &'a [u8]) -> Option<Frame<'a>> {
    let len = header.expected_len()?;
    let data = payload.get(..len)?;
    Some(Frame {
        width: header.width,
        height: header.height,
        stride: header.stride,
        encoding: PixelEncoding::from_raw(header.encoding)?,
        data,
        undistorted: header.undistorted == 1,
    })
}
