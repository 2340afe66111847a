//! NED/FRD (PX4) <-> ENU/FLU (the rest of the stack). The only place NED appears.

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

/// A vector in NED as the same vector in ENU (x east, y north, z up).
pub fn enu_from_ned(v: [f64; 3]) -> Vector3<f64> {
    Vector3::new(v[1], v[0], -v[2])
}

/// A vector in ENU as the same vector in NED.
pub fn ned_from_enu(v: &Vector3<f64>) -> [f64; 3] {
    [v.y, v.x, -v.z]
}

fn enu_from_ned_rotation() -> Rotation3<f64> {
    Rotation3::from_matrix_unchecked(Matrix3::new(0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0))
}

fn frd_from_flu_rotation() -> Rotation3<f64> {
    Rotation3::from_matrix_unchecked(Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0))
}

/// PX4's attitude (FRD body in NED, quaternion w, x, y, z) as FLU body in ENU.
pub fn world_from_body_enu(q_ned_frd: [f32; 4]) -> Option<UnitQuaternion<f64>> {
    let q = nalgebra::Quaternion::new(
        f64::from(q_ned_frd[0]),
        f64::from(q_ned_frd[1]),
        f64::from(q_ned_frd[2]),
        f64::from(q_ned_frd[3]),
    );
    if !(q.coords.iter().all(|v| v.is_finite()) && q.norm() > 0.5) {
        return None;
    }
    let ned_from_frd = UnitQuaternion::from_quaternion(q);
    let enu_from_ned = UnitQuaternion::from_rotation_matrix(&enu_from_ned_rotation());
    let frd_from_flu = UnitQuaternion::from_rotation_matrix(&frd_from_flu_rotation());
    Some(enu_from_ned * ned_from_frd * frd_from_flu)
}

/// ENU yaw (from +x east toward +y north) as NED yaw (from north toward east).
pub fn ned_yaw(enu_yaw: f64) -> f64 {
    let y = std::f64::consts::FRAC_PI_2 - enu_yaw;
    y.sin().atan2(y.cos())
}

/// Body rates FRD as FLU.
pub fn flu_from_frd(v: [f32; 3]) -> Vector3<f64> {
    Vector3::new(f64::from(v[0]), -f64::from(v[1]), -f64::from(v[2]))
}
