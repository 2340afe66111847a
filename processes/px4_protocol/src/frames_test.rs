#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Tests of `frames`.

use super::*;

fn close(a: &Vector3<f64>, b: &Vector3<f64>) -> bool {
    (a - b).norm() < 1e-9
}

#[test]
fn position_swap_is_an_involution() {
    let enu = Vector3::new(1.0, 2.0, 3.0);
    let ned = enu_to_ned(&enu);
    assert!(close(&ned, &Vector3::new(2.0, 1.0, -3.0)));
    assert!(close(&ned_to_enu(&ned), &enu));
}

#[test]
fn yaw_conversion() {
    // Facing east in ENU (0) is 90 deg in NED; facing north (pi/2) is 0.
    assert!((yaw_enu_to_ned(0.0) - FRAC_PI_2).abs() < 1e-12);
    assert!(yaw_enu_to_ned(FRAC_PI_2).abs() < 1e-12);
    // Facing west: ENU pi, NED -pi/2.
    assert!((yaw_enu_to_ned(PI) + FRAC_PI_2).abs() < 1e-12);
    for y in [-3.0, -1.0, 0.0, 0.5, 2.0, 3.1] {
        assert!((yaw_ned_to_enu(yaw_enu_to_ned(y)) - y).abs() < 1e-12);
    }
    assert!((wrap_pi(3.0 * PI) - PI).abs() < 1e-12);
    assert!((wrap_pi(-PI) - PI).abs() < 1e-12);
}

#[test]
fn level_attitude_facing_east_is_yaw_90_in_ned() {
    let q = ned_from_frd(&UnitQuaternion::identity());
    let (roll, pitch, yaw) = q.euler_angles();
    assert!(roll.abs() < 1e-9 && pitch.abs() < 1e-9);
    assert!((yaw - FRAC_PI_2).abs() < 1e-9);
    let w = quaternion_wxyz(&q);
    let h = (0.5f64).sqrt() as f32;
    assert!((w[0] - h).abs() < 1e-6 && (w[3] - h).abs() < 1e-6);
    assert!(w[1].abs() < 1e-6 && w[2].abs() < 1e-6);
}

#[test]
fn body_axes_map_consistently() {
    // An arbitrary attitude: every body axis, expressed in NED via the
    // converted quaternion, must equal the ENU-expressed axis swapped.
    let q_enu = UnitQuaternion::from_euler_angles(0.3, -0.2, 1.1);
    let q_ned = ned_from_frd(&q_enu);
    let fwd = Vector3::x();
    let left = Vector3::y();
    let up = Vector3::z();
    // FRD forward = FLU forward; FRD right = -FLU left; FRD down = -FLU up.
    assert!(close(&(q_ned * fwd), &enu_to_ned(&(q_enu * fwd))));
    assert!(close(&(q_ned * left), &enu_to_ned(&(q_enu * -left))));
    assert!(close(&(q_ned * up), &enu_to_ned(&(q_enu * -up))));
}

#[test]
fn roll_and_pitch_keep_their_sign() {
    // Right side down is positive roll in both FLU and FRD; nose up is a
    // negative FLU pitch (about y = left) but a positive FRD pitch.
    let roll = 0.2;
    let q_enu = UnitQuaternion::from_euler_angles(roll, 0.0, FRAC_PI_2);
    let (r, p, y) = ned_from_frd(&q_enu).euler_angles();
    assert!((r - roll).abs() < 1e-9, "roll {r}");
    assert!(p.abs() < 1e-9);
    assert!(y.abs() < 1e-9);
    // Nose up: FLU rotation about +y (left) by -0.3 raises the nose.
    let q_enu = UnitQuaternion::from_euler_angles(0.0, -0.3, FRAC_PI_2);
    let (_, p, _) = ned_from_frd(&q_enu).euler_angles();
    assert!((p - 0.3).abs() < 1e-9, "pitch {p}");
}

#[test]
fn frd_rates() {
    assert!(close(
        &flu_to_frd(&Vector3::new(1.0, 2.0, 3.0)),
        &Vector3::new(1.0, -2.0, -3.0)
    ));
}

#[test]
fn an_attitude_sent_by_the_autopilot_comes_back_as_the_same_attitude() {
    for (r, p, y) in [
        (0.0, 0.0, 0.0),
        (0.3, -0.2, 1.1),
        (-0.5, 0.4, -2.9),
        (0.1, 0.1, 3.1),
    ] {
        let q = UnitQuaternion::from_euler_angles(r, p, y);
        let back = world_from_body_enu(quaternion_wxyz(&ned_from_frd(&q))).unwrap();
        assert!(back.angle_to(&q) < 1e-6, "({r}, {p}, {y})");
    }
}

#[test]
fn vectors_and_rates_round_trip_between_the_two_ends() {
    let v = Vector3::new(1.0, -2.0, 3.0);
    assert!(close(&enu_from_ned(ned_from_enu(&v)), &v));
    let w = flu_to_frd(&v);
    assert!(close(
        &flu_from_frd([w.x as f32, w.y as f32, w.z as f32]),
        &v
    ));
}
