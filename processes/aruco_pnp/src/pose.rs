//! One pad pose from the corners of every marker seen, as the paper's bundle adjustment
//! does: a planar PnP (IPPE) for the start, then Levenberg-Marquardt on the total
//! reprojection error through the full lens model, markers whose own error stands out
//! dropped, and a covariance from the Gauss-Newton information matrix.

use nalgebra::{
    Isometry3, Matrix3, Matrix6, Point2, Point3, Rotation3, Translation3, UnitQuaternion, Vector3,
    Vector6,
};
use opencv::calib3d;
use opencv::core::{Mat, Point2f, Point3f, Vector};
use opencv::prelude::*;
use optics::CameraCalibration;
use thiserror::Error;

/// Why no pose was solved.
#[derive(Debug, Error)]
pub enum PoseError {
    /// Fewer than one marker (four corners) to solve from.
    #[error("pose: no marker corners")]
    NoCorners,
    /// A corner is not a finite pixel.
    #[error("pose: a corner is not finite")]
    NonFinite,
    /// OpenCV's PnP failed.
    #[error("pose: {0}")]
    OpenCv(#[from] opencv::Error),
    /// The solution put the pad behind the camera or went non-finite.
    #[error("pose: no valid solution")]
    Diverged,
}

/// The four image corners of one marker and where they are on the pad.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MarkerCorners {
    /// Marker id.
    pub id: u32,
    /// Corners in the pad frame (z = 0), in OpenCV's ArUco order.
    pub object: [Point3<f64>; 4],
    /// Corners in the (distorted) image, pixels, same order.
    pub image: [Point2<f64>; 4],
}

/// Solver settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseSettings {
    /// When the joint fit's RMS reprojection error exceeds this, the marker without
    /// which the rest fit best is dropped as an outlier (if that halves the error), px.
    pub outlier_px: f64,
    /// Floor of the corner noise assumed for the covariance, px: a perfect fit must
    /// not claim a perfect pose.
    pub min_sigma_px: f64,
    /// Levenberg-Marquardt iterations at most.
    pub max_iterations: usize,
}

impl Default for PoseSettings {
    fn default() -> Self {
        Self {
            outlier_px: 1.5,
            min_sigma_px: 0.2,
            max_iterations: 20,
        }
    }
}

/// What the vehicle's attitude says about the pad: it lies level (its normal is world
/// up) within `sigma_rad`. One 16 px marker at 3 m leaves the pad's tilt and its
/// distance trading off against each other (the planar PnP ambiguity); the autopilot's
/// attitude, good to a fraction of a degree, settles it. Soft, so a pad that pitches
/// on its vehicle is still seen as it is when the markers say so.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LevelPrior {
    /// The camera's orientation in the world at capture time.
    pub world_from_camera: Rotation3<f64>,
    /// How far from level the pad may be, 1 sigma, rad.
    pub sigma_rad: f64,
}

/// A solved pose.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseSolution {
    /// Pad in the camera's optical frame.
    pub camera_from_pad: Isometry3<f64>,
    /// Covariance of (rotation vector, translation), both in the camera frame: the
    /// rotation as a left perturbation `exp(w) * R`, rad; the translation, m.
    pub covariance: Matrix6<f64>,
    /// RMS reprojection error over the corners used, px.
    pub rms_px: f64,
    /// Markers whose corners went into the pose.
    pub used: Vec<u32>,
    /// Markers dropped as outliers.
    pub rejected: Vec<u32>,
}

/// Solves `camera_from_pad` from all markers together.
pub fn solve(
    calibration: &CameraCalibration,
    markers: &[MarkerCorners],
    settings: &PoseSettings,
    level: Option<&LevelPrior>,
) -> Result<PoseSolution, PoseError> {
    if markers.is_empty() {
        return Err(PoseError::NoCorners);
    }
    if markers.iter().any(|m| {
        m.image
            .iter()
            .any(|p| !(p.x.is_finite() && p.y.is_finite()))
    }) {
        return Err(PoseError::NonFinite);
    }
    let mut used: Vec<MarkerCorners> = markers.to_vec();
    let mut rejected = Vec::new();
    let problem = |used: &[MarkerCorners]| Problem {
        calibration,
        markers: used.to_vec(),
        level: level.map(|l| (*l, settings.min_sigma_px / l.sigma_rad.max(1e-6))),
    };
    let mut pose = initial_pose(&problem(&used))?;
    loop {
        pose = refine(&problem(&used), pose, settings.max_iterations)?;
        // A fit worse than the outlier threshold: find the marker without which the
        // others fit best (leave one out; only then, so good frames pay nothing) and
        // drop it if that halves the error. One bad marker pulls a joint fit, so the
        // markers' own errors alone do not point at it.
        let rms = rms_of(calibration, &pose, &used);
        if used.len() < 2 || rms <= settings.outlier_px {
            break;
        }
        let mut best: Option<(usize, f64, Isometry3<f64>)> = None;
        for k in 0..used.len() {
            let mut rest = used.clone();
            rest.remove(k);
            let Ok(p) = refine(&problem(&rest), pose, settings.max_iterations) else {
                continue;
            };
            let e = rms_of(calibration, &p, &rest);
            if best.as_ref().is_none_or(|(_, b, _)| e < *b) {
                best = Some((k, e, p));
            }
        }
        match best {
            Some((k, e, p)) if e < 0.5 * rms => {
                rejected.push(used.remove(k).id);
                pose = p;
            }
            _ => break,
        }
    }
    let (jacobian_tj, _, residuals) = normal_equations(&problem(&used), &pose);
    let n = used.len() * 4;
    let dof = (2 * n).saturating_sub(6).max(1) as f64;
    let sigma2 = (residuals / dof).max(settings.min_sigma_px.powi(2));
    let covariance = jacobian_tj
        .try_inverse()
        .map(|inv| inv * sigma2)
        .ok_or(PoseError::Diverged)?;
    let rms_px = rms_of(calibration, &pose, &used);
    if !(rms_px.is_finite() && covariance.iter().all(|v| v.is_finite())) {
        return Err(PoseError::Diverged);
    }
    Ok(PoseSolution {
        camera_from_pad: pose,
        covariance,
        rms_px,
        used: used.iter().map(|m| m.id).collect(),
        rejected,
    })
}

/// RMS reprojection error over every corner of `markers`, px.
fn rms_of(
    calibration: &CameraCalibration,
    pose: &Isometry3<f64>,
    markers: &[MarkerCorners],
) -> f64 {
    (markers
        .iter()
        .map(|m| marker_rms(calibration, pose, m).powi(2))
        .sum::<f64>()
        / markers.len().max(1) as f64)
        .sqrt()
}

/// RMS reprojection error of one marker's corners, px.
pub fn marker_rms(
    calibration: &CameraCalibration,
    pose: &Isometry3<f64>,
    m: &MarkerCorners,
) -> f64 {
    let mut sum = 0.0;
    for (o, i) in m.object.iter().zip(&m.image) {
        sum += match calibration.project(&pose.transform_point(o)) {
            Some(p) => (p - i).norm_squared(),
            None => 1e6,
        };
    }
    (sum / 4.0).sqrt()
}

/// The least-squares problem: corners through the lens model, plus the level prior.
struct Problem<'a> {
    calibration: &'a CameraCalibration,
    markers: Vec<MarkerCorners>,
    /// The prior and the weight that puts its radians on the corners' pixel scale
    /// (corner sigma / tilt sigma).
    level: Option<(LevelPrior, f64)>,
}

/// IPPE on undistorted (normalized) corners: the planar PnP with no iteration, which
/// needs no initial guess. It returns the two poses a plane allows; the one with the
/// lower total cost (reprojection plus the level prior) starts the refinement.
fn initial_pose(problem: &Problem<'_>) -> Result<Isometry3<f64>, PoseError> {
    let n = problem.markers.len() * 4;
    let mut object = Vector::<Point3f>::with_capacity(n);
    let mut image = Vector::<Point2f>::with_capacity(n);
    for m in &problem.markers {
        for (o, i) in m.object.iter().zip(&m.image) {
            let p = problem.calibration.undistort_pixel(i);
            object.push(Point3f::new(o.x as f32, o.y as f32, o.z as f32));
            image.push(Point2f::new(p.x as f32, p.y as f32));
        }
    }
    let k = Mat::from_slice_2d(&[[1.0f64, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])?;
    let (mut rvecs, mut tvecs) = (Vector::<Mat>::new(), Vector::<Mat>::new());
    calib3d::solve_pnp_generic(
        &object,
        &image,
        &k,
        &Mat::default(),
        &mut rvecs,
        &mut tvecs,
        false,
        calib3d::SolvePnPMethod::SOLVEPNP_IPPE,
        &Mat::default(),
        &Mat::default(),
        &mut Mat::default(),
    )?;
    let mut best: Option<(f64, Isometry3<f64>)> = None;
    let mut r0 = Vec::new();
    for (rvec, tvec) in rvecs.iter().zip(tvecs.iter()) {
        let r = Vector3::new(
            *rvec.at::<f64>(0)?,
            *rvec.at::<f64>(1)?,
            *rvec.at::<f64>(2)?,
        );
        let t = Vector3::new(
            *tvec.at::<f64>(0)?,
            *tvec.at::<f64>(1)?,
            *tvec.at::<f64>(2)?,
        );
        if !(t.z > 0.0 && t.iter().chain(r.iter()).all(|v| v.is_finite())) {
            continue;
        }
        let pose =
            Isometry3::from_parts(Translation3::from(t), UnitQuaternion::from_scaled_axis(r));
        if !residuals(problem, &pose, &mut r0) {
            continue;
        }
        let cost: f64 = r0.iter().map(|v| v * v).sum();
        if best.is_none_or(|(c, _)| cost < c) {
            best = Some((cost, pose));
        }
    }
    best.map(|(_, p)| p).ok_or(PoseError::Diverged)
}

/// Applies the 6-vector (rotation vector w, translation step dt) to `pose` as
/// `exp(w) * R`, `t + dt`.
fn perturb(pose: &Isometry3<f64>, delta: &Vector6<f64>) -> Isometry3<f64> {
    let w = Vector3::new(delta[0], delta[1], delta[2]);
    let dt = Vector3::new(delta[3], delta[4], delta[5]);
    Isometry3::from_parts(
        Translation3::from(pose.translation.vector + dt),
        UnitQuaternion::from_scaled_axis(w) * pose.rotation,
    )
}

/// Residuals (projected - observed) of every corner, x then y; then the level prior's
/// two (the pad normal's world x and y, weighted).
fn residuals(problem: &Problem<'_>, pose: &Isometry3<f64>, out: &mut Vec<f64>) -> bool {
    out.clear();
    for m in &problem.markers {
        for (o, i) in m.object.iter().zip(&m.image) {
            match problem.calibration.project(&pose.transform_point(o)) {
                Some(p) => {
                    out.push(p.x - i.x);
                    out.push(p.y - i.y);
                }
                None => return false,
            }
        }
    }
    if let Some((prior, weight)) = &problem.level {
        let normal = prior.world_from_camera * (pose.rotation * Vector3::z());
        out.push(normal.x * weight);
        out.push(normal.y * weight);
    }
    true
}

/// JᵀJ, Jᵀr and the squared residual sum at `pose`.
fn normal_equations(
    problem: &Problem<'_>,
    pose: &Isometry3<f64>,
) -> (Matrix6<f64>, Vector6<f64>, f64) {
    const H: f64 = 1e-7;
    let mut r0 = Vec::new();
    let mut rk = Vec::new();
    if !residuals(problem, pose, &mut r0) {
        return (Matrix6::zeros(), Vector6::zeros(), f64::INFINITY);
    }
    let mut columns: [Vec<f64>; 6] = Default::default();
    for (k, col) in columns.iter_mut().enumerate() {
        let mut d = Vector6::zeros();
        d[k] = H;
        if !residuals(problem, &perturb(pose, &d), &mut rk) {
            return (Matrix6::zeros(), Vector6::zeros(), f64::INFINITY);
        }
        *col = rk.iter().zip(&r0).map(|(a, b)| (a - b) / H).collect();
    }
    let mut jtj = Matrix6::zeros();
    let mut jtr = Vector6::zeros();
    for i in 0..6 {
        jtr[i] = columns[i].iter().zip(&r0).map(|(a, b)| a * b).sum();
        for j in i..6 {
            let v: f64 = columns[i].iter().zip(&columns[j]).map(|(a, b)| a * b).sum();
            jtj[(i, j)] = v;
            jtj[(j, i)] = v;
        }
    }
    let sse = r0.iter().map(|v| v * v).sum();
    (jtj, jtr, sse)
}

/// Levenberg-Marquardt on the pixel reprojection error through the lens model.
fn refine(
    problem: &Problem<'_>,
    start: Isometry3<f64>,
    max_iterations: usize,
) -> Result<Isometry3<f64>, PoseError> {
    let mut pose = start;
    let mut lambda = 1e-3;
    let (mut jtj, mut jtr, mut sse) = normal_equations(problem, &pose);
    if !sse.is_finite() {
        return Err(PoseError::Diverged);
    }
    for _ in 0..max_iterations {
        let mut a = jtj;
        for k in 0..6 {
            a[(k, k)] *= 1.0 + lambda;
            a[(k, k)] += 1e-12;
        }
        let Some(step) = a.cholesky().map(|c| c.solve(&(-jtr))) else {
            lambda *= 10.0;
            continue;
        };
        let candidate = perturb(&pose, &step);
        let (cj, cr, cs) = normal_equations(problem, &candidate);
        if cs.is_finite() && cs < sse {
            let gain = sse - cs;
            (pose, jtj, jtr, sse) = (candidate, cj, cr, cs);
            lambda = (lambda * 0.3).max(1e-9);
            if gain < 1e-10 * sse.max(1e-12) || step.norm() < 1e-10 {
                break;
            }
        } else {
            lambda *= 10.0;
            if lambda > 1e8 {
                break;
            }
        }
    }
    if pose.translation.vector.z <= 0.0 {
        return Err(PoseError::Diverged);
    }
    Ok(pose)
}

/// The covariance of `world_from_pad` as (x, y, z, roll, pitch, yaw), given the camera's
/// orientation in the world: rotation and translation blocks rotated into world axes;
/// small rotations about world x, y, z stand for roll, pitch and yaw (the pad is near
/// level). The vehicle state's own uncertainty is not included.
pub fn world_covariance(camera: &Matrix6<f64>, world_from_camera: &Rotation3<f64>) -> Matrix6<f64> {
    let r: Matrix3<f64> = *world_from_camera.matrix();
    // Reorder (w, t) -> (t, w) and rotate both blocks.
    let mut t = Matrix6::zeros();
    t.fixed_view_mut::<3, 3>(0, 3).copy_from(&r);
    t.fixed_view_mut::<3, 3>(3, 0).copy_from(&r);
    t * camera * t.transpose()
}

#[cfg(test)]
#[path = "pose_test.rs"]
mod tests;
