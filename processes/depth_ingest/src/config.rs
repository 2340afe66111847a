//! The `[depth_ingest]` section of the stack file and the flags over it: where depth
//! frames come from, and what a source that does not record them is taken to have
//! (intrinsics, depth units, rate).

use std::path::Path;

use ipc_types::msg::Intrinsics;
use serde::Deserialize;
use stack_config::{Invalid, Validate};

use crate::source::{ALLOWED_SOURCES, DepthSourceSpec, RealSenseTarget};

/// depth-ingest's own keys.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DepthIngestConfig {
    /// Where depth frames come from, as `--source` takes it (empty: give `--source`).
    pub source: String,
    /// Intrinsics of the depth image, `[fx, fy, cx, cy]` px, for a source that does not
    /// record them (`file:`); a `.bag` carries its own.
    pub intrinsics: [f64; 4],
    /// Metres per depth unit for a source that does not record it (`file:`).
    pub depth_scale_m: f64,
    /// Playback rate, Hz, for a source that does not record it (`file:`).
    pub rate_hz: f64,
    /// The live stream asked of a camera (`v4l2:`, `realsense:any` or a serial number):
    /// `[width, height, fps]` (a D435: 640x480 or 848x480 at 6 to 90 Hz).
    pub mode: [u32; 3],
}

impl Default for DepthIngestConfig {
    fn default() -> Self {
        Self {
            source: String::new(),
            // A D435's depth stream at 640x480: fx = fy ~ 380 px.
            intrinsics: [380.0, 380.0, 320.0, 240.0],
            depth_scale_m: 0.001,
            rate_hz: 30.0,
            mode: [640, 480, 30],
        }
    }
}

fn positive(v: f64) -> bool {
    v.is_finite() && v > 0.0
}

impl Validate for DepthIngestConfig {
    fn validate(&self) -> Result<(), Invalid> {
        if !self.source.is_empty() {
            self.source.parse::<DepthSourceSpec>().map_err(|_| {
                Invalid::new(
                    "source",
                    format!(
                        "`{}` is not allowed (allowed: {ALLOWED_SOURCES})",
                        self.source
                    ),
                )
            })?;
        }
        if !self.intrinsics.iter().all(|v| positive(*v)) {
            return Err(Invalid::new(
                "intrinsics",
                "must be four positive numbers, [fx, fy, cx, cy] in px",
            ));
        }
        if !(positive(self.depth_scale_m) && self.depth_scale_m <= 1.0) {
            return Err(Invalid::new(
                "depth_scale_m",
                format!(
                    "{} is not allowed (allowed: above 0, at most 1 m per unit)",
                    self.depth_scale_m
                ),
            ));
        }
        if !(self.rate_hz.is_finite() && (0.1..=1000.0).contains(&self.rate_hz)) {
            return Err(Invalid::new(
                "rate_hz",
                format!("{} is not allowed (allowed: 0.1 to 1000)", self.rate_hz),
            ));
        }
        let [w, h, fps] = self.mode;
        if !((1..=4096).contains(&w) && (1..=4096).contains(&h) && (1..=1000).contains(&fps)) {
            return Err(Invalid::new(
                "mode",
                format!(
                    "{:?} is not allowed (allowed: [width, height, fps], 1 to 4096 px and 1 to 1000 Hz)",
                    self.mode
                ),
            ));
        }
        Ok(())
    }
}

/// depth-ingest's source flags; each overrides its `[depth_ingest]` key.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct SourceFlags {
    /// Where depth frames come from: `file:<directory of 16-bit PNGs>`, `bag:<RealSense
    /// .bag>`, `v4l2:/dev/videoN` (Z16), or with the `realsense` build `realsense:any`, `realsense:<serial>`,
    /// `realsense:<file.bag>` [default: [depth_ingest] source].
    #[arg(long)]
    pub source: Option<String>,
    /// Playback rate, Hz [default: a bag's recorded rate; [depth_ingest] rate_hz for
    /// file:].
    #[arg(long)]
    pub rate_hz: Option<f64>,
    /// Start again from the beginning at the end instead of exiting.
    #[arg(long = "loop")]
    pub looping: bool,
}

/// The flags and the section, resolved and checked.
#[derive(Debug, Clone, PartialEq)]
pub struct Source {
    /// Where depth frames come from.
    pub spec: DepthSourceSpec,
    /// `--rate-hz`, when given.
    pub rate_hz: Option<f64>,
    /// Play again at the end.
    pub looping: bool,
    /// What a source that does not record them is taken to have.
    pub intrinsics: Intrinsics,
    /// Metres per depth unit, likewise.
    pub depth_scale_m: f64,
    /// The section's rate, likewise.
    pub default_rate_hz: f64,
    /// The live stream asked of a camera: width, height px, fps.
    pub mode: [u32; 3],
}

impl SourceFlags {
    /// Resolves the flags over `cfg` (a relative path against `config_dir` when the
    /// source came from the file). The error is the line to print.
    pub fn resolve(&self, cfg: &DepthIngestConfig, config_dir: &Path) -> Result<Source, String> {
        let (text, from_file) = match &self.source {
            Some(s) => (s.clone(), false),
            None => (cfg.source.clone(), true),
        };
        if text.is_empty() {
            return Err(format!(
                "no depth source: give --source or [depth_ingest] source (allowed: {ALLOWED_SOURCES})"
            ));
        }
        let mut spec: DepthSourceSpec = text
            .parse()
            .map_err(|e: crate::UnknownSource| e.to_string())?;
        if from_file {
            spec = match spec {
                DepthSourceSpec::File(p) => DepthSourceSpec::File(stack_config::resolve_path(
                    config_dir,
                    &p.to_string_lossy(),
                )),
                DepthSourceSpec::Bag(p) => DepthSourceSpec::Bag(stack_config::resolve_path(
                    config_dir,
                    &p.to_string_lossy(),
                )),
                DepthSourceSpec::RealSense(RealSenseTarget::Recording(p)) => {
                    DepthSourceSpec::RealSense(RealSenseTarget::Recording(
                        stack_config::resolve_path(config_dir, &p.to_string_lossy()),
                    ))
                }
                live @ (DepthSourceSpec::RealSense(_) | DepthSourceSpec::V4l2(_)) => live,
            };
        }
        if let Some(r) = self.rate_hz
            && !(r.is_finite() && (0.1..=1000.0).contains(&r))
        {
            return Err(format!(
                "--rate-hz {r} is not allowed (allowed: 0.1 to 1000)"
            ));
        }
        let [fx, fy, cx, cy] = cfg.intrinsics;
        Ok(Source {
            spec,
            rate_hz: self.rate_hz,
            looping: self.looping,
            intrinsics: Intrinsics { fx, fy, cx, cy },
            depth_scale_m: cfg.depth_scale_m,
            default_rate_hz: cfg.rate_hz,
            mode: cfg.mode,
        })
    }
}
