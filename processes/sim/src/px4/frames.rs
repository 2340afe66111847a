//! Frame conversions at the MAVLink boundary: the world is ENU / FLU, PX4
//! speaks NED / FRD. Only the MAVLink side of the simulator uses these, so the
//! rest of the crate never sees a NED quantity.

use std::f64::consts::{FRAC_PI_2, PI};

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

/// Swaps ENU to NED (or back: the map is its own inverse), because MAVLink
/// local positions and velocities are NED while the world is ENU.
pub fn enu_to_ned(v: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(v.y, v.x, -v.z)
}

/// NED to ENU, for incoming setpoints (same swap as [`enu_to_ned`]).
pub fn ned_to_enu(v: &Vector3<f64>) -> Vector3<f64> {
    enu_to_ned(v)
}

/// Body FLU to FRD (and back), because MAVLink body rates are FRD.
pub fn flu_to_frd(v: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(v.x, -v.y, -v.z)
}

/// Wraps an angle to (-pi, pi], so reported yaws stay in MAVLink's range.
pub fn wrap_pi(a: f64) -> f64 {
    let w = (a + PI).rem_euclid(2.0 * PI) - PI;
    if w <= -PI { w + 2.0 * PI } else { w }
}

/// ENU yaw (0 = east, counter-clockwise) to NED yaw (0 = north, clockwise).
pub fn yaw_enu_to_ned(yaw_enu: f64) -> f64 {
    wrap_pi(FRAC_PI_2 - yaw_enu)
}

/// NED yaw to ENU yaw (the same reflection as [`yaw_enu_to_ned`]).
pub fn yaw_ned_to_enu(yaw_ned: f64) -> f64 {
    wrap_pi(FRAC_PI_2 - yaw_ned)
}

fn ned_from_enu() -> UnitQuaternion<f64> {
    let m = Matrix3::new(0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0);
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m))
}

fn flu_from_frd() -> UnitQuaternion<f64> {
    let m = Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0);
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m))
}

/// Converts the world's attitude (`world_from_body`, FLU to ENU) to PX4's
/// (`ned_from_frd`), the quaternion MAVLink's ATTITUDE_QUATERNION carries.
pub fn ned_from_frd(world_from_body: &UnitQuaternion<f64>) -> UnitQuaternion<f64> {
    ned_from_enu() * world_from_body * flu_from_frd()
}

/// A MAVLink quaternion `[w, x, y, z]` as f32, the wire order of
/// ATTITUDE_QUATERNION and ODOMETRY.
pub fn quaternion_wxyz(q: &UnitQuaternion<f64>) -> [f32; 4] {
    let q = if q.w < 0.0 {
        -q.into_inner()
    } else {
        q.into_inner()
    };
    [q.w as f32, q.i as f32, q.j as f32, q.k as f32]
}

#[cfg(test)]
#[path = "frames_test.rs"]
mod tests;
