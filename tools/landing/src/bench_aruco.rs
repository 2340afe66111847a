//! `landing bench aruco`: detection + pose time per frame, ours against plain OpenCV,
//! on the same rendered descents in the same run.
//!
//! A descent from 3 m to 0.15 m over the pad (drifting sideways, yawing, tilting a
//! little, sensor noise on) is rendered once per resolution. Ours: `PadEstimator`
//! fed the frames in order, as aruco-pnp is (so it tracks the pad's region). Plain
//! OpenCV: `detectMarkers` with default parameters on the whole frame, then one
//! `solvePnP` over every pad marker found, the way a first implementation would.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use aruco_pnp::{EstimatorSettings, Frame, PadEstimator};
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

use crate::stats::percentile;

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
struct Sequence {
    calibration: CameraCalibration,
    camera_from_body: Isometry3<f64>,
    frames: Vec<(Vec<u8>, Isometry3<f64>, Isometry3<f64>)>,
}

fn render(file: &str, n: usize, deploy: &std::path::Path, pad: &PadModel) -> Result<Sequence> {
    let calibration = CameraCalibration::load(deploy.join("config").join(file))?;
    let mut cam = DownCamera::new(DownCameraParams::default(), calibration, pad)?;
    let state = PadState {
        world_from_pad: Isometry3::from_parts(
            Translation3::new(3.0, -2.0, 0.4),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 0.5),
        ),
        linear_velocity: nalgebra::Vector3::zeros(),
        linear_acceleration: nalgebra::Vector3::zeros(),
        angular_velocity: nalgebra::Vector3::zeros(),
        speed_m_s: 0.0,
        distance_m: 0.0,
    };
    let body_from_camera = cam.camera_from_body().inverse();
    let mut frames = Vec::with_capacity(n);
    for k in 0..n {
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
        let world_from_body = world_from_camera * cam.camera_from_body();
        let truth = world_from_camera.inverse() * state.world_from_pad;
        let data = cam
            .render(&BodyMotion::at_rest(world_from_body), Some(&state))?
            .data;
        frames.push((data, world_from_body, truth));
    }
    Ok(Sequence {
        calibration,
        camera_from_body: cam.camera_from_body(),
        frames,
    })
}

fn ours(seq: &Sequence, pad: &PadModel) -> Result<Run> {
    let mut est = PadEstimator::new(
        seq.calibration,
        pad.clone(),
        seq.camera_from_body,
        EstimatorSettings::default(),
    )?;
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

fn plain_opencv(seq: &Sequence, pad: &PadModel) -> Result<Run> {
    let dict =
        aruco::get_predefined_dictionary(aruco::PREDEFINED_DICTIONARY_NAME::DICT_ARUCO_ORIGINAL)?;
    let params = aruco::DetectorParameters::create()?;
    let k = seq.calibration.camera_matrix_mat()?;
    let d = seq.calibration.distortion_mat()?;
    let mut run = Run {
        ms: Vec::new(),
        found: 0,
        position_error_m: Vec::new(),
    };
    for (data, _, truth) in &seq.frames {
        let image = Mat::new_rows_cols_with_data(
            seq.calibration.height as i32,
            seq.calibration.width as i32,
            data,
        )?;
        let t = Instant::now();
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
        )?;
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
        eprintln!("bench aruco: ours, then plain OpenCV, on the same frames...");
        let a = ours(&seq, &pad)?;
        let b = plain_opencv(&seq, &pad)?;
        let (pa, pb) = (percentile(&a.ms, 50.0), percentile(&b.ms, 50.0));
        out.insert(format!("ours_ms_p50_{tag}"), json!(round3(pa)));
        out.insert(format!("opencv_ms_p50_{tag}"), json!(round3(pb)));
        out.insert(
            format!("ours_ms_p99_{tag}"),
            json!(round3(percentile(&a.ms, 99.0))),
        );
        out.insert(format!("speedup_{tag}"), json!(round3(pb / pa.max(1e-9))));
        out.insert(format!("ours_found_{tag}"), json!(a.found));
        out.insert(format!("opencv_found_{tag}"), json!(b.found));
        out.insert(
            format!("ours_position_error_mm_p95_{tag}"),
            json!(round3(percentile(&a.position_error_m, 95.0) * 1e3)),
        );
        out.insert(
            format!("opencv_position_error_mm_p95_{tag}"),
            json!(round3(percentile(&b.position_error_m, 95.0) * 1e3)),
        );
        lines.push(format!(
            "{tag}: ours p50 {pa:.3} ms (p99 {:.3}), plain OpenCV p50 {pb:.3} ms: {:.1}x faster; \
             poses {}/{} vs {}/{}; position error p95 {:.1} mm vs {:.1} mm",
            percentile(&a.ms, 99.0),
            pb / pa.max(1e-9),
            a.found,
            seq.frames.len(),
            b.found,
            seq.frames.len(),
            percentile(&a.position_error_m, 95.0) * 1e3,
            percentile(&b.position_error_m, 95.0) * 1e3,
        ));
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
