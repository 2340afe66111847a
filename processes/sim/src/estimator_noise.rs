//! What the autopilot reports is truth plus VIO-like noise and drift.
//!
//! On the real vehicle PX4's estimator fuses visual-inertial odometry, so the
//! state it reports (and that px4-link forwards to the pipeline) is noisy and
//! slowly drifts away from the truth. This module reproduces that, seeded and
//! deterministic: noise on position, velocity, attitude and body rates, plus a
//! random-walk drift of position and heading. With [`EstimatorNoiseParams::zero`]
//! the estimate equals the truth exactly.
//!
//! The noise is a first-order Gauss-Markov process with a configurable
//! correlation time (0 gives white noise, a new independent sample every
//! step). A small correlation time is the default because an estimator's
//! output is smoothed: white noise at the simulation rate (500 Hz) would be far
//! rougher than any real EKF output and would make derivative terms meaningless.

use nalgebra::{UnitQuaternion, Vector3};
use serde::Deserialize;

use crate::autopilot::EstimatedState;
use crate::params::{self, ParamError};
use crate::quadrotor::VehicleState;
use crate::rng::Pcg32;

/// Noise and drift levels of the simulated state estimate.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EstimatorNoiseParams {
    /// Seed of the noise generator: the same seed gives the same noise.
    pub seed: u64,
    /// Standard deviation of the position noise per axis, m.
    pub position_std_m: f64,
    /// Standard deviation of the velocity noise per axis, m/s.
    pub velocity_std_m_s: f64,
    /// Standard deviation of the attitude noise per axis (small rotation), rad.
    pub attitude_std_rad: f64,
    /// Standard deviation of the body-rate noise per axis, rad/s.
    pub rate_std_rad_s: f64,
    /// Correlation time of the noise, s (0 = white noise, new sample every step).
    pub correlation_time_s: f64,
    /// Random-walk intensity of the position drift per axis, m per sqrt(s).
    pub position_drift_m_per_sqrt_s: f64,
    /// Random-walk intensity of the heading drift, rad per sqrt(s).
    pub yaw_drift_rad_per_sqrt_s: f64,
}

impl Default for EstimatorNoiseParams {
    /// Levels typical of a VIO-fed PX4 EKF: centimetre position noise, about
    /// 1 cm per sqrt(s) of drift, a fraction of a degree of attitude noise.
    fn default() -> Self {
        Self {
            seed: 1,
            position_std_m: 0.02,
            velocity_std_m_s: 0.03,
            attitude_std_rad: 0.2f64.to_radians(),
            rate_std_rad_s: 0.01,
            correlation_time_s: 0.05,
            position_drift_m_per_sqrt_s: 0.01,
            yaw_drift_rad_per_sqrt_s: 0.002,
        }
    }
}

impl EstimatorNoiseParams {
    /// No noise and no drift: the estimate is the truth.
    pub fn zero() -> Self {
        Self {
            seed: 0,
            position_std_m: 0.0,
            velocity_std_m_s: 0.0,
            attitude_std_rad: 0.0,
            rate_std_rad_s: 0.0,
            correlation_time_s: 0.0,
            position_drift_m_per_sqrt_s: 0.0,
            yaw_drift_rad_per_sqrt_s: 0.0,
        }
    }

    /// Checks every field (all must be finite and >= 0).
    pub fn validate(&self) -> Result<(), ParamError> {
        params::non_negative("position_std_m", self.position_std_m)?;
        params::non_negative("velocity_std_m_s", self.velocity_std_m_s)?;
        params::non_negative("attitude_std_rad", self.attitude_std_rad)?;
        params::non_negative("rate_std_rad_s", self.rate_std_rad_s)?;
        params::non_negative("correlation_time_s", self.correlation_time_s)?;
        params::non_negative(
            "position_drift_m_per_sqrt_s",
            self.position_drift_m_per_sqrt_s,
        )?;
        params::non_negative("yaw_drift_rad_per_sqrt_s", self.yaw_drift_rad_per_sqrt_s)?;
        Ok(())
    }
}

/// The noise generator with its current noise and drift.
#[derive(Debug, Clone)]
pub struct EstimatorNoise {
    params: EstimatorNoiseParams,
    rng: Pcg32,
    position_noise: Vector3<f64>,
    velocity_noise: Vector3<f64>,
    attitude_noise: Vector3<f64>,
    rate_noise: Vector3<f64>,
    position_drift: Vector3<f64>,
    yaw_drift: f64,
}

impl EstimatorNoise {
    /// Builds the generator; the noise starts in its stationary distribution
    /// and the drift at zero.
    pub fn new(params: EstimatorNoiseParams) -> Result<Self, ParamError> {
        params.validate()?;
        let mut rng = Pcg32::new(params.seed);
        let position_noise = normal3(&mut rng) * params.position_std_m;
        let velocity_noise = normal3(&mut rng) * params.velocity_std_m_s;
        let attitude_noise = normal3(&mut rng) * params.attitude_std_rad;
        let rate_noise = normal3(&mut rng) * params.rate_std_rad_s;
        Ok(Self {
            params,
            rng,
            position_noise,
            velocity_noise,
            attitude_noise,
            rate_noise,
            position_drift: Vector3::zeros(),
            yaw_drift: 0.0,
        })
    }

    /// The parameters in use.
    pub fn params(&self) -> &EstimatorNoiseParams {
        &self.params
    }

    /// Accumulated position drift, m (for evaluation: how far the estimate wandered).
    pub fn position_drift(&self) -> Vector3<f64> {
        self.position_drift
    }

    /// Accumulated heading drift, rad.
    pub fn yaw_drift(&self) -> f64 {
        self.yaw_drift
    }

    /// Advances the noise by `dt_s` and returns the estimate of `truth`.
    ///
    /// The estimated frame is rotated by the heading drift (velocity and
    /// attitude turn with it) and shifted by the position drift. A `dt_s` that
    /// is not finite and positive holds the noise where it is.
    pub fn apply(&mut self, dt_s: f64, truth: &VehicleState, landed: bool) -> EstimatedState {
        if dt_s.is_finite() && dt_s > 0.0 {
            self.advance(dt_s);
        }
        let yaw = (self.yaw_drift != 0.0)
            .then(|| UnitQuaternion::from_axis_angle(&Vector3::z_axis(), self.yaw_drift));
        let mut velocity = truth.velocity;
        let mut world_from_body = truth.world_from_body;
        if let Some(r) = yaw {
            velocity = r * velocity;
            world_from_body = r * world_from_body;
        }
        if self.attitude_noise != Vector3::zeros() {
            world_from_body =
                UnitQuaternion::from_scaled_axis(self.attitude_noise) * world_from_body;
        }
        EstimatedState {
            position: truth.position + self.position_drift + self.position_noise,
            velocity: velocity + self.velocity_noise,
            world_from_body,
            body_rates: truth.body_rates + self.rate_noise,
            landed,
        }
    }

    fn advance(&mut self, dt: f64) {
        let p = &self.params;
        let a = if p.correlation_time_s > 0.0 {
            (-dt / p.correlation_time_s).exp()
        } else {
            0.0
        };
        let b = (1.0 - a * a).sqrt();
        let rng = &mut self.rng;
        self.position_noise = self.position_noise * a + normal3(rng) * (b * p.position_std_m);
        self.velocity_noise = self.velocity_noise * a + normal3(rng) * (b * p.velocity_std_m_s);
        self.attitude_noise = self.attitude_noise * a + normal3(rng) * (b * p.attitude_std_rad);
        self.rate_noise = self.rate_noise * a + normal3(rng) * (b * p.rate_std_rad_s);
        let sqrt_dt = dt.sqrt();
        self.position_drift += normal3(rng) * (p.position_drift_m_per_sqrt_s * sqrt_dt);
        self.yaw_drift += rng.normal() * p.yaw_drift_rad_per_sqrt_s * sqrt_dt;
    }
}

fn normal3(rng: &mut Pcg32) -> Vector3<f64> {
    Vector3::new(rng.normal(), rng.normal(), rng.normal())
}

#[cfg(test)]
#[path = "estimator_noise_test.rs"]
mod tests;
