//! The `[camera_ingest]` section of the stack file (`deploy/config/landing.toml`): what a
//! deployed camera-ingest reads without flags (on the vehicle, a systemd unit starts it
//! with `--config` only). Flags override every key.

use std::path::{Path, PathBuf};

use serde::Deserialize;
use stack_config::{Invalid, IpcConfig, Validate};

use crate::source::{ALLOWED_SOURCES, SourceSpec};

/// camera-ingest's own keys.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CameraIngestConfig {
    /// Where frames come from, as `--source` takes it.
    pub source: String,
    /// OpenCV calibration YAML, relative to the config file's directory unless absolute.
    pub camera: PathBuf,
    /// Publish undistorted frames.
    pub undistort: bool,
}

impl Default for CameraIngestConfig {
    fn default() -> Self {
        Self {
            source: "sim".into(),
            camera: PathBuf::from("camera_down_640x480.yaml"),
            undistort: false,
        }
    }
}

impl CameraIngestConfig {
    /// The calibration file, resolved against `config_dir` (the directory of the file this
    /// section came from) when relative.
    pub fn camera_path(&self, config_dir: &Path) -> PathBuf {
        if self.camera.is_absolute() {
            self.camera.clone()
        } else {
            config_dir.join(&self.camera)
        }
    }
}

impl Validate for CameraIngestConfig {
    fn validate(&self) -> Result<(), Invalid> {
        self.source.parse::<SourceSpec>().map_err(|_| {
            Invalid::new(
                "source",
                format!(
                    "`{}` is not allowed (allowed: {ALLOWED_SOURCES})",
                    self.source
                ),
            )
        })?;
        if self.camera.as_os_str().is_empty() {
            return Err(Invalid::new(
                "camera",
                "is empty (allowed: a calibration YAML file, e.g. camera_down_640x480.yaml)",
            ));
        }
        Ok(())
    }
}

/// What camera-ingest reads from the stack file: `[ipc]` and `[camera_ingest]`, each
/// strictly; other processes' sections are theirs to check (`landing config check` checks
/// the whole file).
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
pub struct IngestFileConfig {
    /// How processes find each other and prove they are alive.
    #[serde(default)]
    pub ipc: IpcConfig,
    /// This process's section.
    #[serde(default)]
    pub camera_ingest: CameraIngestConfig,
}

impl Validate for IngestFileConfig {
    fn validate(&self) -> Result<(), Invalid> {
        self.ipc.validate().map_err(|e| e.under("ipc"))?;
        self.camera_ingest
            .validate()
            .map_err(|e| e.under("camera_ingest"))
    }
}

#[cfg(test)]
#[path = "config_test.rs"]
mod tests;
