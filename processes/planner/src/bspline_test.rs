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
