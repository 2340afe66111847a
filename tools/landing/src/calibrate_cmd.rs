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
