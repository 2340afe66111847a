//! `camera-ingest`: the pipeline's camera as its own process. Reads sim/camera, or a
//! camera, GStreamer pipeline, video file or image directory through OpenCV (`capture`);
//! publishes camera/frame, each frame written (copied or undistorted) straight into a
//! loaned shared-memory sample. Everything per frame is `camera_ingest::IngestStage`.

mod capture;

use std::process::ExitCode;

use anyhow::{Context, Result, anyhow};
use camera_ingest::config::{CameraIngestConfig, SourceFlags};
use camera_ingest::{IngestStage, SourceSpec};
use clap::Parser;
use ipc_types::topics;
use optics::CameraCalibration;
use runtime::StageArgs;

/// Publishes the landing pipeline's camera frames (landing/camera/frame) from the
/// simulator or a real camera, optionally undistorted. A consumer that lags loses old
/// frames; nothing queues latency.
#[derive(Debug, Parser)]
#[command(name = "camera-ingest", version, about)]
struct Args {
    #[command(flatten)]
    stage: StageArgs,
    #[command(flatten)]
    source: SourceFlags,
}

fn main() -> ExitCode {
    runtime::process_main("info", run)
}

fn run(args: &Args) -> Result<()> {
    let (ipc, cfg): (_, CameraIngestConfig) = args.stage.load("camera_ingest")?;
    let s = args
        .source
        .resolve(&cfg, &args.stage.config_dir())
        .map_err(|e| anyhow!(e))?;
    let calibration = CameraCalibration::load(&s.camera)?;
    let section = CameraIngestConfig {
        undistort: s.undistort,
        ..cfg
    };
    let mut stage = IngestStage::from_config(&section, calibration).context("undistortion maps")?;
    tracing::info!(source = %s.spec, camera = %s.camera.display(), s.undistort, "camera-ingest");
    if s.spec == SourceSpec::Sim {
        runtime::serve(&args.stage, &ipc, &mut stage, None, None)?;
        return Ok(());
    }
    let mut capture = capture::Capture::start(&s, &calibration)?;
    let rename = Some((topics::SIM_CAMERA, topics::CAMERA_DEVICE));
    let served = runtime::serve(&args.stage, &ipc, &mut stage, Some(&mut capture), rename);
    // Joined before `main` returns, whatever the driver did (a stuck read: exit code 80).
    capture.stop()?;
    Ok(served?)
}
