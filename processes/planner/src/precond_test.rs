use super::*;

/// The dense matrix the preconditioner factors, built directly from the jerk rows.
fn dense(n: usize, weight: f64, extra: &[f64]) -> Vec<Vec<f64>> {
    let m = n - 6;
    let mut a = vec![vec![0.0; m]; m];
    let c = [-1.0, 3.0, -3.0, 1.0];
    for row in 0..n - 3 {
        for i in 0..4 {
            for j in 0..4 {
                let (p, q) = (row + i, row + j);
                if (3..n - 3).contains(&p) && (3..n - 3).contains(&q) {
                    a[p - 3][q - 3] += 2.0 * weight * c[i] * c[j];
                }
            }
        }
    }
    for (k, e) in extra.iter().enumerate() {
        a[k][k] += e;
    }
    a
}

#[test]
fn applying_the_factor_inverts_the_jerk_hessian_on_every_axis() {
    for n in [7usize, 8, 9, 12, 40] {
        let m = n - 6;
        let extra: Vec<f64> = (0..m).map(|k| if k % 3 == 1 { 5.0 } else { 0.0 }).collect();
        let mut p = JerkPreconditioner::default();
        assert!(p.factor(n, 1.5, &extra), "n {n}");
        let a = dense(n, 1.5, &extra);
        let z: Vec<f64> = (0..3 * m).map(|i| (i as f64 * 0.37).sin() + 0.1).collect();
        // d = A z per axis, then apply must give z back.
        let mut d = vec![0.0; 3 * m];
        for axis in 0..3 {
            for i in 0..m {
                d[3 * i + axis] = (0..m).map(|j| a[i][j] * z[3 * j + axis]).sum();
            }
        }
        assert!(p.apply(&mut d));
        for i in 0..3 * m {
            assert!(
                (d[i] - z[i]).abs() < 1e-6 * (1.0 + z[i].abs()),
                "n {n} i {i}: {} vs {}",
                d[i],
                z[i]
            );
        }
    }
}

#[test]
fn without_free_points_or_weight_the_preconditioner_does_nothing() {
    let mut p = JerkPreconditioner::default();
    assert!(!p.factor(6, 1.0, &[]));
    assert!(!p.factor(20, 0.0, &[]));
    let mut d = vec![1.0; 42];
    assert!(!p.apply(&mut d));
    assert!(d.iter().all(|&v| v == 1.0));
}
