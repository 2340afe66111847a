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

use crate::params::{self, ParamError};
use crate::quadrotor::Surface;

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
    /// The pad as a surface the quadrotor can land on.
    pub fn surface(&self) -> Surface {
        Surface {
            id: PAD_SURFACE_ID,
            world_from_surface: self.world_from_pad,
            linear_velocity: self.linear_velocity,
            angular_velocity: self.angular_velocity,
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
}

impl GroundVehicle {
    /// Builds the vehicle after validating its parameters.
    pub fn new(params: GroundVehicleParams) -> Result<Self, ParamError> {
        params.validate()?;
        let polyline = match &params.path {
            PathParams::Waypoints { points_m, closed } => Polyline::new(points_m, *closed),
            _ => None,
        };
        Ok(Self { params, polyline })
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
        let distance = self.distance_at(driving_time);
        let point = self.point_at(distance);
        let (mut speed, mut accel) = if driving {
            (
                self.speed_at(driving_time),
                self.speed_rate_at(driving_time),
            )
        } else {
            (0.0, 0.0)
        };
        if point.at_end {
            speed = 0.0;
            accel = 0.0;
        }
        let (roll, pitch, roll_rate, pitch_rate) = self.oscillation_at(t);
        let heading = point.heading;
        let tangent = Vector3::new(heading.cos(), heading.sin(), 0.0);
        let normal = Vector3::new(-heading.sin(), heading.cos(), 0.0);
        let yaw_rate = point.curvature * speed;
        let rz = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), heading);
        let ry = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), pitch);
        let angular_velocity = Vector3::z() * yaw_rate
            + rz * (Vector3::y() * pitch_rate)
            + (rz * ry) * (Vector3::x() * roll_rate);
        let rotation = UnitQuaternion::from_euler_angles(roll, pitch, heading);
        PadState {
            world_from_pad: Isometry3::from_parts(
                Translation3::new(point.position.x, point.position.y, self.params.pad_height_m),
                rotation,
            ),
            linear_velocity: tangent * speed,
            linear_acceleration: tangent * accel + normal * (point.curvature * speed * speed),
            angular_velocity,
            speed_m_s: speed,
            distance_m: distance,
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
mod tests {
    use super::*;

    fn vehicle(path: PathParams, speed: SpeedProfile) -> GroundVehicle {
        GroundVehicle::new(GroundVehicleParams {
            path,
            speed,
            ..GroundVehicleParams::default()
        })
        .unwrap()
    }

    fn constant(speed_m_s: f64) -> SpeedProfile {
        SpeedProfile::Constant { speed_m_s }
    }

    fn wrap(a: f64) -> f64 {
        (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
    }

    fn translation(s: &PadState) -> Vector3<f64> {
        s.world_from_pad.translation.vector
    }

    #[test]
    fn straight_line_has_the_right_speed_heading_and_pad_height() {
        let v = vehicle(
            PathParams::Straight {
                start_m: [1.0, -2.0],
                heading_rad: 0.3,
            },
            constant(5.0),
        );
        let s = v.state_at(10.0);
        let expected = Vector3::new(1.0 + 50.0 * 0.3f64.cos(), -2.0 + 50.0 * 0.3f64.sin(), 0.4);
        assert!((translation(&s) - expected).norm() < 1e-9);
        assert!((s.linear_velocity.norm() - 5.0).abs() < 1e-12);
        assert!((s.linear_velocity.y.atan2(s.linear_velocity.x) - 0.3).abs() < 1e-12);
        assert!((s.world_from_pad.rotation.euler_angles().2 - 0.3).abs() < 1e-12);
        assert_eq!(s.angular_velocity, Vector3::zeros());
    }

    #[test]
    fn circle_keeps_its_radius_and_turns_at_speed_over_radius() {
        for clockwise in [false, true] {
            let v = vehicle(
                PathParams::Circle {
                    centre_m: [3.0, 4.0],
                    radius_m: 10.0,
                    start_angle_rad: 0.5,
                    clockwise,
                },
                constant(4.0),
            );
            for k in 1..200 {
                let s = v.state_at(k as f64 * 0.5);
                let r = translation(&s).xy() - Vector2::new(3.0, 4.0);
                assert!((r.norm() - 10.0).abs() < 1e-9);
                assert!(r.dot(&s.linear_velocity.xy()).abs() < 1e-9);
                let expected_rate = if clockwise { -0.4 } else { 0.4 };
                assert!((s.angular_velocity.z - expected_rate).abs() < 1e-12);
                assert!((s.linear_acceleration.norm() - 1.6).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn speeds_above_60_km_h_are_rejected() {
        let too_fast = GroundVehicleParams {
            speed: constant(61.0 / 3.6),
            ..GroundVehicleParams::default()
        };
        let msg = too_fast.validate().unwrap_err().to_string();
        assert!(msg.starts_with("speed.speed_m_s = 16.9"), "{msg}");
        assert!(msg.contains("60 km/h"), "{msg}");
        let ok = GroundVehicleParams {
            speed: constant(60.0 / 3.6),
            ..GroundVehicleParams::default()
        };
        ok.validate().unwrap();
        let gusty = GroundVehicleParams {
            speed: SpeedProfile::Sinusoidal {
                mean_m_s: 15.0,
                amplitude_m_s: 2.0,
                period_s: 10.0,
            },
            ..GroundVehicleParams::default()
        };
        assert!(gusty.validate().is_err());
        let ramp = GroundVehicleParams {
            speed: SpeedProfile::PiecewiseLinear {
                points: vec![[0.0, 0.0], [10.0, 20.0]],
            },
            ..GroundVehicleParams::default()
        };
        assert!(ramp.validate().is_err());
    }

    #[test]
    fn negative_speeds_are_rejected() {
        let p = GroundVehicleParams {
            speed: constant(-1.0),
            ..GroundVehicleParams::default()
        };
        assert!(p.validate().is_err());
        let p = GroundVehicleParams {
            speed: SpeedProfile::Sinusoidal {
                mean_m_s: 1.0,
                amplitude_m_s: 2.0,
                period_s: 10.0,
            },
            ..GroundVehicleParams::default()
        };
        assert!(p.validate().is_err());
    }

    #[test]
    fn figure_eight_is_continuous_in_position_and_heading() {
        let v = vehicle(
            PathParams::FigureEight {
                centre_m: [0.0, 0.0],
                lobe_radius_m: 8.0,
                heading_rad: 0.7,
            },
            constant(6.0),
        );
        let dt = 0.01;
        let mut prev = v.state_at(0.0);
        let mut max_left: f64 = 0.0;
        let mut max_right: f64 = 0.0;
        for k in 1..(40.0 / dt) as usize {
            let s = v.state_at(k as f64 * dt);
            let jump = (translation(&s) - translation(&prev)).norm();
            assert!(jump <= 6.0 * dt * 1.0001, "jump {jump}");
            let dyaw = wrap(
                s.world_from_pad.rotation.euler_angles().2
                    - prev.world_from_pad.rotation.euler_angles().2,
            );
            assert!(dyaw.abs() <= 6.0 / 8.0 * dt * 1.0001, "heading jump {dyaw}");
            let side = Vector2::new(-0.7f64.sin(), 0.7f64.cos()).dot(&translation(&s).xy());
            max_left = max_left.max(side);
            max_right = max_right.max(-side);
            prev = s;
        }
        // Both lobes are driven, each 2 r wide.
        assert!((max_left - 16.0).abs() < 0.01 && (max_right - 16.0).abs() < 0.01);
        // One full figure eight is 4 pi r long and returns to the start.
        let period = 4.0 * std::f64::consts::PI * 8.0 / 6.0;
        assert!((translation(&v.state_at(period)) - translation(&v.state_at(0.0))).norm() < 1e-9);
    }

    #[test]
    fn waypoints_are_followed_at_path_speed_and_the_vehicle_stops_at_the_end() {
        let v = vehicle(
            PathParams::Waypoints {
                points_m: vec![[0.0, 0.0], [10.0, 0.0], [10.0, 5.0]],
                closed: false,
            },
            constant(2.0),
        );
        let s = v.state_at(2.5);
        assert!((translation(&s).xy() - Vector2::new(5.0, 0.0)).norm() < 1e-9);
        assert!((s.linear_velocity - Vector3::new(2.0, 0.0, 0.0)).norm() < 1e-12);
        let s = v.state_at(6.0);
        assert!((translation(&s).xy() - Vector2::new(10.0, 2.0)).norm() < 1e-9);
        assert!((s.linear_velocity - Vector3::new(0.0, 2.0, 0.0)).norm() < 1e-12);
        let s = v.state_at(100.0);
        assert!((translation(&s).xy() - Vector2::new(10.0, 5.0)).norm() < 1e-9);
        assert_eq!(s.linear_velocity, Vector3::zeros());
        let closed = vehicle(
            PathParams::Waypoints {
                points_m: vec![[0.0, 0.0], [10.0, 0.0], [10.0, 5.0]],
                closed: true,
            },
            constant(2.0),
        );
        let lap = (10.0 + 5.0 + 125f64.sqrt()) / 2.0;
        let s = closed.state_at(lap + 1.0);
        assert!((translation(&s).xy() - Vector2::new(2.0, 0.0)).norm() < 1e-9);
    }

    #[test]
    fn waypoints_need_two_distinct_points() {
        let p = GroundVehicleParams {
            path: PathParams::Waypoints {
                points_m: vec![[1.0, 1.0], [1.0, 1.0]],
                closed: false,
            },
            ..GroundVehicleParams::default()
        };
        assert!(p.validate().is_err());
    }

    #[test]
    fn the_vehicle_waits_for_its_start_delay() {
        let v = GroundVehicle::new(GroundVehicleParams {
            start_delay_s: 5.0,
            speed: constant(3.0),
            ..GroundVehicleParams::default()
        })
        .unwrap();
        let s = v.state_at(4.0);
        assert_eq!(translation(&s), Vector3::new(0.0, 0.0, 0.4));
        assert_eq!(s.linear_velocity, Vector3::zeros());
        let s = v.state_at(7.0);
        assert!((translation(&s).x - 6.0).abs() < 1e-12);
    }

    #[test]
    fn varying_speed_profiles_integrate_to_the_right_distance() {
        let sin = vehicle(
            PathParams::Straight {
                start_m: [0.0, 0.0],
                heading_rad: 0.0,
            },
            SpeedProfile::Sinusoidal {
                mean_m_s: 5.0,
                amplitude_m_s: 2.0,
                period_s: 8.0,
            },
        );
        // Whole periods: the sinusoid integrates to zero.
        assert!((sin.state_at(16.0).distance_m - 80.0).abs() < 1e-9);
        let pw = vehicle(
            PathParams::Straight {
                start_m: [0.0, 0.0],
                heading_rad: 0.0,
            },
            SpeedProfile::PiecewiseLinear {
                points: vec![[0.0, 0.0], [4.0, 8.0], [6.0, 8.0], [8.0, 4.0]],
            },
        );
        // 16 + 16 + 12 + 4 * 2 (held after the end).
        assert!((pw.state_at(10.0).distance_m - 52.0).abs() < 1e-9);
        assert!((pw.state_at(2.0).speed_m_s - 4.0).abs() < 1e-12);
        assert!((pw.state_at(2.0).linear_acceleration.x - 2.0).abs() < 1e-12);
    }

    #[test]
    fn velocities_match_the_change_of_pose_on_every_path() {
        let paths = [
            PathParams::Straight {
                start_m: [0.0, 0.0],
                heading_rad: -1.0,
            },
            PathParams::Circle {
                centre_m: [0.0, 0.0],
                radius_m: 7.0,
                start_angle_rad: 0.0,
                clockwise: true,
            },
            PathParams::FigureEight {
                centre_m: [1.0, 1.0],
                lobe_radius_m: 5.0,
                heading_rad: 0.0,
            },
        ];
        for path in paths {
            let v = GroundVehicle::new(GroundVehicleParams {
                path,
                speed: SpeedProfile::Sinusoidal {
                    mean_m_s: 6.0,
                    amplitude_m_s: 3.0,
                    period_s: 7.0,
                },
                oscillation: Some(PadOscillation {
                    roll_amplitude_rad: 0.05,
                    pitch_amplitude_rad: 0.08,
                    frequency_hz: 0.7,
                }),
                ..GroundVehicleParams::default()
            })
            .unwrap();
            let h = 1e-5;
            for k in 0..50 {
                let t = 0.37 * k as f64 + 0.01;
                let a = v.state_at(t - h);
                let b = v.state_at(t + h);
                let s = v.state_at(t);
                let v_fd = (translation(&b) - translation(&a)) / (2.0 * h);
                assert!((v_fd - s.linear_velocity).norm() < 1e-5, "t {t}");
                let dq = b.world_from_pad.rotation * a.world_from_pad.rotation.inverse();
                let w_fd = dq.scaled_axis() / (2.0 * h);
                assert!((w_fd - s.angular_velocity).norm() < 1e-5, "t {t}");
            }
        }
    }

    #[test]
    fn pad_oscillation_tilts_the_pad_by_its_amplitude() {
        let v = GroundVehicle::new(GroundVehicleParams {
            oscillation: Some(PadOscillation {
                roll_amplitude_rad: 0.1,
                pitch_amplitude_rad: 0.0,
                frequency_hz: 1.0,
            }),
            ..GroundVehicleParams::default()
        })
        .unwrap();
        let s = v.state_at(0.25);
        let n = s.world_from_pad.rotation * Vector3::z();
        assert!((n.z.acos() - 0.1).abs() < 1e-9);
    }

    #[test]
    fn the_footprint_test_uses_the_pad_frame() {
        let v = GroundVehicle::new(GroundVehicleParams {
            path: PathParams::Straight {
                start_m: [0.0, 0.0],
                heading_rad: std::f64::consts::FRAC_PI_2,
            },
            pad_half_size_m: [1.0, 0.3],
            ..GroundVehicleParams::default()
        })
        .unwrap();
        let s = v.state_at(0.0);
        // Pad x points north: 0.8 m north is inside, 0.8 m east is not.
        assert!(v.is_over_pad(&s, &Vector3::new(0.0, 0.8, 2.0)));
        assert!(!v.is_over_pad(&s, &Vector3::new(0.8, 0.0, 2.0)));
    }

    #[test]
    fn parses_from_toml() {
        let p: GroundVehicleParams = toml::from_str(
            r#"
            start_delay_s = 2.0
            path = { type = "circle", centre_m = [0.0, 0.0], radius_m = 20.0 }
            speed = { type = "piecewise_linear", points = [[0.0, 0.0], [5.0, 10.0]] }
            oscillation = { roll_amplitude_rad = 0.02, pitch_amplitude_rad = 0.03, frequency_hz = 0.5 }
            "#,
        )
        .unwrap();
        p.validate().unwrap();
        assert_eq!(p.pad_height_m, 0.4);
        let bad = toml::from_str::<GroundVehicleParams>(
            r#"
            path = { type = "straight", start_m = [0.0, 0.0], heading_rad = 0.0, radius_m = 3.0 }
            speed = { type = "constant", speed_m_s = 1.0 }
            "#,
        );
        assert!(bad.is_err());
    }
}
