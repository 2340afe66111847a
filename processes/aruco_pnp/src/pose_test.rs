use super::*;
use nalgebra::Vector3;

fn calibration() -> CameraCalibration {
    CameraCalibration::new(
        640,
        480,
        400.0,
        400.0,
        320.0,
        240.0,
        [-0.05, 0.01, 0.0005, 0.0005, 0.0],
    )
    .unwrap()
}

fn square(id: u32, cx: f64, cy: f64, size: f64) -> [Point3<f64>; 4] {
    let _ = id;
    let h = size / 2.0;
    [
        Point3::new(cx - h, cy + h, 0.0),
        Point3::new(cx + h, cy + h, 0.0),
        Point3::new(cx + h, cy - h, 0.0),
        Point3::new(cx - h, cy - h, 0.0),
    ]
}

fn truth() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(0.05, -0.03, 1.2),
        UnitQuaternion::from_euler_angles(0.1, -0.05, 0.7),
    )
}

fn observe(cal: &CameraCalibration, pose: &Isometry3<f64>) -> Vec<MarkerCorners> {
    [
        (1, 0.0, 0.15, 0.1),
        (2, -0.15, 0.0, 0.1),
        (68, 0.25, 0.25, 0.25),
    ]
    .iter()
    .map(|&(id, x, y, s)| {
        let object = square(id, x, y, s);
        let image = object.map(|o| cal.project(&pose.transform_point(&o)).unwrap());
        MarkerCorners { id, object, image }
    })
    .collect()
}

#[test]
fn exact_corners_give_the_exact_pose() {
    let cal = calibration();
    let s = solve(
        &cal,
        &observe(&cal, &truth()),
        &PoseSettings::default(),
        None,
    )
    .unwrap();
    assert!((s.camera_from_pad.translation.vector - truth().translation.vector).norm() < 1e-6);
    assert!(s.camera_from_pad.rotation.angle_to(&truth().rotation) < 1e-6);
    assert!(s.rms_px < 1e-4);
    assert!(s.rejected.is_empty());
    // The floor on the corner noise keeps the covariance from claiming perfection.
    assert!(s.covariance[(5, 5)] > 0.0);
}

#[test]
fn a_marker_with_displaced_corners_is_rejected_as_an_outlier() {
    let cal = calibration();
    let mut markers = observe(&cal, &truth());
    for p in &mut markers[1].image {
        p.x += 6.0;
    }
    let s = solve(&cal, &markers, &PoseSettings::default(), None).unwrap();
    assert_eq!(s.rejected, vec![2]);
    assert!((s.camera_from_pad.translation.vector - truth().translation.vector).norm() < 1e-5);
}

#[test]
fn non_finite_or_missing_corners_are_errors_not_poses() {
    let cal = calibration();
    assert!(matches!(
        solve(&cal, &[], &PoseSettings::default(), None),
        Err(PoseError::NoCorners)
    ));
    let mut markers = observe(&cal, &truth());
    markers[0].image[2].y = f64::NAN;
    assert!(matches!(
        solve(&cal, &markers, &PoseSettings::default(), None),
        Err(PoseError::NonFinite)
    ));
}

#[test]
fn the_level_prior_keeps_a_level_pad_level_and_moves_nothing_when_it_agrees() {
    let cal = calibration();
    // The pad is level in the world; the camera's orientation in the world follows.
    let world_from_camera = truth().rotation.inverse().to_rotation_matrix();
    let prior = LevelPrior {
        world_from_camera,
        sigma_rad: 0.02,
    };
    let s = solve(
        &cal,
        &observe(&cal, &truth()),
        &PoseSettings::default(),
        Some(&prior),
    )
    .unwrap();
    assert!((s.camera_from_pad.translation.vector - truth().translation.vector).norm() < 1e-6);
    let normal = world_from_camera * (s.camera_from_pad.rotation * Vector3::z());
    assert!(normal.z > 0.999_999);
}

#[test]
fn the_world_covariance_rotates_both_blocks_and_puts_translation_first() {
    let mut c = Matrix6::zeros();
    c[(0, 0)] = 1.0; // rotation about camera x
    c[(5, 5)] = 4.0; // translation along camera z
    let r = Rotation3::from_euler_angles(std::f64::consts::PI, 0.0, 0.0); // camera z -> world -z
    let w = world_covariance(&c, &r);
    assert!((w[(2, 2)] - 4.0).abs() < 1e-12);
    assert!((w[(3, 3)] - 1.0).abs() < 1e-12);
}
