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
        stack_config::resolve_path(config_dir, &self.camera.to_string_lossy())
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

/// camera-ingest's source flags; each overrides its `[camera_ingest]` key.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct SourceFlags {
    /// Where frames come from: `sim`, `v4l2:/dev/videoN`, `gst:<pipeline ending in
    /// appsink>`, or `file:<video file or image directory>` [default: [camera_ingest]
    /// source, else sim].
    #[arg(long)]
    pub source: Option<String>,
    /// Camera calibration, OpenCV YAML [default: [camera_ingest] camera, relative to the
    /// config file, else deploy/config/camera_down_640x480.yaml].
    #[arg(long)]
    pub camera: Option<PathBuf>,
    /// Publish undistorted frames (pinhole with the calibration's camera matrix).
    #[arg(long)]
    pub undistort: bool,
    /// file: playback rate (default: the video's recorded rate; required for an image
    /// directory); v4l2: the frame rate asked of the camera.
    #[arg(long)]
    pub rate_hz: Option<f64>,
    /// file: start again from the beginning at the end instead of exiting.
    #[arg(long = "loop")]
    pub looping: bool,
}

/// The source flags and the `[camera_ingest]` section, resolved and checked.
#[derive(Debug, Clone, PartialEq)]
pub struct Source {
    /// Where frames come from.
    pub spec: SourceSpec,
    /// The calibration file.
    pub camera: PathBuf,
    /// Publish undistorted frames.
    pub undistort: bool,
    /// Playback or camera rate.
    pub rate_hz: Option<f64>,
    /// Play a file again at its end.
    pub looping: bool,
}

impl SourceFlags {
    /// Resolves the flags over `cfg` (relative calibration paths against `config_dir`)
    /// and checks them: `--rate-hz` within 0.1 to 1000 Hz and only for file and v4l2
    /// sources, `--loop` only for files. The error is the line to print.
    pub fn resolve(&self, cfg: &CameraIngestConfig, config_dir: &Path) -> Result<Source, String> {
        let spec: SourceSpec = self
            .source
            .as_deref()
            .unwrap_or(&cfg.source)
            .parse()
            .map_err(|e: crate::SourceError| e.to_string())?;
        if let Some(r) = self.rate_hz
            && !(r.is_finite() && (0.1..=1000.0).contains(&r))
        {
            return Err(format!(
                "--rate-hz {r} is not allowed (allowed: 0.1 to 1000)"
            ));
        }
        match &spec {
            SourceSpec::Sim | SourceSpec::Gst(_) if self.rate_hz.is_some() => {
                return Err(format!(
                    "--rate-hz does not apply to --source {spec} (allowed with file: and v4l2: sources)"
                ));
            }
            SourceSpec::File(_) => {}
            _ if self.looping => {
                return Err(format!(
                    "--loop does not apply to --source {spec} (allowed with file: sources)"
                ));
            }
            _ => {}
        }
        Ok(Source {
            camera: self
                .camera
                .clone()
                .unwrap_or_else(|| cfg.camera_path(config_dir)),
            undistort: self.undistort || cfg.undistort,
            rate_hz: self.rate_hz,
            looping: self.looping,
            spec,
        })
    }
}

#[cfg(test)]
#[path = "config_test.rs"]
mod tests;
