//! Uniform cubic B-splines: evaluation, end-state control points, and the fit of a
//! sampled curve to control points (the planner front end's initialization).
//!
//! A crate of its own because two processes need it: the planner builds trajectories
//! with it and the fsm samples them at 50 Hz; the fsm must not depend on the planner.

// `!(x > 0.0)` is how this crate rejects NaN along with the out-of-range values; index
// loops over control points read like the formulas they implement.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]

use nalgebra::Vector3;

/// Position, velocity and acceleration at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct State {
    /// Position, m.
    pub p: Vector3<f64>,
    /// Velocity, m/s.
    pub v: Vector3<f64>,
    /// Acceleration, m/s^2.
    pub a: Vector3<f64>,
}

impl State {
    /// The planning start from px4-link's vehicle state (acceleration taken as 0: the
    /// autopilot does not report it); `None` when it is not finite.
    pub fn from_vehicle(v: &ipc_types::msg::VehicleState) -> Option<Self> {
        let s = Self {
            p: Vector3::from(v.world_from_body.translation),
            v: Vector3::from(v.velocity),
            a: Vector3::zeros(),
        };
        s.is_finite().then_some(s)
    }

    /// A state at rest at `p`.
    pub fn at_rest(p: Vector3<f64>) -> Self {
        Self {
            p,
            ..Self::default()
        }
    }

    /// True when every component is finite.
    pub fn is_finite(&self) -> bool {
        self.p
            .iter()
            .chain(self.v.iter())
            .chain(self.a.iter())
            .all(|x| x.is_finite())
    }
}

/// A uniform cubic B-spline: control points and a knot interval; the curve runs over
/// `0..=(n - 3) * ts` and segment `s` is shaped by points `s..s + 4`.
#[derive(Debug, Clone, PartialEq)]
pub struct BSpline {
    /// Control points, m.
    pub points: Vec<Vector3<f64>>,
    /// Knot interval, s.
    pub ts: f64,
}

impl BSpline {
    /// Duration of the curve, s (0 for fewer than 4 points).
    pub fn duration(&self) -> f64 {
        self.points.len().saturating_sub(3) as f64 * self.ts
    }

    /// Position, velocity and acceleration at `t` (clamped to the curve's span).
    pub fn eval(&self, t: f64) -> State {
        let n = self.points.len();
        if n < 4 || !(self.ts > 0.0) {
            return State::at_rest(self.points.first().copied().unwrap_or_default());
        }
        let segs = n - 3;
        let x = (t / self.ts).clamp(0.0, segs as f64);
        // x >= 0 after the clamp: truncation is the floor (and is inlined).
        let s = (x as usize).min(segs - 1);
        let u = x - s as f64;
        let q = &self.points[s..s + 4];
        let (u2, u3) = (u * u, u * u * u);
        let m = 1.0 - u;
        let bp = [
            m * m * m / 6.0,
            (3.0 * u3 - 6.0 * u2 + 4.0) / 6.0,
            (-3.0 * u3 + 3.0 * u2 + 3.0 * u + 1.0) / 6.0,
            u3 / 6.0,
        ];
        let bv = [
            -0.5 * m * m,
            1.5 * u2 - 2.0 * u,
            -1.5 * u2 + u + 0.5,
            0.5 * u2,
        ];
        let ba = [m, 3.0 * u - 2.0, -3.0 * u + 1.0, u];
        let mut st = State::default();
        for i in 0..4 {
            st.p += q[i] * bp[i];
            st.v += q[i] * bv[i];
            st.a += q[i] * ba[i];
        }
        st.v /= self.ts;
        st.a /= self.ts * self.ts;
        st
    }

    /// Largest velocity and acceleration norms over the control points' differences:
    /// bounds on the curve's (the convex-hull property).
    pub fn max_vel_acc(&self) -> (f64, f64) {
        let q = &self.points;
        let mut v: f64 = 0.0;
        let mut a: f64 = 0.0;
        for i in 0..q.len().saturating_sub(1) {
            v = v.max((q[i + 1] - q[i]).norm() / self.ts);
        }
        for i in 0..q.len().saturating_sub(2) {
            a = a.max((q[i + 2] - 2.0 * q[i + 1] + q[i]).norm() / (self.ts * self.ts));
        }
        (v, a)
    }
}

/// Position weights of the four control points at `k / per_seg` of a segment, computed
/// once per sampling density: the collision scans evaluate thousands of positions per
/// rebound round, and a full [`BSpline::eval`] (velocity and acceleration too) costs
/// three times as much.
#[derive(Debug, Clone, Default)]
pub struct SegmentSampler {
    weights: Vec<[f64; 4]>,
}

impl SegmentSampler {
    /// Weights for `per_seg` samples per segment (at least 1), reusing the buffer.
    pub fn prepare(&mut self, per_seg: usize) {
        let per_seg = per_seg.max(1);
        if self.weights.len() == per_seg {
            return;
        }
        self.weights.clear();
        self.weights.extend((0..per_seg).map(|k| {
            let u = k as f64 / per_seg as f64;
            let (u2, u3, m) = (u * u, u * u * u, 1.0 - u);
            [
                m * m * m / 6.0,
                (3.0 * u3 - 6.0 * u2 + 4.0) / 6.0,
                (-3.0 * u3 + 3.0 * u2 + 3.0 * u + 1.0) / 6.0,
                u3 / 6.0,
            ]
        }));
    }

    /// Samples per segment the weights are for.
    pub fn per_segment(&self) -> usize {
        self.weights.len()
    }

    /// The curve's position at sample `k` of segment `s` (`points[s..s + 4]` exist).
    #[inline]
    pub fn position(&self, points: &[Vector3<f64>], s: usize, k: usize) -> Vector3<f64> {
        let w = &self.weights[k];
        points[s] * w[0] + points[s + 1] * w[1] + points[s + 2] * w[2] + points[s + 3] * w[3]
    }
}

/// The three control points that give a curve the state `s` at its start (`end` false)
/// or at its end (`end` true), for knot interval `ts`.
pub fn end_points(s: &State, ts: f64) -> [Vector3<f64>; 3] {
    // p = (q0 + 4 q1 + q2) / 6, v = (q2 - q0) / 2ts, a = (q0 - 2 q1 + q2) / ts^2.
    let q1 = s.p - s.a * (ts * ts / 6.0);
    let half = s.a * (ts * ts / 2.0);
    [q1 + half - s.v * ts, q1, q1 + half + s.v * ts]
}

/// Control points for positions sampled every `ts` (`samples[k]` at `k * ts`), with the
/// first and last three points set exactly from `start` and `end` and the others fitted
/// by least squares to the interior samples (rows (1/6)[1 4 1]). Needs >= 5 samples.
pub fn fit(samples: &[Vector3<f64>], ts: f64, start: &State, end: &State) -> Option<BSpline> {
    let k = samples.len();
    if k < 5 || !(ts > 0.0) {
        return None;
    }
    let n = k + 2;
    let mut q = vec![Vector3::zeros(); n];
    let s3 = end_points(start, ts);
    let e3 = end_points(end, ts);
    q[..3].copy_from_slice(&s3);
    q[n - 3..].copy_from_slice(&e3);
    let m = n - 6;
    if m > 0 {
        // Normal equations A^T A x = A^T b for samples 1..=k-2, rows (q_j + 4 q_{j+1} +
        // q_{j+2}) / 6 = s_j. A row touches three consecutive points, so A^T A is banded
        // (half bandwidth 2): a[u][d] = (A^T A)(u, u - d). Built and solved in O(m).
        let mut a = vec![[0.0f64; 3]; m];
        let mut rhs = vec![Vector3::zeros(); m];
        const W: [f64; 3] = [1.0 / 6.0, 4.0 / 6.0, 1.0 / 6.0];
        for j in 1..=k - 2 {
            let mut r = samples[j];
            let mut row = [(0usize, 0.0f64); 3];
            let mut len = 0;
            for (off, w) in W.iter().enumerate() {
                let idx = j + off;
                if (3..n - 3).contains(&idx) {
                    row[len] = (idx - 3, *w);
                    len += 1;
                } else {
                    r -= q[idx] * *w;
                }
            }
            let row = &row[..len];
            for &(u, wu) in row {
                rhs[u] += r * wu;
                for &(v, wv) in row {
                    if v <= u {
                        a[u][u - v] += wu * wv;
                    }
                }
            }
        }
        for d in a.iter_mut() {
            d[0] += 1e-9;
        }
        // Banded Cholesky in place: a[i][d] becomes L(i, i - d).
        for i in 0..m {
            for d in (0..=2usize.min(i)).rev() {
                let j = i - d;
                let mut s = a[i][d];
                for t in 1..=2 {
                    if j < t || d + t > 2 {
                        break;
                    }
                    s -= a[i][d + t] * a[j][t];
                }
                if d == 0 {
                    if !(s > 0.0) {
                        return None;
                    }
                    a[i][0] = s.sqrt();
                } else {
                    a[i][d] = s / a[j][0];
                }
            }
        }
        // L y = rhs, then L^T x = y, the three axes at once.
        for i in 0..m {
            let mut s = rhs[i];
            for d in 1..=2usize.min(i) {
                s -= rhs[i - d] * a[i][d];
            }
            rhs[i] = s / a[i][0];
        }
        for i in (0..m).rev() {
            let mut s = rhs[i];
            for d in 1..=2 {
                if i + d >= m {
                    break;
                }
                s -= rhs[i + d] * a[i + d][d];
            }
            rhs[i] = s / a[i][0];
        }
        q[3..3 + m].copy_from_slice(&rhs);
    }
    if q.iter().all(|p| p.iter().all(|v| v.is_finite())) {
        Some(BSpline { points: q, ts })
    } else {
        None
    }
}

/// A quintic polynomial per axis joining two states in `duration` seconds.
#[derive(Debug, Clone, Copy)]
pub struct Quintic {
    c: [Vector3<f64>; 6],
}

impl Quintic {
    /// The quintic from `a` to `b` over `t` s (`t` > 0).
    pub fn new(a: &State, b: &State, t: f64) -> Self {
        let (t2, t3) = (t * t, t * t * t);
        let (t4, t5) = (t3 * t, t3 * t2);
        // Solve for c3, c4, c5 from the end position, velocity and acceleration.
        let m = nalgebra::Matrix3::new(
            t3,
            t4,
            t5, //
            3.0 * t2,
            4.0 * t3,
            5.0 * t4, //
            6.0 * t,
            12.0 * t2,
            20.0 * t3,
        );
        let inv = m.try_inverse().unwrap_or_else(nalgebra::Matrix3::zeros);
        let rp = b.p - a.p - a.v * t - a.a * (0.5 * t2);
        let rv = b.v - a.v - a.a * t;
        let ra = b.a - a.a;
        let mut c3 = Vector3::zeros();
        let mut c4 = Vector3::zeros();
        let mut c5 = Vector3::zeros();
        for i in 0..3 {
            let x = inv * Vector3::new(rp[i], rv[i], ra[i]);
            c3[i] = x[0];
            c4[i] = x[1];
            c5[i] = x[2];
        }
        Self {
            c: [a.p, a.v, a.a * 0.5, c3, c4, c5],
        }
    }

    /// Position, velocity, acceleration at `t`.
    pub fn eval(&self, t: f64) -> State {
        let c = &self.c;
        let p = c[0] + (c[1] + (c[2] + (c[3] + (c[4] + c[5] * t) * t) * t) * t) * t;
        let v = c[1] + (c[2] * 2.0 + (c[3] * 3.0 + (c[4] * 4.0 + c[5] * (5.0 * t)) * t) * t) * t;
        let a = c[2] * 2.0 + (c[3] * 6.0 + (c[4] * 12.0 + c[5] * (20.0 * t)) * t) * t;
        State { p, v, a }
    }
}

#[cfg(test)]
#[path = "lib_test.rs"]
mod tests;
