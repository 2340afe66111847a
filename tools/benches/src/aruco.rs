//! `landing bench aruco`: detection + pose time per frame, ours against plain OpenCV,
//! on the same rendered descents in the same run.
//!
//! A descent from 3 m to 0.15 m in 5 s over a pad that is not level (2 deg), drifting
//! sideways, yawing, tilting a little, rendered once per resolution with the motion's
//! blur and sensor noise. Ours: `PadEstimator` fed the frames in order, as aruco-pnp is
//! (so it tracks the pad's region), with the attitude the autopilot would report (the
//! simulator's VIO-like attitude noise), not the true one. OpenCV: `detectMarkers` at
//! its best settings (ArUco3 mode; subpixel and contour corner refinement both run, the
//! more accurate is the row), then one `solvePnP` over every pad marker found; on the
//! whole frame, and as a second row with the same search-region tracking as ours (the
//! region of the markers last found, widened by 35 %, whole frame when it finds none).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use aruco_pnp::{ArucoConfig, ArucoStage, Frame};
use clap::Args;
use ipc_types::msg::PixelEncoding;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
use opencv::core::{Mat, Point2f, Point3f, Vector};
use opencv::prelude::*;
use opencv::{aruco, calib3d};
use optics::{CameraCalibration, PadModel};
use serde_json::json;
use sim::camera::{BodyMotion, DownCamera, DownCameraParams};
use sim::ground_vehicle::PadState;
use stack_config::deploy_dir;

use evaluation::stats::percentile;

/// Arguments of `landing bench aruco`.
#[derive(Debug, Args)]
pub struct ArucoArgs {
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
    /// Frames rendered per resolution.
    #[arg(long, default_value_t = 150)]
    frames: usize,
    /// The deploy directory (default: found above the current directory or executable).
    #[arg(long)]
    deploy_dir: Option<PathBuf>,
}

/// Times (ms) and poses found by one method over one sequence.
struct Run {
    ms: Vec<f64>,
    found: usize,
    position_error_m: Vec<f64>,
}

/// A rendered descent: frames and the true camera_from_pad of each.
pub(crate) struct Sequence {
    calibration: CameraCalibration,
    camera_from_body: Isometry3<f64>,
    pub(crate) frames: Vec<(Vec<u8>, Isometry3<f64>, Isometry3<f64>)>,
}

/// Frame period of the descent, s (30 Hz).
const FRAME_S: f64 = 1.0 / 30.0;

pub(crate) fn render(
    file: &str,
    n: usize,
    deploy: &std::path::Path,
    pad: &PadModel,
) -> Result<Sequence> {
    let calibration = CameraCalibration::load(deploy.join("config").join(file))?;
    let mut cam = DownCamera::new(DownCameraParams::default(), calibration, pad)?;
    let state = PadState {
        // Not level: a vehicle's roof is not a surveyed plane.
        world_from_pad: Isometry3::from_parts(
            Translation3::new(3.0, -2.0, 0.4),
            UnitQuaternion::from_euler_angles(0.035, -0.025, 0.5),
        ),
        linear_velocity: nalgebra::Vector3::zeros(),
        linear_acceleration: nalgebra::Vector3::zeros(),
        angular_velocity: nalgebra::Vector3::zeros(),
        speed_m_s: 0.0,
        distance_m: 0.0,
    };
    let camera_from_body = cam.camera_from_body();
    let body_from_camera = camera_from_body.inverse();
    let pose = |k: usize| {
        let s = k as f64 / (n.max(2) - 1) as f64;
        let h = 3.0 * (0.15f64 / 3.0).powf(s);
        let drift = 0.15 * h;
        let centre =
            state.world_from_pad * Point3::new(drift * (6.0 * s).sin(), drift * (4.0 * s).cos(), h);
        let rotation = state.world_from_pad.rotation
            * UnitQuaternion::from_euler_angles(
                0.08 * (9.0 * s).sin(),
                0.08 * (7.0 * s).cos(),
                1.5 * s,
            )
            * body_from_camera.rotation;
        let world_from_camera = Isometry3::from_parts(Translation3::from(centre.coords), rotation);
        (world_from_camera * camera_from_body, world_from_camera)
    };
    // The autopilot's attitude: the truth times a small rotation of the simulator's
    // VIO-like attitude noise (per axis).
    let sigma = sim::estimator_noise::EstimatorNoiseParams::default().attitude_std_rad;
    let mut rng = sim::rng::Pcg32::with_stream(7, 3);
    let mut frames = Vec::with_capacity(n);
    for k in 0..n {
        let (world_from_body, world_from_camera) = pose(k);
        let (next, _) = pose(k + 1);
        // The motion over the exposure, from the next frame's pose: the blur.
        let motion = BodyMotion {
            world_from_body,
            linear_velocity: (next.translation.vector - world_from_body.translation.vector)
                / FRAME_S,
            angular_velocity_body: (world_from_body.rotation.inverse() * next.rotation)
                .scaled_axis()
                / FRAME_S,
        };
        let truth = world_from_camera.inverse() * state.world_from_pad;
        let data = cam.render(&motion, Some(&state))?.data;
        let noise = UnitQuaternion::from_euler_angles(
            sigma * rng.normal(),
            sigma * rng.normal(),
            sigma * rng.normal(),
        );
        let estimated = Isometry3::from_parts(
            world_from_body.translation,
            world_from_body.rotation * noise,
        );
        frames.push((data, estimated, truth));
    }
    Ok(Sequence {
        calibration,
        camera_from_body: cam.camera_from_body(),
        frames,
    })
}

/// Ours as it ships: the stage built from the deploy directory's `[aruco_pnp]`, its
/// estimator fed the frames.
fn ours(seq: &Sequence, pad: &PadModel, cfg: &ArucoConfig) -> Result<Run> {
    let mut stage = ArucoStage::from_config(cfg, seq.calibration, pad.clone())?;
    anyhow::ensure!(
        stage.estimator_mut().camera_from_body() == seq.camera_from_body,
        "the renderer's camera mount is not the config's"
    );
    let est = stage.estimator_mut();
    let mut run = Run {
        ms: Vec::new(),
        found: 0,
        position_error_m: Vec::new(),
    };
    for (k, (data, body, truth)) in seq.frames.iter().enumerate() {
        let frame = Frame {
            width: seq.calibration.width,
            height: seq.calibration.height,
            stride: seq.calibration.width,
            encoding: PixelEncoding::Mono8,
            data,
            undistorted: false,
        };
        let t = Instant::now();
        let e = est.process(&frame, k as u64 * 33_333_333, Some(body))?;
        run.ms.push(t.elapsed().as_secs_f64() * 1e3);
        if let Some(e) = e {
            run.found += 1;
            run.position_error_m
                .push((e.camera_from_pad.translation.vector - truth.translation.vector).norm());
        }
    }
    Ok(run)
}

/// OpenCV's detector with one corner refinement method, ArUco3 mode on.
fn opencv_params(refinement: i32) -> Result<opencv::core::Ptr<aruco::DetectorParameters>> {
    let mut params = aruco::DetectorParameters::create()?;
    params.set_corner_refinement_method(refinement);
    params.set_use_aruco3_detection(true);
    Ok(params)
}

/// The markers' bounding box widened by 35 % (and 16 px), inside the image.
fn region(corners: &Vector<Vector<Point2f>>, w: i32, h: i32) -> Option<opencv::core::Rect> {
    let (mut x0, mut y0, mut x1, mut y1) = (f32::MAX, f32::MAX, f32::MIN, f32::MIN);
    for c in corners.iter() {
        for p in c.iter() {
            (x0, y0, x1, y1) = (x0.min(p.x), y0.min(p.y), x1.max(p.x), y1.max(p.y));
        }
    }
    if x0 > x1 {
        return None;
    }
    let (mx, my) = (0.35 * (x1 - x0) / 2.0 + 16.0, 0.35 * (y1 - y0) / 2.0 + 16.0);
    let (ax, ay) = ((x0 - mx).max(0.0) as i32, (y0 - my).max(0.0) as i32);
    let (bx, by) = (((x1 + mx) as i32).min(w), ((y1 + my) as i32).min(h));
    (bx - ax >= 16 && by - ay >= 16).then(|| opencv::core::Rect::new(ax, ay, bx - ax, by - ay))
}

fn plain_opencv(seq: &Sequence, pad: &PadModel, refinement: i32, track: bool) -> Result<Run> {
    let dict =
        aruco::get_predefined_dictionary(aruco::PREDEFINED_DICTIONARY_NAME::DICT_ARUCO_ORIGINAL)?;
    let params = opencv_params(refinement)?;
    let k = seq.calibration.camera_matrix_mat()?;
    let d = seq.calibration.distortion_mat()?;
    let (w, h) = (seq.calibration.width as i32, seq.calibration.height as i32);
    let mut run = Run {
        ms: Vec::new(),
        found: 0,
        position_error_m: Vec::new(),
    };
    let mut last: Option<opencv::core::Rect> = None;
    for (data, _, truth) in &seq.frames {
        let image = Mat::new_rows_cols_with_data(h, w, data)?;
        let t = Instant::now();
        let mut corners = Vector::<Vector<Point2f>>::new();
        let mut ids = Vector::<i32>::new();
        let mut rejected = Vector::<Vector<Point2f>>::new();
        if let Some(r) = last.filter(|_| track) {
            let roi = Mat::roi(&image, r)?;
            aruco::detect_markers(&roi, &dict, &mut corners, &mut ids, &params, &mut rejected)?;
            let shifted: Vector<Vector<Point2f>> = corners
                .iter()
                .map(|c| {
                    c.iter()
                        .map(|p| Point2f::new(p.x + r.x as f32, p.y + r.y as f32))
                        .collect()
                })
                .collect();
            corners = shifted;
        }
        if ids.is_empty() {
            aruco::detect_markers(
                &image,
                &dict,
                &mut corners,
                &mut ids,
                &params,
                &mut rejected,
            )?;
        }
        last = region(&corners, w, h);
        let mut object = Vector::<Point3f>::new();
        let mut points = Vector::<Point2f>::new();
        for (id, c) in ids.iter().zip(corners.iter()) {
            if let Ok(model) = pad.marker_corners_pad(id as u32) {
                for (m, p) in model.iter().zip(c.iter()) {
                    object.push(Point3f::new(m.x as f32, m.y as f32, 0.0));
                    points.push(p);
                }
            }
        }
        let mut pose = None;
        if !object.is_empty() {
            let (mut rvec, mut tvec) = (Mat::default(), Mat::default());
            if calib3d::solve_pnp(
                &object,
                &points,
                &k,
                &d,
                &mut rvec,
                &mut tvec,
                false,
                calib3d::SOLVEPNP_ITERATIVE,
            )? {
                pose = Some([
                    *tvec.at::<f64>(0)?,
                    *tvec.at::<f64>(1)?,
                    *tvec.at::<f64>(2)?,
                ]);
            }
        }
        run.ms.push(t.elapsed().as_secs_f64() * 1e3);
        if let Some([x, y, z]) = pose {
            run.found += 1;
            run.position_error_m
                .push((nalgebra::Vector3::new(x, y, z) - truth.translation.vector).norm());
        }
    }
    Ok(run)
}

/// OpenCV at its best settings: both refinements run, the one with the lower p95
/// position error kept (ties: the faster), with its name.
fn opencv_best(seq: &Sequence, pad: &PadModel, track: bool) -> Result<(Run, &'static str)> {
    let sub = plain_opencv(seq, pad, aruco::CORNER_REFINE_SUBPIX, track)?;
    let con = plain_opencv(seq, pad, aruco::CORNER_REFINE_CONTOUR, track)?;
    let score = |r: &Run| (percentile(&r.position_error_m, 95.0), -(r.found as f64));
    Ok(if score(&con) < score(&sub) {
        (con, "contour")
    } else {
        (sub, "subpix")
    })
}

fn round3(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}

/// Runs the benchmark and prints the figures.
pub fn run(args: &ArucoArgs) -> Result<()> {
    if !(10..=5000).contains(&args.frames) {
        anyhow::bail!(
            "--frames {} is not allowed (allowed: 10 to 5000)",
            args.frames
        );
    }
    let deploy = args.deploy_dir.clone().unwrap_or_else(deploy_dir);
    let pad = PadModel::load(deploy.join("config").join("pad.toml")).context("pad layout")?;
    let shipped = stack::StackConfig::load(&deploy.join("config").join("landing.toml"))?.aruco_pnp;
    let mut out = serde_json::Map::new();
    let mut lines = Vec::new();
    for (file, tag) in [
        ("camera_down_640x480.yaml", "640x480"),
        ("camera_down_1280x720.yaml", "1280x720"),
    ] {
        eprintln!(
            "bench aruco: rendering a {}-frame descent at {tag}...",
            args.frames
        );
        let seq = render(file, args.frames, &deploy, &pad)?;
        eprintln!(
            "bench aruco: ours, then OpenCV (best settings, whole frame and tracked), on the same frames..."
        );
        let a = ours(&seq, &pad, &shipped)?;
        let (b, b_how) = opencv_best(&seq, &pad, false)?;
        let (c, c_how) = opencv_best(&seq, &pad, true)?;
        let pa = percentile(&a.ms, 50.0);
        let mut row = |name: &str, r: &Run| {
            let p50 = percentile(&r.ms, 50.0);
            out.insert(format!("{name}_ms_p50_{tag}"), json!(round3(p50)));
            out.insert(
                format!("{name}_ms_p99_{tag}"),
                json!(round3(percentile(&r.ms, 99.0))),
            );
            out.insert(format!("{name}_found_{tag}"), json!(r.found));
            out.insert(
                format!("{name}_position_error_mm_p95_{tag}"),
                json!(round3(percentile(&r.position_error_m, 95.0) * 1e3)),
            );
            if name != "ours" {
                out.insert(
                    format!("speedup_{name}_{tag}"),
                    json!(round3(p50 / pa.max(1e-9))),
                );
            }
            lines.push(format!(
                "{tag} {name}: p50 {p50:.3} ms (p99 {:.3}), poses {}/{}, position error p95 {:.1} mm{}",
                percentile(&r.ms, 99.0),
                r.found,
                seq.frames.len(),
                percentile(&r.position_error_m, 95.0) * 1e3,
                match p50 / pa.max(1e-9) {
                    _ if name == "ours" => String::new(),
                    x if x >= 1.0 => format!(", ours {x:.1}x faster"),
                    x => format!(", OpenCV {:.1}x faster than ours", 1.0 / x.max(1e-9)),
                }
            ));
        };
        row("ours", &a);
        row("opencv", &b);
        row("opencv_tracked", &c);
        out.insert(format!("opencv_refinement_{tag}"), json!(b_how));
        out.insert(format!("opencv_tracked_refinement_{tag}"), json!(c_how));
    }
    out.insert("frames".into(), json!(args.frames));
    if args.json {
        println!("{}", serde_json::Value::Object(out));
    } else {
        for l in lines {
            println!("{l}");
        }
    }
    Ok(())
}
