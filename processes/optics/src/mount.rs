//! How the down camera sits on the body: the renderer and the detector must agree.

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion};

/// camera_from_body for a camera looking straight down from `position` (body FLU, m):
/// optical z = -body z, image up = body forward (optical x = -body y, optical
/// y = -body x).
pub fn down_camera_from_body(position: [f64; 3]) -> Isometry3<f64> {
    let r = Rotation3::from_matrix_unchecked(Matrix3::new(
        0.0, -1.0, 0.0, //
        -1.0, 0.0, 0.0, //
        0.0, 0.0, -1.0,
    ));
    Isometry3::from_parts(
        Translation3::new(position[0], position[1], position[2]),
        UnitQuaternion::from_rotation_matrix(&r),
    )
    .inverse()
}

/// Where the depth camera sits on the body, from its position (FLU, m) and its mount
/// rotation (roll, pitch, yaw, deg; pitch positive looks down). Zero rotation is the
/// simulator's forward camera: optical z = body x, optical x = -body y,
/// optical y = -body z. Maps optical-frame points into the body frame.
pub fn body_from_forward_camera(position_m: [f64; 3], rpy_deg: [f64; 3]) -> Isometry3<f64> {
    let optical = Rotation3::from_matrix_unchecked(Matrix3::new(
        0.0, 0.0, 1.0, //
        -1.0, 0.0, 0.0, //
        0.0, -1.0, 0.0,
    ));
    let mount = UnitQuaternion::from_euler_angles(
        rpy_deg[0].to_radians(),
        rpy_deg[1].to_radians(),
        rpy_deg[2].to_radians(),
    );
    Isometry3::from_parts(
        Translation3::new(position_m[0], position_m[1], position_m[2]),
        mount * UnitQuaternion::from_rotation_matrix(&optical),
    )
}
