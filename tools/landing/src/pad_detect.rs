//! `landing pad detect`: the pad pose in one image, with the same estimator aruco-pnp runs.

use std::path::PathBuf;

use anyhow::{Context, Result};
use aruco_pnp::{ArucoConfig, ArucoStage, Frame};
use clap::Args;
use ipc_types::msg::PixelEncoding;
use opencv::imgcodecs;
use opencv::prelude::*;
use optics::{CameraCalibration, PadModel};
use serde_json::json;
use stack_config::deploy_dir;

/// Arguments of `landing pad detect`.
#[derive(Debug, Args)]
pub struct DetectArgs {
    /// The image (any format OpenCV reads; colour is converted to grey).
    #[arg(long)]
    image: PathBuf,
    /// Camera calibration, OpenCV YAML (camera_matrix, distortion_coefficients,
    /// image_width, image_height).
    #[arg(long)]
    camera: PathBuf,
    /// Pad layout (default: pad.toml in the deploy config directory).
    #[arg(long)]
    pad: Option<PathBuf>,
    /// The deploy directory (default: found above the current directory or executable).
    #[arg(long)]
    deploy_dir: Option<PathBuf>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// Exit code when the image holds no pad.
pub const NOT_FOUND: u8 = 3;

/// Detects the pad; `Ok(false)` when there is none (the caller exits with [`NOT_FOUND`]).
pub fn run(args: &DetectArgs) -> Result<bool> {
    let deploy = args.deploy_dir.clone().unwrap_or_else(deploy_dir);
    let pad_path = args
        .pad
        .clone()
        .unwrap_or_else(|| deploy.join("config").join("pad.toml"));
    let pad = PadModel::load(&pad_path)?;
    let calibration = CameraCalibration::load(&args.camera)?;
    let path = args.image.to_string_lossy().to_string();
    if !args.image.is_file() {
        anyhow::bail!("image {path}: no such file");
    }
    let image = imgcodecs::imread(&path, imgcodecs::IMREAD_GRAYSCALE)
        .with_context(|| format!("image {path}: cannot read"))?;
    if image.empty() {
        anyhow::bail!("image {path}: not an image OpenCV can read (PNG, JPEG, BMP, TIFF, ...)");
    }
    let (w, h) = (image.cols() as u32, image.rows() as u32);
    if (w, h) != (calibration.width, calibration.height) {
        anyhow::bail!(
            "image {path} is {w}x{h}, the calibration {} is {}x{}",
            args.camera.display(),
            calibration.width,
            calibration.height
        );
    }
    let data = image.data_bytes()?;
    let frame = Frame {
        width: w,
        height: h,
        stride: w,
        encoding: PixelEncoding::Mono8,
        data,
        undistorted: false,
    };
    // The estimator aruco-pnp runs: its stage from the shipped `[aruco_pnp]` section.
    let config = deploy_dir().join("config").join("landing.toml");
    let section: ArucoConfig = stack_config::load_process(&config, "aruco_pnp")?.1;
    let mut stage = ArucoStage::from_config(&section, calibration, pad)?;
    let est = stage.estimator_mut();
    let Some(e) = est.process(&frame, 0, None)? else {
        if args.json {
            println!("{}", json!({"found": false}));
        } else {
            println!("no pad found in {path}");
        }
        return Ok(false);
    };
    let t = e.camera_from_pad.translation.vector;
    let q = e.camera_from_pad.rotation.coords;
    if args.json {
        println!(
            "{}",
            json!({
                "found": true,
                "ids": e.used,
                "detected_ids": e.detected,
                "rejected_ids": e.rejected,
                "camera_from_pad": {
                    "translation": [t.x, t.y, t.z],
                    "rotation_xyzw": [q.x, q.y, q.z, q.w],
                },
                "reprojection_error_px": e.rms_px,
            })
        );
    } else {
        println!("pad found in {path}");
        println!("  markers used: {:?} (detected {:?})", e.used, e.detected);
        println!(
            "  camera_from_pad: translation [{:.4}, {:.4}, {:.4}] m, rotation xyzw [{:.5}, {:.5}, {:.5}, {:.5}]",
            t.x, t.y, t.z, q.x, q.y, q.z, q.w
        );
        println!("  reprojection error: {:.3} px RMS", e.rms_px);
    }
    Ok(true)
}
