use super::*;

#[test]
fn an_emergency_stop_comes_to_rest_along_the_current_velocity() {
    let s = State {
        p: Vector3::new(0.0, 0.0, 2.0),
        v: Vector3::new(4.0, 0.0, 0.0),
        a: Vector3::zeros(),
    };
    let t = stop_trajectory(&s, 6.0).unwrap();
    let end = t.eval(t.duration());
    assert!(end.v.norm() < 1e-9 && end.p.x > 0.0);
    assert!((t.eval(0.0).v - s.v).norm() < 1e-9);
    assert!(
        stop_trajectory(
            &State {
                p: Vector3::new(f64::NAN, 0.0, 0.0),
                ..s
            },
            6.0
        )
        .is_none()
    );
}
