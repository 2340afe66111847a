#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Pose accuracy on rendered frames with known truth: both resolutions, 0.1 to 3 m,
//! lateral offsets, tilts up to 30 deg, sensor noise.

mod common;

use common::*;

/// Every view of the sweep: heights, offsets (a fraction of the height, so the pad stays
/// in the 120 deg field), tilts and yaws.
fn views() -> Vec<View> {
    let mut out = Vec::new();
    let heights: [f64; 13] = [
        0.1, 0.15, 0.2, 0.3, 0.45, 0.6, 0.8, 1.0, 1.3, 1.7, 2.2, 2.6, 3.0,
    ];
    let poses: [([f64; 2], f64, f64, f64); 6] = [
        ([0.0, 0.0], 0.0, 0.0, 0.0),
        ([0.25, 0.0], 0.0, 10.0, 35.0),
        ([0.0, -0.3], 15.0, 0.0, -60.0),
        ([-0.2, 0.2], -20.0, 20.0, 120.0),
        ([0.15, 0.15], 0.0, -30.0, 200.0),
        ([-0.1, -0.1], 30.0, 0.0, 270.0),
    ];
    for h in heights {
        for (off, roll, pitch, yaw) in poses {
            // A tilted camera at 10 cm would look past the 2.5 cm marker: tilt with height.
            let tilt_scale = (h / 0.5).min(1.0);
            out.push(View {
                height: h,
                offset: [off[0] * h, off[1] * h],
                roll_deg: roll * tilt_scale,
                pitch_deg: pitch * tilt_scale,
                yaw_deg: yaw,
            });
        }
    }
    out
}

#[test]
fn pose_error_p95_is_within_1_percent_of_distance_plus_5_mm_and_yaw_within_1_deg() {
    let pad = pad_state();
    for file in CAMERAS {
        let mut cam = camera(file);
        let cal = calibration(file);
        let (mut pos_excess, mut yaw_err) = (Vec::new(), Vec::new());
        let (mut cases, mut found) = (0, 0);
        let mut worst = (0.0, String::new());
        for v in views() {
            let (body, truth) = place(&cam, &pad, &v);
            let data = render(&mut cam, &pad, body);
            // A fresh estimator: no track, the whole frame searched.
            let mut est = estimator(file, &cam);
            cases += 1;
            // The vehicle attitude the estimator gets is off by up to ~0.5 deg, as an
            // autopilot's is.
            let k = cases as f64;
            let attitude_error = nalgebra::UnitQuaternion::from_euler_angles(
                0.5f64.to_radians() * (k * 1.7).sin(),
                0.5f64.to_radians() * (k * 2.3).cos(),
                0.0,
            );
            let believed =
                nalgebra::Isometry3::from_parts(body.translation, body.rotation * attitude_error);
            let Some(e) = est
                .process(&frame(&cal, &data), 0, Some(&believed))
                .unwrap()
            else {
                println!(
                    "{file}: h {:.2} off {:?} tilt ({}, {}): no pose",
                    v.height, v.offset, v.roll_deg, v.pitch_deg
                );
                continue;
            };
            found += 1;
            let (dt, dyaw, _) = errors(&e.camera_from_pad, &truth);
            let distance = truth.translation.vector.norm();
            let bound = 0.01 * distance + 0.005;
            // Error as a fraction of its bound: p95 <= 1 is the requirement.
            pos_excess.push(dt / bound);
            if std::env::var("VERBOSE").is_ok() {
                println!(
                    "{file} h {:.2} off {:.2?} tilt ({:.0},{:.0}) yaw {:.0}: {:.1} mm / {:.1} = {:.2}, yaw {:.2} deg, rms {:.2} px used {:?} {:?}",
                    v.height,
                    v.offset,
                    v.roll_deg,
                    v.pitch_deg,
                    v.yaw_deg,
                    dt * 1e3,
                    bound * 1e3,
                    dt / bound,
                    dyaw,
                    e.rms_px,
                    e.used,
                    e.rejected
                );
            }
            yaw_err.push(dyaw);
            if dt / bound > worst.0 {
                worst = (
                    dt / bound,
                    format!(
                        "h {:.2} off {:?} tilt ({:.0}, {:.0}) used {:?}: {:.1} mm (bound {:.1})",
                        v.height,
                        v.offset,
                        v.roll_deg,
                        v.pitch_deg,
                        e.used,
                        dt * 1e3,
                        bound * 1e3
                    ),
                );
            }
            // The world pose is the camera pose carried through the vehicle's.
            // The world pose is the camera pose carried through the believed vehicle pose.
            let world = e.world_from_pad.unwrap();
            let expected = believed * cam.camera_from_body().inverse() * e.camera_from_pad;
            assert!((world.translation.vector - expected.translation.vector).norm() < 1e-9);
        }
        let p95_pos = percentile(&mut pos_excess, 95.0);
        let p95_yaw = percentile(&mut yaw_err, 95.0);
        println!(
            "{file}: {found}/{cases} poses; position error p95 = {p95_pos:.2} x (1% of distance + 5 mm); yaw error p95 {p95_yaw:.3} deg; worst {}",
            worst.1
        );
        assert!(
            found as f64 >= 0.95 * cases as f64,
            "{file}: only {found}/{cases} poses"
        );
        assert!(
            p95_pos <= 1.0,
            "{file}: position p95 {p95_pos} of the bound"
        );
        assert!(p95_yaw <= 1.0, "{file}: yaw p95 {p95_yaw} deg");
    }
}

#[test]
fn a_frame_camera_ingest_already_undistorted_is_not_undistorted_again() {
    use opencv::core::Mat;
    use opencv::prelude::*;
    let pad = pad_state();
    let file = CAMERAS[0];
    let mut cam = camera(file);
    let cal = calibration(file);
    let v = View {
        height: 1.2,
        offset: [0.3, 0.2],
        roll_deg: 5.0,
        pitch_deg: -5.0,
        yaw_deg: 20.0,
    };
    let (body, truth) = place(&cam, &pad, &v);
    let raw = render(&mut cam, &pad, body);
    // What camera-ingest --undistort publishes: the same camera matrix, no distortion.
    let src = Mat::new_rows_cols_with_data(cal.height as i32, cal.width as i32, &raw).unwrap();
    let mut out = Mat::default();
    let k = cal.camera_matrix_mat().unwrap();
    opencv::calib3d::undistort(&src, &mut out, &k, &cal.distortion_mat().unwrap(), &k).unwrap();
    let data = out.data_bytes().unwrap().to_vec();
    let mut est = estimator(file, &cam);
    let f = aruco_pnp::Frame {
        undistorted: true,
        ..frame(&cal, &data)
    };
    let e = est.process(&f, 0, Some(&body)).unwrap().expect("pad");
    let (dt, dyaw, _) = errors(&e.camera_from_pad, &truth);
    // Applying the lens model a second time costs about 17 mm here; done right, ~2 mm.
    assert!(dt < 0.005, "{dt} m");
    assert!(dyaw < 1.0, "{dyaw} deg");
}
