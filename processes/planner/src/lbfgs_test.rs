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
