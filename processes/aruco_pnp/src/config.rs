//! The `[aruco_pnp]` section of the stack configuration.

use serde::Deserialize;
use stack_config::{Invalid, Validate, check_range};

use crate::{DetectSettings, EstimatorSettings, PoseSettings};

/// What aruco-pnp reads from `landing.toml`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ArucoConfig {
    /// Camera calibration (OpenCV YAML), relative to the deploy `config/` directory
    /// unless absolute.
    pub camera: String,
    /// Pad layout, relative to the deploy `config/` directory unless absolute.
    pub pad: String,
    /// Optical centre of the down camera in the body frame (FLU), m.
    pub camera_position_in_body_m: [f64; 3],
    /// Above this joint RMS reprojection error, the marker without which the others fit
    /// best is dropped as an outlier, px.
    pub outlier_px: f64,
    /// The search region grows by this fraction of its size on every side.
    pub region_margin: f64,
    /// Adaptive threshold window, px (odd, 3 to 51).
    pub threshold_window_px: i32,
    /// A frame newer than the newest vehicle state by more than this gets no
    /// world pose, ms.
    pub max_state_age_ms: u64,
    /// How far from level the pad may be, 1 sigma, deg: the soft prior the vehicle
    /// attitude gives the pose (docs/perception.md). 0 turns it off (a pad that pitches
    /// and rolls a lot on its vehicle).
    pub level_prior_deg: f64,
}

impl Default for ArucoConfig {
    fn default() -> Self {
        let s = EstimatorSettings::default();
        Self {
            camera: "camera_down_640x480.yaml".into(),
            pad: "pad.toml".into(),
            camera_position_in_body_m: [0.05, 0.0, -0.05],
            outlier_px: s.pose.outlier_px,
            region_margin: s.region_margin,
            threshold_window_px: s.detect.threshold_window_px,
            max_state_age_ms: 50,
            level_prior_deg: s.level_sigma_rad.to_degrees(),
        }
    }
}

impl ArucoConfig {
    /// The estimator settings these values give.
    pub fn settings(&self) -> EstimatorSettings {
        let d = EstimatorSettings::default();
        EstimatorSettings {
            detect: DetectSettings {
                threshold_window_px: self.threshold_window_px | 1,
                ..d.detect
            },
            pose: PoseSettings {
                outlier_px: self.outlier_px,
                ..d.pose
            },
            region_margin: self.region_margin,
            level_sigma_rad: self.level_prior_deg.to_radians(),
            ..d
        }
    }
}

impl Validate for ArucoConfig {
    fn validate(&self) -> Result<(), Invalid> {
        for (i, v) in self.camera_position_in_body_m.iter().enumerate() {
            check_range(&format!("camera_position_in_body_m[{i}]"), *v, -2.0, 2.0)?;
        }
        check_range("outlier_px", self.outlier_px, 0.1, 50.0)?;
        check_range("region_margin", self.region_margin, 0.0, 5.0)?;
        check_range("threshold_window_px", self.threshold_window_px, 3, 51)?;
        check_range("max_state_age_ms", self.max_state_age_ms, 0, 1000)?;
        check_range("level_prior_deg", self.level_prior_deg, 0.0, 30.0)?;
        if self.camera.is_empty() || self.pad.is_empty() {
            return Err(Invalid::new("camera", "camera and pad must name files"));
        }
        Ok(())
    }
}
