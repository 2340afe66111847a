use super::*;

struct Rosenbrock;

impl Objective for Rosenbrock {
    fn eval(&mut self, x: &[f64], g: &mut [f64]) -> f64 {
        let mut f = 0.0;
        g.iter_mut().for_each(|v| *v = 0.0);
        for i in 0..x.len() - 1 {
            let a = x[i + 1] - x[i] * x[i];
            let b = 1.0 - x[i];
            f += 100.0 * a * a + b * b;
            g[i] += -400.0 * a * x[i] - 2.0 * b;
            g[i + 1] += 200.0 * a;
        }
        f
    }
}

#[test]
fn lbfgs_minimizes_a_rosenbrock_function() {
    let mut solver = Lbfgs::new(LbfgsSettings {
        g_tolerance: 1e-8,
        max_iterations: 2000,
        ..LbfgsSettings::default()
    });
    let mut x = vec![-1.2, 1.0, -1.2, 1.0, -1.2, 1.0];
    let r = solver.minimize(&mut Rosenbrock, &mut x);
    assert!(r.cost < 1e-10, "{r:?}");
    for v in &x {
        assert!((v - 1.0).abs() < 1e-4, "{x:?}");
    }
}

struct NanCost;

impl Objective for NanCost {
    fn eval(&mut self, _x: &[f64], g: &mut [f64]) -> f64 {
        g.iter_mut().for_each(|v| *v = 0.0);
        f64::NAN
    }
}

#[test]
fn a_cost_that_is_not_finite_stops_the_solver_without_moving() {
    let mut x = vec![1.0, 2.0];
    let r = Lbfgs::new(LbfgsSettings::default()).minimize(&mut NanCost, &mut x);
    assert_eq!(r.stop, Stop::NotFinite);
    assert_eq!(x, vec![1.0, 2.0]);
}

struct Counting {
    calls: usize,
}

impl Objective for Counting {
    fn eval(&mut self, x: &[f64], g: &mut [f64]) -> f64 {
        Rosenbrock.eval(x, g)
    }

    fn cancel(&mut self, _x: &[f64], iteration: usize) -> bool {
        self.calls += 1;
        iteration >= 3
    }
}

#[test]
fn a_cancelling_objective_stops_the_solver_after_that_iteration() {
    let mut x = vec![-1.2, 1.0];
    let mut f = Counting { calls: 0 };
    let r = Lbfgs::new(LbfgsSettings::default()).minimize(&mut f, &mut x);
    assert_eq!((r.stop, r.iterations, f.calls), (Stop::Cancelled, 3, 3));
}

#[test]
fn the_four_lane_dot_product_equals_the_plain_sum_for_every_tail_length() {
    for n in 0..11 {
        let a: Vec<f64> = (0..n).map(|i| i as f64 * 0.5 - 1.0).collect();
        let b: Vec<f64> = (0..n).map(|i| 2.0 - i as f64 * 0.25).collect();
        let plain: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
        assert!((dot(&a, &b) - plain).abs() < 1e-12, "n {n}");
    }
}
