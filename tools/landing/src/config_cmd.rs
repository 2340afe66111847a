//! `landing config check`: validates the whole stack configuration file.

use std::path::Path;

use anyhow::Result;
use camera_ingest::CameraIngestConfig;
use serde::Deserialize;
use stack_config::{self as config, Invalid, IpcConfig, Validate};

/// The whole stack configuration. Each process reads only its own section, strictly; this
/// type checks the file as a whole, so an unknown section is caught too.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StackConfig {
    /// How processes find each other and prove they are alive.
    pub ipc: IpcConfig,
    /// The pad estimator.
    #[serde(default)]
    pub aruco_pnp: aruco_pnp::ArucoConfig,
    /// The autopilot link.
    #[serde(default)]
    pub px4_link: px4_link::config::Px4LinkConfig,
    /// The planner.
    #[serde(default)]
    pub planner: planner::PlannerConfig,
    /// camera-ingest: where frames come from, the calibration, undistortion.
    #[serde(default)]
    pub camera_ingest: Option<CameraIngestConfig>,
    /// depth-map: the depth camera's mount, ray casting, the window, the log-odds model.
    #[serde(default)]
    pub depth_map: depth_map::DepthMapConfig,
    /// The mission state machine and the pad filter.
    #[serde(default)]
    pub fsm: fsm::FsmConfig,
    /// The supervisor: its deadlines, the data paths' limits, its policy.
    #[serde(default)]
    pub watchdog: watchdog::WatchdogStageConfig,
    /// The recorder: images as JPEG or raw, chunk compression, flush period.
    #[serde(default)]
    pub recorder: recorder::RecorderConfig,
}

impl Validate for StackConfig {
    fn validate(&self) -> Result<(), Invalid> {
        self.ipc.validate().map_err(|e| e.under("ipc"))?;
        self.aruco_pnp
            .validate()
            .map_err(|e| e.under("aruco_pnp"))?;
        self.px4_link.validate().map_err(|e| e.under("px4_link"))?;
        self.depth_map
            .validate()
            .map_err(|e| e.under("depth_map"))?;
        self.planner.validate().map_err(|e| e.under("planner"))?;
        self.fsm.validate().map_err(|e| e.under("fsm"))?;
        self.watchdog.validate().map_err(|e| e.under("watchdog"))?;
        self.recorder.validate().map_err(|e| e.under("recorder"))?;
        if let Some(c) = &self.camera_ingest {
            c.validate().map_err(|e| e.under("camera_ingest"))?;
        }
        Ok(())
    }
}

/// Loads and validates `file`; prints `ok` on success.
pub fn check(file: &Path) -> Result<()> {
    let _cfg: StackConfig = config::load(file)?;
    println!("{}: ok", file.display());
    Ok(())
}
