//! A VIO sample as PX4 reads it: MAVLink ODOMETRY, pose in `MAV_FRAME_LOCAL_NED`, velocity
//! in the same frame (`child_frame_id` LOCAL_NED: PX4 v1.16's `handle_message_odometry`
//! takes it as world-frame velocity), the covariance diagonals where PX4's receiver reads
//! them (pose: x 0, y 6, z 11, roll 15, pitch 18, yaw 20; velocity 0, 6, 11), estimator
//! VIO and the reset counter, so that EKF2 fuses it (`EKF2_EV_CTRL`) and resets with it.
//!
//! `time_usec` is the companion's capture time in microseconds: PX4 converts it with its
//! TIMESYNC estimate when it has one and otherwise stamps the arrival, so the
//! VIO's latency is `EKF2_EV_DELAY`'s to cover (docs/px4-sitl.md).

use ipc_types::msg::VioOdometry;
use mavlink::dialects::common::{MavEstimatorType, MavFrame, ODOMETRY_DATA};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use px4_protocol::frames::{enu_to_ned, flu_to_frd, ned_from_frd, quaternion_wxyz};

/// ODOMETRY for `vio`; `None` when any value is not finite or a variance is negative
/// (nothing half-valid goes to the estimator).
pub fn odometry_from_vio(vio: &VioOdometry) -> Option<ODOMETRY_DATA> {
    let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
    let non_negative = |v: &[f64; 3]| v.iter().all(|x| *x >= 0.0 && x.is_finite());
    let pose = &vio.odom_from_body;
    if !(finite(&pose.translation)
        && finite(&pose.rotation_xyzw)
        && finite(&vio.velocity)
        && finite(&vio.body_rates)
        && non_negative(&vio.position_variance)
        && non_negative(&vio.orientation_variance)
        && non_negative(&vio.velocity_variance))
    {
        return None;
    }
    let [qx, qy, qz, qw] = pose.rotation_xyzw;
    let q = Quaternion::new(qw, qx, qy, qz);
    if q.norm() < 0.5 {
        return None;
    }
    let attitude = UnitQuaternion::from_quaternion(q);
    let p = enu_to_ned(&Vector3::from(pose.translation));
    let v = enu_to_ned(&Vector3::from(vio.velocity));
    let rates = flu_to_frd(&Vector3::from(vio.body_rates));
    // ENU variances to NED: x and y swap, z keeps its own.
    let (pv, ov, vv) = (
        vio.position_variance,
        vio.orientation_variance,
        vio.velocity_variance,
    );
    let mut pose_covariance = [0.0f32; 21];
    pose_covariance[0] = pv[1] as f32;
    pose_covariance[6] = pv[0] as f32;
    pose_covariance[11] = pv[2] as f32;
    pose_covariance[15] = ov[0] as f32;
    pose_covariance[18] = ov[1] as f32;
    pose_covariance[20] = ov[2] as f32;
    let mut velocity_covariance = [0.0f32; 21];
    velocity_covariance[0] = vv[1] as f32;
    velocity_covariance[6] = vv[0] as f32;
    velocity_covariance[11] = vv[2] as f32;
    Some(ODOMETRY_DATA {
        time_usec: vio.msg.capture_ns / 1000,
        x: p.x as f32,
        y: p.y as f32,
        z: p.z as f32,
        q: quaternion_wxyz(&ned_from_frd(&attitude)),
        vx: v.x as f32,
        vy: v.y as f32,
        vz: v.z as f32,
        rollspeed: rates.x as f32,
        pitchspeed: rates.y as f32,
        yawspeed: rates.z as f32,
        pose_covariance,
        velocity_covariance,
        frame_id: MavFrame::MAV_FRAME_LOCAL_NED,
        child_frame_id: MavFrame::MAV_FRAME_LOCAL_NED,
        reset_counter: (vio.reset_counter % 256) as u8,
        estimator_type: MavEstimatorType::MAV_ESTIMATOR_TYPE_VIO,
        quality: vio.quality.clamp(-1, 100) as i8,
    })
}

#[cfg(test)]
#[path = "odometry_test.rs"]
mod tests;
