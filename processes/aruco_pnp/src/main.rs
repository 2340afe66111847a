//! `aruco-pnp`: the pad estimator as its own process. Reads vehicle/state and
//! camera/frame; publishes pad/observation (deploy/graph.toml). Everything it computes
//! is `aruco_pnp::ArucoStage`; this file loads the calibration and the pad, builds the
//! stage and hands it to the iceoryx2 driver.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;
use aruco_pnp::{ArucoConfig, ArucoStage};
use clap::Parser;
use optics::{CameraCalibration, PadModel};
use runtime::StageArgs;

/// Finds the landing pad in camera frames and publishes its pose.
#[derive(Debug, Parser)]
#[command(name = "aruco-pnp", version, about)]
struct Args {
    #[command(flatten)]
    stage: StageArgs,
    /// Camera calibration, OpenCV YAML (default: [aruco_pnp] camera, relative to the
    /// config file).
    #[arg(long)]
    camera: Option<PathBuf>,
    /// Pad layout (default: [aruco_pnp] pad, relative to the config file).
    #[arg(long)]
    pad: Option<PathBuf>,
}

fn main() -> ExitCode {
    runtime::process_main("info", run)
}

fn run(args: &Args) -> Result<()> {
    let (ipc, cfg): (_, ArucoConfig) = args.stage.load("aruco_pnp")?;
    // Relative to the config file, as every process and `landing config check` read it.
    let dir = args.stage.config_dir();
    let in_config = |name: &str| stack_config::resolve_path(&dir, name);
    let camera = args
        .camera
        .clone()
        .unwrap_or_else(|| in_config(&cfg.camera));
    let pad = args.pad.clone().unwrap_or_else(|| in_config(&cfg.pad));
    let mut stage = ArucoStage::from_config(
        &cfg,
        CameraCalibration::load(&camera)?,
        PadModel::load(&pad)?,
    )?;
    tracing::info!(camera = %camera.display(), "aruco-pnp");
    runtime::serve(&args.stage, &ipc, &mut stage, None, None)?;
    Ok(())
}
