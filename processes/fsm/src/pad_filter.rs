//! The pad's motion: a constant-velocity Kalman filter on each world axis plus one on
//! the heading, fed by pad observations at their capture time and predicted to "now".
//!
//! Each axis is its own 2-state filter: the measurement noise is diagonal in the world
//! frame (a range-scaled sphere), so the joint filter would factor into exactly these.
//! Observations arrive late (camera exposure, detection, IPC); the filter runs on capture
//! times and only the estimate is extrapolated to the caller's clock, which is what
//! compensates each observation's age.

use ipc_types::msg::PadObservation;
use nalgebra::{UnitQuaternion, Vector3};

use crate::config::PadFilterConfig;

/// One constant-velocity axis: state (x, v) and its covariance.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Axis {
    x: f64,
    v: f64,
    pxx: f64,
    pxv: f64,
    pvv: f64,
}

impl Axis {
    fn new(x: f64, var_x: f64, var_v: f64) -> Self {
        Self {
            x,
            v: 0.0,
            pxx: var_x,
            pxv: 0.0,
            pvv: var_v,
        }
    }

    /// Prediction over `dt` with white acceleration of spectral density `q`.
    fn predict(&mut self, dt: f64, q: f64) {
        let (dt2, dt3) = (dt * dt, dt * dt * dt);
        self.x += self.v * dt;
        self.pxx += 2.0 * dt * self.pxv + dt2 * self.pvv + q * dt3 / 3.0;
        self.pxv += dt * self.pvv + q * dt2 / 2.0;
        self.pvv += q * dt;
    }

    /// Innovation and its variance for a position measurement with variance `r`.
    fn innovation(&self, z: f64, r: f64) -> (f64, f64) {
        (z - self.x, self.pxx + r)
    }

    fn update(&mut self, innovation: f64, s: f64) {
        let (kx, kv) = (self.pxx / s, self.pxv / s);
        self.x += kx * innovation;
        self.v += kv * innovation;
        let (pxx, pxv, pvv) = (self.pxx, self.pxv, self.pvv);
        self.pxx = (1.0 - kx) * pxx;
        self.pxv = (1.0 - kx) * pxv;
        self.pvv = pvv - kv * pxv;
    }
}

/// What became of one observation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Update {
    /// Used.
    Accepted,
    /// The first observation, or the first after a restart.
    Started,
    /// Outside the innovation gate: ignored.
    Rejected,
    /// Too many outliers in a row: the filter restarted at this observation (the pad
    /// really is elsewhere, or the filter was wrong).
    Restarted,
    /// No world pose, a non-finite number, older than the filter, or too old.
    Dropped,
}

/// The pad's estimated motion at a time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PadEstimate {
    /// Pad centre (top surface), world ENU, m.
    pub position: Vector3<f64>,
    /// Velocity, m/s.
    pub velocity: Vector3<f64>,
    /// Heading of the pad's x axis, rad from +x toward +y.
    pub yaw: f64,
    /// Heading rate, rad/s.
    pub yaw_rate: f64,
    /// 1-sigma position uncertainty per axis, m.
    pub position_sigma: Vector3<f64>,
    /// Time since the last used observation's capture, s.
    pub age_s: f64,
}

/// Counts of what the filter did with its input.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FilterCounters {
    /// Observations used.
    pub accepted: u64,
    /// Observations outside the gate.
    pub rejected: u64,
    /// Restarts after consecutive outliers.
    pub restarts: u64,
    /// Observations dropped before the gate.
    pub dropped: u64,
}

/// The pad motion filter.
#[derive(Debug, Clone)]
pub struct PadFilter {
    cfg: PadFilterConfig,
    axes: Option<[Axis; 3]>,
    yaw: Axis,
    /// Capture time the state refers to, ns.
    t_ns: u64,
    updates: u32,
    rejects_in_row: u32,
    counters: FilterCounters,
}

/// Yaw of the pad's x axis from a quaternion (x, y, z, w), rad.
fn yaw_of(q: [f64; 4]) -> Option<f64> {
    let [x, y, z, w] = q;
    let n = (x * x + y * y + z * z + w * w).sqrt();
    if !(n.is_finite() && n > 1e-9) {
        return None;
    }
    let uq = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
    let ax = uq * Vector3::x();
    let yaw = ax.y.atan2(ax.x);
    yaw.is_finite().then_some(yaw)
}

/// `a` wrapped into (-pi, pi].
pub(crate) fn wrap(a: f64) -> f64 {
    let w = a.rem_euclid(std::f64::consts::TAU);
    if w > std::f64::consts::PI {
        w - std::f64::consts::TAU
    } else {
        w
    }
}

impl PadFilter {
    /// An empty filter with `cfg` (validated).
    pub fn new(cfg: PadFilterConfig) -> Self {
        Self {
            cfg,
            axes: None,
            yaw: Axis::new(0.0, 1.0, 1.0),
            t_ns: 0,
            updates: 0,
            rejects_in_row: 0,
            counters: FilterCounters::default(),
        }
    }

    /// What the filter did so far.
    pub fn counters(&self) -> FilterCounters {
        self.counters
    }

    /// Capture time of the newest used observation, ns (None before the first).
    pub fn last_update_ns(&self) -> Option<u64> {
        self.axes.map(|_| self.t_ns)
    }

    /// Takes in `obs`, received at `now_ns` (same clock as its capture time).
    pub fn update(&mut self, now_ns: u64, obs: &PadObservation) -> Update {
        let Some((z, r, yaw)) = self.measurement(now_ns, obs) else {
            self.counters.dropped += 1;
            return Update::Dropped;
        };
        let t = obs.msg.capture_ns.min(now_ns);
        let Some(mut axes) = self.axes else {
            self.start(t, &z, r, yaw);
            return Update::Started;
        };
        if t < self.t_ns {
            // Out of order (an older frame overtaken by a newer one): the state has moved on.
            self.counters.dropped += 1;
            return Update::Dropped;
        }
        let dt = (t - self.t_ns) as f64 * 1e-9;
        let q = [
            self.cfg.accel_noise_xy.powi(2),
            self.cfg.accel_noise_xy.powi(2),
            self.cfg.accel_noise_z.powi(2),
        ];
        for (a, qa) in axes.iter_mut().zip(q) {
            a.predict(dt, qa);
        }
        let mut nis = 0.0;
        let mut innovations = [(0.0, 1.0); 3];
        for (k, a) in axes.iter().enumerate() {
            let (e, s) = a.innovation(z[k], r);
            nis += e * e / s;
            innovations[k] = (e, s);
        }
        if !(nis.is_finite() && nis <= self.cfg.gate_chi2) {
            self.rejects_in_row += 1;
            if self.rejects_in_row >= self.cfg.max_rejects {
                self.counters.restarts += 1;
                self.start(t, &z, r, yaw);
                return Update::Restarted;
            }
            self.counters.rejected += 1;
            return Update::Rejected;
        }
        self.rejects_in_row = 0;
        for (a, (e, s)) in axes.iter_mut().zip(innovations) {
            a.update(e, s);
        }
        self.axes = Some(axes);
        self.yaw.predict(dt, self.cfg.yaw_accel_noise.powi(2));
        if let Some(y) = yaw {
            let (e, s) = self.yaw.innovation(y, self.cfg.sigma_yaw_rad.powi(2));
            let e = wrap(e);
            // A heading jump beyond 3 sigma (a marker misread) moves only the position.
            if e * e / s <= 9.0 {
                self.yaw.update(e, s);
                self.yaw.x = wrap(self.yaw.x);
            }
        }
        self.t_ns = t;
        self.updates = self.updates.saturating_add(1);
        self.counters.accepted += 1;
        Update::Accepted
    }

    /// The estimate extrapolated to `at_ns`; `None` until `min_updates` observations
    /// were used. Extrapolation is capped at 2 s: beyond that the caller is lost anyway.
    pub fn estimate(&self, at_ns: u64) -> Option<PadEstimate> {
        let axes = self.axes?;
        if self.updates < self.cfg.min_updates {
            return None;
        }
        let age_s = at_ns.saturating_sub(self.t_ns) as f64 * 1e-9;
        let dt = age_s.min(2.0);
        let mut p = Vector3::zeros();
        let mut v = Vector3::zeros();
        let mut sigma = Vector3::zeros();
        let q = [
            self.cfg.accel_noise_xy.powi(2),
            self.cfg.accel_noise_xy.powi(2),
            self.cfg.accel_noise_z.powi(2),
        ];
        for k in 0..3 {
            let mut a = axes[k];
            a.predict(dt, q[k]);
            p[k] = a.x;
            v[k] = a.v;
            sigma[k] = a.pxx.max(0.0).sqrt();
        }
        let mut y = self.yaw;
        y.predict(dt, self.cfg.yaw_accel_noise.powi(2));
        let est = PadEstimate {
            position: p,
            velocity: v,
            yaw: wrap(y.x),
            yaw_rate: y.v,
            position_sigma: sigma,
            age_s,
        };
        let finite = est
            .position
            .iter()
            .chain(est.velocity.iter())
            .all(|x| x.is_finite())
            && est.yaw.is_finite();
        finite.then_some(est)
    }

    /// World position, its variance, and the heading of `obs`; `None` when unusable.
    fn measurement(
        &self,
        now_ns: u64,
        obs: &PadObservation,
    ) -> Option<(Vector3<f64>, f64, Option<f64>)> {
        if obs.world_valid == 0 || !obs.world_from_pad.is_finite() {
            return None;
        }
        let age_s = now_ns.saturating_sub(obs.msg.capture_ns) as f64 * 1e-9;
        if age_s > self.cfg.max_age_s {
            return None;
        }
        let z = Vector3::from(obs.world_from_pad.translation);
        let range = Vector3::from(obs.camera_from_pad.translation).norm();
        let range = if range.is_finite() { range } else { 0.0 };
        let sigma = self.cfg.sigma_m + self.cfg.sigma_per_m * range;
        Some((z, sigma * sigma, yaw_of(obs.world_from_pad.rotation_xyzw)))
    }

    fn start(&mut self, t: u64, z: &Vector3<f64>, r: f64, yaw: Option<f64>) {
        let vv = self.cfg.initial_speed_sigma.powi(2);
        self.axes = Some([
            Axis::new(z.x, r, vv),
            Axis::new(z.y, r, vv),
            Axis::new(z.z, r, 1.0),
        ]);
        self.yaw = Axis::new(
            yaw.unwrap_or(0.0),
            if yaw.is_some() { 0.01 } else { 10.0 },
            1.0,
        );
        self.t_ns = t;
        self.updates = 1;
        self.rejects_in_row = 0;
        self.counters.accepted += 1;
    }
}
