use super::*;
use ipc_types::msg::{Header, Pose};

fn sample() -> VioOdometry {
    // Nose north (ENU yaw 90 deg), at 3 m east, 2 m north, 1.5 m up, climbing east.
    let q = UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2);
    VioOdometry {
        msg: Header::captured_at(5_000_000_000),
        odom_from_body: Pose {
            translation: [3.0, 2.0, 1.5],
            rotation_xyzw: [q.i, q.j, q.k, q.w],
        },
        velocity: [1.0, 0.0, 0.5],
        body_rates: [0.0, 0.0, 0.3],
        position_variance: [0.01, 0.04, 0.09],
        orientation_variance: [1e-4, 2e-4, 3e-4],
        velocity_variance: [0.001, 0.002, 0.003],
        reset_counter: 257,
        quality: 100,
    }
}

#[test]
fn a_vio_sample_goes_to_px4_in_ned_with_its_covariances_where_px4_reads_them() {
    let o = odometry_from_vio(&sample()).expect("finite");
    assert_eq!(o.time_usec, 5_000_000);
    assert_eq!((o.x, o.y, o.z), (2.0, 3.0, -1.5));
    assert_eq!((o.vx, o.vy, o.vz), (0.0, 1.0, -0.5));
    // Nose north is NED yaw 0: the identity.
    assert!((o.q[0] - 1.0).abs() < 1e-6, "{:?}", o.q);
    // A left (CCW) turn is a negative FRD yaw rate.
    assert!((o.yawspeed + 0.3).abs() < 1e-6);
    assert_eq!(o.pose_covariance[0], 0.04);
    assert_eq!(o.pose_covariance[6], 0.01);
    assert_eq!(o.pose_covariance[11], 0.09);
    assert_eq!(
        [
            o.pose_covariance[15],
            o.pose_covariance[18],
            o.pose_covariance[20]
        ],
        [1e-4, 2e-4, 3e-4]
    );
    assert_eq!(o.velocity_covariance[0], 0.002);
    assert_eq!(o.frame_id, MavFrame::MAV_FRAME_LOCAL_NED);
    assert_eq!(o.child_frame_id, MavFrame::MAV_FRAME_LOCAL_NED);
    assert_eq!(o.estimator_type, MavEstimatorType::MAV_ESTIMATOR_TYPE_VIO);
    assert_eq!(o.reset_counter, 1, "the counter wraps at 256 on the wire");
}

#[test]
fn a_sample_with_anything_not_finite_is_never_sent() {
    let mut s = sample();
    s.velocity[1] = f64::NAN;
    assert!(odometry_from_vio(&s).is_none());
    let mut s = sample();
    s.position_variance[0] = -1.0;
    assert!(odometry_from_vio(&s).is_none());
    let mut s = sample();
    s.odom_from_body.rotation_xyzw = [0.0; 4];
    assert!(odometry_from_vio(&s).is_none());
}
