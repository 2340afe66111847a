//! The whole stack's configuration (`deploy/config/landing.toml`): every process's
//! section, checked as one file, with every file it names read once.

use std::path::Path;

use px4_protocol::signing::SigningKey;

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
    /// depth-ingest: where a real depth camera's frames come from, and what a source that
    /// does not record them has (intrinsics, depth units, rate).
    #[serde(default)]
    pub depth_ingest: Option<depth_ingest::DepthIngestConfig>,
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
        if let Some(c) = &self.depth_ingest {
            c.validate().map_err(|e| e.under("depth_ingest"))?;
        }
        Ok(())
    }
}

impl StackConfig {
    /// Loads and validates `file`, every file it names resolved against the file's
    /// directory (here, once, as each process resolves them) and read: the calibrations,
    /// the pad layout and the signing key. A missing or broken one is an error now, in
    /// one line naming the key, rather than at the first flight.
    pub fn load(file: &Path) -> Result<Self> {
        let mut cfg: Self = config::load(file)?;
        let dir = file
            .parent()
            .filter(|d| !d.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        if let Some(key) = cfg.px4_link.signing_key_path(dir) {
            cfg.px4_link.signing_key = key.display().to_string();
        }
        cfg.signing_key()?;
        let resolved = |v: &str| config::resolve_path(dir, v).display().to_string();
        cfg.aruco_pnp.camera = resolved(&cfg.aruco_pnp.camera);
        cfg.aruco_pnp.pad = resolved(&cfg.aruco_pnp.pad);
        optics::CameraCalibration::load(&cfg.aruco_pnp.camera)
            .map_err(|e| anyhow::anyhow!("{}: aruco_pnp.camera: {e}", file.display()))?;
        optics::PadModel::load(&cfg.aruco_pnp.pad)
            .map_err(|e| anyhow::anyhow!("{}: aruco_pnp.pad: {e}", file.display()))?;
        if let Some(c) = cfg.camera_ingest.as_mut() {
            c.camera = c.camera_path(dir);
            optics::CameraCalibration::load(&c.camera)
                .map_err(|e| anyhow::anyhow!("{}: camera_ingest.camera: {e}", file.display()))?;
        }
        Ok(cfg)
    }

    /// The MAVLink signing key (`[px4_link] signing_key`), `None` for an unsigned link.
    pub fn signing_key(&self) -> Result<Option<SigningKey>> {
        if self.px4_link.signing_key.is_empty() {
            return Ok(None);
        }
        let key = SigningKey::load(Path::new(&self.px4_link.signing_key))
            .map_err(|e| anyhow::anyhow!("px4_link.signing_key: {e}"))?;
        Ok(Some(key))
    }
}
