use super::*;

#[test]
fn analytic_gradients_match_finite_differences() {
    let n = 12;
    let mut q: Vec<Vector3<f64>> = (0..n)
        .map(|i| {
            let t = i as f64;
            Vector3::new(0.45 * t, 0.3 * (0.7 * t).sin(), 1.0 + 0.05 * t * t)
        })
        .collect();
    let reference: Vec<Vector3<f64>> = q
        .iter()
        .map(|p| p + Vector3::new(0.05, -0.1, 0.02))
        .collect();
    let mut pairs = vec![Vec::new(); n];
    pairs[4].push(Pair {
        p: q[4] + Vector3::new(0.0, 0.2, 0.0),
        v: Vector3::new(0.0, -1.0, 0.0),
    });
    pairs[6].push(Pair {
        p: q[6] - Vector3::new(0.0, 0.9, 0.0),
        v: Vector3::new(0.0, 1.0, 0.0),
    });
    pairs[7].push(Pair {
        p: q[7] + Vector3::new(0.0, 0.0, 0.1),
        v: Vector3::new(0.0, 0.6, -0.8),
    });
    let mut grad = vec![Vector3::zeros(); n];
    let mut cost = Cost {
        q: &mut q,
        grad: &mut grad,
        pairs: &pairs,
        w: Weights {
            smooth: 1.0,
            collision: 8.5,
            feasibility: 0.1,
            fitness: 1.0,
        },
        ts: 0.15,
        max_vel: 2.0,
        max_acc: 3.0,
        clearance: 0.5,
        reference: Some(&reference),
        fitness_inv2: (1.0 / 400.0, 1.0),
    };
    let m = 3 * (n - 6);
    let x0: Vec<f64> = (3..n - 3)
        .flat_map(|i| [q_at(&cost, i, 0), q_at(&cost, i, 1), q_at(&cost, i, 2)])
        .collect();
    let mut g = vec![0.0; m];
    cost.eval(&x0, &mut g);
    let mut scratch = vec![0.0; m];
    for k in 0..m {
        let h = 1e-6;
        let mut xp = x0.clone();
        xp[k] += h;
        let fp = cost.eval(&xp, &mut scratch);
        let mut xm = x0.clone();
        xm[k] -= h;
        let fm = cost.eval(&xm, &mut scratch);
        let fd = (fp - fm) / (2.0 * h);
        assert!(
            (fd - g[k]).abs() <= 1e-4 * fd.abs().max(1.0),
            "component {k}: analytic {} finite difference {fd}",
            g[k]
        );
    }
}

fn q_at(c: &Cost<'_>, i: usize, axis: usize) -> f64 {
    c.q[i][axis]
}

#[test]
fn the_collision_penalty_is_continuous_in_value_and_slope_at_the_clearance() {
    let sf = 0.5;
    let (a, da) = collision_penalty(sf - 1e-9, sf);
    let (b, db) = collision_penalty(sf + 1e-9, sf);
    assert!((a - b).abs() < 1e-6 && (da - db).abs() < 1e-6);
    assert_eq!(collision_penalty(-0.1, sf), (0.0, 0.0));
}
