//! `landing calibrate`: the camera's intrinsics and distortion from views of a ChArUco
//! board (a directory of images, or a V4L2 camera), written as the calibration YAML the
//! stack reads, with a figure of the coverage and the per-view errors; and the board
//! itself, to print.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use calibration::{CharucoSpec, Detection, Rejected, calibrate, detect};
use clap::{Args, Subcommand};
use opencv::core::{Mat, Vector};
use opencv::prelude::*;
use opencv::{imgcodecs, videoio};

/// `landing calibrate ...`.
#[derive(Debug, Subcommand)]
pub enum CalibrateCommand {
    /// Fit the camera's intrinsics and distortion to views of a ChArUco board (20 or
    /// more, from many angles and distances, the board reaching every part of the
    /// image): writes the calibration YAML the stack reads (--out), prints the RMS
    /// reprojection error, the coverage of the image and the rejected views, and draws
    /// them (--plot). Exit code 1 when the fit is poor (RMS over 1 px).
    Camera(CameraArgs),
    /// The down camera's mount (its tilt from straight down and its offset on the body)
    /// from a recording of a flight over a static pad (`landing run --record`, or the
    /// vehicle's recorder): hover over the pad and move a metre or more sideways and up
    /// and down, turning a little, with the pad in view. Uses the pad observations (PnP)
    /// and the autopilot's state only; prints the mount and the [aruco_pnp] keys.
    Mount(MountArgs),
    /// Write a ChArUco board as a PNG, to print (check the printed square with a ruler:
    /// --board must say the true size).
    Board(BoardArgs),
}

/// Arguments of `landing calibrate camera`.
#[derive(Debug, Args)]
pub struct CameraArgs {
    /// The board: charuco:<squares x>x<squares y>:<square m>:<marker m>:<dictionary>.
    #[arg(long, default_value = "charuco:7x5:0.04:0.03:DICT_5X5_100")]
    board: String,
    /// A directory of views (png, jpg, bmp, tiff), all of one size.
    #[arg(long, conflicts_with = "device", required_unless_present = "device")]
    images: Option<PathBuf>,
    /// A V4L2 camera to take the views from: one every --interval-s, --frames of them,
    /// keeping those with enough corners; move the board between them.
    #[arg(long)]
    device: Option<String>,
    /// Views to take from --device.
    #[arg(long, default_value_t = 30)]
    frames: u32,
    /// Seconds between views from --device.
    #[arg(long, default_value_t = 1.0)]
    interval_s: f64,
    /// Where to write the calibration (OpenCV YAML, as deploy/config/camera_*.yaml).
    #[arg(long)]
    out: PathBuf,
    /// Draw the coverage and the per-view errors into this PNG.
    #[arg(long)]
    plot: Option<PathBuf>,
}

/// Arguments of `landing calibrate mount`.
#[derive(Debug, Args)]
pub struct MountArgs {
    /// The recording (.mcap) with /pad/observation and /vehicle/state.
    #[arg(long)]
    recording: PathBuf,
    /// The stack file whose [aruco_pnp] camera_position_in_body_m is the drawing's mount
    /// (the start of the fit) [default: defaults].
    #[arg(long)]
    config: Option<PathBuf>,
    /// Added to each frame's capture time before the vehicle state is looked up, ms
    /// [default: found, within 100 ms, as the offset at which the pad holds stillest].
    #[arg(long, allow_negative_numbers = true)]
    time_offset_ms: Option<f64>,
    /// Use the pad only while the vehicle is this slow, m/s.
    #[arg(long, default_value_t = 2.0)]
    max_speed_m_s: f64,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// Arguments of `landing calibrate board`.
#[derive(Debug, Args)]
pub struct BoardArgs {
    /// The board: charuco:<squares x>x<squares y>:<square m>:<marker m>:<dictionary>.
    #[arg(long, default_value = "charuco:7x5:0.04:0.03:DICT_5X5_100")]
    board: String,
    /// Pixels per square.
    #[arg(long, default_value_t = 200)]
    px_per_square: i32,
    /// The PNG to write.
    #[arg(long)]
    out: PathBuf,
}

/// Runs a `landing calibrate` command; `Ok(false)` when the fit is poor.
pub fn run(cmd: &CalibrateCommand) -> Result<bool> {
    match cmd {
        CalibrateCommand::Camera(a) => camera(a),
        CalibrateCommand::Board(a) => board(a).map(|_| true),
        CalibrateCommand::Mount(a) => mount(a).map(|_| true),
    }
}

fn board(a: &BoardArgs) -> Result<()> {
    let spec: CharucoSpec = a.board.parse()?;
    if !(20..=2000).contains(&a.px_per_square) {
        bail!(
            "--px-per-square {} is not allowed (allowed: 20 to 2000)",
            a.px_per_square
        );
    }
    let image = spec.image(a.px_per_square)?;
    write_png(&a.out, &image)?;
    println!(
        "wrote {}: {} ({} x {} px); print it so that a square is {} m",
        a.out.display(),
        spec,
        image.cols(),
        image.rows(),
        spec.square_m
    );
    Ok(())
}

fn write_png(path: &Path, image: &Mat) -> Result<()> {
    let ok = imgcodecs::imwrite(&*path.to_string_lossy(), image, &Vector::new())
        .with_context(|| format!("{}: cannot write", path.display()))?;
    if !ok {
        bail!("{}: OpenCV could not write it", path.display());
    }
    Ok(())
}

/// What the views gave: their corners, the rejected ones, the image size.
struct Views {
    detections: Vec<Detection>,
    rejected: Vec<Rejected>,
    size: Option<(u32, u32)>,
}

impl Views {
    fn add(
        &mut self,
        name: &str,
        image: &Mat,
        spec: &CharucoSpec,
        board: &opencv::core::Ptr<opencv::aruco::CharucoBoard>,
    ) {
        let size = (image.cols() as u32, image.rows() as u32);
        match self.size {
            Some(s) if s != size => {
                self.rejected.push(Rejected {
                    name: name.to_string(),
                    why: format!(
                        "{}x{}, not the first view's {}x{}",
                        size.0, size.1, s.0, s.1
                    ),
                });
                return;
            }
            _ => self.size = Some(size),
        }
        match detect(name, image, spec, board) {
            Ok(d) => {
                println!("{name}: {} corners", d.ids.len());
                self.detections.push(d);
            }
            Err(r) => {
                println!("{name}: rejected, {}", r.why);
                self.rejected.push(r);
            }
        }
    }
}

const IMAGE_EXTENSIONS: &[&str] = &["png", "jpg", "jpeg", "bmp", "tif", "tiff", "pgm", "ppm"];

fn camera(a: &CameraArgs) -> Result<bool> {
    let spec: CharucoSpec = a.board.parse()?;
    let board = spec.board()?;
    let mut views = Views {
        detections: Vec::new(),
        rejected: Vec::new(),
        size: None,
    };
    if let Some(dir) = &a.images {
        let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
            .with_context(|| format!("--images {}", dir.display()))?
            .flatten()
            .map(|e| e.path())
            .filter(|p| {
                p.extension()
                    .and_then(|e| e.to_str())
                    .is_some_and(|e| IMAGE_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
            })
            .collect();
        files.sort();
        if files.is_empty() {
            bail!(
                "--images {}: no images (looked for {})",
                dir.display(),
                IMAGE_EXTENSIONS.join(", ")
            );
        }
        for f in &files {
            let name = f
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            let image = imgcodecs::imread(&*f.to_string_lossy(), imgcodecs::IMREAD_GRAYSCALE)?;
            if image.empty() {
                println!("{name}: rejected, not a readable image");
                views.rejected.push(Rejected {
                    name,
                    why: "not a readable image".into(),
                });
                continue;
            }
            views.add(&name, &image, &spec, &board);
        }
    } else if let Some(device) = &a.device {
        take_views(device, a, &spec, &board, &mut views)?;
    }
    let Some(size) = views.size else {
        bail!("no readable view of the board");
    };
    let c = calibrate(&views.detections, views.rejected, size, &board)?;
    c.calibration
        .save(&a.out)
        .with_context(|| format!("--out {}", a.out.display()))?;
    let k = &c.calibration;
    println!(
        "{} views used, {} rejected; RMS reprojection error {:.3} px; {:.0} % of the image covered",
        c.per_view_px.len(),
        c.rejected.len(),
        c.rms_px,
        c.coverage * 100.0
    );
    println!(
        "fx {:.2} fy {:.2} cx {:.2} cy {:.2} px; distortion k1 {:.5} k2 {:.5} p1 {:.5} p2 {:.5} k3 {:.5}",
        k.fx,
        k.fy,
        k.cx,
        k.cy,
        k.distortion[0],
        k.distortion[1],
        k.distortion[2],
        k.distortion[3],
        k.distortion[4]
    );
    println!("wrote {}", a.out.display());
    if c.coverage < 0.5 {
        println!(
            "warning: the board reached {:.0} % of the image: the distortion is only known where it was; take views with the board near the edges and corners",
            c.coverage * 100.0
        );
    }
    if let Some(p) = &a.plot {
        calibration::plot::write(p, &c).with_context(|| format!("--plot {}", p.display()))?;
        println!("wrote {}", p.display());
    }
    Ok(c.rms_px <= 1.0)
}

fn take_views(
    device: &str,
    a: &CameraArgs,
    spec: &CharucoSpec,
    board: &opencv::core::Ptr<opencv::aruco::CharucoBoard>,
    views: &mut Views,
) -> Result<()> {
    if !(a.interval_s.is_finite() && (0.05..=60.0).contains(&a.interval_s)) {
        bail!(
            "--interval-s {} is not allowed (allowed: 0.05 to 60)",
            a.interval_s
        );
    }
    let mut cap = videoio::VideoCapture::from_file(device, videoio::CAP_V4L2)
        .with_context(|| format!("--device {device}"))?;
    if !cap.is_opened()? {
        bail!("--device {device}: OpenCV could not open it");
    }
    let mut frame = Mat::default();
    let mut next = Instant::now();
    for k in 0..a.frames {
        // Frames between views are read and dropped: the view is the newest.
        while Instant::now() < next {
            cap.grab()?;
        }
        next += Duration::from_secs_f64(a.interval_s);
        if !cap.read(&mut frame)? || frame.empty() {
            bail!("--device {device}: the camera stopped delivering frames");
        }
        views.add(&format!("frame{k:03}"), &frame, spec, board);
    }
    Ok(())
}

/// The largest offset between frame and state stamps the fit looks for, ms.
const MAX_TIME_OFFSET_MS: f64 = 100.0;

/// Observations with a reprojection error above this are not used, px.
const MAX_REPROJECTION_PX: f64 = 2.0;

fn mount(a: &MountArgs) -> Result<()> {
    use ipc_types::msg::{PadObservation, Pose, VehicleState};
    use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
    let (_, aruco): (_, aruco_pnp::ArucoConfig) =
        stack_config::load_process_or_default(a.config.as_deref(), "aruco_pnp")?;
    let nominal = optics::down_camera_from_body(aruco.camera_position_in_body_m).inverse();
    let mut states = Vec::new();
    let mut observations = Vec::new();
    recorder::decode::read_recording(&a.recording, |m| {
        match m.topic {
            "/vehicle/state" => states.push(m.decode::<VehicleState>()?),
            "/pad/observation" => observations.push(m.decode::<PadObservation>()?),
            _ => {}
        }
        Ok(())
    })
    .with_context(|| format!("--recording {}", a.recording.display()))?;
    states.sort_by_key(|s| s.msg.capture_ns);
    let mut history = state_history::StateHistory::new(states.len() + 2, 0);
    for s in &states {
        if let Some(p) = state_history::timed_pose_of(s) {
            history.push(p);
        }
    }
    let iso = |p: &Pose| {
        let [x, y, z, w] = p.rotation_xyzw;
        Isometry3::from_parts(
            Translation3::new(p.translation[0], p.translation[1], p.translation[2]),
            UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z)),
        )
    };
    let samples_at = |offset_ms: f64| -> Vec<calibration::Sample> {
        observations
            .iter()
            .filter(|o| {
                o.marker_count > 0
                    && o.camera_from_pad.is_finite()
                    && o.reprojection_error_px < MAX_REPROJECTION_PX
            })
            .filter(|o| {
                // Moving fast, a few ms of stamp or estimator lag are centimetres.
                let k = states.partition_point(|s| s.msg.capture_ns < o.msg.capture_ns);
                let v = states
                    .get(k.min(states.len().saturating_sub(1)))
                    .map(|s| s.velocity);
                v.is_some_and(|v| {
                    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt() <= a.max_speed_m_s
                })
            })
            .filter_map(|o| {
                let at = o
                    .msg
                    .capture_ns
                    .saturating_add_signed((offset_ms * 1e6) as i64);
                Some(calibration::Sample {
                    at_s: o.msg.capture_ns as f64 * 1e-9,
                    world_from_body: history.at(at).ok()?,
                    camera_from_pad: iso(&o.camera_from_pad),
                })
            })
            .collect()
    };
    let (fit, offset_ms) = match a.time_offset_ms {
        Some(ms) => (calibration::fit_mount(&samples_at(ms), &nominal)?, ms),
        None => calibration::fit_mount_and_offset(samples_at, &nominal, MAX_TIME_OFFSET_MS)?,
    };
    // The tilt from the drawing's straight-down mount, as a rotation in the body frame.
    let tilt = fit.body_from_camera.rotation * nominal.rotation.inverse();
    let (roll, pitch, yaw) = tilt.euler_angles();
    let t = fit.body_from_camera.translation.vector;
    let q = fit.body_from_camera.rotation;
    if a.json {
        println!(
            "{}",
            serde_json::json!({
                "samples": fit.samples,
                "time_offset_ms": offset_ms,
                "motion_m": fit.motion_m,
                "drift_max_m": fit.drift_max_m,
                "rms_position_m": fit.rms_position_m,
                "rms_rotation_deg": fit.rms_rotation_deg,
                "tilt_from_straight_down_deg": [roll.to_degrees(), pitch.to_degrees(), yaw.to_degrees()],
                "camera_position_in_body_m": [t.x, t.y, t.z],
                "body_from_camera_xyzw": [q.i, q.j, q.k, q.w],
            })
        );
        return Ok(());
    }
    println!(
        "{} samples of the pad over {:.2} m of flight; the pad holds still to {:.3} m and {:.2} deg RMS, the autopilot's position drifting up to {:.3} m",
        fit.samples, fit.motion_m, fit.rms_position_m, fit.rms_rotation_deg, fit.drift_max_m
    );
    println!(
        "the frames' stamps are {offset_ms:.1} ms behind the autopilot's state (added to them before the state is looked up)"
    );
    println!(
        "the camera is tilted from straight down by roll {:.2} deg, pitch {:.2} deg, yaw {:.2} deg (about body x, y, z)",
        roll.to_degrees(),
        pitch.to_degrees(),
        yaw.to_degrees()
    );
    println!(
        "[aruco_pnp] camera_position_in_body_m = [{:.3}, {:.3}, {:.3}]  (was {:?})",
        t.x, t.y, t.z, aruco.camera_position_in_body_m
    );
    Ok(())
}
