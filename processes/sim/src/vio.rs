//! A visual-inertial odometry sensor (the paper flew an Intel T265): the true pose seen
//! through a VIO's errors, for an autopilot that fuses it (real PX4 through `sim
//! --px4-sitl`, GPS-denied, as the paper's vehicle flew). Its frame starts at the world's
//! origin and wanders from it: position and heading drift as random walks; samples carry
//! white noise and arrive after a latency; now and then the VIO resets (relocalises), its
//! frame jumps and the reset counter says so, as a T265's does.
//!
//! Pure and seeded: the same seed gives the same samples.

use ipc_types::msg::{Header, Pose, VioOdometry};
use nalgebra::{UnitQuaternion, Vector3};
use serde::Deserialize;

use crate::params::{self, ParamError};
use crate::quadrotor::VehicleState;
use crate::rng::Pcg32;

/// The VIO's rate and errors, the `[vio]` section of a scenario (these defaults when
/// absent: a T265-class tracking camera at 30 Hz).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VioParams {
    /// Samples per second (0: no VIO).
    pub rate_hz: f64,
    /// From the camera's exposure to the sample's arrival, ms.
    pub latency_ms: f64,
    /// White noise on each position axis, m (one sigma).
    pub position_std_m: f64,
    /// White noise on each velocity axis, m/s.
    pub velocity_std_m_s: f64,
    /// White noise on roll, pitch and yaw, rad.
    pub attitude_std_rad: f64,
    /// Random walk of the frame's position, m per sqrt(s).
    pub drift_m_per_sqrt_s: f64,
    /// Random walk of the frame's heading, rad per sqrt(s).
    pub yaw_drift_rad_per_sqrt_s: f64,
    /// Mean time between resets, s (exponentially distributed; 0: never).
    pub reset_interval_s: f64,
    /// How far a reset moves the frame, m (one sigma per horizontal axis).
    pub reset_jump_m: f64,
}

impl Default for VioParams {
    fn default() -> Self {
        Self {
            rate_hz: 30.0,
            latency_ms: 15.0,
            position_std_m: 0.005,
            velocity_std_m_s: 0.02,
            attitude_std_rad: 0.3f64.to_radians(),
            drift_m_per_sqrt_s: 0.005,
            yaw_drift_rad_per_sqrt_s: 0.001,
            reset_interval_s: 0.0,
            reset_jump_m: 0.1,
        }
    }
}

impl VioParams {
    /// Checks every field.
    pub fn validate(&self) -> Result<(), ParamError> {
        params::in_range("vio.rate_hz", self.rate_hz, 0.0, 500.0)?;
        params::in_range("vio.latency_ms", self.latency_ms, 0.0, 500.0)?;
        params::in_range("vio.position_std_m", self.position_std_m, 0.0, 1.0)?;
        params::in_range("vio.velocity_std_m_s", self.velocity_std_m_s, 0.0, 1.0)?;
        params::in_range("vio.attitude_std_rad", self.attitude_std_rad, 0.0, 0.2)?;
        params::in_range("vio.drift_m_per_sqrt_s", self.drift_m_per_sqrt_s, 0.0, 1.0)?;
        params::in_range(
            "vio.yaw_drift_rad_per_sqrt_s",
            self.yaw_drift_rad_per_sqrt_s,
            0.0,
            0.1,
        )?;
        params::in_range("vio.reset_interval_s", self.reset_interval_s, 0.0, 1e6)?;
        params::in_range("vio.reset_jump_m", self.reset_jump_m, 0.0, 10.0)
    }
}

/// The sensor: its frame's drift, its schedule, its samples in flight.
#[derive(Debug, Clone)]
pub struct Vio {
    params: VioParams,
    rng: Pcg32,
    /// Where the odometry frame's origin is in the world, m.
    offset: Vector3<f64>,
    /// The odometry frame's heading from the world's, rad.
    yaw: f64,
    next_ns: u64,
    last_ns: u64,
    next_reset_ns: u64,
    resets: u32,
    held: std::collections::VecDeque<(u64, VioOdometry)>,
}

impl Vio {
    /// A VIO with `params`, drawn from `seed`, starting at the world's origin.
    pub fn new(params: VioParams, seed: u64) -> Self {
        let mut rng = Pcg32::with_stream(seed, 61);
        let next_reset_ns = next_reset(&params, &mut rng, 0);
        Self {
            params,
            rng,
            offset: Vector3::zeros(),
            yaw: 0.0,
            next_ns: 0,
            last_ns: 0,
            next_reset_ns,
            resets: 0,
            held: std::collections::VecDeque::new(),
        }
    }

    /// Takes a sample of `truth` at simulated time `now_ns` when one is due.
    pub fn step(&mut self, truth: &VehicleState, now_ns: u64) {
        if self.params.rate_hz <= 0.0 || now_ns < self.next_ns {
            return;
        }
        let dt = (now_ns - self.last_ns) as f64 * 1e-9;
        self.last_ns = now_ns;
        self.next_ns = now_ns + (1e9 / self.params.rate_hz) as u64;
        let p = &self.params;
        let walk = p.drift_m_per_sqrt_s * dt.sqrt();
        self.offset += Vector3::new(self.rng.normal(), self.rng.normal(), self.rng.normal()) * walk;
        self.yaw += p.yaw_drift_rad_per_sqrt_s * dt.sqrt() * self.rng.normal();
        if now_ns >= self.next_reset_ns {
            self.resets += 1;
            let jump = p.reset_jump_m;
            self.offset += Vector3::new(self.rng.normal(), self.rng.normal(), 0.0) * jump;
            self.next_reset_ns = next_reset(p, &mut self.rng, now_ns);
        }
        let odom_from_world = UnitQuaternion::from_euler_angles(0.0, 0.0, self.yaw);
        let mut noise =
            |s: f64| Vector3::new(self.rng.normal(), self.rng.normal(), self.rng.normal()) * s;
        let position = odom_from_world * (truth.position - self.offset) + noise(p.position_std_m);
        let velocity = odom_from_world * truth.velocity + noise(p.velocity_std_m_s);
        let tilt = noise(p.attitude_std_rad);
        let attitude = odom_from_world
            * truth.world_from_body
            * UnitQuaternion::from_euler_angles(tilt.x, tilt.y, tilt.z);
        let q = attitude.into_inner();
        let var = |s: f64| [s * s; 3];
        let sample = VioOdometry {
            msg: Header::captured_at(now_ns),
            odom_from_body: Pose {
                translation: position.into(),
                rotation_xyzw: [q.i, q.j, q.k, q.w],
            },
            velocity: velocity.into(),
            body_rates: truth.body_rates.into(),
            position_variance: var(p.position_std_m.max(0.001)),
            orientation_variance: var(p.attitude_std_rad.max(0.001)),
            velocity_variance: var(p.velocity_std_m_s.max(0.005)),
            reset_counter: self.resets,
            quality: 100,
        };
        let due = now_ns + (p.latency_ms * 1e6) as u64;
        self.held.push_back((due, sample));
    }

    /// The next sample whose latency has passed by `now_ns`, oldest first.
    pub fn take_due(&mut self, now_ns: u64) -> Option<VioOdometry> {
        if self.held.front().is_some_and(|(t, _)| *t <= now_ns) {
            return self.held.pop_front().map(|(_, s)| s);
        }
        None
    }

    /// Resets so far.
    pub fn resets(&self) -> u32 {
        self.resets
    }
}

fn next_reset(p: &VioParams, rng: &mut Pcg32, now_ns: u64) -> u64 {
    if p.reset_interval_s <= 0.0 {
        return u64::MAX;
    }
    let u = rng.uniform().clamp(1e-9, 1.0);
    now_ns + (-u.ln() * p.reset_interval_s * 1e9) as u64
}

#[cfg(test)]
#[path = "vio_test.rs"]
mod tests;
