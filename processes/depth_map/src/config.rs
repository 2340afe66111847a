//! The `[depth_map]` section of the stack configuration.

use ipc_types::services;
use nalgebra::Isometry3;
use serde::Deserialize;
use stack_config::{Invalid, Validate, check_range};

use crate::map::{LogOdds, MapSettings, RaySettings};

/// Which topic the depth frames come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Input {
    /// The simulator's depth camera, `landing/sim/depth`.
    Sim,
    /// A depth-ingest stage's output, `landing/depth/frame` (same payload).
    DepthFrame,
}

impl Input {
    /// The service name to subscribe to.
    pub fn service(self) -> &'static str {
        match self {
            Self::Sim => services::SIM_DEPTH,
            Self::DepthFrame => services::DEPTH_FRAME,
        }
    }

    /// The topic (`ipc_types::topics`) it names.
    pub fn topic(self) -> &'static str {
        match self {
            Self::Sim => ipc_types::topics::SIM_DEPTH,
            Self::DepthFrame => ipc_types::topics::DEPTH_FRAME,
        }
    }

    /// Parses the `--input` flag's text.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "sim" => Some(Self::Sim),
            "depth-frame" => Some(Self::DepthFrame),
            _ => None,
        }
    }
}

/// What depth-map reads from `landing.toml`. Every key has a default (the simulator's
/// forward camera and EGO-Planner's mapping parameters).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DepthMapConfig {
    /// Where frames come from: `sim` or `depth-frame`.
    pub input: Input,
    /// Depth frame width, px; frames of another size are counted and skipped.
    pub width: u32,
    /// Depth frame height, px.
    pub height: u32,
    /// Optical centre of the depth camera in the body frame (FLU), m.
    pub camera_position_in_body_m: [f64; 3],
    /// Mount rotation of the forward camera, deg: roll about body x, pitch about body y
    /// (positive looks down), yaw about body z (positive looks left). Zero: the optical
    /// axis along body x, image right = body -y, image down = body -z.
    pub camera_rpy_deg: [f64; 3],
    /// A ray through every k-th pixel of every k-th row.
    pub pixel_step: u32,
    /// Rays are cut at this length, m.
    pub max_ray_m: f64,
    /// Returns nearer than this are ignored, m.
    pub min_depth_m: f64,
    /// A pixel with no return (0) frees its ray up to `max_ray_m`.
    pub no_return_as_free: bool,
    /// A ray cast back from its end stops after this many consecutive cells already
    /// walked by another ray of the frame (0: never; exact but slower).
    pub shared_run_to_stop: u32,
    /// Cell edge, m.
    pub resolution_m: f64,
    /// Window size (x, y, z), m.
    pub size_m: [f64; 3],
    /// The window's bottom never goes below this height (world z), m.
    pub floor_z_m: f64,
    /// The window follows the vehicle once it is this far from its centre, m.
    pub recenter_threshold_m: f64,
    /// Inflation radius, m.
    pub inflation_m: f64,
    /// Log-odds added by a hit.
    pub log_odds_hit: f64,
    /// Log-odds added by a miss (negative).
    pub log_odds_miss: f64,
    /// Lower clamp of the log-odds.
    pub log_odds_min: f64,
    /// Upper clamp of the log-odds.
    pub log_odds_max: f64,
    /// Occupied above this log-odds.
    pub log_odds_occupied: f64,
    /// A frame whose capture time is newer than the newest vehicle state by more than
    /// this is counted and skipped, ms.
    pub max_state_age_ms: u64,
    /// The map is published after every frame and at least this often, ms.
    pub publish_period_ms: u64,
}

impl Default for DepthMapConfig {
    fn default() -> Self {
        let m = MapSettings::default();
        Self {
            input: Input::Sim,
            width: m.rays.width,
            height: m.rays.height,
            camera_position_in_body_m: [0.1, 0.0, 0.1],
            camera_rpy_deg: [0.0; 3],
            pixel_step: m.rays.pixel_step,
            max_ray_m: m.rays.max_ray_m,
            min_depth_m: m.rays.min_depth_m,
            no_return_as_free: m.rays.no_return_as_free,
            shared_run_to_stop: m.rays.shared_run_to_stop,
            resolution_m: m.resolution_m,
            size_m: m.size_m,
            floor_z_m: m.floor_z_m,
            recenter_threshold_m: m.recenter_threshold_m,
            inflation_m: m.inflation_m,
            log_odds_hit: m.log_odds.hit,
            log_odds_miss: m.log_odds.miss,
            log_odds_min: m.log_odds.min,
            log_odds_max: m.log_odds.max,
            log_odds_occupied: m.log_odds.occupied,
            max_state_age_ms: 50,
            publish_period_ms: 100,
        }
    }
}

impl DepthMapConfig {
    /// The map settings these values give.
    pub fn map_settings(&self) -> MapSettings {
        MapSettings {
            resolution_m: self.resolution_m,
            size_m: self.size_m,
            floor_z_m: self.floor_z_m,
            recenter_threshold_m: self.recenter_threshold_m,
            inflation_m: self.inflation_m,
            log_odds: LogOdds {
                hit: self.log_odds_hit,
                miss: self.log_odds_miss,
                min: self.log_odds_min,
                max: self.log_odds_max,
                occupied: self.log_odds_occupied,
            },
            rays: RaySettings {
                width: self.width,
                height: self.height,
                pixel_step: self.pixel_step,
                max_ray_m: self.max_ray_m,
                min_depth_m: self.min_depth_m,
                no_return_as_free: self.no_return_as_free,
                shared_run_to_stop: self.shared_run_to_stop,
            },
        }
    }

    /// The camera mount these values give.
    pub fn body_from_camera(&self) -> Isometry3<f64> {
        crate::body_from_forward_camera(self.camera_position_in_body_m, self.camera_rpy_deg)
    }
}

impl Validate for DepthMapConfig {
    fn validate(&self) -> Result<(), Invalid> {
        check_range("width", self.width, 16, 4096)?;
        check_range("height", self.height, 16, 4096)?;
        for (i, v) in self.camera_position_in_body_m.iter().enumerate() {
            check_range(&format!("camera_position_in_body_m[{i}]"), *v, -2.0, 2.0)?;
        }
        for (i, v) in self.camera_rpy_deg.iter().enumerate() {
            check_range(&format!("camera_rpy_deg[{i}]"), *v, -180.0, 180.0)?;
        }
        check_range("pixel_step", self.pixel_step, 1, 16)?;
        check_range("shared_run_to_stop", self.shared_run_to_stop, 0, 64)?;
        check_range("resolution_m", self.resolution_m, 0.02, 2.0)?;
        check_range("max_ray_m", self.max_ray_m, 2.0 * self.resolution_m, 50.0)?;
        check_range("min_depth_m", self.min_depth_m, 0.0, self.max_ray_m / 2.0)?;
        for (i, v) in self.size_m.iter().enumerate() {
            check_range(&format!("size_m[{i}]"), *v, 4.0 * self.resolution_m, 200.0)?;
        }
        let cells: f64 = self
            .size_m
            .iter()
            .map(|s| (s / self.resolution_m).round())
            .product();
        if cells > crate::map::MAX_CELLS as f64 {
            return Err(Invalid::new(
                "size_m",
                format!(
                    "{cells} cells at resolution_m {} (allowed: at most {})",
                    self.resolution_m,
                    crate::map::MAX_CELLS
                ),
            ));
        }
        if !(self.floor_z_m == f64::NEG_INFINITY) {
            check_range("floor_z_m", self.floor_z_m, -1000.0, 1000.0)?;
        }
        let half = self.size_m.iter().fold(f64::INFINITY, |a, b| a.min(*b)) / 2.0;
        check_range(
            "recenter_threshold_m",
            self.recenter_threshold_m,
            0.0,
            half - self.resolution_m,
        )?;
        check_range(
            "inflation_m",
            self.inflation_m,
            0.0,
            (8.0 * self.resolution_m).min(2.0),
        )?;
        check_range("log_odds_hit", self.log_odds_hit, 0.01, 10.0)?;
        check_range("log_odds_miss", self.log_odds_miss, -10.0, -0.01)?;
        check_range("log_odds_min", self.log_odds_min, -30.0, -0.01)?;
        check_range("log_odds_max", self.log_odds_max, 0.01, 30.0)?;
        check_range(
            "log_odds_occupied",
            self.log_odds_occupied,
            self.log_odds_min + 0.001,
            self.log_odds_max - 0.001,
        )?;
        check_range("max_state_age_ms", self.max_state_age_ms, 0, 1000)?;
        check_range("publish_period_ms", self.publish_period_ms, 10, 1000)?;
        Ok(())
    }
}

#[cfg(test)]
#[path = "config_test.rs"]
mod tests;
