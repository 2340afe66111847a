//! The camera's intrinsics and distortion from views of a ChArUco board: the corners of
//! each view found (markers, then the chessboard corners between them, to subpixel),
//! views with too few corners rejected with the reason, and OpenCV's
//! `calibrateCameraCharuco` fitted to the rest.

use opencv::aruco::{self, CharucoBoard};
use opencv::core::{Mat, Point2f, Ptr, Size, TermCriteria, Vector};
use opencv::imgproc;
use opencv::prelude::*;
use optics::CameraCalibration;

use crate::board::{BoardError, CharucoSpec};

/// Corners fewer than this in a view, and the view is not used: a few corners pin the
/// board's pose poorly and pull the fit.
pub const MIN_CORNERS: usize = 8;
/// Views fewer than this, and there is no calibration.
pub const MIN_VIEWS: usize = 10;

/// The board's corners found in one view.
#[derive(Debug, Clone)]
pub struct Detection {
    /// The view (its file name, or its frame number).
    pub name: String,
    /// The corners, px.
    pub corners: Vector<Point2f>,
    /// Their ids on the board.
    pub ids: Vector<i32>,
}

/// A view that was not used, and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Rejected {
    /// The view.
    pub name: String,
    /// Why, in a few words.
    pub why: String,
}

/// Why there is no calibration.
#[derive(Debug, thiserror::Error)]
pub enum CalibrateError {
    /// The board.
    #[error(transparent)]
    Board(#[from] BoardError),
    /// Not enough usable views.
    #[error(
        "{used} usable views of the board (at least {MIN_VIEWS}; {rejected} rejected): take more, from more angles and distances, filling the image"
    )]
    TooFewViews {
        /// Views with enough corners.
        used: usize,
        /// Views rejected.
        rejected: usize,
    },
    /// OpenCV's fit failed.
    #[error("the fit failed: OpenCV: {0}")]
    OpenCv(String),
    /// The fit gave numbers that are not a camera.
    #[error("the fit gave no usable camera (fx {fx}, fy {fy}): the views are too alike")]
    Degenerate {
        /// Fitted focal length x.
        fx: f64,
        /// Fitted focal length y.
        fy: f64,
    },
}

fn cv(e: opencv::Error) -> CalibrateError {
    CalibrateError::OpenCv(e.message)
}

/// The board's corners in `image` (grey or colour), or why the view is not usable.
pub fn detect(
    name: &str,
    image: &Mat,
    spec: &CharucoSpec,
    board: &Ptr<CharucoBoard>,
) -> Result<Detection, Rejected> {
    let reject = |why: String| Rejected {
        name: name.to_string(),
        why,
    };
    let grey = if image.channels() == 1 {
        image.clone()
    } else {
        let mut g = Mat::default();
        imgproc::cvt_color_def(image, &mut g, imgproc::COLOR_BGR2GRAY)
            .map_err(|e| reject(e.message))?;
        g
    };
    let dictionary = spec.dictionary().map_err(|e| reject(e.to_string()))?;
    let mut marker_corners: Vector<Vector<Point2f>> = Vector::new();
    let mut marker_ids: Vector<i32> = Vector::new();
    aruco::detect_markers_def(&grey, &dictionary, &mut marker_corners, &mut marker_ids)
        .map_err(|e| reject(e.message))?;
    if marker_ids.is_empty() {
        return Err(reject("no marker of the board".into()));
    }
    let mut corners: Vector<Point2f> = Vector::new();
    let mut ids: Vector<i32> = Vector::new();
    aruco::interpolate_corners_charuco_def(
        &marker_corners,
        &marker_ids,
        &grey,
        board,
        &mut corners,
        &mut ids,
    )
    .map_err(|e| reject(e.message))?;
    if ids.len() < MIN_CORNERS {
        return Err(reject(format!(
            "{} corners (at least {MIN_CORNERS})",
            ids.len()
        )));
    }
    Ok(Detection {
        name: name.to_string(),
        corners,
        ids,
    })
}

/// A fitted camera and how well it fits.
#[derive(Debug, Clone)]
pub struct Calibrated {
    /// The camera, as the stack reads it.
    pub calibration: CameraCalibration,
    /// RMS reprojection error over every corner of every used view, px.
    pub rms_px: f64,
    /// Each used view's RMS reprojection error, px.
    pub per_view_px: Vec<(String, f64)>,
    /// The corners of the used views, px (for the coverage plot).
    pub corners: Vec<Vec<(f32, f32)>>,
    /// Fraction of the image's 8 x 6 cells with a corner in them: a fit is only good
    /// where it saw corners (distortion grows toward the edges).
    pub coverage: f64,
    /// The views that were not used.
    pub rejected: Vec<Rejected>,
}

/// Fits the camera of `image_size` to `detections`.
pub fn calibrate(
    detections: &[Detection],
    rejected: Vec<Rejected>,
    image_size: (u32, u32),
    board: &Ptr<CharucoBoard>,
) -> Result<Calibrated, CalibrateError> {
    if detections.len() < MIN_VIEWS {
        return Err(CalibrateError::TooFewViews {
            used: detections.len(),
            rejected: rejected.len(),
        });
    }
    let mut all_corners: Vector<Vector<Point2f>> = Vector::new();
    let mut all_ids: Vector<Vector<i32>> = Vector::new();
    for d in detections {
        all_corners.push(d.corners.clone());
        all_ids.push(d.ids.clone());
    }
    let size = Size::new(image_size.0 as i32, image_size.1 as i32);
    let mut k = Mat::default();
    let mut dist = Mat::default();
    let (mut rvecs, mut tvecs) = (Mat::default(), Mat::default());
    let (mut std_i, mut std_e, mut per_view) = (Mat::default(), Mat::default(), Mat::default());
    let criteria = TermCriteria::new(
        opencv::core::TermCriteria_COUNT + opencv::core::TermCriteria_EPS,
        100,
        1e-9,
    )
    .map_err(cv)?;
    let rms = aruco::calibrate_camera_charuco_extended(
        &all_corners,
        &all_ids,
        board,
        size,
        &mut k,
        &mut dist,
        &mut rvecs,
        &mut tvecs,
        &mut std_i,
        &mut std_e,
        &mut per_view,
        0,
        criteria,
    )
    .map_err(cv)?;
    let at = |m: &Mat, r: i32, c: i32| m.at_2d::<f64>(r, c).copied().map_err(cv);
    let (fx, fy, cx, cy) = (at(&k, 0, 0)?, at(&k, 1, 1)?, at(&k, 0, 2)?, at(&k, 1, 2)?);
    if !(fx.is_finite() && fy.is_finite() && fx > 0.0 && fy > 0.0) {
        return Err(CalibrateError::Degenerate { fx, fy });
    }
    let d: Vec<f64> = dist.data_typed::<f64>().map_err(cv)?.to_vec();
    let mut distortion = [0.0; 5];
    for (slot, v) in distortion.iter_mut().zip(d) {
        *slot = v;
    }
    let per_view_px = detections
        .iter()
        .enumerate()
        .map(|(i, det)| {
            let e = per_view.at::<f64>(i as i32).copied().unwrap_or(f64::NAN);
            (det.name.clone(), e)
        })
        .collect();
    let corners: Vec<Vec<(f32, f32)>> = detections
        .iter()
        .map(|d| d.corners.iter().map(|p| (p.x, p.y)).collect())
        .collect();
    let coverage = coverage(&corners, image_size);
    Ok(Calibrated {
        calibration: CameraCalibration {
            width: image_size.0,
            height: image_size.1,
            fx,
            fy,
            cx,
            cy,
            distortion,
        },
        rms_px: rms,
        per_view_px,
        corners,
        coverage,
        rejected,
    })
}

/// Fraction of the image's 8 x 6 cells holding at least one corner.
pub fn coverage(corners: &[Vec<(f32, f32)>], image_size: (u32, u32)) -> f64 {
    let (w, h) = (f64::from(image_size.0), f64::from(image_size.1));
    let mut seen = [[false; 8]; 6];
    for (x, y) in corners.iter().flatten() {
        let cx = ((f64::from(*x) / w) * 8.0).floor();
        let cy = ((f64::from(*y) / h) * 6.0).floor();
        if (0.0..8.0).contains(&cx) && (0.0..6.0).contains(&cy) {
            seen[cy as usize][cx as usize] = true;
        }
    }
    seen.iter().flatten().filter(|s| **s).count() as f64 / 48.0
}
