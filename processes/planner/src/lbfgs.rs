//! L-BFGS with a strong-Wolfe line search (Nocedal & Wright, algorithms 7.4, 3.5, 3.6).
//!
//! All buffers live in [`Lbfgs`] and are sized once per problem size: an iteration
//! allocates nothing, so the planner's time does not depend on the allocator.

/// A differentiable cost.
pub trait Objective {
    /// The cost at `x`; writes the gradient into `g` (same length as `x`).
    fn eval(&mut self, x: &[f64], g: &mut [f64]) -> f64;

    /// Called after every accepted iteration with the new point; returning true stops
    /// the solver there ([`Stop::Cancelled`]). The planner stops as soon as the curve
    /// enters a new obstacle, as EGO-Planner does, instead of converging first.
    fn cancel(&mut self, _x: &[f64], _iteration: usize) -> bool {
        false
    }

    /// Applies an initial inverse-Hessian approximation H0 to `d` in place and returns
    /// true, or returns false (the default) for the usual scaled identity. A good H0 (the
    /// planner's: the exact inverse of the smoothness term's Hessian) turns a badly
    /// conditioned problem into a few iterations.
    fn precondition(&mut self, _d: &mut [f64]) -> bool {
        false
    }
}

/// Solver settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LbfgsSettings {
    /// Correction pairs kept.
    pub memory: usize,
    /// Iteration limit.
    pub max_iterations: usize,
    /// Stop when |g| <= this * max(1, |x|).
    pub g_tolerance: f64,
    /// Sufficient-decrease constant (Armijo).
    pub c1: f64,
    /// Curvature constant (strong Wolfe).
    pub c2: f64,
    /// Function evaluations allowed per line search.
    pub max_line_evals: usize,
    /// Stop when the cost fell by less than `delta` (relative) over the last `past`
    /// iterations (0 disables): the planner needs a good curve, not the last digit.
    pub past: usize,
    /// Relative decrease threshold for `past`.
    pub delta: f64,
}

impl Default for LbfgsSettings {
    fn default() -> Self {
        Self {
            memory: 16,
            max_iterations: 200,
            g_tolerance: 0.01,
            c1: 1e-4,
            c2: 0.9,
            max_line_evals: 30,
            past: 3,
            delta: 1e-4,
        }
    }
}

/// Why the solver stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stop {
    /// The gradient is small enough.
    Converged,
    /// The iteration limit was reached.
    MaxIterations,
    /// The line search found no acceptable step (often: already at a minimum within
    /// rounding).
    LineSearchFailed,
    /// The cost or gradient was not finite at the start.
    NotFinite,
    /// [`Objective::cancel`] asked to stop.
    Cancelled,
}

/// What a minimization did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Report {
    /// Why it stopped.
    pub stop: Stop,
    /// Iterations taken.
    pub iterations: usize,
    /// Cost evaluations.
    pub evaluations: usize,
    /// Final cost.
    pub cost: f64,
}

/// An L-BFGS solver with preallocated workspace.
#[derive(Debug, Clone, Default)]
pub struct Lbfgs {
    settings: LbfgsSettings,
    n: usize,
    s: Vec<f64>,
    y: Vec<f64>,
    rho: Vec<f64>,
    alpha: Vec<f64>,
    d: Vec<f64>,
    g: Vec<f64>,
    x0: Vec<f64>,
    g0: Vec<f64>,
    hy: Vec<f64>,
    history: [f64; 8],
}

/// The ring-buffer slot of the `k`-th newest correction pair (`head` is the next slot to
/// write, `m` the memory): no division in the two-loop recursion.
#[inline]
fn slot(head: usize, k: usize, m: usize) -> usize {
    if head > k {
        head - 1 - k
    } else {
        head + m - 1 - k
    }
}

/// Dot product with four independent accumulators: a single running sum is one long
/// chain of dependent additions, and the two-loop recursion is mostly dot products.
#[inline]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [0.0f64; 4];
    let mut ca = a.chunks_exact(4);
    let mut cb = b.chunks_exact(4);
    for (x, y) in (&mut ca).zip(&mut cb) {
        for k in 0..4 {
            acc[k] += x[k] * y[k];
        }
    }
    let tail: f64 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

impl Lbfgs {
    /// A solver with `settings`.
    pub fn new(settings: LbfgsSettings) -> Self {
        Self {
            settings,
            ..Self::default()
        }
    }

    /// Changes the iteration limit (the planner lowers it to what its work budget has
    /// left).
    pub fn set_max_iterations(&mut self, max_iterations: usize) {
        self.settings.max_iterations = max_iterations;
    }

    /// Changes the relative gradient tolerance for the next minimizations.
    pub fn set_g_tolerance(&mut self, g_tolerance: f64) {
        self.settings.g_tolerance = g_tolerance;
    }

    fn reserve(&mut self, n: usize) {
        let m = self.settings.memory.max(1);
        if self.n == n && self.s.len() == m * n {
            return;
        }
        self.n = n;
        for v in [&mut self.s, &mut self.y] {
            v.clear();
            v.resize(m * n, 0.0);
        }
        for v in [&mut self.rho, &mut self.alpha] {
            v.clear();
            v.resize(m, 0.0);
        }
        for v in [
            &mut self.d,
            &mut self.g,
            &mut self.x0,
            &mut self.g0,
            &mut self.hy,
        ] {
            v.clear();
            v.resize(n, 0.0);
        }
    }

    /// Minimizes `f` from `x` in place.
    pub fn minimize<F: Objective>(&mut self, f: &mut F, x: &mut [f64]) -> Report {
        let n = x.len();
        self.reserve(n);
        let set = self.settings;
        let m = set.memory.max(1);
        let mut evals = 1;
        let mut fx = f.eval(x, &mut self.g);
        if !fx.is_finite() || !self.g.iter().all(|v| v.is_finite()) {
            return Report {
                stop: Stop::NotFinite,
                iterations: 0,
                evaluations: evals,
                cost: fx,
            };
        }
        let mut stored = 0usize;
        let mut head = 0usize; // next slot to write
        let mut iter = 0usize;
        let stop = loop {
            let gn = dot(&self.g, &self.g).sqrt();
            let xn = dot(x, x).sqrt();
            if gn <= set.g_tolerance * xn.max(1.0) {
                break Stop::Converged;
            }
            if iter >= set.max_iterations {
                break Stop::MaxIterations;
            }
            // Two-loop recursion: d = -H g.
            for (d, g) in self.d.iter_mut().zip(&self.g) {
                *d = -g;
            }
            for k in 0..stored {
                let j = slot(head, k, m);
                let sj = &self.s[j * n..(j + 1) * n];
                let a = self.rho[j] * dot(sj, &self.d);
                self.alpha[j] = a;
                let yj = &self.y[j * n..(j + 1) * n];
                for (d, y) in self.d.iter_mut().zip(yj) {
                    *d -= a * y;
                }
            }
            let preconditioned = f.precondition(&mut self.d);
            if stored > 0 && preconditioned {
                // Scale H0 by s.y / y.H0 y, the curvature the last step measured.
                let j = (head + m - 1) % m;
                self.hy.copy_from_slice(&self.y[j * n..(j + 1) * n]);
                if f.precondition(&mut self.hy) {
                    let yj = &self.y[j * n..(j + 1) * n];
                    let sj = &self.s[j * n..(j + 1) * n];
                    let gamma = dot(sj, yj) / dot(yj, &self.hy);
                    if gamma.is_finite() && gamma > 0.0 {
                        for d in self.d.iter_mut() {
                            *d *= gamma;
                        }
                    }
                }
            }
            if stored > 0 && !preconditioned {
                let j = (head + m - 1) % m;
                let sj = &self.s[j * n..(j + 1) * n];
                let yj = &self.y[j * n..(j + 1) * n];
                let gamma = dot(sj, yj) / dot(yj, yj);
                if gamma.is_finite() && gamma > 0.0 {
                    for d in self.d.iter_mut() {
                        *d *= gamma;
                    }
                }
            }
            for k in (0..stored).rev() {
                let j = slot(head, k, m);
                let yj = &self.y[j * n..(j + 1) * n];
                let b = self.rho[j] * dot(yj, &self.d);
                let sj = &self.s[j * n..(j + 1) * n];
                let a = self.alpha[j];
                for (d, s) in self.d.iter_mut().zip(sj) {
                    *d += (a - b) * s;
                }
            }
            let mut dg = dot(&self.d, &self.g);
            let mut preconditioned = preconditioned;
            if !(dg < 0.0) {
                // Not a descent direction: restart from steepest descent (preconditioned
                // when that is one).
                for (d, g) in self.d.iter_mut().zip(&self.g) {
                    *d = -g;
                }
                stored = 0;
                dg = -gn * gn;
                if f.precondition(&mut self.d) && dot(&self.d, &self.g) < 0.0 {
                    dg = dot(&self.d, &self.g);
                } else {
                    preconditioned = false;
                    for (d, g) in self.d.iter_mut().zip(&self.g) {
                        *d = -g;
                    }
                }
            }
            let step0 = if stored == 0 && !preconditioned {
                (1.0 / gn).min(1.0)
            } else {
                1.0
            };
            self.x0.copy_from_slice(x);
            self.g0.copy_from_slice(&self.g);
            let f0 = fx;
            match self.line_search(f, x, f0, dg, step0, &mut evals) {
                Some(fnew) => fx = fnew,
                None => {
                    x.copy_from_slice(&self.x0);
                    self.g.copy_from_slice(&self.g0);
                    fx = f0;
                    break Stop::LineSearchFailed;
                }
            }
            // x and g now hold the new point; store s and y.
            let sl = &mut self.s[head * n..(head + 1) * n];
            for i in 0..n {
                sl[i] = x[i] - self.x0[i];
            }
            let yl = &mut self.y[head * n..(head + 1) * n];
            for i in 0..n {
                yl[i] = self.g[i] - self.g0[i];
            }
            let sy = dot(
                &self.s[head * n..(head + 1) * n],
                &self.y[head * n..(head + 1) * n],
            );
            if sy > 1e-16 {
                self.rho[head] = 1.0 / sy;
                head = (head + 1) % m;
                stored = (stored + 1).min(m);
            }
            iter += 1;
            if f.cancel(x, iter) {
                break Stop::Cancelled;
            }
            let past = set.past.min(self.history.len());
            if past > 0 {
                if iter > past {
                    let old = self.history[iter % past];
                    if (old - fx) / fx.abs().max(1e-12) < set.delta {
                        break Stop::Converged;
                    }
                }
                self.history[iter % past] = fx;
            }
        };
        Report {
            stop,
            iterations: iter,
            evaluations: evals,
            cost: fx,
        }
    }

    /// Strong-Wolfe line search along `self.d` from `self.x0`; on success `x`, `self.g`
    /// hold the accepted point and its gradient and the cost is returned.
    fn line_search<F: Objective>(
        &mut self,
        f: &mut F,
        x: &mut [f64],
        f0: f64,
        dg0: f64,
        step0: f64,
        evals: &mut usize,
    ) -> Option<f64> {
        let set = self.settings;
        let mut a_prev = 0.0;
        let mut f_prev = f0;
        let mut dg_prev = dg0;
        let mut a = step0;
        let mut budget = set.max_line_evals;
        let mut first = true;
        loop {
            if budget == 0 {
                return None;
            }
            budget -= 1;
            let (fa, dga) = self.probe(f, x, a, evals);
            if !fa.is_finite() || fa > f0 + set.c1 * a * dg0 || (!first && fa >= f_prev) {
                return self.zoom(
                    f,
                    x,
                    f0,
                    dg0,
                    (a_prev, f_prev, dg_prev),
                    (a, fa, dga),
                    budget,
                    evals,
                );
            }
            if dga.abs() <= -set.c2 * dg0 {
                return Some(fa);
            }
            if dga >= 0.0 {
                return self.zoom(
                    f,
                    x,
                    f0,
                    dg0,
                    (a, fa, dga),
                    (a_prev, f_prev, dg_prev),
                    budget,
                    evals,
                );
            }
            first = false;
            a_prev = a;
            f_prev = fa;
            dg_prev = dga;
            a *= 2.5;
            if a > 1e10 {
                return None;
            }
        }
    }

    /// Cost and directional derivative at step `a`; leaves x = x0 + a d and g there.
    fn probe<F: Objective>(
        &mut self,
        f: &mut F,
        x: &mut [f64],
        a: f64,
        evals: &mut usize,
    ) -> (f64, f64) {
        for i in 0..x.len() {
            x[i] = self.x0[i] + a * self.d[i];
        }
        *evals += 1;
        let fa = f.eval(x, &mut self.g);
        let dga = dot(&self.g, &self.d);
        if self.g.iter().all(|v| v.is_finite()) {
            (fa, dga)
        } else {
            (f64::NAN, f64::NAN)
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn zoom<F: Objective>(
        &mut self,
        f: &mut F,
        x: &mut [f64],
        f0: f64,
        dg0: f64,
        lo: (f64, f64, f64),
        hi: (f64, f64, f64),
        mut budget: usize,
        evals: &mut usize,
    ) -> Option<f64> {
        let set = self.settings;
        let (mut lo, mut hi) = (lo, hi);
        // Best acceptable (Armijo) point seen, a fallback when the budget runs out.
        let mut best: Option<(f64, f64)> = None;
        if lo.0 > 0.0 && lo.1 < f0 {
            best = Some((lo.0, lo.1));
        }
        while budget > 0 {
            budget -= 1;
            let a = cubic_min(lo, hi);
            let (fa, dga) = self.probe(f, x, a, evals);
            if !fa.is_finite() || fa > f0 + set.c1 * a * dg0 || fa >= lo.1 {
                hi = (a, fa, dga);
            } else {
                if dga.abs() <= -set.c2 * dg0 {
                    return Some(fa);
                }
                if dga * (hi.0 - lo.0) >= 0.0 {
                    hi = lo;
                }
                lo = (a, fa, dga);
                best = Some((a, fa));
            }
            if (hi.0 - lo.0).abs() < 1e-14 * lo.0.abs().max(1e-10) {
                break;
            }
        }
        // Accept the best sufficient-decrease point when strong Wolfe was not reached.
        let (a, _) = best?;
        let (fa, _) = self.probe(f, x, a, evals);
        if fa.is_finite() && fa < f0 {
            Some(fa)
        } else {
            None
        }
    }
}

/// Minimizer of the cubic through two points with slopes, kept inside the bracket
/// (bisection when the cubic misbehaves).
fn cubic_min(lo: (f64, f64, f64), hi: (f64, f64, f64)) -> f64 {
    let (a0, f0, d0) = lo;
    let (a1, f1, d1) = hi;
    let mid = 0.5 * (a0 + a1);
    if !(f1.is_finite() && d1.is_finite()) {
        return mid;
    }
    let d1t = d0 + d1 - 3.0 * (f0 - f1) / (a0 - a1);
    let rad = d1t * d1t - d0 * d1;
    if !(rad >= 0.0) {
        return mid;
    }
    let d2 = (a1 - a0).signum() * rad.sqrt();
    let a = a1 - (a1 - a0) * (d1 + d2 - d1t) / (d1 - d0 + 2.0 * d2);
    let (l, h) = (a0.min(a1), a0.max(a1));
    let margin = 0.1 * (h - l);
    if a.is_finite() && a > l + margin && a < h - margin {
        a
    } else {
        mid
    }
}

#[cfg(test)]
#[path = "lbfgs_test.rs"]
mod tests;
