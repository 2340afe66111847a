//! NED/FRD (PX4, MAVLink) <-> ENU/FLU (the rest of the stack). The only place NED
//! appears: px4-link converts telemetry in and setpoints out, and the simulator's
//! autopilot (`sim::px4::frames` re-exports these) converts the other way, with the same
//! code, so the two ends of the link cannot disagree on a sign.

use std::f64::consts::{FRAC_PI_2, PI};

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

/// A vector in ENU as the same vector in NED (x north, y east, z down). The swap is its
/// own inverse.
pub fn enu_to_ned(v: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(v.y, v.x, -v.z)
}

/// A vector in NED as the same vector in ENU (x east, y north, z up).
pub fn ned_to_enu(v: &Vector3<f64>) -> Vector3<f64> {
    enu_to_ned(v)
}

/// A NED vector as MAVLink carries it (x, y, z), in ENU.
pub fn enu_from_ned(v: [f64; 3]) -> Vector3<f64> {
    ned_to_enu(&Vector3::from(v))
}

/// An ENU vector as the NED (x, y, z) MAVLink carries.
pub fn ned_from_enu(v: &Vector3<f64>) -> [f64; 3] {
    enu_to_ned(v).into()
}

/// Body FLU to FRD (and back: the same flip), because MAVLink body rates are FRD.
pub fn flu_to_frd(v: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(v.x, -v.y, -v.z)
}

/// MAVLink's FRD body rates (f32) as FLU.
pub fn flu_from_frd(v: [f32; 3]) -> Vector3<f64> {
    flu_to_frd(&Vector3::new(
        f64::from(v[0]),
        f64::from(v[1]),
        f64::from(v[2]),
    ))
}

/// Wraps an angle to (-pi, pi], so yaws stay in MAVLink's range.
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

/// The rotation between ENU and NED (a reflection-free swap: its own inverse).
fn q_ned_from_enu() -> UnitQuaternion<f64> {
    let m = Matrix3::new(0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0);
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m))
}

/// The rotation between FRD and FLU (its own inverse).
fn q_flu_from_frd() -> UnitQuaternion<f64> {
    let m = Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0);
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m))
}

/// The stack's attitude (`world_from_body`, FLU in ENU) as PX4's (FRD in NED), the
/// rotation ATTITUDE_QUATERNION and ODOMETRY carry.
pub fn ned_from_frd(world_from_body: &UnitQuaternion<f64>) -> UnitQuaternion<f64> {
    q_ned_from_enu() * world_from_body * q_flu_from_frd()
}

/// PX4's attitude (FRD body in NED, quaternion w, x, y, z as MAVLink sends it) as FLU
/// body in ENU; `None` when it is not finite or far from unit length.
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
    // Both swaps are their own inverses: the same product as `ned_from_frd`.
    Some(ned_from_frd(&UnitQuaternion::from_quaternion(q)))
}

/// A quaternion as MAVLink's `[w, x, y, z]` f32, with w >= 0 (one of the two signs).
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
