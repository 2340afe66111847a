use super::*;

fn state(p: [f64; 3], v: [f64; 3], a: [f64; 3]) -> State {
    State {
        p: Vector3::from(p),
        v: Vector3::from(v),
        a: Vector3::from(a),
    }
}

#[test]
fn a_quintic_meets_both_end_states() {
    let a = state([0.0, 1.0, 2.0], [1.0, 0.0, -1.0], [0.5, 0.0, 0.0]);
    let b = state([5.0, -2.0, 1.0], [0.0, 2.0, 0.0], [0.0, -1.0, 0.0]);
    let q = Quintic::new(&a, &b, 3.0);
    let s0 = q.eval(0.0);
    let s1 = q.eval(3.0);
    for (x, y) in [
        (s0.p, a.p),
        (s0.v, a.v),
        (s0.a, a.a),
        (s1.p, b.p),
        (s1.v, b.v),
        (s1.a, b.a),
    ] {
        assert!((x - y).norm() < 1e-9, "{x} != {y}");
    }
}

#[test]
fn a_fitted_spline_starts_and_ends_exactly_at_the_requested_states() {
    let a = state([0.0, 0.0, 1.0], [1.0, 0.5, 0.0], [0.0, 0.0, 0.3]);
    let b = state([6.0, 2.0, 1.5], [2.0, 0.0, 0.0], [0.0, 0.0, 0.0]);
    let t = 4.0;
    let q = Quintic::new(&a, &b, t);
    let k = 21;
    let ts = t / (k - 1) as f64;
    let samples: Vec<_> = (0..k).map(|i| q.eval(i as f64 * ts).p).collect();
    let s = fit(&samples, ts, &a, &b).unwrap();
    assert_eq!(s.points.len(), k + 2);
    assert!((s.duration() - t).abs() < 1e-9);
    let e0 = s.eval(0.0);
    let e1 = s.eval(s.duration());
    for (x, y) in [
        (e0.p, a.p),
        (e0.v, a.v),
        (e0.a, a.a),
        (e1.p, b.p),
        (e1.v, b.v),
        (e1.a, b.a),
    ] {
        assert!((x - y).norm() < 1e-9, "{x} != {y}");
    }
    // The interior follows the quintic closely.
    for i in 0..k {
        assert!((s.eval(i as f64 * ts).p - samples[i]).norm() < 0.02);
    }
}

#[test]
fn derivatives_of_the_evaluation_match_finite_differences() {
    let s = BSpline {
        points: (0..8)
            .map(|i| Vector3::new(i as f64, (i as f64).sin(), (i * i) as f64 * 0.1))
            .collect(),
        ts: 0.3,
    };
    let h = 1e-5;
    for k in 1..30 {
        let t = k as f64 * 0.05;
        let d = (s.eval(t + h).p - s.eval(t - h).p) / (2.0 * h);
        assert!((d - s.eval(t).v).norm() < 1e-5);
        let dd = (s.eval(t + h).v - s.eval(t - h).v) / (2.0 * h);
        assert!((dd - s.eval(t).a).norm() < 1e-4);
    }
}

#[test]
fn too_few_samples_or_a_bad_interval_give_no_spline() {
    let st = State::default();
    let five = vec![Vector3::zeros(); 4];
    assert!(fit(&five, 0.1, &st, &st).is_none());
    assert!(fit(&[Vector3::zeros(); 6], f64::NAN, &st, &st).is_none());
}

/// The least-squares fit by dense normal equations (the straightforward way), to check
/// the banded solver against.
fn dense_fit(samples: &[Vector3<f64>], ts: f64, start: &State, end: &State) -> Vec<Vector3<f64>> {
    use nalgebra::{DMatrix, DVector};
    let k = samples.len();
    let n = k + 2;
    let mut q = vec![Vector3::zeros(); n];
    q[..3].copy_from_slice(&end_points(start, ts));
    q[n - 3..].copy_from_slice(&end_points(end, ts));
    let m = n - 6;
    let mut a = DMatrix::<f64>::zeros(k - 2, m);
    let mut b = DMatrix::<f64>::zeros(k - 2, 3);
    for (r, j) in (1..=k - 2).enumerate() {
        let mut rhs = samples[j];
        for (off, w) in [(0usize, 1.0 / 6.0), (1, 4.0 / 6.0), (2, 1.0 / 6.0)] {
            let idx = j + off;
            if (3..n - 3).contains(&idx) {
                a[(r, idx - 3)] += w;
            } else {
                rhs -= q[idx] * w;
            }
        }
        for c in 0..3 {
            b[(r, c)] = rhs[c];
        }
    }
    let chol = (a.transpose() * &a).cholesky().unwrap();
    let atb = a.transpose() * b;
    for c in 0..3 {
        let x = chol.solve(&DVector::from(atb.column(c)));
        for i in 0..m {
            q[3 + i][c] = x[i];
        }
    }
    q
}

#[test]
fn the_banded_fit_equals_the_dense_least_squares_solution() {
    let a = state([0.0, 0.0, 1.0], [1.0, -0.5, 0.0], [0.0, 1.0, 0.3]);
    let b = state([9.0, 3.0, 2.0], [0.0, 2.0, 0.0], [0.0, 0.0, -1.0]);
    for k in [5, 6, 7, 12, 40, 62] {
        let ts = 0.2;
        // Wiggly samples, not a quintic, so the residual is not zero.
        let samples: Vec<_> = (0..k)
            .map(|i| {
                let t = i as f64;
                Vector3::new(t * 0.3, (t * 0.7).sin(), 1.0 + 0.2 * (t * 1.3).cos())
            })
            .collect();
        let s = fit(&samples, ts, &a, &b).unwrap();
        let d = dense_fit(&samples, ts, &a, &b);
        for (x, y) in s.points.iter().zip(&d) {
            assert!((x - y).norm() < 1e-6, "k {k}: {x} != {y}");
        }
    }
}

#[test]
fn a_vehicle_state_becomes_a_start_at_its_position_and_velocity_unless_not_finite() {
    let mut v = ipc_types::msg::VehicleState::default();
    v.world_from_body.translation = [1.0, 2.0, 3.0];
    v.velocity = [0.5, 0.0, -0.1];
    let s = State::from_vehicle(&v).unwrap();
    assert_eq!(s.p, Vector3::new(1.0, 2.0, 3.0));
    assert_eq!(s.v, Vector3::new(0.5, 0.0, -0.1));
    assert_eq!(s.a, Vector3::zeros());
    v.velocity[1] = f64::NAN;
    assert!(State::from_vehicle(&v).is_none());
}
