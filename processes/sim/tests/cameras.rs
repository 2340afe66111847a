#![allow(clippy::unwrap_used, clippy::expect_used)]
//! The simulated cameras, checked with OpenCV's own ArUco detector and PnP.

use std::path::PathBuf;
use std::time::Instant;

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use opencv::aruco;
use opencv::calib3d;
use opencv::core::{Mat, Point2f, Point3f, Size, TermCriteria, Vector};
use opencv::imgproc;
use opencv::prelude::*;
use optics::{CameraCalibration, PadModel};
use sim::camera::{BodyMotion, DownCamera, DownCameraParams, Frame, PixelFormat};
use sim::depth::{DepthCamera, DepthCameraParams};
use sim::ground_vehicle::PadState;
use sim::world::{Aabb, Obb};

fn config(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../deploy/config")
        .join(name)
}

const CAMERAS: [&str; 2] = ["camera_down_640x480.yaml", "camera_down_1280x720.yaml"];

fn pad_model() -> PadModel {
    PadModel::load(config("pad.toml")).unwrap()
}

fn camera(file: &str, params: DownCameraParams) -> DownCamera {
    let calib = CameraCalibration::load(config(file)).unwrap();
    DownCamera::new(params, calib, &pad_model()).unwrap()
}

fn pad_state() -> PadState {
    PadState {
        world_from_pad: Isometry3::from_parts(
            Translation3::new(3.0, -2.0, 0.4),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 30f64.to_radians()),
        ),
        linear_velocity: Vector3::zeros(),
        linear_acceleration: Vector3::zeros(),
        angular_velocity: Vector3::zeros(),
        speed_m_s: 0.0,
        distance_m: 0.0,
    }
}

/// Body pose that puts the camera's optical centre `height` above the pad
/// centre, body level, yawed 10 deg from the pad.
fn body_over_pad(cam: &DownCamera, pad: &PadState, height: f64) -> Isometry3<f64> {
    let body_from_camera = cam.camera_from_body().inverse();
    let centre = pad.world_from_pad.translation.vector + Vector3::new(0.0, 0.0, height);
    let yaw = UnitQuaternion::from_euler_angles(0.0, 0.0, 40f64.to_radians());
    let world_from_camera =
        Isometry3::from_parts(Translation3::from(centre), yaw * body_from_camera.rotation);
    world_from_camera * cam.camera_from_body()
}

struct Detection {
    ids: Vec<i32>,
    corners: Vec<[Point2f; 4]>,
}

fn detect(frame: &Frame) -> Detection {
    let image = frame.to_mat().unwrap();
    let dict =
        aruco::get_predefined_dictionary(aruco::PREDEFINED_DICTIONARY_NAME::DICT_ARUCO_ORIGINAL)
            .unwrap();
    // Corners come from the contour (no refinement), then each marker is
    // refined with a window of about a third of its bit cell: OpenCV's fixed
    // 5 px SUBPIX window reaches across the inner bit corners of a 15 px marker
    // and drags its corners by several pixels.
    let params = aruco::DetectorParameters::create().unwrap();
    let mut corners = Vector::<Vector<Point2f>>::new();
    let mut ids = Vector::<i32>::new();
    let mut rejected = Vector::<Vector<Point2f>>::new();
    aruco::detect_markers(
        &image,
        &dict,
        &mut corners,
        &mut ids,
        &params,
        &mut rejected,
    )
    .unwrap();
    let criteria = TermCriteria::new(3, 30, 0.01).unwrap();
    let mut refined = Vec::new();
    for mut c in corners {
        let pts: Vec<Point2f> = c.to_vec();
        let perimeter: f64 = (0..4).map(|k| (pts[k] - pts[(k + 1) % 4]).norm()).sum();
        let win = ((perimeter / 4.0 / 7.0 / 3.0).round() as i32).clamp(1, 5);
        imgproc::corner_sub_pix(
            &image,
            &mut c,
            Size::new(win, win),
            Size::new(-1, -1),
            criteria,
        )
        .unwrap();
        refined.push([
            c.get(0).unwrap(),
            c.get(1).unwrap(),
            c.get(2).unwrap(),
            c.get(3).unwrap(),
        ]);
    }
    Detection {
        ids: ids.to_vec(),
        corners: refined,
    }
}

impl Detection {
    fn filter(&self, keep: impl Fn(i32) -> bool) -> Detection {
        let (ids, corners) = self
            .ids
            .iter()
            .zip(&self.corners)
            .filter(|(id, _)| keep(**id))
            .map(|(id, c)| (*id, *c))
            .unzip();
        Detection { ids, corners }
    }
}

/// `camera_from_pad` from all the given markers at once (one PnP).
fn solve_pose(det: &Detection, pad: &PadModel, calib: &CameraCalibration) -> Isometry3<f64> {
    let mut object = Vector::<Point3f>::new();
    let mut image = Vector::<Point2f>::new();
    for (id, corners) in det.ids.iter().zip(&det.corners) {
        let model = pad.marker_corners_pad(*id as u32).unwrap();
        for (m, c) in model.iter().zip(corners) {
            object.push(Point3f::new(m.x as f32, m.y as f32, m.z as f32));
            image.push(*c);
        }
    }
    let mut rvec = Mat::default();
    let mut tvec = Mat::default();
    let ok = calib3d::solve_pnp(
        &object,
        &image,
        &calib.camera_matrix_mat().unwrap(),
        &calib.distortion_mat().unwrap(),
        &mut rvec,
        &mut tvec,
        false,
        calib3d::SOLVEPNP_ITERATIVE,
    )
    .unwrap();
    assert!(ok);
    let mut rmat = Mat::default();
    calib3d::rodrigues(&rvec, &mut rmat, &mut opencv::core::no_array()).unwrap();
    let r = Matrix3::from_fn(|i, j| *rmat.at_2d::<f64>(i as i32, j as i32).unwrap());
    let t = Vector3::from_fn(|i, _| *tvec.at_2d::<f64>(i as i32, 0).unwrap());
    Isometry3::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r)),
    )
}

#[test]
fn a_pad_rendered_at_1_m_decodes_to_the_right_ids_and_pnp_recovers_the_pose() {
    let pad_model = pad_model();
    let pad = pad_state();
    for file in CAMERAS {
        let mut cam = camera(file, DownCameraParams::default());
        let body = body_over_pad(&cam, &pad, 1.0);
        let frame = cam.render(&BodyMotion::at_rest(body), Some(&pad)).unwrap();
        let det = detect(&frame);
        let mut ids = det.ids.clone();
        ids.sort_unstable();
        assert!(
            ids.iter().all(|id| pad_model.marker(*id as u32).is_some()),
            "{file}: unknown ids in {ids:?}"
        );
        assert!(ids.contains(&68), "{file}: 68 missing from {ids:?}");
        for id in 1..=4 {
            assert!(ids.contains(&id), "{file}: {id} missing from {ids:?}");
        }
        let world_from_camera = body * cam.camera_from_body().inverse();
        let truth = world_from_camera.inverse() * pad.world_from_pad;
        let error = |est: Isometry3<f64>| {
            (
                (est.translation.vector - truth.translation.vector).norm(),
                est.rotation.angle_to(&truth.rotation).to_degrees(),
            )
        };
        // Every detected marker together (informative: at 1 m the 6.4 cm
        // markers are 12 px wide on the 640x480 camera and their corners are
        // off by up to a pixel, which tilts the pose by about 1 deg there).
        let (dt_all, dr_all) = error(solve_pose(&det, &pad_model, cam.calibration()));
        // What the detector will do: every detected marker whose active range
        // (pad.toml) contains the distance, all of them in one PnP.
        let distance = truth.translation.vector.z;
        let active = det.filter(|id| {
            let [lo, hi] = pad_model.marker(id as u32).unwrap().active_range_m;
            (lo..=hi).contains(&distance)
        });
        let mut active_ids = active.ids.clone();
        active_ids.sort_unstable();
        let (dt, dr) = error(solve_pose(&active, &pad_model, cam.calibration()));
        println!(
            "{file}: detected {ids:?}: all markers {:.2} mm {dr_all:.3} deg; active {active_ids:?}: {:.2} mm {dr:.3} deg",
            dt_all * 1000.0,
            dt * 1000.0
        );
        assert_eq!(active_ids, vec![1, 2, 3, 4, 68], "{file}");
        if cam.calibration().width >= 1280 {
            assert!(
                dt_all < 0.01 && dr_all < 0.5,
                "{file}: all markers {dt_all} m {dr_all} deg"
            );
        }
        assert!(dt < 0.01, "{file}: position error {dt} m");
        assert!(dr < 0.5, "{file}: rotation error {dr} deg");
    }
}

#[test]
fn the_layout_keeps_a_marker_fully_visible_and_detected_from_3_m_to_touchdown() {
    let pad_model = pad_model();
    let pad = pad_state();
    for file in CAMERAS {
        let mut cam = camera(file, DownCameraParams::default());
        for height in [3.0, 2.0, 1.0, 0.5, 0.3, 0.2, 0.15, 0.1] {
            let body = body_over_pad(&cam, &pad, height);
            let frame = cam.render(&BodyMotion::at_rest(body), Some(&pad)).unwrap();
            let det = detect(&frame);
            let mut ids = det.ids.clone();
            ids.sort_unstable();
            println!("{file} at {height} m: {ids:?}");
            assert!(
                ids.iter().all(|id| pad_model.marker(*id as u32).is_some()),
                "{file} at {height} m: {ids:?}"
            );
            assert!(!ids.is_empty(), "{file} at {height} m: no marker detected");
            // The layout's intent: a marker meant for this distance is among them.
            assert!(
                ids.iter().any(|id| {
                    let [lo, hi] = pad_model.marker(*id as u32).unwrap().active_range_m;
                    (lo..=hi).contains(&height)
                }),
                "{file} at {height} m: no detected marker is active at this distance ({ids:?})"
            );
        }
    }
}

#[test]
fn a_blurred_frame_blends_several_sub_exposures_and_still_decodes() {
    let pad = pad_state();
    let mut cam = camera(
        "camera_down_640x480.yaml",
        DownCameraParams {
            exposure_time_s: 0.01,
            ..DownCameraParams::default()
        },
    );
    let body = body_over_pad(&cam, &pad, 1.0);
    let still = cam.render(&BodyMotion::at_rest(body), Some(&pad)).unwrap();
    assert_eq!(still.blur_samples, 1);
    let moving = BodyMotion {
        world_from_body: body,
        linear_velocity: Vector3::new(1.0, 0.0, 0.0),
        angular_velocity_body: Vector3::new(0.0, 0.0, 0.5),
    };
    let blurred = cam.render(&moving, Some(&pad)).unwrap();
    assert!(blurred.blur_samples > 1, "{}", blurred.blur_samples);
    assert_ne!(still.data, blurred.data);
    assert!(detect(&blurred).ids.contains(&68));
}

#[test]
fn the_same_seed_renders_the_same_image_and_bgr_replicates_grey() {
    let pad = pad_state();
    let mut a = camera("camera_down_640x480.yaml", DownCameraParams::default());
    let mut b = camera("camera_down_640x480.yaml", DownCameraParams::default());
    let body = BodyMotion::at_rest(body_over_pad(&a, &pad, 2.0));
    let fa = a.render(&body, Some(&pad)).unwrap();
    assert_eq!(fa, b.render(&body, Some(&pad)).unwrap());
    assert_eq!(fa.data.len(), 640 * 480);
    let mut c = camera(
        "camera_down_640x480.yaml",
        DownCameraParams {
            format: PixelFormat::Bgr8,
            noise_sigma: 0.0,
            ..DownCameraParams::default()
        },
    );
    let fc = c.render(&body, Some(&pad)).unwrap();
    assert_eq!(fc.data.len(), 640 * 480 * 3);
    assert!(
        fc.data
            .chunks_exact(3)
            .all(|p| p[0] == p[1] && p[1] == p[2])
    );
}

#[test]
fn without_a_pad_the_camera_sees_textured_ground() {
    let mut cam = camera(
        "camera_down_640x480.yaml",
        DownCameraParams {
            noise_sigma: 0.0,
            ..DownCameraParams::default()
        },
    );
    let pad = pad_state();
    let body = body_over_pad(&cam, &pad, 2.0);
    let frame = cam.render(&BodyMotion::at_rest(body), None).unwrap();
    let mean = frame.data.iter().map(|&v| f64::from(v)).sum::<f64>() / frame.data.len() as f64;
    let var = frame
        .data
        .iter()
        .map(|&v| (f64::from(v) - mean).powi(2))
        .sum::<f64>()
        / frame.data.len() as f64;
    assert!((60.0..150.0).contains(&mean), "mean {mean}");
    assert!(
        var.sqrt() > 4.0,
        "ground has no texture: std {}",
        var.sqrt()
    );
    assert!(detect(&frame).ids.is_empty());
}

fn level_body(x: f64, y: f64, z: f64, yaw_deg: f64) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_euler_angles(0.0, 0.0, yaw_deg.to_radians()),
    )
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[test]
fn a_box_3_m_ahead_appears_at_3_m_in_the_centre_of_the_depth_image() {
    let mut cam = DepthCamera::new(DepthCameraParams::default()).unwrap();
    // Body at 1.5 m facing north; the camera is 0.1 m ahead of the body origin,
    // so the box face is 3 m from the camera.
    let body = level_body(0.0, 0.0, 1.5, 90.0);
    let face_y = 0.1 + 3.0;
    let obstacle = Aabb {
        min_m: [-0.3, face_y, 0.0],
        max_m: [0.3, face_y + 0.6, 2.4],
    };
    let frame = cam.render(&body, &[Obb::from(&obstacle)]);
    let mut centre = Vec::new();
    for v in 230..250 {
        for u in 310..330 {
            centre.push(frame.depth_m(u, v).unwrap());
        }
    }
    let m = median(centre);
    assert!((m - 3.0).abs() < 0.05, "centre depth {m}");
    // Without the box the centre looks at the horizon: beyond 10 m, so invalid.
    let empty = cam.render(&body, &[]);
    assert_eq!(empty.depth_m(320, 240), None);
    assert_eq!(
        empty.depth_m(320, 200),
        None,
        "above the horizon there is nothing"
    );
}

#[test]
fn the_ground_vehicles_body_turned_45_degrees_shows_its_corner_to_the_depth_camera() {
    use sim::ground_vehicle::{GroundVehicleParams, PathParams, SpeedProfile};
    use sim::world::{World, WorldParams};
    for (heading_deg, nearest_x) in [(0.0_f64, 3.0 - 0.5), (45.0, 3.0 - 0.5 * 2f64.sqrt())] {
        let world = World::new(WorldParams {
            ground_vehicle: Some(GroundVehicleParams {
                path: PathParams::Straight {
                    start_m: [3.0, 0.0],
                    heading_rad: heading_deg.to_radians(),
                },
                speed: SpeedProfile::Constant { speed_m_s: 0.0 },
                ..GroundVehicleParams::default()
            }),
            ..WorldParams::default()
        })
        .unwrap();
        let boxes = world.boxes_in_view();
        assert_eq!(boxes.len(), 1, "the body is the only box");
        let mut cam = DepthCamera::new(DepthCameraParams::default()).unwrap();
        // The camera (10 cm ahead of and above the body origin) at the roof's half
        // height (0.2 m), looking east at the body.
        let body = level_body(0.0, 0.0, 0.1, 0.0);
        let frame = cam.render(&body, &boxes);
        let d = frame.depth_m(320, 240).unwrap();
        let expected = nearest_x - 0.1;
        assert!(
            (d - expected).abs() < 0.03,
            "heading {heading_deg}: depth {d}, the body's nearest face or corner is {expected} m away"
        );
    }
}

/// The default depth camera without noise, its vertical focal length and principal
/// point, px, and its mount's height over the body origin, m.
fn noiseless_depth_camera() -> (DepthCamera, f64, f64, f64) {
    let params = DepthCameraParams {
        noise_k_per_m: 0.0,
        ..DepthCameraParams::default()
    };
    let (fy, cy) = (params.focal_px().1, params.principal_point_px().1);
    let mount_z = params.position_in_body_m[2];
    (DepthCamera::new(params).unwrap(), fy, cy, mount_z)
}

#[test]
fn the_ground_appears_where_it_should_and_out_of_range_reads_zero() {
    let (mut cam, fy, cy, mount_z) = noiseless_depth_camera();
    // The camera 1 m above the ground (its mount is above the body origin).
    let height = 1.0;
    let body = level_body(5.0, 5.0, height - mount_z, 0.0);
    let frame = cam.render(&body, &[]);
    // A row below the horizon looks down at angle atan(dy/fy): the ground is
    // at depth z = height * fy / dy along the optical axis.
    for v in [300u32, 400, 479] {
        let expect = height * fy / (f64::from(v) - cy);
        let got = frame.depth_m(320, v).unwrap();
        assert!((got - expect).abs() < 0.002, "row {v}: {got} vs {expect}");
    }
    // Rows just below the horizon are farther than 10 m: zero.
    let far_row = (cy + height * fy / 12.0).floor() as u32;
    assert_eq!(frame.depth_mm[(far_row * 640 + 320) as usize], 0);
    // Too close: a camera 0.1 m above the ground sees it nearer than 0.2 m in the bottom rows.
    let low = cam.render(&level_body(0.0, 0.0, 0.1 - mount_z, 0.0), &[]);
    assert_eq!(low.depth_mm[(479 * 640 + 320) as usize], 0);
    // A box right in front of the lens (closer than 0.2 m) also reads zero.
    let near = Aabb {
        min_m: [5.15, 4.0, 0.0],
        max_m: [5.2, 6.0, 3.0],
    };
    let blocked = cam.render(&body, &[Obb::from(&near)]);
    assert_eq!(blocked.depth_m(320, 240), None);
}

#[test]
fn a_depth_camera_mounted_a_degree_off_its_drawing_sees_the_ground_where_its_true_mount_does() {
    let (mut cam, fy, cy, mount_z) = noiseless_depth_camera();
    // Pitched 1 deg about the optical x axis (the true optical frame into the drawn one).
    let error = Isometry3::from_parts(
        Translation3::identity(),
        UnitQuaternion::from_euler_angles(1f64.to_radians(), 0.0, 0.0),
    );
    cam.set_mount_error(error);
    let height = 1.0;
    let frame = cam.render(&level_body(5.0, 5.0, height - mount_z, 0.0), &[]);
    for v in [300u32, 400, 479] {
        // The pixel's ray, turned into the drawn (level) frame, meets the ground at
        // `height` below; the depth is along the true optical axis.
        let ray = nalgebra::Vector3::new(0.0, (f64::from(v) - cy) / fy, 1.0);
        let down = (error.rotation * ray).y;
        let expect = height / down;
        let nominal = height * fy / (f64::from(v) - cy);
        let got = frame.depth_m(320, v).unwrap();
        assert!((got - expect).abs() < 0.002, "row {v}: {got} vs {expect}");
        assert!(
            (got - nominal).abs() > 0.01,
            "row {v}: as if mounted as drawn"
        );
    }
    // Drawn per seed, within its standard deviations, and the same for the same seed.
    let mount = sim::camera::MountErrors::default();
    let (a, b) = (mount.draw(7), mount.draw(7));
    assert_eq!(a, b);
    assert!(a.rotation.angle() < 5f64.to_radians() && a.translation.vector.norm() < 0.05);
    assert_ne!(a, mount.draw(8));
}

#[test]
fn depth_noise_grows_with_range() {
    let mut cam = DepthCamera::new(DepthCameraParams::default()).unwrap();
    let body = level_body(0.0, 0.0, 1.5, 0.0);
    let spread = |d: f64, cam: &mut DepthCamera| {
        let wall = Aabb {
            min_m: [d + 0.1, -20.0, 0.0],
            max_m: [d + 1.0, 20.0, 20.0],
        };
        let f = cam.render(&body, &[Obb::from(&wall)]);
        let v: Vec<f64> = (200..280)
            .flat_map(|v| (280..360).map(move |u| (u, v)))
            .map(|(u, v)| f.depth_m(u, v).unwrap())
            .collect();
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        (
            mean,
            (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / v.len() as f64).sqrt(),
        )
    };
    let (m1, s1) = spread(1.0, &mut cam);
    let (m4, s4) = spread(4.0, &mut cam);
    assert!(
        (m1 - 1.0).abs() < 0.01 && (m4 - 4.0).abs() < 0.02,
        "{m1} {m4}"
    );
    assert!(s4 > 8.0 * s1, "sigma at 1 m {s1}, at 4 m {s4}");
}

/// Median render times over 100 frames (run with `--ignored --nocapture`).
#[test]
#[ignore = "benchmark: prints timings, asserts nothing"]
fn render_bench() {
    let pad = pad_state();
    let time = |f: &mut dyn FnMut()| {
        let mut times: Vec<f64> = (0..100)
            .map(|_| {
                let t = Instant::now();
                f();
                t.elapsed().as_secs_f64() * 1e3
            })
            .collect();
        median(std::mem::take(&mut times))
    };
    for threads in [None, Some(1)] {
        if let Some(n) = threads {
            opencv::core::set_num_threads(n).unwrap();
        }
        let label = threads.map_or("OpenCV default threads".to_string(), |n| {
            format!("OpenCV {n} thread")
        });
        for file in CAMERAS {
            let mut cam = camera(file, DownCameraParams::default());
            for height in [3.0, 1.0, 0.2] {
                let body = BodyMotion::at_rest(body_over_pad(&cam, &pad, height));
                let ms = time(&mut || {
                    std::hint::black_box(cam.render(&body, Some(&pad)).unwrap());
                });
                println!("down camera {file} at {height} m, static ({label}): median {ms:.3} ms");
            }
            let moving = BodyMotion {
                linear_velocity: Vector3::new(3.0, 0.0, 0.0),
                ..BodyMotion::at_rest(body_over_pad(&cam, &pad, 1.0))
            };
            let samples = cam.render(&moving, Some(&pad)).unwrap().blur_samples;
            let ms = time(&mut || {
                std::hint::black_box(cam.render(&moving, Some(&pad)).unwrap());
            });
            println!(
                "down camera {file} at 1 m, 3 m/s, {samples} sub-exposures ({label}): median {ms:.3} ms"
            );
        }
    }
    let mut depth = DepthCamera::new(DepthCameraParams::default()).unwrap();
    let body = level_body(0.0, 0.0, 1.5, 0.0);
    let boxes = [
        Aabb {
            min_m: [3.1, -0.3, 0.0],
            max_m: [3.7, 0.3, 1.2],
        },
        Aabb {
            min_m: [5.0, 1.0, 0.0],
            max_m: [6.0, 2.0, 2.0],
        },
        Aabb {
            min_m: [4.0, -3.0, 0.0],
            max_m: [4.5, -1.5, 3.0],
        },
    ];
    let mut times = Vec::new();
    for _ in 0..100 {
        let t = Instant::now();
        let f = depth.render(&body, &boxes.map(|b| Obb::from(&b)));
        times.push(t.elapsed().as_secs_f64() * 1e3);
        std::hint::black_box(f);
    }
    println!(
        "depth camera 640x480, 3 boxes: median {:.3} ms",
        median(times)
    );
}

#[test]
fn camera_parameters_parse_from_toml_and_bad_values_name_the_field() {
    let p: DownCameraParams = toml::from_str(
        "exposure_time_s = 0.008\nformat = \"bgr8\"\nposition_in_body_m = [0.0, 0.0, -0.1]",
    )
    .unwrap();
    assert_eq!(p.exposure_time_s, 0.008);
    assert_eq!(p.format, PixelFormat::Bgr8);
    assert!(toml::from_str::<DownCameraParams>("exposure = 0.008").is_err());
    let bad = DownCameraParams {
        exposure_time_s: -1.0,
        ..DownCameraParams::default()
    };
    assert!(
        bad.validate()
            .unwrap_err()
            .to_string()
            .contains("exposure_time_s")
    );
    let bad = DownCameraParams {
        black_level: 240,
        ..DownCameraParams::default()
    };
    assert!(
        bad.validate()
            .unwrap_err()
            .to_string()
            .contains("black_level")
    );
    let d: DepthCameraParams = toml::from_str("max_depth_m = 6.0\nnoise_k_per_m = 0.0").unwrap();
    assert_eq!(d.max_depth_m, 6.0);
    let bad = DepthCameraParams {
        max_depth_m: 0.1,
        ..DepthCameraParams::default()
    };
    assert!(
        DepthCamera::new(bad)
            .unwrap_err()
            .to_string()
            .contains("max_depth_m")
    );
}
