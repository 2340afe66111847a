//! L-BFGS's initial inverse Hessian for the planner: the smoothness term's Hessian on the
//! free control points, plus a diagonal for the points that have rebound pairs, factored
//! once per optimization.
//!
//! The jerk term alone is badly conditioned (its Hessian's eigenvalues span ~(n/pi)^6), so
//! L-BFGS with a scaled identity needs 50-200 iterations per optimization; with this H0
//! the quadratic part is solved exactly and the iterations only have to learn the rest.
//! The matrix is the same for x, y and z and banded (half bandwidth 3): the factor and a
//! solve are O(n).

/// Half bandwidth of the jerk Hessian.
const BAND: usize = 3;

/// A banded Cholesky factor of `2 w J^T J + diag(extra)` on the free points `3..n-3`.
#[derive(Debug, Clone, Default)]
pub struct JerkPreconditioner {
    /// `l[i][k]` = L(i, i - k); `l[i][0]` is the diagonal.
    l: Vec<[f64; BAND + 1]>,
    /// 1 / L(i, i).
    inv: Vec<f64>,
    /// Whether the last [`JerkPreconditioner::factor`] succeeded.
    ready: bool,
}

impl JerkPreconditioner {
    /// Factors the Hessian of `weight * sum |jerk|^2` over `n` control points (the first
    /// and last three fixed) plus `extra[k]` on the diagonal of free point `k` (missing
    /// entries count as 0). Returns false, and [`JerkPreconditioner::apply`] does
    /// nothing, when there are no free points or the matrix is not positive definite.
    pub fn factor(&mut self, n: usize, weight: f64, extra: &[f64]) -> bool {
        self.ready = false;
        self.l.clear();
        if n < 7 || !(weight > 0.0 && weight.is_finite()) {
            return false;
        }
        let m = n - 6;
        // The banded symmetric matrix, stored like the factor: a[i][k] = A(i, i - k).
        self.l.resize(m, [0.0; BAND + 1]);
        const C: [f64; 4] = [-1.0, 3.0, -3.0, 1.0];
        for row in 0..n - 3 {
            // Jerk row `row` touches points row..row + 4.
            for (ca, &a) in C.iter().enumerate() {
                let pa = row + ca;
                if !(3..n - 3).contains(&pa) {
                    continue;
                }
                for (cb, &b) in C.iter().enumerate().take(ca + 1) {
                    let pb = row + cb;
                    if !(3..n - 3).contains(&pb) {
                        continue;
                    }
                    self.l[pa - 3][ca - cb] += 2.0 * weight * a * b;
                }
            }
        }
        for (k, e) in extra.iter().take(m).enumerate() {
            if e.is_finite() && *e > 0.0 {
                self.l[k][0] += e;
            }
        }
        // In-place banded Cholesky.
        for i in 0..m {
            for k in (0..=BAND.min(i)).rev() {
                let j = i - k;
                let mut s = self.l[i][k];
                for t in 1..=BAND {
                    // L(i, j - t) * L(j, j - t), both inside the band.
                    if j < t || k + t > BAND {
                        break;
                    }
                    s -= self.l[i][k + t] * self.l[j][t];
                }
                if k == 0 {
                    if !(s > 0.0) {
                        return false;
                    }
                    self.l[i][0] = s.sqrt();
                } else {
                    self.l[i][k] = s / self.l[j][0];
                }
            }
        }
        self.inv.clear();
        self.inv.extend(self.l.iter().map(|r| 1.0 / r[0]));
        self.ready = true;
        true
    }

    /// Solves `A z = d` in place for each axis; `d` holds the free points as
    /// `[x0, y0, z0, x1, ...]`. Does nothing unless the last factorization succeeded and
    /// `d` has its size.
    pub fn apply(&self, d: &mut [f64]) -> bool {
        let m = self.l.len();
        if !self.ready || d.len() != 3 * m {
            return false;
        }
        // The three axes share the factor: one pass carries three independent chains
        // (the substitutions are latency-bound), and the diagonal is multiplied by its
        // inverse rather than divided by.
        for i in 0..m {
            let row = &self.l[i];
            let mut s = [d[3 * i], d[3 * i + 1], d[3 * i + 2]];
            for k in 1..=BAND.min(i) {
                let j = 3 * (i - k);
                for a in 0..3 {
                    s[a] -= row[k] * d[j + a];
                }
            }
            for a in 0..3 {
                d[3 * i + a] = s[a] * self.inv[i];
            }
        }
        for i in (0..m).rev() {
            let mut s = [d[3 * i], d[3 * i + 1], d[3 * i + 2]];
            for k in 1..=BAND {
                let r = i + k;
                if r >= m {
                    break;
                }
                for a in 0..3 {
                    s[a] -= self.l[r][k] * d[3 * r + a];
                }
            }
            for a in 0..3 {
                d[3 * i + a] = s[a] * self.inv[i];
            }
        }
        true
    }
}

#[cfg(test)]
#[path = "precond_test.rs"]
mod tests;
