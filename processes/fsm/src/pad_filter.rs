//! The pad's motion: on each horizontal axis an interacting multiple model (IMM) of a
//! constant-velocity and a constant-acceleration Kalman filter, a constant-velocity one
//! on the height and one on the heading, fed by pad observations at their capture time
//! and predicted to "now".
//!
//! Each axis is its own filter: the measurement noise is diagonal in the world frame (a
//! range-scaled sphere), so the joint filter would factor into these. Constant velocity
//! alone lags a braking or a lane change (its velocity trails a 0.45 m/s^2 braking by
//! about 0.17 m/s, enough to drift 10 cm in a touchdown's drop); constant acceleration
//! alone is noisier on a cruising vehicle. The IMM weighs the two by how well each
//! explains the observations (docs/fsm.md, "Pad motion filter").
//! A vehicle's velocity turns with its heading: with `turn_with_heading_below_m_s` set
//! (off by default) the heading filter's rate turns both horizontal models' velocity and
//! acceleration at each prediction (a coordinated turn whose rate is measured, not
//! guessed), so a curve is followed without the Cartesian models' lag (docs/fsm.md,
//! "Turning with the heading").
//! Observations arrive late (camera exposure, detection, IPC); the filter runs on capture
//! times and only the estimate is extrapolated to the caller's clock, which is what
//! compensates each observation's age.

use ipc_types::msg::PadObservation;
use nalgebra::{Matrix3, UnitQuaternion, Vector3};

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

/// One horizontal axis as an interacting multiple model: model 0 constant velocity (the
/// acceleration held at zero), model 1 constant acceleration; states (x, v, a).
#[derive(Debug, Clone, Copy, PartialEq)]
struct ImmAxis {
    x: [Vector3<f64>; 2],
    p: [Matrix3<f64>; 2],
    /// Model probabilities.
    mu: [f64; 2],
}

/// The probability of either model never falls below this: a model written off for good
/// could not take over when the vehicle starts to brake.
const MU_MIN: f64 = 1e-3;

/// How far ahead the estimate extrapolates the pad's acceleration, s.
const ACCEL_HORIZON_S: f64 = 0.5;

/// Process noise of the models over `dt`.
struct ImmNoise {
    /// White acceleration of the constant-velocity model, (m/s^2)^2 s.
    q_cv: f64,
    /// White jerk of the constant-acceleration model, (m/s^3)^2 s.
    q_ca: f64,
    /// Mean time in each model, s.
    sojourn_s: [f64; 2],
}

impl ImmAxis {
    fn new(x: f64, var_x: f64, var_v: f64, var_a: f64) -> Self {
        let p = Matrix3::from_diagonal(&Vector3::new(var_x, var_v, var_a));
        let p_cv = Matrix3::from_diagonal(&Vector3::new(var_x, var_v, 0.0));
        Self {
            x: [Vector3::new(x, 0.0, 0.0); 2],
            p: [p_cv, p],
            mu: [0.9, 0.1],
        }
    }

    /// Mixing (each model starts from the others' states weighted by how likely the
    /// switch was), then each model's prediction over `dt`.
    fn predict(&mut self, dt: f64, n: &ImmNoise) {
        let stay = [(-dt / n.sojourn_s[0]).exp(), (-dt / n.sojourn_s[1]).exp()];
        // pi[i][j]: from model i to model j.
        let pi = [[stay[0], 1.0 - stay[0]], [1.0 - stay[1], stay[1]]];
        let c = [
            pi[0][0] * self.mu[0] + pi[1][0] * self.mu[1],
            pi[0][1] * self.mu[0] + pi[1][1] * self.mu[1],
        ];
        let mut x0 = [Vector3::zeros(); 2];
        let mut p0 = [Matrix3::zeros(); 2];
        for j in 0..2 {
            let w = [pi[0][j] * self.mu[0] / c[j], pi[1][j] * self.mu[1] / c[j]];
            x0[j] = self.x[0] * w[0] + self.x[1] * w[1];
            for ((x, p), w) in self.x.iter().zip(&self.p).zip(w) {
                let d = x - x0[j];
                p0[j] += (p + d * d.transpose()) * w;
            }
        }
        let (dt2, dt3) = (dt * dt, dt * dt * dt);
        let f_cv = Matrix3::new(1.0, dt, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0);
        let q_cv =
            Matrix3::new(dt3 / 3.0, dt2 / 2.0, 0.0, dt2 / 2.0, dt, 0.0, 0.0, 0.0, 0.0) * n.q_cv;
        let f_ca = Matrix3::new(1.0, dt, dt2 / 2.0, 0.0, 1.0, dt, 0.0, 0.0, 1.0);
        let (dt4, dt5) = (dt3 * dt, dt3 * dt2);
        let q_ca = Matrix3::new(
            dt5 / 20.0,
            dt4 / 8.0,
            dt3 / 6.0,
            dt4 / 8.0,
            dt3 / 3.0,
            dt2 / 2.0,
            dt3 / 6.0,
            dt2 / 2.0,
            dt,
        ) * n.q_ca;
        self.x = [f_cv * x0[0], f_ca * x0[1]];
        self.p = [
            f_cv * p0[0] * f_cv.transpose() + q_cv,
            f_ca * p0[1] * f_ca.transpose() + q_ca,
        ];
        self.mu = c;
    }

    /// The models' weighted velocity (the combined state's, without its covariance).
    fn velocity(&self) -> f64 {
        self.x[0][1] * self.mu[0] + self.x[1][1] * self.mu[1]
    }

    /// The models combined: state and covariance.
    fn combined(&self) -> (Vector3<f64>, Matrix3<f64>) {
        let x = self.x[0] * self.mu[0] + self.x[1] * self.mu[1];
        let mut p = Matrix3::zeros();
        for j in 0..2 {
            let d = self.x[j] - x;
            p += (self.p[j] + d * d.transpose()) * self.mu[j];
        }
        (x, p)
    }

    /// Innovation and its variance of the combined prediction, for the gate.
    fn innovation(&self, z: f64, r: f64) -> (f64, f64) {
        let (x, p) = self.combined();
        (z - x[0], p[(0, 0)] + r)
    }

    /// Each model updated with a position measurement `z` of variance `r`, and the model
    /// probabilities with each model's likelihood of it.
    fn update(&mut self, z: f64, r: f64) {
        let mut like = [0.0; 2];
        for ((x, p), l) in self.x.iter_mut().zip(&mut self.p).zip(&mut like) {
            let e = z - x[0];
            let s = p[(0, 0)] + r;
            let k = p.column(0) / s;
            *x += k * e;
            *p -= k * p.row(0);
            *p = (*p + p.transpose()) * 0.5;
            *l = (-0.5 * e * e / s).exp() / s.sqrt();
        }
        let w = [like[0] * self.mu[0], like[1] * self.mu[1]];
        let sum = w[0] + w[1];
        if sum.is_finite() && sum > 0.0 {
            let m1 = (w[1] / sum).clamp(MU_MIN, 1.0 - MU_MIN);
            self.mu = [1.0 - m1, m1];
        }
    }
}

/// Turns both models' horizontal velocity and acceleration by `angle` (rad, about up):
/// the pad's velocity follows its heading. The covariances are left as they are: they are
/// nearly the same on both axes, so a rotation hardly changes them.
fn turn(xy: &mut [ImmAxis; 2], angle: f64) {
    if angle == 0.0 || !angle.is_finite() {
        return;
    }
    let (s, c) = angle.sin_cos();
    let [ex, ny] = xy;
    for j in 0..2 {
        for k in 1..3 {
            let (a, b) = (ex.x[j][k], ny.x[j][k]);
            ex.x[j][k] = c * a - s * b;
            ny.x[j][k] = s * a + c * b;
        }
    }
}

/// The acceleration that turns velocity `v` at `w` rad/s (horizontal, toward the turn).
pub(crate) fn turn_pull(v: &Vector3<f64>, w: f64) -> Vector3<f64> {
    Vector3::new(-v.y, v.x, 0.0) * w
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
    /// Horizontal acceleration, m/s^2 (the models' weighted mean, near zero while the
    /// vehicle cruises, plus the turn of the velocity at the heading rate).
    pub acceleration: Vector3<f64>,
    /// Horizontal acceleration by the manoeuvring model alone (plus the turn), m/s^2: it
    /// sees a braking begin within a few frames, where the weighted mean takes twice as
    /// long.
    pub manoeuvre_acceleration: Vector3<f64>,
    /// 1-sigma position uncertainty per axis, m.
    pub position_sigma: Vector3<f64>,
    /// How long the heading has been measured for since the filter started, s (gaps
    /// longer than [`HEADING_GAP_S`] not counted): a heading rate read off a glimpse of a
    /// fast pad passing under the camera is noise, not a curve.
    pub heading_seen_s: f64,
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
    /// East and north (IMM), and up (constant velocity).
    axes: Option<([ImmAxis; 2], Axis)>,
    yaw: Axis,
    /// Whether the heading was measured since the last start (a filter started without
    /// one has a heading rate of nothing).
    heading_seen: bool,
    /// [`PadEstimate::heading_seen_s`].
    heading_seen_s: f64,
    /// Capture time the state refers to, ns.
    t_ns: u64,
    updates: u32,
    rejects_in_row: u32,
    counters: FilterCounters,
}

/// The longest gap between two heading measurements counted in
/// [`PadEstimate::heading_seen_s`], s: a few dropped frames, not a pass out of view.
pub const HEADING_GAP_S: f64 = 0.2;

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
            heading_seen: false,
            heading_seen_s: 0.0,
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
        let Some((z, r, yaw_seen)) = self.measurement(now_ns, obs) else {
            self.counters.dropped += 1;
            return Update::Dropped;
        };
        let t = obs.msg.capture_ns.min(now_ns);
        let Some(axes) = self.axes else {
            self.start(t, &z, r, yaw_seen);
            return Update::Started;
        };
        if t < self.t_ns {
            // Out of order (an older frame overtaken by a newer one): the state has moved on.
            self.counters.dropped += 1;
            return Update::Dropped;
        }
        let dt = (t - self.t_ns) as f64 * 1e-9;
        let noise = self.imm_noise();
        let (mut xy, mut up) = axes;
        let mut yaw = self.yaw;
        yaw.predict(dt, self.cfg.yaw_accel_noise.powi(2));
        self.predict_xy(&mut xy, dt, yaw.v, &noise);
        up.predict(dt, self.cfg.accel_noise_z.powi(2));
        let innovations = [
            xy[0].innovation(z.x, r),
            xy[1].innovation(z.y, r),
            up.innovation(z.z, r),
        ];
        let nis: f64 = innovations.iter().map(|(e, s)| e * e / s).sum();
        if !(nis.is_finite() && nis <= self.cfg.gate_chi2) {
            self.rejects_in_row += 1;
            if self.rejects_in_row >= self.cfg.max_rejects {
                self.counters.restarts += 1;
                self.start(t, &z, r, yaw_seen);
                return Update::Restarted;
            }
            self.counters.rejected += 1;
            return Update::Rejected;
        }
        self.rejects_in_row = 0;
        xy[0].update(z.x, r);
        xy[1].update(z.y, r);
        let (e, s) = innovations[2];
        up.update(e, s);
        self.axes = Some((xy, up));
        self.yaw = yaw;
        if let Some(y) = yaw_seen {
            let (e, s) = self.yaw.innovation(y, self.cfg.sigma_yaw_rad.powi(2));
            let e = wrap(e);
            // A heading jump beyond 3 sigma (a marker misread) moves only the position.
            if e * e / s <= 9.0 {
                self.yaw.update(e, s);
                self.yaw.x = wrap(self.yaw.x);
                if self.heading_seen && dt <= HEADING_GAP_S {
                    self.heading_seen_s += dt;
                }
                self.heading_seen = true;
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
        // The acceleration is trusted for a short extrapolation only (latency, a missed
        // frame); beyond it the pad goes on at its velocity, as a braking car stops
        // rather than reversing.
        let dt_a = dt.min(ACCEL_HORIZON_S);
        let dt_v = dt - dt_a;
        let (mut xy, mut up) = axes;
        let noise = self.imm_noise();
        if dt_a > 0.0 {
            self.predict_xy(&mut xy, dt_a, self.yaw.v, &noise);
        }
        let mut p = Vector3::zeros();
        let mut v = Vector3::zeros();
        let mut acc = Vector3::zeros();
        let mut manoeuvre_acc = Vector3::zeros();
        let mut sigma = Vector3::zeros();
        for (k, a) in xy.iter().enumerate() {
            let (x, cov) = a.combined();
            p[k] = x[0] + x[1] * dt_v;
            v[k] = x[1];
            acc[k] = x[2];
            manoeuvre_acc[k] = a.x[1][2];
            sigma[k] = (cov[(0, 0)] + cov[(1, 1)] * dt_v * dt_v).max(0.0).sqrt();
        }
        // The turn of the velocity is an acceleration as well, across it: a curve is a
        // manoeuvre to wait out as a braking is.
        let pull = turn_pull(&v, self.turn_rate(v.xy().norm(), self.yaw.v));
        acc += pull;
        manoeuvre_acc += pull;
        up.predict(dt, self.cfg.accel_noise_z.powi(2));
        p.z = up.x;
        v.z = up.v;
        sigma.z = up.pxx.max(0.0).sqrt();
        let mut y = self.yaw;
        y.predict(dt, self.cfg.yaw_accel_noise.powi(2));
        let est = PadEstimate {
            position: p,
            velocity: v,
            yaw: wrap(y.x),
            yaw_rate: y.v,
            acceleration: acc,
            manoeuvre_acceleration: manoeuvre_acc,
            position_sigma: sigma,
            heading_seen_s: self.heading_seen_s,
            age_s,
        };
        let finite = est
            .position
            .iter()
            .chain(est.velocity.iter())
            .chain(est.acceleration.iter())
            .chain(est.manoeuvre_acceleration.iter())
            .all(|x| x.is_finite())
            && est.yaw.is_finite();
        finite.then_some(est)
    }

    /// Both horizontal models predicted over `dt`, their velocity turned at `yaw_rate`
    /// (half before, half after: the position moves along the arc's chord). Only a heading
    /// that was measured turns them, and only below `turn_with_heading_below_m_s`.
    fn predict_xy(&self, xy: &mut [ImmAxis; 2], dt: f64, yaw_rate: f64, noise: &ImmNoise) {
        let speed = xy[0].velocity().hypot(xy[1].velocity());
        let angle = self.turn_rate(speed, yaw_rate) * dt;
        turn(xy, 0.5 * angle);
        for a in xy.iter_mut() {
            a.predict(dt, noise);
        }
        turn(xy, 0.5 * angle);
    }

    /// The rate the models' velocity turns at, for a pad at `speed`: the heading's
    /// `yaw_rate` once a heading was measured and below `turn_with_heading_below_m_s`,
    /// else 0.
    fn turn_rate(&self, speed: f64, yaw_rate: f64) -> f64 {
        if self.heading_seen && speed < self.cfg.turn_with_heading_below_m_s {
            yaw_rate
        } else {
            0.0
        }
    }

    fn imm_noise(&self) -> ImmNoise {
        ImmNoise {
            q_cv: self.cfg.accel_noise_xy.powi(2),
            q_ca: self.cfg.jerk_noise_xy.powi(2),
            sojourn_s: [self.cfg.cruise_sojourn_s, self.cfg.manoeuvre_sojourn_s],
        }
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
        let va = self.cfg.initial_accel_sigma.powi(2);
        self.axes = Some((
            [ImmAxis::new(z.x, r, vv, va), ImmAxis::new(z.y, r, vv, va)],
            Axis::new(z.z, r, 1.0),
        ));
        self.yaw = Axis::new(
            yaw.unwrap_or(0.0),
            if yaw.is_some() { 0.01 } else { 10.0 },
            1.0,
        );
        self.heading_seen = yaw.is_some();
        self.heading_seen_s = 0.0;
        self.t_ns = t;
        self.updates = 1;
        self.rejects_in_row = 0;
        self.counters.accepted += 1;
    }
}

#[cfg(test)]
#[path = "pad_filter_test.rs"]
mod tests;
