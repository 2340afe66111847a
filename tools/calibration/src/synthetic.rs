//! Views of a flat board rendered through a known camera (its intrinsics and its lens
//! distortion), supersampled: what a calibration must recover, and a check of a setup
//! (board size, distances) before taking real pictures.

use nalgebra::Point2;
use nalgebra::{Rotation3, Vector3};
use opencv::core::{CV_8UC1, Mat, Scalar};
use opencv::prelude::*;
use optics::CameraCalibration;

/// Renders boards through one camera; the rays of its pixels are found once.
pub struct Renderer {
    width: u32,
    height: u32,
    supersample: u32,
    /// Each supersampled pixel's ray (undistorted normalized coordinates), row-major.
    rays: Vec<(f64, f64)>,
}

impl Renderer {
    /// A renderer for `camera`, `supersample` x `supersample` samples per pixel (3 is
    /// plenty for corner positions to a few hundredths of a pixel).
    pub fn new(camera: &CameraCalibration, supersample: u32) -> Self {
        let s = supersample.max(1);
        let (w, h) = (camera.width * s, camera.height * s);
        let mut rays = Vec::with_capacity((w * h) as usize);
        for r in 0..h {
            for c in 0..w {
                let pixel = Point2::new(
                    (f64::from(c) + 0.5) / f64::from(s) - 0.5,
                    (f64::from(r) + 0.5) / f64::from(s) - 0.5,
                );
                let n = camera.undistort_pixel(&pixel);
                rays.push((n.x, n.y));
            }
        }
        Self {
            width: camera.width,
            height: camera.height,
            supersample: s,
            rays,
        }
    }

    /// The view of `board` (8-bit grey, drawn edge to edge, `board_m` wide and high) whose
    /// frame (x right, y up the image as drawn, origin at its lower-left corner: OpenCV's
    /// ChArUco object frame) is at `camera_from_board`; white around it.
    pub fn render(
        &self,
        board: &Mat,
        board_m: (f64, f64),
        rotation: &Rotation3<f64>,
        translation: &Vector3<f64>,
    ) -> opencv::Result<Mat> {
        let (tw, th) = (board.cols(), board.rows());
        let texture = board.data_bytes()?;
        let sample = |u: f64, v: f64| -> f64 {
            // Bilinear, white outside the board.
            let (x0, y0) = (u.floor(), v.floor());
            let (fx, fy) = (u - x0, v - y0);
            let at = |x: f64, y: f64| -> f64 {
                if x < 0.0 || y < 0.0 || x >= f64::from(tw) || y >= f64::from(th) {
                    255.0
                } else {
                    f64::from(texture[(y as i32 * tw + x as i32) as usize])
                }
            };
            at(x0, y0) * (1.0 - fx) * (1.0 - fy)
                + at(x0 + 1.0, y0) * fx * (1.0 - fy)
                + at(x0, y0 + 1.0) * (1.0 - fx) * fy
                + at(x0 + 1.0, y0 + 1.0) * fx * fy
        };
        let rt = rotation.transpose();
        let t_b = rt * translation;
        let s = self.supersample as usize;
        let (w, h) = (self.width as usize, self.height as usize);
        let mut sums = vec![0.0f64; w * h];
        let sw = w * s;
        for (i, (x, y)) in self.rays.iter().enumerate() {
            let d_b = rt * Vector3::new(*x, *y, 1.0);
            // On the board's plane (z = 0 in its frame), in front of the camera.
            let value = if d_b.z.abs() < 1e-12 {
                255.0
            } else {
                let lambda = t_b.z / d_b.z;
                if lambda <= 0.0 {
                    255.0
                } else {
                    let p = d_b * lambda - t_b;
                    let u = p.x / board_m.0 * f64::from(tw) - 0.5;
                    let v = (1.0 - p.y / board_m.1) * f64::from(th) - 0.5;
                    sample(u, v)
                }
            };
            let (r, c) = (i / sw, i % sw);
            sums[(r / s) * w + c / s] += value;
        }
        let mut out =
            Mat::new_rows_cols_with_default(h as i32, w as i32, CV_8UC1, Scalar::all(0.0))?;
        let n = (s * s) as f64;
        for (px, sum) in out.data_bytes_mut()?.iter_mut().zip(sums) {
            *px = (sum / n).round().clamp(0.0, 255.0) as u8;
        }
        Ok(out)
    }
}

/// A small deterministic generator, so that a set of views is the same every run.
struct Lcg(u64);

impl Lcg {
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        lo + (hi - lo) * ((self.0 >> 11) as f64 / (1u64 << 53) as f64)
    }
}

/// `n` poses (`camera_from_board` rotation and translation) of a board `board_m` wide and
/// high, drawn as a careful calibration is taken: the board faces the camera (its y up
/// the image), turns up to about 35 deg each way, stands `distance_m` away (a range), and
/// its centre goes everywhere in a field of view `tan_half_fov` wide (x) and 3/4 of that
/// high; the same for the same `seed`.
pub fn spread_poses(
    n: usize,
    seed: u64,
    board_m: (f64, f64),
    distance_m: (f64, f64),
    tan_half_fov: f64,
) -> Vec<(Rotation3<f64>, Vector3<f64>)> {
    let facing = Rotation3::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
    let centre = Vector3::new(board_m.0 / 2.0, board_m.1 / 2.0, 0.0);
    let mut rng = Lcg(seed);
    (0..n)
        .map(|_| {
            let tilt = Rotation3::from_euler_angles(
                rng.uniform(-0.6, 0.6),
                rng.uniform(-0.6, 0.6),
                rng.uniform(-0.5, 0.5),
            );
            let rotation = tilt * facing;
            let d = rng.uniform(distance_m.0, distance_m.1);
            let at = Vector3::new(
                rng.uniform(-1.0, 1.0) * tan_half_fov * d,
                rng.uniform(-0.75, 0.75) * tan_half_fov * d,
                d,
            );
            (rotation, at - rotation * centre)
        })
        .collect()
}
