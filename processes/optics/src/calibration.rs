//! Camera calibration: pinhole intrinsics plus OpenCV's radial-tangential
//! distortion (k1, k2, p1, p2, k3), read from and written to the YAML files
//! OpenCV's calibration tools produce, so a real camera's calibration drops in
//! where the simulated one was.

use std::path::{Path, PathBuf};

use nalgebra::{Point2, Point3, Vector2};
use opencv::core::{FileStorage, FileStorage_Mode, Mat};
use opencv::prelude::*;
use thiserror::Error;

use crate::calibration_yaml;

/// Why a calibration could not be loaded, saved or used.
#[derive(Debug, Error)]
pub enum CalibrationError {
    /// The file does not exist (the most common mistake: a wrong path).
    #[error("calibration file {path}: not found")]
    Missing {
        /// The path that was tried.
        path: PathBuf,
    },
    /// The file exists but cannot be read as text.
    #[error("calibration file {path}: cannot be read: {message}")]
    Unreadable {
        /// The file.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// The file is not a calibration YAML the stack reads.
    #[error("calibration file {path}: line {line}: {message}")]
    Syntax {
        /// The file.
        path: PathBuf,
        /// The line of the fault (1-based; 0: the file as a whole).
        line: usize,
        /// What is wrong and what is allowed.
        message: String,
    },
    /// A required key is absent.
    #[error("calibration file {path}: missing key `{key}`")]
    MissingKey {
        /// The file.
        path: PathBuf,
        /// The key that should be there.
        key: &'static str,
    },
    /// A matrix has the wrong number of elements.
    #[error("calibration file {path}: `{key}` is {rows}x{cols}, expected {expected}")]
    WrongSize {
        /// The file.
        path: PathBuf,
        /// The matrix key.
        key: &'static str,
        /// Rows found.
        rows: i32,
        /// Columns found.
        cols: i32,
        /// What is accepted.
        expected: &'static str,
    },
    /// A value is out of range (non-finite, non-positive focal length, ...).
    #[error("calibration file {path}: `{key}` = {value}: {allowed}")]
    BadValue {
        /// The file (empty when the calibration was built in code).
        path: PathBuf,
        /// The offending key.
        key: &'static str,
        /// The value found.
        value: f64,
        /// What is accepted.
        allowed: &'static str,
    },
    /// Writing the file failed.
    #[error("calibration file {path}: cannot be written: {message}")]
    Write {
        /// The file.
        path: PathBuf,
        /// OpenCV's message.
        message: String,
    },
}

/// The file as text, reading at most one byte past the reader's limit (a huge or
/// endless file, `/dev/zero` say, is refused without being read whole).
fn read_text(path: &Path) -> Result<String, CalibrationError> {
    use std::io::Read;
    let unreadable = |message: String| CalibrationError::Unreadable {
        path: path.to_path_buf(),
        message,
    };
    let file = std::fs::File::open(path).map_err(|e| unreadable(e.to_string()))?;
    let mut bytes = Vec::new();
    file.take(calibration_yaml::MAX_FILE_BYTES as u64 + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| unreadable(e.to_string()))?;
    if bytes.len() > calibration_yaml::MAX_FILE_BYTES {
        return Err(unreadable(format!(
            "larger than {} bytes; a calibration file is well under that",
            calibration_yaml::MAX_FILE_BYTES
        )));
    }
    String::from_utf8(bytes).map_err(|e| {
        unreadable(format!(
            "not UTF-8 text (byte {})",
            e.utf8_error().valid_up_to()
        ))
    })
}

/// A calibrated camera: image size, pinhole intrinsics and OpenCV's 5-term
/// distortion, the model both the renderer and the detector use.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraCalibration {
    /// Image width, px.
    pub width: u32,
    /// Image height, px.
    pub height: u32,
    /// Focal length along x, px.
    pub fx: f64,
    /// Focal length along y, px.
    pub fy: f64,
    /// Principal point x, px.
    pub cx: f64,
    /// Principal point y, px.
    pub cy: f64,
    /// Distortion in OpenCV's order: k1, k2, p1, p2, k3.
    pub distortion: [f64; 5],
}

/// Iterations of the undistortion fixed point; it converges in well under 20
/// for the mild lens distortion of a calibrated camera.
const UNDISTORT_MAX_ITER: usize = 100;

impl CameraCalibration {
    /// Builds a calibration in code and checks it, so a bad one fails here
    /// rather than as NaN pixels later.
    pub fn new(
        width: u32,
        height: u32,
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
        distortion: [f64; 5],
    ) -> Result<Self, CalibrationError> {
        let c = Self {
            width,
            height,
            fx,
            fy,
            cx,
            cy,
            distortion,
        };
        c.validate(Path::new(""))?;
        Ok(c)
    }

    /// An ideal pinhole whose horizontal field of view is `hfov_deg`, with the
    /// principal point at the image centre and square pixels.
    pub fn from_hfov(
        width: u32,
        height: u32,
        hfov_deg: f64,
        distortion: [f64; 5],
    ) -> Result<Self, CalibrationError> {
        let f = (f64::from(width) / 2.0) / (hfov_deg.to_radians() / 2.0).tan();
        Self::new(
            width,
            height,
            f,
            f,
            f64::from(width) / 2.0,
            f64::from(height) / 2.0,
            distortion,
        )
    }

    fn validate(&self, path: &Path) -> Result<(), CalibrationError> {
        let bad = |key, value: f64, allowed| CalibrationError::BadValue {
            path: path.to_path_buf(),
            key,
            value,
            allowed,
        };
        if self.width == 0 {
            return Err(bad("image_width", 0.0, "must be > 0"));
        }
        if self.height == 0 {
            return Err(bad("image_height", 0.0, "must be > 0"));
        }
        for (key, v) in [("camera_matrix fx", self.fx), ("camera_matrix fy", self.fy)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(key, v, "focal length must be finite and > 0"));
            }
        }
        for (key, v) in [("camera_matrix cx", self.cx), ("camera_matrix cy", self.cy)] {
            if !v.is_finite() {
                return Err(bad(key, v, "must be finite"));
            }
        }
        for v in self.distortion {
            if !v.is_finite() {
                return Err(bad("distortion_coefficients", v, "must be finite"));
            }
        }
        Ok(())
    }

    /// Loads a calibration YAML as OpenCV's calibration tools or ROS's
    /// `camera_calibration` write it (`image_width`, `image_height`, `camera_matrix`
    /// 3x3, `distortion_coefficients` with 4, 5 or more terms; only the first five are
    /// used and the rest must be zero). Read by the stack's own bounded reader, not
    /// OpenCV's, which can hang on a malformed file (see `calibration_yaml`).
    pub fn load(path: impl AsRef<Path>) -> Result<Self, CalibrationError> {
        let path = path.as_ref();
        if !path.is_file() {
            return Err(CalibrationError::Missing {
                path: path.to_path_buf(),
            });
        }
        let text = read_text(path)?;
        let syntax = |e: calibration_yaml::SyntaxError| CalibrationError::Syntax {
            path: path.to_path_buf(),
            line: e.line,
            message: e.message,
        };
        let at =
            |line: usize, message: String| syntax(calibration_yaml::SyntaxError { line, message });
        let doc = calibration_yaml::parse(&text).map_err(syntax)?;
        let model = match doc.get("distortion_model") {
            Some(calibration_yaml::Value::Scalar { text, .. }) => text.as_str(),
            _ => "plumb_bob",
        };
        if !["plumb_bob", "rational_polynomial"].contains(&model) {
            return Err(at(
                0,
                format!(
                    "distortion_model `{model}`: allowed plumb_bob or rational_polynomial \
                     (OpenCV's radial-tangential model)"
                ),
            ));
        }
        let missing = |key| CalibrationError::MissingKey {
            path: path.to_path_buf(),
            key,
        };
        let int = |key: &'static str| -> Result<u32, CalibrationError> {
            let v = match doc.get(key) {
                None => return Err(missing(key)),
                Some(calibration_yaml::Value::Scalar { line, text }) => {
                    calibration_yaml::number(*line, key, text).map_err(syntax)?
                }
                Some(calibration_yaml::Value::Matrix { line, .. }) => {
                    return Err(at(
                        *line,
                        format!("`{key}` is a matrix; expected a positive integer"),
                    ));
                }
            };
            if v.is_finite() && v >= 1.0 && v.fract() == 0.0 && v <= f64::from(u32::MAX) {
                Ok(v as u32)
            } else {
                Err(CalibrationError::BadValue {
                    path: path.to_path_buf(),
                    key,
                    value: v,
                    allowed: "must be a positive integer",
                })
            }
        };
        let matrix = |key: &'static str| -> Result<(i32, i32, &[f64]), CalibrationError> {
            match doc.get(key) {
                None => Err(missing(key)),
                Some(calibration_yaml::Value::Matrix {
                    rows, cols, data, ..
                }) => Ok((*rows, *cols, data.as_slice())),
                Some(calibration_yaml::Value::Scalar { line, .. }) => Err(at(
                    *line,
                    format!("`{key}` is not a matrix (rows, cols and data indented under it)"),
                )),
            }
        };
        let width = int("image_width")?;
        let height = int("image_height")?;
        let (rows, cols, k) = matrix("camera_matrix")?;
        if rows != 3 || cols != 3 {
            return Err(CalibrationError::WrongSize {
                path: path.to_path_buf(),
                key: "camera_matrix",
                rows,
                cols,
                expected: "3x3",
            });
        }
        let (rows, cols, d) = matrix("distortion_coefficients")?;
        if !(rows == 1 || cols == 1) || d.len() < 4 {
            return Err(CalibrationError::WrongSize {
                path: path.to_path_buf(),
                key: "distortion_coefficients",
                rows,
                cols,
                expected: "1xN or Nx1 with N >= 4",
            });
        }
        if d.iter().skip(5).any(|&x| x != 0.0) {
            return Err(CalibrationError::BadValue {
                path: path.to_path_buf(),
                key: "distortion_coefficients",
                value: d.iter().skip(5).copied().find(|&x| x != 0.0).unwrap_or(0.0),
                allowed: "only k1, k2, p1, p2, k3 are supported; further terms must be 0",
            });
        }
        let mut distortion = [0.0; 5];
        for (dst, src) in distortion.iter_mut().zip(d) {
            *dst = *src;
        }
        let calibration = Self {
            width,
            height,
            fx: k[0],
            fy: k[4],
            cx: k[2],
            cy: k[5],
            distortion,
        };
        calibration.validate(path)?;
        Ok(calibration)
    }

    /// Writes the calibration in OpenCV's YAML format (what `load` reads and
    /// what OpenCV's own tools read).
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), CalibrationError> {
        let path = path.as_ref();
        let err = |e: opencv::Error| CalibrationError::Write {
            path: path.to_path_buf(),
            message: e.message,
        };
        let mut fs = FileStorage::new_def(path, FileStorage_Mode::WRITE as i32).map_err(err)?;
        if !fs.is_opened().map_err(err)? {
            return Err(CalibrationError::Write {
                path: path.to_path_buf(),
                message: "OpenCV could not open it for writing".into(),
            });
        }
        let k = Mat::from_slice_2d(&[
            [self.fx, 0.0, self.cx],
            [0.0, self.fy, self.cy],
            [0.0, 0.0, 1.0],
        ])
        .map_err(err)?;
        let d = Mat::from_slice_2d(&[self.distortion]).map_err(err)?;
        opencv::core::write_i32(&mut fs, "image_width", self.width as i32).map_err(err)?;
        opencv::core::write_i32(&mut fs, "image_height", self.height as i32).map_err(err)?;
        opencv::core::write_mat(&mut fs, "camera_matrix", &k).map_err(err)?;
        opencv::core::write_mat(&mut fs, "distortion_coefficients", &d).map_err(err)?;
        fs.release().map_err(err)?;
        Ok(())
    }

    /// The camera matrix as an OpenCV `Mat` (3x3, f64), for `solve_pnp` and friends.
    pub fn camera_matrix_mat(&self) -> opencv::Result<Mat> {
        Mat::from_slice_2d(&[
            [self.fx, 0.0, self.cx],
            [0.0, self.fy, self.cy],
            [0.0, 0.0, 1.0],
        ])
    }

    /// The distortion as an OpenCV `Mat` (1x5, f64), in OpenCV's order.
    pub fn distortion_mat(&self) -> opencv::Result<Mat> {
        Mat::from_slice_2d(&[self.distortion])
    }

    /// Applies the lens distortion to a normalized image point (x/z, y/z).
    pub fn distort_normalized(&self, n: Vector2<f64>) -> Vector2<f64> {
        let [k1, k2, p1, p2, k3] = self.distortion;
        let (x, y) = (n.x, n.y);
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        Vector2::new(
            x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
            y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
        )
    }

    /// Projects a point in the camera's optical frame (x right, y down, z
    /// forward) to a pixel; `None` if it is not in front of the camera.
    pub fn project(&self, point_camera: &Point3<f64>) -> Option<Point2<f64>> {
        if point_camera.z.is_nan() || point_camera.z <= 0.0 {
            return None;
        }
        let n = Vector2::new(
            point_camera.x / point_camera.z,
            point_camera.y / point_camera.z,
        );
        let d = self.distort_normalized(n);
        Some(Point2::new(
            self.fx * d.x + self.cx,
            self.fy * d.y + self.cy,
        ))
    }

    /// The normalized ray (x/z, y/z) whose projection is `pixel`: the inverse of
    /// [`project`](Self::project), by the same fixed-point iteration OpenCV's
    /// `undistortPoints` uses but run to convergence.
    pub fn undistort_pixel(&self, pixel: &Point2<f64>) -> Vector2<f64> {
        let [k1, k2, p1, p2, k3] = self.distortion;
        let d = Vector2::new((pixel.x - self.cx) / self.fx, (pixel.y - self.cy) / self.fy);
        let mut n = d;
        for _ in 0..UNDISTORT_MAX_ITER {
            let (x, y) = (n.x, n.y);
            let r2 = x * x + y * y;
            let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
            let dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
            let dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
            let next = Vector2::new((d.x - dx) / radial, (d.y - dy) / radial);
            let step = (next - n).norm();
            n = next;
            if step < 1e-14 {
                break;
            }
        }
        n
    }
}
