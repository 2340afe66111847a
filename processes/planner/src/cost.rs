//! The back end's cost on the free control points: smoothness, collision, feasibility
//! and (during refinement) fitness, each with its analytic gradient.

use nalgebra::Vector3;

use crate::lbfgs::Objective;

/// A rebound anchor: `p` on an obstacle's surface, `v` the unit direction a control point
/// must move to leave it. The point's signed distance is `(q - p) . v`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pair {
    /// Anchor on the obstacle surface, m.
    pub p: Vector3<f64>,
    /// Unit escape direction.
    pub v: Vector3<f64>,
}

/// Weights of the cost terms.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Weights {
    /// Jerk of the control points.
    pub smooth: f64,
    /// Distance penalty of the {p, v} pairs.
    pub collision: f64,
    /// Velocity and acceleration beyond the limits.
    pub feasibility: f64,
    /// Displacement from the reference curve (refinement only).
    pub fitness: f64,
}

/// The cost function over the free control points `3..n-3` (the first and last three fix
/// the end states).
#[derive(Debug)]
pub struct Cost<'a> {
    /// All control points; the free ones are overwritten from `x` at each evaluation.
    pub q: &'a mut [Vector3<f64>],
    /// Gradient buffer, same length as `q`.
    pub grad: &'a mut [Vector3<f64>],
    /// Pairs per control point.
    pub pairs: &'a [Vec<Pair>],
    /// Term weights.
    pub w: Weights,
    /// Knot interval, s.
    pub ts: f64,
    /// Velocity limit (norm), m/s.
    pub max_vel: f64,
    /// Acceleration limit (norm), m/s^2.
    pub max_acc: f64,
    /// Clearance sf, m.
    pub clearance: f64,
    /// Reference points for the fitness term (same length as `q`), when refining.
    pub reference: Option<&'a [Vector3<f64>]>,
    /// 1 / a^2 (axial) and 1 / b^2 (radial) of the fitness ellipsoid.
    pub fitness_inv2: (f64, f64),
}

/// Collision penalty of one pair and its derivative with respect to c = sf - d.
pub fn collision_penalty(c: f64, sf: f64) -> (f64, f64) {
    if c <= 0.0 {
        (0.0, 0.0)
    } else if c <= sf {
        (c * c * c, 3.0 * c * c)
    } else {
        (
            3.0 * sf * c * c - 3.0 * sf * sf * c + sf * sf * sf,
            6.0 * sf * c - 3.0 * sf * sf,
        )
    }
}

impl Cost<'_> {
    /// Evaluates the cost of `self.q` into `self.grad` (all points, fixed included).
    pub fn evaluate_points(&mut self) -> f64 {
        let n = self.q.len();
        let q = &*self.q;
        let g = &mut *self.grad;
        g.iter_mut().for_each(|v| *v = Vector3::zeros());
        let mut total = 0.0;
        // Smoothness: squared jerk of the control points.
        if self.w.smooth > 0.0 {
            for i in 0..n.saturating_sub(3) {
                let j = q[i + 3] - q[i + 2] * 3.0 + q[i + 1] * 3.0 - q[i];
                total += self.w.smooth * j.norm_squared();
                let d = j * (2.0 * self.w.smooth);
                g[i] -= d;
                g[i + 1] += d * 3.0;
                g[i + 2] -= d * 3.0;
                g[i + 3] += d;
            }
        }
        // Collision: free points only.
        if self.w.collision > 0.0 {
            for i in 3..n.saturating_sub(3) {
                for pr in self.pairs.get(i).map(|v| v.as_slice()).unwrap_or(&[]) {
                    let d = (q[i] - pr.p).dot(&pr.v);
                    let (c, dc) = collision_penalty(self.clearance - d, self.clearance);
                    total += self.w.collision * c;
                    g[i] -= pr.v * (self.w.collision * dc);
                }
            }
        }
        // Feasibility: velocity and acceleration norms on control-point differences.
        if self.w.feasibility > 0.0 {
            let ts = self.ts;
            let inv_ts2 = 1.0 / (ts * ts);
            for i in 0..n.saturating_sub(1) {
                let v = (q[i + 1] - q[i]) / ts;
                let vn = v.norm();
                if vn > self.max_vel {
                    let e = vn - self.max_vel;
                    total += self.w.feasibility * e * e * inv_ts2;
                    let dv = v * (2.0 * self.w.feasibility * e * inv_ts2 / vn / ts);
                    g[i + 1] += dv;
                    g[i] -= dv;
                }
            }
            for i in 0..n.saturating_sub(2) {
                let a = (q[i + 2] - q[i + 1] * 2.0 + q[i]) * inv_ts2;
                let an = a.norm();
                if an > self.max_acc {
                    let e = an - self.max_acc;
                    total += self.w.feasibility * e * e;
                    let da = a * (2.0 * self.w.feasibility * e / an * inv_ts2);
                    g[i + 2] += da;
                    g[i + 1] -= da * 2.0;
                    g[i] += da;
                }
            }
        }
        // Fitness: axial and radial displacement from the reference curve.
        if let (Some(r), true) = (self.reference, self.w.fitness > 0.0) {
            let (ia, ib) = self.fitness_inv2;
            for i in 3..n.saturating_sub(3).min(r.len().saturating_sub(1)) {
                let t = r[i + 1] - r[i - 1];
                let tn = t.norm();
                let dq = q[i] - r[i];
                if tn < 1e-9 {
                    total += self.w.fitness * ib * dq.norm_squared();
                    g[i] += dq * (2.0 * self.w.fitness * ib);
                    continue;
                }
                let t = t / tn;
                let ax = dq.dot(&t);
                let rad = dq - t * ax;
                total += self.w.fitness * (ia * ax * ax + ib * rad.norm_squared());
                g[i] += (t * (2.0 * ia * ax) + rad * (2.0 * ib)) * self.w.fitness;
            }
        }
        total
    }
}

impl Objective for Cost<'_> {
    fn eval(&mut self, x: &[f64], gx: &mut [f64]) -> f64 {
        let n = self.q.len();
        for (k, i) in (3..n.saturating_sub(3)).enumerate() {
            self.q[i] = Vector3::new(x[3 * k], x[3 * k + 1], x[3 * k + 2]);
        }
        let c = self.evaluate_points();
        for (k, i) in (3..n.saturating_sub(3)).enumerate() {
            gx[3 * k] = self.grad[i][0];
            gx[3 * k + 1] = self.grad[i][1];
            gx[3 * k + 2] = self.grad[i][2];
        }
        c
    }
}

#[cfg(test)]
#[path = "cost_test.rs"]
mod tests;
