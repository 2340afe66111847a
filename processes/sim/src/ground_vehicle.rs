//! The ground vehicle that carries the landing pad.
//!
//! The vehicle follows a path (straight line, circle, figure-eight, or a
//! polyline of waypoints) at a speed given by a profile (constant, sinusoidal
//! or piecewise linear), at most 60 km/h, after an optional start delay. The
//! pad sits on top at a configurable height and may pitch and roll.
//!
//! Everything is a pure function of time, so the pad is known exactly at any
//! instant (for the camera renderer, the physics and the evaluator alike)
//! without integrating anything.
//!
//! Pad frame: origin at the centre of the pad surface, x along the vehicle's
//! heading, y left, z up.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector2, Vector3};
use serde::Deserialize;

use crate::geometry::Obb;
use crate::params::{self, ParamError};
use crate::quadrotor::Surface;
use crate::rng::Pcg32;

/// The highest ground-vehicle speed the simulator accepts: 60 km/h, in m/s.
pub const MAX_GROUND_SPEED_M_S: f64 = 60.0 / 3.6;

/// Surface id of the pad in [`Surface`] (0 is the ground).
pub const PAD_SURFACE_ID: u32 = 1;

/// The shape of the route, in the world horizontal plane.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum PathParams {
    /// A straight line from `start_m` along `heading_rad` (ENU: 0 = east, CCW).
    Straight {
        /// Start point (x, y), m.
        start_m: [f64; 2],
        /// Direction of travel, rad.
        heading_rad: f64,
    },
    /// A circle around `centre_m`, starting at angle `start_angle_rad`.
    Circle {
        /// Centre (x, y), m.
        centre_m: [f64; 2],
        /// Radius, m.
        radius_m: f64,
        /// Polar angle of the start point around the centre, rad.
        #[serde(default)]
        start_angle_rad: f64,
        /// Drive clockwise (seen from above) instead of counter-clockwise.
        #[serde(default)]
        clockwise: bool,
    },
    /// Two tangent circles of radius `lobe_radius_m` driven one after the
    /// other (left lobe first), crossing `centre_m` along `heading_rad`. The
    /// route is continuous in position and heading.
    FigureEight {
        /// The crossing point (x, y), m.
        centre_m: [f64; 2],
        /// Radius of each lobe, m.
        lobe_radius_m: f64,
        /// Heading at the crossing point, rad.
        heading_rad: f64,
    },
    /// A straight line from `start_m` along `heading_rad` for `straight_m`, then an arc
    /// of `radius_m` turning by `turn_rad` (positive: left), then straight on: a car
    /// taking a corner.
    Corner {
        /// Start point (x, y), m.
        start_m: [f64; 2],
        /// Direction of travel at the start, rad.
        heading_rad: f64,
        /// Length of the first straight, m.
        straight_m: f64,
        /// Radius of the turn, m.
        radius_m: f64,
        /// How far it turns, rad (positive: left).
        turn_rad: f64,
    },
    /// A polyline through `points_m`, turning in place at each corner; the
    /// vehicle stops at the last point unless `closed` (then it loops).
    Waypoints {
        /// The points (x, y), m; at least two distinct ones.
        points_m: Vec<[f64; 2]>,
        /// Return to the first point and loop forever.
        #[serde(default)]
        closed: bool,
    },
}

/// How fast the vehicle drives along the path over time (after the start delay).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum SpeedProfile {
    /// Always the same speed.
    Constant {
        /// Speed, m/s.
        speed_m_s: f64,
    },
    /// `mean + amplitude * sin(2 pi t / period)`.
    Sinusoidal {
        /// Mean speed, m/s.
        mean_m_s: f64,
        /// Amplitude, m/s (mean - amplitude must stay >= 0).
        amplitude_m_s: f64,
        /// Period, s.
        period_s: f64,
    },
    /// Linear interpolation between `(time_s, speed_m_s)` points, holding the
    /// first value before the first point and the last after the last.
    PiecewiseLinear {
        /// `[time_s, speed_m_s]` pairs with strictly increasing times.
        points: Vec<[f64; 2]>,
    },
}

/// Pitch and roll oscillation of the pad (a vehicle on rough ground).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PadOscillation {
    /// Roll amplitude, rad.
    pub roll_amplitude_rad: f64,
    /// Pitch amplitude, rad.
    pub pitch_amplitude_rad: f64,
    /// Frequency, Hz (pitch lags roll by a quarter period).
    pub frequency_hz: f64,
}

/// Everything that defines the ground vehicle and its pad.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GroundVehicleParams {
    /// The route.
    pub path: PathParams,
    /// The speed over time.
    pub speed: SpeedProfile,
    /// Time the vehicle waits at the start of its route before driving, s.
    #[serde(default)]
    pub start_delay_s: f64,
    /// Height of the pad surface above the ground, m.
    #[serde(default = "default_pad_height")]
    pub pad_height_m: f64,
    /// Half the pad size along pad x and y, m (the landable footprint).
    #[serde(default = "default_pad_half_size")]
    pub pad_half_size_m: [f64; 2],
    /// Optional pitch/roll oscillation of the pad.
    #[serde(default)]
    pub oscillation: Option<PadOscillation>,
    /// How a driver drives the route: speed noise and heading wander; absent, the
    /// vehicle follows the route and the speed profile exactly.
    #[serde(default)]
    pub driver: Option<DriverParams>,
    /// A lane change: a smooth sideways move off the route.
    #[serde(default)]
    pub lane_change: Option<LaneChange>,
    /// The whole route moved by this much in x and y, m: where a run's seed puts the
    /// vehicle's start and the take-off point (the scenario's `[variation]`), not a
    /// scenario file's key.
    #[serde(skip)]
    pub offset_m: [f64; 2],
}

/// A driver's imperfection, seeded per run: the speed wanders around the profile
/// (relative, so a parked vehicle stays parked) and the heading around the route.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DriverParams {
    /// Standard deviation of the speed relative to the profile (0.1 = 10 %), at most 0.3.
    pub speed_noise_fraction: f64,
    /// Typical period of the speed's wander, s.
    pub speed_period_s: f64,
    /// Standard deviation of the heading off the route, rad.
    pub heading_wander_rad: f64,
    /// Typical distance over which the heading wanders, m.
    pub wander_wavelength_m: f64,
    /// Seed of the wander (the run's seed; not read from files).
    #[serde(skip)]
    pub seed: u64,
}

impl Default for DriverParams {
    /// 10 % speed noise over about 6 s, 1 deg of heading wander over about 8 m.
    fn default() -> Self {
        Self {
            speed_noise_fraction: 0.1,
            speed_period_s: 6.0,
            heading_wander_rad: 0.0175,
            wander_wavelength_m: 8.0,
            seed: 1,
        }
    }
}

/// A lane change: from `at_s` (time since the scenario's start), the vehicle moves
/// `offset_m` to its left (negative: right) over `duration_s`, smoothly (quintic).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LaneChange {
    /// When it starts, s.
    pub at_s: f64,
    /// Sideways distance, m (positive: left).
    pub offset_m: f64,
    /// How long it takes, s.
    pub duration_s: f64,
}

fn default_pad_height() -> f64 {
    0.4
}

fn default_pad_half_size() -> [f64; 2] {
    [0.5, 0.5]
}

impl Default for GroundVehicleParams {
    /// The paper's simulation: a target driving straight at 2.8 km/h.
    fn default() -> Self {
        Self {
            path: PathParams::Straight {
                start_m: [0.0, 0.0],
                heading_rad: 0.0,
            },
            speed: SpeedProfile::Constant {
                speed_m_s: 2.8 / 3.6,
            },
            start_delay_s: 0.0,
            pad_height_m: default_pad_height(),
            pad_half_size_m: default_pad_half_size(),
            oscillation: None,
            driver: None,
            lane_change: None,
            offset_m: [0.0; 2],
        }
    }
}

fn speed_in_range(field: &str, value: f64) -> Result<(), ParamError> {
    if value.is_finite() && (0.0..=MAX_GROUND_SPEED_M_S + 1e-9).contains(&value) {
        Ok(())
    } else {
        Err(ParamError::new(
            field,
            value,
            format!("must be within [0, {MAX_GROUND_SPEED_M_S:.3}] m/s (60 km/h)"),
        ))
    }
}

impl GroundVehicleParams {
    /// Checks every field; speeds above 60 km/h or below zero are rejected.
    pub fn validate(&self) -> Result<(), ParamError> {
        match &self.path {
            PathParams::Straight {
                start_m,
                heading_rad,
            } => {
                params::finite_all("path.start_m", start_m)?;
                params::finite("path.heading_rad", *heading_rad)?;
            }
            PathParams::Circle {
                centre_m,
                radius_m,
                start_angle_rad,
                ..
            } => {
                params::finite_all("path.centre_m", centre_m)?;
                params::positive("path.radius_m", *radius_m)?;
                params::finite("path.start_angle_rad", *start_angle_rad)?;
            }
            PathParams::FigureEight {
                centre_m,
                lobe_radius_m,
                heading_rad,
            } => {
                params::finite_all("path.centre_m", centre_m)?;
                params::positive("path.lobe_radius_m", *lobe_radius_m)?;
                params::finite("path.heading_rad", *heading_rad)?;
            }
            PathParams::Corner {
                start_m,
                heading_rad,
                straight_m,
                radius_m,
                turn_rad,
            } => {
                params::finite_all("path.start_m", start_m)?;
                params::finite("path.heading_rad", *heading_rad)?;
                params::non_negative("path.straight_m", *straight_m)?;
                params::positive("path.radius_m", *radius_m)?;
                params::in_range(
                    "path.turn_rad",
                    *turn_rad,
                    -std::f64::consts::PI,
                    std::f64::consts::PI,
                )?;
            }
            PathParams::Waypoints { points_m, .. } => {
                for (i, p) in points_m.iter().enumerate() {
                    params::finite_all(&format!("path.points_m[{i}]"), p)?;
                }
                if Polyline::new(points_m, false).is_none() {
                    return Err(ParamError::new(
                        "path.points_m",
                        format!("{points_m:?}"),
                        "needs at least two distinct points",
                    ));
                }
            }
        }
        match &self.speed {
            SpeedProfile::Constant { speed_m_s } => speed_in_range("speed.speed_m_s", *speed_m_s)?,
            SpeedProfile::Sinusoidal {
                mean_m_s,
                amplitude_m_s,
                period_s,
            } => {
                speed_in_range("speed.mean_m_s", *mean_m_s)?;
                params::non_negative("speed.amplitude_m_s", *amplitude_m_s)?;
                speed_in_range(
                    "speed.mean_m_s - speed.amplitude_m_s",
                    mean_m_s - amplitude_m_s,
                )?;
                speed_in_range(
                    "speed.mean_m_s + speed.amplitude_m_s",
                    mean_m_s + amplitude_m_s,
                )?;
                params::positive("speed.period_s", *period_s)?;
            }
            SpeedProfile::PiecewiseLinear { points } => {
                if points.is_empty() {
                    return Err(ParamError::new(
                        "speed.points",
                        "[]",
                        "needs at least one [time_s, speed_m_s] point",
                    ));
                }
                let mut last_t = f64::NEG_INFINITY;
                for (i, [t, v]) in points.iter().enumerate() {
                    params::non_negative(&format!("speed.points[{i}] time"), *t)?;
                    if *t <= last_t {
                        return Err(ParamError::new(
                            format!("speed.points[{i}] time"),
                            t,
                            "times must be strictly increasing",
                        ));
                    }
                    last_t = *t;
                    speed_in_range(&format!("speed.points[{i}] speed"), *v)?;
                }
            }
        }
        if let Some(d) = &self.driver {
            params::in_range(
                "driver.speed_noise_fraction",
                d.speed_noise_fraction,
                0.0,
                0.3,
            )?;
            params::positive("driver.speed_period_s", d.speed_period_s)?;
            params::in_range("driver.heading_wander_rad", d.heading_wander_rad, 0.0, 0.2)?;
            params::positive("driver.wander_wavelength_m", d.wander_wavelength_m)?;
        }
        if let Some(l) = &self.lane_change {
            params::non_negative("lane_change.at_s", l.at_s)?;
            params::in_range("lane_change.offset_m", l.offset_m, -10.0, 10.0)?;
            params::positive("lane_change.duration_s", l.duration_s)?;
        }
        params::non_negative("start_delay_s", self.start_delay_s)?;
        params::in_range("pad_height_m", self.pad_height_m, 0.0, 5.0)?;
        params::positive("pad_half_size_m[0]", self.pad_half_size_m[0])?;
        params::positive("pad_half_size_m[1]", self.pad_half_size_m[1])?;
        if let Some(o) = &self.oscillation {
            params::in_range(
                "oscillation.roll_amplitude_rad",
                o.roll_amplitude_rad,
                0.0,
                0.5,
            )?;
            params::in_range(
                "oscillation.pitch_amplitude_rad",
                o.pitch_amplitude_rad,
                0.0,
                0.5,
            )?;
            params::in_range("oscillation.frequency_hz", o.frequency_hz, 0.0, 10.0)?;
        }
        Ok(())
    }
}

/// The pad's motion at one instant, all in world ENU.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PadState {
    /// Pose of the pad frame (origin on the pad surface centre, x forward, z up).
    pub world_from_pad: Isometry3<f64>,
    /// Velocity of the pad origin, m/s.
    pub linear_velocity: Vector3<f64>,
    /// Acceleration of the pad origin (ignoring the oscillation), m/s^2.
    pub linear_acceleration: Vector3<f64>,
    /// Angular velocity of the pad, rad/s.
    pub angular_velocity: Vector3<f64>,
    /// Ground speed of the vehicle, m/s.
    pub speed_m_s: f64,
    /// Distance driven since the start, m.
    pub distance_m: f64,
}

impl PadState {
    /// Velocity of the pad's rigid body at world point `p` (the pad turns as its vehicle
    /// steers: a point off its centre moves otherwise than the centre), m/s: its
    /// surface's (whose extent does not matter to a velocity).
    pub fn velocity_at(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.surface([0.0, 0.0]).velocity_at(p)
    }

    /// The pad as a surface the quadrotor can land on, `half_extent_m` in size
    /// (the vehicle's roof; beyond it the gear misses).
    pub fn surface(&self, half_extent_m: [f64; 2]) -> Surface {
        Surface {
            id: PAD_SURFACE_ID,
            world_from_surface: self.world_from_pad,
            linear_velocity: self.linear_velocity,
            angular_velocity: self.angular_velocity,
            half_extent_m: Some(half_extent_m),
        }
    }
}

/// A polyline with cumulative arc lengths.
#[derive(Debug, Clone, PartialEq)]
struct Polyline {
    points: Vec<Vector2<f64>>,
    cumulative: Vec<f64>,
    closed: bool,
}

impl Polyline {
    /// Drops repeated points; None if fewer than two distinct points remain.
    fn new(points: &[[f64; 2]], closed: bool) -> Option<Self> {
        let mut pts: Vec<Vector2<f64>> = Vec::with_capacity(points.len() + 1);
        for p in points {
            let v = Vector2::new(p[0], p[1]);
            if pts.last().is_none_or(|last| (v - last).norm() > 1e-9) {
                pts.push(v);
            }
        }
        if pts.len() < 2 {
            return None;
        }
        if closed
            && let Some(first) = pts.first().copied()
            && pts.last().is_some_and(|last| (first - last).norm() > 1e-9)
        {
            pts.push(first);
        }
        let mut cumulative = vec![0.0];
        for w in pts.windows(2) {
            let last = cumulative.last().copied().unwrap_or(0.0);
            cumulative.push(last + (w[1] - w[0]).norm());
        }
        Some(Self {
            points: pts,
            cumulative,
            closed,
        })
    }

    fn length(&self) -> f64 {
        self.cumulative.last().copied().unwrap_or(0.0)
    }
}

/// A point on the route.
struct PathPoint {
    position: Vector2<f64>,
    heading: f64,
    /// Signed curvature, 1/m (left turn positive).
    curvature: f64,
    /// True past the end of an open route (the vehicle has stopped).
    at_end: bool,
}

/// The ground vehicle: a pure function of time.
#[derive(Debug, Clone)]
pub struct GroundVehicle {
    params: GroundVehicleParams,
    polyline: Option<Polyline>,
    /// The driver's speed wander: time is warped by `1 + sum(a sin(w t + p))`.
    speed_wander: Vec<Wave>,
    /// The driver's sideways wander along the route: `sum(a (sin(w s + p) - sin p))`, m.
    lateral_wander: Vec<Wave>,
}

/// One sinusoid of a wander.
#[derive(Debug, Clone, Copy)]
struct Wave {
    amplitude: f64,
    omega: f64,
    phase: f64,
}

/// Three sinusoids around `period` (in the unit of their argument) whose sum has the
/// standard deviation `std`, seeded.
fn waves(rng: &mut Pcg32, period: f64, std: f64) -> Vec<Wave> {
    if std == 0.0 {
        return Vec::new();
    }
    let amplitude = std / 1.5f64.sqrt();
    [0.6, 1.0, 1.7]
        .iter()
        .map(|f| {
            let p = period * f * (0.8 + 0.4 * rng.uniform());
            Wave {
                amplitude,
                omega: std::f64::consts::TAU / p,
                phase: std::f64::consts::TAU * rng.uniform(),
            }
        })
        .collect()
}

impl GroundVehicle {
    /// Builds the vehicle after validating its parameters.
    pub fn new(params: GroundVehicleParams) -> Result<Self, ParamError> {
        params.validate()?;
        let polyline = match &params.path {
            PathParams::Waypoints { points_m, closed } => Polyline::new(points_m, *closed),
            _ => None,
        };
        let (speed_wander, lateral_wander) = match &params.driver {
            Some(d) => {
                let mut rng = Pcg32::with_stream(d.seed, 11);
                let speed = waves(&mut rng, d.speed_period_s, d.speed_noise_fraction);
                // Heading ~ d(offset)/ds: an offset wave of amplitude a and wavenumber k
                // turns the heading by a k.
                let heading = waves(&mut rng, d.wander_wavelength_m, d.heading_wander_rad);
                let lateral = heading
                    .into_iter()
                    .map(|w| Wave {
                        amplitude: w.amplitude / w.omega,
                        ..w
                    })
                    .collect();
                (speed, lateral)
            }
            None => (Vec::new(), Vec::new()),
        };
        Ok(Self {
            params,
            polyline,
            speed_wander,
            lateral_wander,
        })
    }

    /// The parameters in use.
    pub fn params(&self) -> &GroundVehicleParams {
        &self.params
    }

    /// The pad's pose and motion at time `t_s` (seconds since the start of the
    /// scenario). Times before zero or non-finite are treated as zero.
    pub fn state_at(&self, t_s: f64) -> PadState {
        let t = if t_s.is_finite() { t_s.max(0.0) } else { 0.0 };
        let driving_time = (t - self.params.start_delay_s).max(0.0);
        let driving = t > self.params.start_delay_s;
        // The driver's speed wander warps the profile's time: tau' = 1 + sum(a sin(..)).
        let (tau, dtau, ddtau) =
            self.speed_wander
                .iter()
                .fold((driving_time, 1.0, 0.0), |(tau, d, dd), w| {
                    let x = w.omega * driving_time + w.phase;
                    (
                        tau + w.amplitude / w.omega * (w.phase.cos() - x.cos()),
                        d + w.amplitude * x.sin(),
                        dd + w.amplitude * w.omega * x.cos(),
                    )
                });
        let distance = self.distance_at(tau);
        let point = self.point_at(distance);
        let (mut speed, mut accel) = if driving {
            let v = self.speed_at(tau);
            (v * dtau, self.speed_rate_at(tau) * dtau * dtau + v * ddtau)
        } else {
            (0.0, 0.0)
        };
        if point.at_end {
            speed = 0.0;
            accel = 0.0;
        }
        // Sideways: the driver's wander along the route plus a lane change in time.
        let (mut y, mut dy_ds, mut d2y_ds2) = (0.0, 0.0, 0.0);
        for w in &self.lateral_wander {
            let x = w.omega * distance + w.phase;
            // From the route itself at its start: a parked vehicle stays on it.
            y += w.amplitude * (x.sin() - w.phase.sin());
            dy_ds += w.amplitude * w.omega * x.cos();
            d2y_ds2 -= w.amplitude * w.omega * w.omega * x.sin();
        }
        let (lane, lane_v, lane_a) = self.lane_offset_at(t);
        y += lane;
        let lat_v = dy_ds * speed + lane_v;
        let lat_a = d2y_ds2 * speed * speed + dy_ds * accel + lane_a;
        let (roll, pitch, roll_rate, pitch_rate) = self.oscillation_at(t);
        let tangent = Vector3::new(point.heading.cos(), point.heading.sin(), 0.0);
        let normal = Vector3::new(-point.heading.sin(), point.heading.cos(), 0.0);
        // The vehicle points along its velocity (at a crawl, along the route).
        let (off, off_rate) = if speed > 0.05 {
            (
                lat_v.atan2(speed),
                (lat_a * speed - lat_v * accel) / (speed * speed + lat_v * lat_v),
            )
        } else {
            (0.0, 0.0)
        };
        let heading = point.heading + off;
        let yaw_rate = point.curvature * speed + off_rate;
        let rz = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), heading);
        let ry = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), pitch);
        let angular_velocity = Vector3::z() * yaw_rate
            + rz * (Vector3::y() * pitch_rate)
            + (rz * ry) * (Vector3::x() * roll_rate);
        let rotation = UnitQuaternion::from_euler_angles(roll, pitch, heading);
        let position = point.position
            + Vector2::new(normal.x, normal.y) * y
            + Vector2::new(self.params.offset_m[0], self.params.offset_m[1]);
        PadState {
            world_from_pad: Isometry3::from_parts(
                Translation3::new(position.x, position.y, self.params.pad_height_m),
                rotation,
            ),
            linear_velocity: tangent * speed + normal * lat_v,
            linear_acceleration: tangent * accel
                + normal * (point.curvature * speed * speed + lat_a),
            angular_velocity,
            speed_m_s: (speed * speed + lat_v * lat_v).sqrt(),
            distance_m: distance,
        }
    }

    /// The lane change's sideways offset, its rate and its acceleration at `t_s`.
    fn lane_offset_at(&self, t_s: f64) -> (f64, f64, f64) {
        let Some(l) = &self.params.lane_change else {
            return (0.0, 0.0, 0.0);
        };
        // Quintic smoothstep: its rate and acceleration vanish at both ends, so the
        // clamped parameter needs no case of its own before or after the change.
        let u = ((t_s - l.at_s) / l.duration_s).clamp(0.0, 1.0);
        let s = u * u * u * (10.0 - 15.0 * u + 6.0 * u * u);
        let ds = 30.0 * u * u * (1.0 - u) * (1.0 - u);
        let dds = 60.0 * u * (1.0 - u) * (1.0 - 2.0 * u);
        (
            l.offset_m * s,
            l.offset_m * ds / l.duration_s,
            l.offset_m * dds / (l.duration_s * l.duration_s),
        )
    }

    /// The roof the quadrotor lands on (the pad's footprint) at `pad`.
    pub fn roof(&self, pad: &PadState) -> Surface {
        pad.surface(self.params.pad_half_size_m)
    }

    /// The vehicle's body: the box from the ground up to the pad on its roof, the
    /// pad's footprint in size. The depth camera sees it; touching it is a crash.
    pub fn body(&self, pad: &PadState) -> Obb {
        let [hx, hy] = self.params.pad_half_size_m;
        let h = self.params.pad_height_m;
        let centre = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, -h / 2.0),
            UnitQuaternion::identity(),
        );
        Obb {
            world_from_box: pad.world_from_pad * centre,
            half_m: [hx, hy, h / 2.0],
        }
    }

    /// True if world point `p` is above or below the pad footprint (inside the
    /// pad's x/y half-size, measured in the pad frame).
    pub fn is_over_pad(&self, pad: &PadState, p: &Vector3<f64>) -> bool {
        let local = pad.world_from_pad.inverse_transform_point(&(*p).into());
        local.x.abs() <= self.params.pad_half_size_m[0]
            && local.y.abs() <= self.params.pad_half_size_m[1]
    }

    fn speed_at(&self, t: f64) -> f64 {
        match &self.params.speed {
            SpeedProfile::Constant { speed_m_s } => *speed_m_s,
            SpeedProfile::Sinusoidal {
                mean_m_s,
                amplitude_m_s,
                period_s,
            } => mean_m_s + amplitude_m_s * (std::f64::consts::TAU * t / period_s).sin(),
            SpeedProfile::PiecewiseLinear { points } => piecewise_speed(points, t).0,
        }
    }

    fn speed_rate_at(&self, t: f64) -> f64 {
        match &self.params.speed {
            SpeedProfile::Constant { .. } => 0.0,
            SpeedProfile::Sinusoidal {
                amplitude_m_s,
                period_s,
                ..
            } => {
                let w = std::f64::consts::TAU / period_s;
                amplitude_m_s * w * (w * t).cos()
            }
            SpeedProfile::PiecewiseLinear { points } => piecewise_speed(points, t).1,
        }
    }

    /// Distance driven after `t` seconds of driving (the integral of the speed).
    fn distance_at(&self, t: f64) -> f64 {
        match &self.params.speed {
            SpeedProfile::Constant { speed_m_s } => speed_m_s * t,
            SpeedProfile::Sinusoidal {
                mean_m_s,
                amplitude_m_s,
                period_s,
            } => {
                let w = std::f64::consts::TAU / period_s;
                mean_m_s * t + amplitude_m_s / w * (1.0 - (w * t).cos())
            }
            SpeedProfile::PiecewiseLinear { points } => piecewise_distance(points, t),
        }
    }

    fn oscillation_at(&self, t: f64) -> (f64, f64, f64, f64) {
        match &self.params.oscillation {
            None => (0.0, 0.0, 0.0, 0.0),
            Some(o) => {
                let w = std::f64::consts::TAU * o.frequency_hz;
                let roll = o.roll_amplitude_rad * (w * t).sin();
                let roll_rate = o.roll_amplitude_rad * w * (w * t).cos();
                let pitch = o.pitch_amplitude_rad * (w * t).cos();
                let pitch_rate = -o.pitch_amplitude_rad * w * (w * t).sin();
                (roll, pitch, roll_rate, pitch_rate)
            }
        }
    }

    fn point_at(&self, s: f64) -> PathPoint {
        match &self.params.path {
            PathParams::Straight {
                start_m,
                heading_rad,
            } => PathPoint {
                position: Vector2::new(start_m[0], start_m[1])
                    + Vector2::new(heading_rad.cos(), heading_rad.sin()) * s,
                heading: *heading_rad,
                curvature: 0.0,
                at_end: false,
            },
            PathParams::Circle {
                centre_m,
                radius_m,
                start_angle_rad,
                clockwise,
            } => {
                let sign = if *clockwise { -1.0 } else { 1.0 };
                arc_point(
                    Vector2::new(centre_m[0], centre_m[1]),
                    *radius_m,
                    *start_angle_rad,
                    sign,
                    s,
                )
            }
            PathParams::FigureEight {
                centre_m,
                lobe_radius_m,
                heading_rad,
            } => {
                let r = *lobe_radius_m;
                let lobe = std::f64::consts::TAU * r;
                let u = s.rem_euclid(2.0 * lobe);
                let c = Vector2::new(centre_m[0], centre_m[1]);
                let left = Vector2::new(-heading_rad.sin(), heading_rad.cos());
                let half_pi = std::f64::consts::FRAC_PI_2;
                if u < lobe {
                    arc_point(c + left * r, r, heading_rad - half_pi, 1.0, u)
                } else {
                    arc_point(c - left * r, r, heading_rad + half_pi, -1.0, u - lobe)
                }
            }
            PathParams::Corner {
                start_m,
                heading_rad,
                straight_m,
                radius_m,
                turn_rad,
            } => {
                let h = *heading_rad;
                let start = Vector2::new(start_m[0], start_m[1]);
                let dir = Vector2::new(h.cos(), h.sin());
                if s <= *straight_m {
                    return PathPoint {
                        position: start + dir * s,
                        heading: h,
                        curvature: 0.0,
                        at_end: false,
                    };
                }
                let sign = if *turn_rad < 0.0 { -1.0 } else { 1.0 };
                let r = *radius_m;
                let left = Vector2::new(-h.sin(), h.cos());
                let centre = start + dir * *straight_m + left * (sign * r);
                let arc = r * turn_rad.abs();
                let half_pi = std::f64::consts::FRAC_PI_2;
                let on_arc = (s - straight_m).min(arc);
                let p = arc_point(centre, r, h - sign * half_pi, sign, on_arc);
                if s - straight_m <= arc {
                    return p;
                }
                let h2 = h + turn_rad;
                PathPoint {
                    position: p.position
                        + Vector2::new(h2.cos(), h2.sin()) * (s - straight_m - arc),
                    heading: h2,
                    curvature: 0.0,
                    at_end: false,
                }
            }
            PathParams::Waypoints { .. } => match &self.polyline {
                Some(line) => polyline_point(line, s),
                None => PathPoint {
                    position: Vector2::zeros(),
                    heading: 0.0,
                    curvature: 0.0,
                    at_end: true,
                },
            },
        }
    }
}

/// A point `s` metres along a circle of radius `r` around `centre`, starting
/// at polar angle `start`, counter-clockwise when `sign` is +1.
fn arc_point(centre: Vector2<f64>, r: f64, start: f64, sign: f64, s: f64) -> PathPoint {
    let theta = start + sign * s / r;
    PathPoint {
        position: centre + Vector2::new(theta.cos(), theta.sin()) * r,
        heading: theta + sign * std::f64::consts::FRAC_PI_2,
        curvature: sign / r,
        at_end: false,
    }
}

fn polyline_point(line: &Polyline, s: f64) -> PathPoint {
    let total = line.length();
    let (s, at_end) = if line.closed {
        (s.rem_euclid(total), false)
    } else if s >= total {
        (total, true)
    } else {
        (s.max(0.0), false)
    };
    // Segment i spans cumulative[i]..cumulative[i + 1].
    let segments = line.points.len() - 1;
    let mut i = line
        .cumulative
        .partition_point(|c| *c <= s)
        .saturating_sub(1);
    i = i.min(segments - 1);
    let a = line.points[i];
    let b = line.points[i + 1];
    let seg = b - a;
    let len = seg.norm();
    let along = (s - line.cumulative[i]).clamp(0.0, len);
    PathPoint {
        position: a + seg * (along / len),
        heading: seg.y.atan2(seg.x),
        curvature: 0.0,
        at_end,
    }
}

/// Speed and its rate of change at `t` for a piecewise-linear profile.
fn piecewise_speed(points: &[[f64; 2]], t: f64) -> (f64, f64) {
    let Some(first) = points.first() else {
        return (0.0, 0.0);
    };
    if t <= first[0] {
        return (first[1], 0.0);
    }
    for w in points.windows(2) {
        let ([t0, v0], [t1, v1]) = (w[0], w[1]);
        if t < t1 {
            let slope = (v1 - v0) / (t1 - t0);
            return (v0 + slope * (t - t0), slope);
        }
    }
    (points.last().map_or(0.0, |p| p[1]), 0.0)
}

/// Distance after `t` seconds for a piecewise-linear profile (exact trapezoids).
fn piecewise_distance(points: &[[f64; 2]], t: f64) -> f64 {
    let Some(first) = points.first() else {
        return 0.0;
    };
    if t <= first[0] {
        return first[1] * t;
    }
    let mut distance = first[1] * first[0];
    for w in points.windows(2) {
        let ([t0, v0], [t1, v1]) = (w[0], w[1]);
        if t <= t1 {
            let v = v0 + (v1 - v0) / (t1 - t0) * (t - t0);
            return distance + 0.5 * (v0 + v) * (t - t0);
        }
        distance += 0.5 * (v0 + v1) * (t1 - t0);
    }
    let last = points.last().map_or([0.0, 0.0], |p| *p);
    distance + last[1] * (t - last[0])
}

#[cfg(test)]
#[path = "ground_vehicle_test.rs"]
mod tests;
