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
