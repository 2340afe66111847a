//! Scenarios: one TOML file per experiment in `deploy/scenarios/`, naming the airframe,
//! the mission's preset point, the ground vehicle's route and speed, wind, obstacles and
//! the sensors. Unknown keys and impossible values are errors that name the key.
//!
//! The `[mission]` table is what an operator would give the vehicle (where to wait for
//! the pad, when to commit to touchdown); everything else is the world, which only the
//! simulator and the evaluator know.

use std::path::{Path, PathBuf};

use serde::Deserialize;
use stack_config::{self as config, ConfigError, Invalid, Validate, check_range};

use crate::autopilot_params::AutopilotParams;
use crate::camera::{CameraErrors, DownCameraParams, MountErrors};
use crate::depth::DepthCameraParams;
use crate::estimator_noise::EstimatorNoiseParams;
use crate::geometry::Aabb;
use crate::ground_vehicle::{GroundVehicle, GroundVehicleParams};
use crate::params::ParamError;
use crate::px4::commander::Px4Params;
use crate::px4::commander::{AutopilotClock, Faults};
use crate::quadrotor::AirframeParams;
use crate::rng::Pcg32;
use crate::wind::WindParams;
use crate::world::{CrashThresholds, ROTOR_RADIUS_FRACTION, WorldParams};

/// Names of the scenarios shipped in `deploy/scenarios/`.
pub const SHIPPED: &[&str] = &[
    "paper-sim",
    "indoor-static",
    "indoor-moving",
    "outdoor-1",
    "outdoor-2",
    "obstacle-demo",
    "paper-braking",
    "paper-lane-change",
    "paper-turn",
    "highspeed-10",
    "highspeed-20",
    "highspeed-30",
    "highspeed-50",
    "highspeed-30-curve",
];

/// What the operator tells the vehicle: the mission, not the world.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MissionParams {
    /// Where to climb to and wait for the pad, world ENU, m (the paper's preset point).
    pub preset_m: [f64; 3],
    /// Height above the pad below which the vehicle commits to touchdown, m (paper: 0.6).
    #[serde(default = "default_commit_height")]
    pub commit_height_m: f64,
}

fn default_commit_height() -> f64 {
    0.6
}

/// The downward camera of a scenario.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CameraParams {
    /// OpenCV calibration YAML, relative to `deploy/config/` unless absolute.
    pub calibration: String,
    /// Frames per second.
    pub rate_hz: f64,
    /// Mount, exposure, latency, noise, pixel format.
    pub sensor: DownCameraParams,
    /// How far the true camera is from the calibration file and the nominal mount the
    /// pipeline reads, drawn per seed (defaults: a real calibrated camera).
    pub errors: CameraErrors,
}

impl Default for CameraParams {
    fn default() -> Self {
        Self {
            calibration: "camera_down_640x480.yaml".into(),
            rate_hz: 30.0,
            sensor: DownCameraParams::default(),
            errors: CameraErrors::default(),
        }
    }
}

/// The forward depth camera of a scenario.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DepthParams {
    /// Frames per second.
    pub rate_hz: f64,
    /// Resolution, field of view, range, noise, mount.
    pub sensor: DepthCameraParams,
    /// How far the true mount is from `sensor`'s (which the pipeline reads), per seed.
    pub mount_errors: MountErrors,
}

impl Default for DepthParams {
    fn default() -> Self {
        Self {
            rate_hz: 30.0,
            sensor: DepthCameraParams::default(),
            mount_errors: MountErrors::default(),
        }
    }
}

/// A scenario as written in its TOML file.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Short name (the file's stem).
    pub name: String,
    /// One line for people.
    pub description: String,
    /// Seed of every random process (noise, gusts); `--seed` overrides it.
    #[serde(default = "default_seed")]
    pub seed: u64,
    /// Simulated time after which the run is a timeout, s.
    pub duration_s: f64,
    /// Airframe profile: a name from `deploy/config/airframes/` (`p450`, `racer`).
    pub airframe: String,
    /// The operator's mission.
    pub mission: MissionParams,
    /// The ground vehicle carrying the pad.
    pub ground_vehicle: GroundVehicleParams,
    /// Wind (calm by default).
    #[serde(default = "calm")]
    pub wind: WindParams,
    /// Noise of the autopilot's state estimate.
    #[serde(default)]
    pub estimator_noise: EstimatorNoiseParams,
    /// Box obstacles.
    #[serde(default)]
    pub obstacles: Vec<Aabb>,
    /// Crash criteria.
    #[serde(default)]
    pub crash: CrashThresholds,
    /// The downward camera.
    #[serde(default)]
    pub camera: CameraParams,
    /// The forward depth camera.
    #[serde(default)]
    pub depth: DepthParams,
    /// Faults the simulated autopilot injects (none by default).
    #[serde(default)]
    pub faults: Faults,
    /// How far the flown vehicle is from its airframe file, drawn per seed.
    #[serde(default)]
    pub airframe_errors: AirframeErrors,
    /// The autopilot's telemetry link: its delay, drawn per seed, and jitter.
    #[serde(default)]
    pub telemetry_link: TelemetryLink,
    /// The autopilot's own clock: its rate against true time, its boot offset, a jump
    /// (keeps time by default).
    #[serde(default)]
    pub autopilot_clock: AutopilotClock,
    /// What else a seed varies of the world: when and where the pad vehicle starts, and
    /// where the vehicle takes off from.
    #[serde(default)]
    pub variation: Variation,
    /// The vehicle's visual-inertial odometry (for an autopilot that fuses it: real PX4
    /// through `sim --px4-sitl`).
    #[serde(default)]
    pub vio: crate::vio::VioParams,
    /// A GPS receiver for PX4 SITL (`sim --px4-sitl`): none by default, the missions are
    /// GPS-denied.
    #[serde(default)]
    pub gps: crate::hil::GpsParams,
}

/// What a flight-test engineer varies from one run to the next besides the weather and
/// the hardware: the pad vehicle's start (a driver never leaves at the same instant or
/// from the same spot) and the take-off point (a vehicle is never set down exactly on its
/// mark). Each is drawn per seed, uniform within +- its value.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Variation {
    /// The pad vehicle's start time, +- s (never before 0).
    pub start_delay_s: f64,
    /// Its route's start, +- m in x and in y.
    pub start_offset_m: f64,
    /// The take-off point, +- m in x and in y: the road, the pad vehicle and the
    /// obstacles move by the opposite in the vehicle's frame (its flight plan, the preset
    /// point, is relative to where it took off).
    pub takeoff_offset_m: f64,
}

impl Default for Variation {
    /// Half a second, 25 cm and 15 cm.
    fn default() -> Self {
        Self {
            start_delay_s: 0.5,
            start_offset_m: 0.25,
            takeoff_offset_m: 0.15,
        }
    }
}

impl Variation {
    /// No variation: every seed starts the world the same (tests that need that).
    pub fn none() -> Self {
        Self {
            start_delay_s: 0.0,
            start_offset_m: 0.0,
            takeoff_offset_m: 0.0,
        }
    }

    /// Checks every field; the error names it.
    pub fn validate(&self) -> Result<(), ParamError> {
        crate::params::in_range("variation.start_delay_s", self.start_delay_s, 0.0, 60.0)?;
        crate::params::in_range("variation.start_offset_m", self.start_offset_m, 0.0, 50.0)?;
        crate::params::in_range(
            "variation.takeoff_offset_m",
            self.takeoff_offset_m,
            0.0,
            10.0,
        )?;
        Ok(())
    }

    /// The draws for `seed`: (start delay change s, route offset m, take-off offset m).
    pub fn draw(&self, seed: u64) -> (f64, [f64; 2], [f64; 2]) {
        let mut rng = Pcg32::with_stream(seed.wrapping_add(VARIATION_SEED_OFFSET), 53);
        let mut u = |half: f64| half * (2.0 * rng.uniform() - 1.0);
        let delay = u(self.start_delay_s);
        let start = [u(self.start_offset_m), u(self.start_offset_m)];
        let takeoff = [u(self.takeoff_offset_m), u(self.takeoff_offset_m)];
        (delay, start, takeoff)
    }
}

/// Offset of the variation draw's seed from the run's seed (see [`MASS_SEED_OFFSET`]).
const VARIATION_SEED_OFFSET: u64 = 8;

/// How many draws [`LoadedScenario::variation`] tries before it keeps the scenario's start.
const VARIATION_DRAWS: u64 = 32;

/// The seed step between two draws of one run (far from any run's neighbour seed).
const VARIATION_REDRAW_STRIDE: u64 = 0x9E37_79B9_7F4A_7C15;

/// Clearance between a standing vehicle and the roof's edge or the body, m.
const STAND_MARGIN_M: f64 = 0.03;

/// The companion's view of the autopilot's clock: every MAVLink message the autopilot
/// sends reaches px4-link late by a per-run delay (serial framing, PX4's mavlink module
/// scheduling) plus per-message jitter, and px4-link stamps telemetry when it arrives, so
/// the pipeline's vehicle states are older than their stamps by that much.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TelemetryLink {
    /// Mean delay, ms.
    pub latency_ms: f64,
    /// Standard deviation of the per-run delay around the mean, ms.
    pub latency_spread_ms: f64,
    /// Standard deviation of each message's delay around the run's, ms.
    pub jitter_ms: f64,
}

impl Default for TelemetryLink {
    /// A 921600-baud serial link: 4 ms +- 2 ms per run, 1 ms jitter.
    fn default() -> Self {
        Self {
            latency_ms: 4.0,
            latency_spread_ms: 2.0,
            jitter_ms: 1.0,
        }
    }
}

impl TelemetryLink {
    /// Checks every field; the error names it.
    pub fn validate(&self) -> Result<(), ParamError> {
        crate::params::in_range("telemetry_link.latency_ms", self.latency_ms, 0.0, 500.0)?;
        crate::params::in_range(
            "telemetry_link.latency_spread_ms",
            self.latency_spread_ms,
            0.0,
            100.0,
        )?;
        crate::params::in_range("telemetry_link.jitter_ms", self.jitter_ms, 0.0, 100.0)?;
        Ok(())
    }
}

/// Offset of the mass draw's seed from the run's seed (noise uses the seed itself, wind
/// +1, the driver +2), so no two random processes of a run share a generator.
const MASS_SEED_OFFSET: u64 = 3;

/// Stream of the mass draw's generator (no other consumer uses it).
const MASS_STREAM: u64 = 31;

/// How far the vehicle that flies is from its airframe file, drawn once per seed: the
/// autopilot is tuned from the file (its MPC_THR_HOVER is the file's hover thrust), the
/// physics flies the drawn vehicle, as a real vehicle's battery and payload make it
/// heavier or lighter than its nominal build and PX4 has to estimate its hover thrust.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AirframeErrors {
    /// Half-width of the true mass's uniform spread around the file's, as a fraction:
    /// 0.1 draws it evenly within +-10 %; 0 flies the file's mass.
    pub mass_spread: f64,
}

impl Default for AirframeErrors {
    /// The true mass within +-10 % of the file's (a battery size, a payload).
    fn default() -> Self {
        Self { mass_spread: 0.1 }
    }
}

impl AirframeErrors {
    /// The file's airframe exactly (tests that need the nominal vehicle).
    pub fn none() -> Self {
        Self { mass_spread: 0.0 }
    }

    /// Checks the spread: at most 30 %, beyond which the file no longer describes the
    /// vehicle (PX4's HTE_THR_RANGE would not reach its hover thrust either).
    pub fn validate(&self) -> Result<(), ParamError> {
        crate::params::in_range("mass_spread", self.mass_spread, 0.0, 0.3)
    }

    /// The true mass over the nominal one for `seed`: uniform in
    /// `[1 - mass_spread, 1 + mass_spread)`, the same for the same seed.
    pub fn draw_mass_factor(&self, seed: u64) -> f64 {
        let mut rng = Pcg32::with_stream(seed.wrapping_add(MASS_SEED_OFFSET), MASS_STREAM);
        1.0 + self.mass_spread * (2.0 * rng.uniform() - 1.0)
    }

    /// The airframe that flies for `seed`: `nominal` with the drawn mass. The inertia
    /// is scaled by the same factor (the extra or missing mass is spread like the
    /// frame's, so the radius of gyration is kept); the rotors, motors and drag are
    /// the file's.
    pub fn true_airframe(&self, nominal: &AirframeParams, seed: u64) -> AirframeParams {
        let k = self.draw_mass_factor(seed);
        AirframeParams {
            mass_kg: nominal.mass_kg * k,
            inertia_diag_kg_m2: nominal.inertia_diag_kg_m2.map(|j| j * k),
            inertia_products_kg_m2: nominal.inertia_products_kg_m2.map(|j| j * k),
            ..nominal.clone()
        }
    }
}

fn default_seed() -> u64 {
    1
}

fn calm() -> WindParams {
    WindParams::constant(nalgebra::Vector3::zeros())
}

fn from_param(section: &str, e: ParamError) -> Invalid {
    Invalid::new(
        format!("{section}.{}", e.field),
        format!("{} is not allowed (allowed: {})", e.value, e.allowed),
    )
}

impl Validate for Scenario {
    fn validate(&self) -> Result<(), Invalid> {
        if self.name.is_empty() {
            return Err(Invalid::new("name", "must not be empty"));
        }
        check_range("seed", self.seed, 0, u64::MAX)?;
        check_range("duration_s", self.duration_s, 1.0, 3600.0)?;
        for (i, v) in self.mission.preset_m.iter().enumerate() {
            check_range(&format!("mission.preset_m[{i}]"), *v, -1000.0, 1000.0)?;
        }
        check_range("mission.preset_m[2]", self.mission.preset_m[2], 0.3, 100.0)?;
        check_range(
            "mission.commit_height_m",
            self.mission.commit_height_m,
            0.05,
            3.0,
        )?;
        self.ground_vehicle
            .validate()
            .map_err(|e| from_param("ground_vehicle", e))?;
        self.wind.validate().map_err(|e| from_param("wind", e))?;
        self.estimator_noise
            .validate()
            .map_err(|e| from_param("estimator_noise", e))?;
        self.crash.validate().map_err(|e| from_param("crash", e))?;
        self.telemetry_link
            .validate()
            .map_err(|e| from_param("scenario", e))?;
        self.autopilot_clock
            .validate()
            .map_err(|e| from_param("scenario", e))?;
        self.variation
            .validate()
            .map_err(|e| from_param("scenario", e))?;
        self.vio.validate().map_err(|e| from_param("scenario", e))?;
        self.gps.validate().map_err(|e| from_param("scenario", e))?;
        for (i, b) in self.obstacles.iter().enumerate() {
            for k in 0..3 {
                let ok =
                    b.min_m[k].is_finite() && b.max_m[k].is_finite() && b.min_m[k] < b.max_m[k];
                if !ok {
                    return Err(Invalid::new(
                        format!("obstacles[{i}]"),
                        "min_m must be below max_m on every axis, all finite".to_string(),
                    ));
                }
            }
        }
        check_range("camera.rate_hz", self.camera.rate_hz, 1.0, 240.0)?;
        self.camera
            .sensor
            .validate()
            .map_err(|e| from_param("camera.sensor", e))?;
        self.camera
            .errors
            .validate()
            .map_err(|e| from_param("camera.errors", e))?;
        check_range("depth.rate_hz", self.depth.rate_hz, 1.0, 90.0)?;
        self.depth
            .sensor
            .validate()
            .map_err(|e| from_param("depth.sensor", e))?;
        self.depth
            .mount_errors
            .validate()
            .map_err(|e| from_param("depth", e))?;
        self.faults
            .validate()
            .map_err(|e| from_param("faults", e))?;
        self.airframe_errors
            .validate()
            .map_err(|e| from_param("airframe_errors", e))?;
        Ok(())
    }
}

/// Why a scenario could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// Neither a shipped name nor a readable file.
    #[error(
        "unknown scenario `{0}` (allowed: a file path, or one of: {list})",
        list = SHIPPED.join(", ")
    )]
    Unknown(String),
    /// The scenario file itself is wrong.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The airframe profile is wrong.
    #[error("scenario {scenario}: airframe `{name}`: {message}")]
    Airframe {
        /// The scenario file.
        scenario: PathBuf,
        /// Profile name.
        name: String,
        /// What is wrong.
        message: String,
    },
}

/// An airframe profile file: the physical `[airframe]`, the PX4 `[limits]` its
/// autopilot flies with (the other gains are PX4's defaults tuned for the airframe), and
/// the `[px4]` parameters set on its autopilot (commander, failsafes, SIH home); absent
/// ones keep PX4 v1.16's defaults.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct AirframeFile {
    airframe: AirframeParams,
    #[serde(default)]
    limits: Limits,
    #[serde(default)]
    px4: Px4Params,
    #[serde(default)]
    touchdown: TouchdownLimits,
    #[serde(default)]
    sensors: crate::hil::HilSensorParams,
}

/// What the referee accepts at a touchdown, relative to the surface touched. Written
/// once: these defaults, which an airframe's `[touchdown]` may tighten, never loosen.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TouchdownLimits {
    /// Speed along the surface normal, m/s.
    pub max_vertical_speed_mps: f64,
    /// Speed along the surface, m/s.
    pub max_horizontal_speed_mps: f64,
    /// Angle between body up and the surface normal, deg.
    pub max_tilt_deg: f64,
}

impl Default for TouchdownLimits {
    /// 1.0 m/s down, 0.5 m/s sideways, 15 deg.
    fn default() -> Self {
        Self {
            max_vertical_speed_mps: 1.0,
            max_horizontal_speed_mps: 0.5,
            max_tilt_deg: 15.0,
        }
    }
}

impl TouchdownLimits {
    /// Each limit is positive and no looser than the default.
    pub fn validate(&self) -> Result<(), ParamError> {
        let d = Self::default();
        for (field, v, max) in [
            (
                "max_vertical_speed_mps",
                self.max_vertical_speed_mps,
                d.max_vertical_speed_mps,
            ),
            (
                "max_horizontal_speed_mps",
                self.max_horizontal_speed_mps,
                d.max_horizontal_speed_mps,
            ),
            ("max_tilt_deg", self.max_tilt_deg, d.max_tilt_deg),
        ] {
            if !(v.is_finite() && v > 0.0 && v <= max) {
                return Err(ParamError::new(
                    field,
                    v,
                    format!(
                        "must be > 0 and <= {max} (an airframe may tighten the referee's limits, not loosen them)"
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// PX4 speed, acceleration and tilt limits, and how the tilt is coupled to the vertical
/// acceleration; absent ones keep PX4's defaults.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, rename_all = "SCREAMING_SNAKE_CASE")]
pub struct Limits {
    /// Horizontal speed limit, m/s.
    pub mpc_xy_vel_max: Option<f64>,
    /// Climb speed limit, m/s.
    pub mpc_z_vel_max_up: Option<f64>,
    /// Descent speed limit, m/s.
    pub mpc_z_vel_max_dn: Option<f64>,
    /// Horizontal acceleration limit, m/s^2.
    pub mpc_acc_hor_max: Option<f64>,
    /// Upward acceleration limit, m/s^2.
    pub mpc_acc_up_max: Option<f64>,
    /// Downward acceleration limit, m/s^2.
    pub mpc_acc_down_max: Option<f64>,
    /// Tilt limit in flight, deg.
    pub mpc_tiltmax_air: Option<f64>,
    /// The tilt from the whole acceleration (0, the simulator's default and what the
    /// stack asks for) or against gravity alone (1, PX4's default): decoupled, a
    /// descent's downward acceleration takes horizontal thrust away, and in wind the
    /// vehicle drifts downwind as it drops onto the pad.
    pub mpc_acc_decouple: Option<u8>,
}

impl Limits {
    fn apply(&self, a: &mut AutopilotParams) {
        let set = |dst: &mut f64, v: Option<f64>| {
            if let Some(v) = v {
                *dst = v;
            }
        };
        set(&mut a.mpc_xy_vel_max, self.mpc_xy_vel_max);
        set(&mut a.mpc_z_vel_max_up, self.mpc_z_vel_max_up);
        set(&mut a.mpc_z_vel_max_dn, self.mpc_z_vel_max_dn);
        set(&mut a.mpc_acc_hor_max, self.mpc_acc_hor_max);
        set(&mut a.mpc_acc_up_max, self.mpc_acc_up_max);
        set(&mut a.mpc_acc_down_max, self.mpc_acc_down_max);
        set(&mut a.mpc_tiltmax_air, self.mpc_tiltmax_air);
        if let Some(v) = self.mpc_acc_decouple {
            a.mpc_acc_decouple = v;
        }
    }
}

impl Validate for AirframeFile {
    fn validate(&self) -> Result<(), Invalid> {
        self.airframe
            .validate()
            .map_err(|e| from_param("airframe", e))?;
        let mut a = AutopilotParams::tuned_for(&self.airframe);
        self.limits.apply(&mut a);
        a.validate().map_err(|e| from_param("limits", e))?;
        self.touchdown
            .validate()
            .map_err(|e| from_param("touchdown", e))?;
        self.sensors
            .validate()
            .map_err(|e| from_param("sensors", e))?;
        self.px4.validate().map_err(|e| from_param("px4", e))
    }
}

/// A scenario with its airframe resolved: everything the simulator needs.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedScenario {
    /// The scenario as written.
    pub scenario: Scenario,
    /// Where it was read from.
    pub path: PathBuf,
    /// The airframe file's (nominal) parameters, which the autopilot is tuned for.
    pub airframe: AirframeParams,
    /// The autopilot for this airframe (PX4 defaults tuned for it, with its limits).
    pub autopilot: AutopilotParams,
    /// The PX4 parameters of its commander (`[px4]`).
    pub px4: Px4Params,
    /// The referee's touchdown limits for this airframe (`[touchdown]`).
    pub touchdown: TouchdownLimits,
    /// Its IMU, magnetometer and barometer as PX4 SITL reads them (`[sensors]`).
    pub sensors: crate::hil::HilSensorParams,
    /// `deploy/config/` (calibration files are resolved against it).
    pub config_dir: PathBuf,
}

impl LoadedScenario {
    /// The world this scenario describes, with `seed` driving every random process:
    /// the physics flies [`Self::true_airframe`], the autopilot stays tuned for the file.
    pub fn world_params(&self, seed: u64) -> WorldParams {
        let s = &self.scenario;
        let mut noise = s.estimator_noise.clone();
        noise.seed = seed;
        let mut wind = s.wind.clone();
        wind.seed = seed.wrapping_add(1);
        let mut ground_vehicle = s.ground_vehicle.clone();
        if let Some(d) = ground_vehicle.driver.as_mut() {
            d.seed = seed.wrapping_add(2);
        }
        let (delay, start, takeoff) = self.variation(seed);
        ground_vehicle.start_delay_s = (ground_vehicle.start_delay_s + delay).max(0.0);
        ground_vehicle.offset_m = [start[0] - takeoff[0], start[1] - takeoff[1]];
        let obstacles = self.obstacles(seed);
        WorldParams {
            airframe: self.true_airframe(seed),
            autopilot: Some(self.autopilot.clone()),
            estimator_noise: noise,
            wind,
            ground_vehicle: Some(ground_vehicle),
            obstacles,
            crash: s.crash.clone(),
            initial_position_m: [0.0; 3],
            initial_yaw_rad: 0.0,
        }
    }

    /// The `[variation]` draws for `seed` (start delay change s, route offset m, take-off
    /// offset m), redrawn until the vehicle can stand where it takes off: wholly on the
    /// pad vehicle's roof or wholly clear of its body, as an engineer sets it down. A
    /// scenario that takes off from the roof (the indoor ones) would otherwise put a skid
    /// over the roof's edge and a rotor into the body. After [`VARIATION_DRAWS`] draws
    /// that all fail, none: the scenario's own start.
    pub fn variation(&self, seed: u64) -> (f64, [f64; 2], [f64; 2]) {
        let v = &self.scenario.variation;
        (0..VARIATION_DRAWS)
            .map(|k| v.draw(seed.wrapping_add(k.wrapping_mul(VARIATION_REDRAW_STRIDE))))
            .find(|&(_, start, takeoff)| self.can_take_off_with(start, takeoff))
            .unwrap_or((0.0, [0.0; 2], [0.0; 2]))
    }

    /// True if the vehicle, at the origin, stands wholly on the roof or wholly clear of
    /// the body of the pad vehicle started `start` m off its route and moved by the
    /// opposite of `takeoff`.
    fn can_take_off_with(&self, start: [f64; 2], takeoff: [f64; 2]) -> bool {
        let mut params = self.scenario.ground_vehicle.clone();
        params.offset_m = [start[0] - takeoff[0], start[1] - takeoff[1]];
        let Ok(vehicle) = GroundVehicle::new(params) else {
            return true;
        };
        let pad = vehicle.state_at(0.0);
        let local = pad
            .world_from_pad
            .inverse_transform_point(&nalgebra::Point3::origin());
        let [hx, hy] = self.scenario.ground_vehicle.pad_half_size_m;
        // Inside the roof by this much (negative: outside it), m.
        let inside = (hx - local.x.abs()).min(hy - local.y.abs());
        let outside = ((local.x.abs() - hx).max(0.0)).hypot((local.y.abs() - hy).max(0.0));
        let air = &self.airframe;
        let feet = air
            .landing_gear_m
            .iter()
            .map(|f| f[0].hypot(f[1]))
            .fold(0.0, f64::max);
        let rotors = air.arm_length_m * (1.0 + ROTOR_RADIUS_FRACTION);
        inside >= feet + STAND_MARGIN_M || outside >= rotors + STAND_MARGIN_M
    }

    /// The obstacles where they are for `seed`: the scenario's, moved by the seed's
    /// take-off point (`[variation]`).
    pub fn obstacles(&self, seed: u64) -> Vec<Aabb> {
        let (_, _, takeoff) = self.variation(seed);
        self.scenario
            .obstacles
            .iter()
            .map(|b| Aabb {
                min_m: [b.min_m[0] - takeoff[0], b.min_m[1] - takeoff[1], b.min_m[2]],
                max_m: [b.max_m[0] - takeoff[0], b.max_m[1] - takeoff[1], b.max_m[2]],
            })
            .collect()
    }

    /// The vehicle that flies for `seed`: the airframe file with the seed's mass error
    /// (`[airframe_errors]`); [`Self::airframe`] stays what the autopilot was tuned for.
    pub fn true_airframe(&self, seed: u64) -> AirframeParams {
        self.scenario
            .airframe_errors
            .true_airframe(&self.airframe, seed)
    }

    /// The camera calibration file.
    pub fn calibration_path(&self) -> PathBuf {
        resolve(&self.config_dir, &self.scenario.camera.calibration)
    }

    /// The landing pad's layout (`deploy/config/pad.toml`).
    pub fn pad_path(&self) -> PathBuf {
        self.config_dir.join("pad.toml")
    }
}

fn resolve(dir: &Path, file: &str) -> PathBuf {
    let p = Path::new(file);
    if p.is_absolute() {
        p.to_path_buf()
    } else {
        dir.join(p)
    }
}

/// Loads a scenario by shipped name (from `deploy_dir/scenarios/NAME.toml`) or by path,
/// and resolves its airframe from `deploy_dir/config/airframes/`.
pub fn load(name_or_path: &str, deploy_dir: &Path) -> Result<LoadedScenario, ScenarioError> {
    let as_path = Path::new(name_or_path);
    let path = if as_path.is_file() {
        as_path.to_path_buf()
    } else if SHIPPED.contains(&name_or_path) {
        deploy_dir
            .join("scenarios")
            .join(format!("{name_or_path}.toml"))
    } else {
        return Err(ScenarioError::Unknown(name_or_path.to_string()));
    };
    let scenario: Scenario = config::load(&path)?;
    let config_dir = deploy_dir.join("config");
    let airframe = load_airframe(&config_dir, &scenario.airframe, &path)?;
    Ok(LoadedScenario::assemble(
        scenario, path, config_dir, airframe,
    ))
}

impl LoadedScenario {
    /// The scenario flown by `airframe`: the autopilot tuned for it, with its limits.
    fn assemble(
        scenario: Scenario,
        path: PathBuf,
        config_dir: PathBuf,
        airframe: AirframeFile,
    ) -> Self {
        let mut autopilot = AutopilotParams::tuned_for(&airframe.airframe);
        airframe.limits.apply(&mut autopilot);
        Self {
            scenario,
            path,
            autopilot,
            px4: airframe.px4,
            touchdown: airframe.touchdown,
            sensors: airframe.sensors,
            airframe: airframe.airframe,
            config_dir,
        }
    }

    /// The same world flown by another vehicle: the airframe profile `name` from
    /// `deploy/config/airframes/` in place of the scenario's (`sim --airframe iris` flies
    /// PX4's SITL vehicle through any scenario).
    pub fn with_airframe(self, name: &str) -> Result<Self, ScenarioError> {
        let airframe = load_airframe(&self.config_dir, name, &self.path)?;
        let mut scenario = self.scenario;
        scenario.airframe = name.to_string();
        Ok(Self::assemble(
            scenario,
            self.path,
            self.config_dir,
            airframe,
        ))
    }
}

/// The airframe profile `name` in `config_dir/airframes/`, for the scenario at `scenario`.
fn load_airframe(
    config_dir: &Path,
    name: &str,
    scenario: &Path,
) -> Result<AirframeFile, ScenarioError> {
    let airframe_path = config_dir.join("airframes").join(format!("{name}.toml"));
    if !name
        .bytes()
        .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_')
        || !airframe_path.is_file()
    {
        return Err(ScenarioError::Airframe {
            scenario: scenario.to_path_buf(),
            name: name.to_string(),
            message: format!(
                "no such profile in {} (allowed: p450, racer, iris)",
                config_dir.join("airframes").display()
            ),
        });
    }
    Ok(config::load(&airframe_path)?)
}

#[cfg(test)]
#[path = "scenario_test.rs"]
mod tests;
