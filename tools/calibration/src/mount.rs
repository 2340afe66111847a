//! The down camera's mount (its rotation and offset on the body) from a flight over a
//! static pad: the pad does not move, so the body pose (the autopilot's estimate) times
//! the mount times the pad seen by the camera (PnP) must be the same pad pose at every
//! sample. The mount and that pad pose are fitted to all samples together
//! (Levenberg-Marquardt on positions and rotations).
//!
//! What pins what: the mount's rotation comes from how the pad moves in the camera as
//! the vehicle moves (a metre or more sideways and up and down) and from how it turns
//! as the vehicle tilts; its offset needs the vehicle to yaw as well, so a weak prior
//! keeps it near the drawing's (`nominal`) where the flight does not show it.

use nalgebra::{DMatrix, DVector, Isometry3, Rotation3, Translation3, UnitQuaternion, Vector3};

/// One moment: the body in the world (interpolated at the frame's capture time) and
/// the pad in the camera.
#[derive(Debug, Clone, Copy)]
pub struct Sample {
    /// The autopilot's estimate of the body pose.
    pub world_from_body: Isometry3<f64>,
    /// The pad pose the camera saw (PnP).
    pub camera_from_pad: Isometry3<f64>,
}

/// Why there is no mount.
#[derive(Debug, thiserror::Error)]
pub enum MountError {
    /// Too few samples.
    #[error("{0} samples of the pad (at least 50): fly longer over it, with the pad in view")]
    TooFewSamples(usize),
    /// The vehicle did not move enough to tell the rotation.
    #[error(
        "the vehicle moved {0:.2} m over the pad (at least 0.5 m): fly a box over it, sideways and up and down"
    )]
    TooLittleMotion(f64),
    /// The fit did not settle.
    #[error("the fit did not settle (RMS {0:.3} m): is the pad static, and in view?")]
    NoFit(f64),
}

/// The fitted mount and how well the samples agree with it.
#[derive(Debug, Clone)]
pub struct MountFit {
    /// The mount: maps camera points into the body.
    pub body_from_camera: Isometry3<f64>,
    /// Where the pad is in the world (a by-product).
    pub world_from_pad: Isometry3<f64>,
    /// RMS of the pad's position over the samples after the fit, m.
    pub rms_position_m: f64,
    /// RMS of the pad's rotation over the samples after the fit, deg.
    pub rms_rotation_deg: f64,
    /// Samples used.
    pub samples: usize,
    /// How far the vehicle moved (the largest distance between two sample positions), m.
    pub motion_m: f64,
}

/// Position noise of a PnP sample, m, and its rotation noise, rad: the weights.
const SIGMA_POSITION_M: f64 = 0.02;
const SIGMA_ROTATION_RAD: f64 = 0.02;
/// How far the offset may stray from the drawing's where the flight does not pin it, m.
const SIGMA_OFFSET_PRIOR_M: f64 = 0.05;

fn exp(v: &Vector3<f64>) -> Rotation3<f64> {
    Rotation3::new(*v)
}

/// The residuals of `samples` at parameters `x` (mount rotation and pad rotation as
/// corrections to `r_bc0`, `r_wp0`; mount offset; pad position).
fn residuals(
    x: &DVector<f64>,
    samples: &[Sample],
    r_bc0: &Rotation3<f64>,
    r_wp0: &Rotation3<f64>,
    t_bc_prior: &Vector3<f64>,
) -> DVector<f64> {
    let r_bc = r_bc0 * exp(&Vector3::new(x[0], x[1], x[2]));
    let t_bc = Vector3::new(x[3], x[4], x[5]);
    let t_wp = Vector3::new(x[6], x[7], x[8]);
    let r_wp = r_wp0 * exp(&Vector3::new(x[9], x[10], x[11]));
    let mut r = DVector::zeros(samples.len() * 6 + 3);
    for (i, s) in samples.iter().enumerate() {
        let r_wb = s.world_from_body.rotation.to_rotation_matrix();
        let t_wb = s.world_from_body.translation.vector;
        let t_cp = s.camera_from_pad.translation.vector;
        let p = (r_wb * (r_bc * t_cp + t_bc) + t_wb - t_wp) / SIGMA_POSITION_M;
        // As quaternions: their angle is an atan2, well-defined at zero, where a
        // rotation matrix's acos of a trace a rounding above 3 is not.
        let q = (UnitQuaternion::from_rotation_matrix(&r_wp).inverse()
            * s.world_from_body.rotation
            * UnitQuaternion::from_rotation_matrix(&r_bc)
            * s.camera_from_pad.rotation)
            .scaled_axis()
            / SIGMA_ROTATION_RAD;
        r.fixed_rows_mut::<3>(i * 6).copy_from(&p);
        r.fixed_rows_mut::<3>(i * 6 + 3).copy_from(&q);
    }
    let prior = (t_bc - t_bc_prior) / SIGMA_OFFSET_PRIOR_M;
    r.fixed_rows_mut::<3>(samples.len() * 6).copy_from(&prior);
    r
}

/// Fits the mount to `samples`, starting from the drawing's `nominal` mount.
pub fn fit_mount(samples: &[Sample], nominal: &Isometry3<f64>) -> Result<MountFit, MountError> {
    if samples.len() < 50 {
        return Err(MountError::TooFewSamples(samples.len()));
    }
    let positions: Vec<Vector3<f64>> = samples
        .iter()
        .map(|s| s.world_from_body.translation.vector)
        .collect();
    let motion_m = positions
        .iter()
        .flat_map(|a| positions.iter().map(move |b| (a - b).norm()))
        .fold(0.0, f64::max);
    if motion_m < 0.5 {
        return Err(MountError::TooLittleMotion(motion_m));
    }
    let r_bc0 = nominal.rotation.to_rotation_matrix();
    let t_bc0 = nominal.translation.vector;
    // The pad where the first sample puts it with the nominal mount.
    let first = samples[0].world_from_body * nominal * samples[0].camera_from_pad;
    let r_wp0 = first.rotation.to_rotation_matrix();
    let mut x = DVector::zeros(12);
    x.fixed_rows_mut::<3>(3).copy_from(&t_bc0);
    let mean_pad: Vector3<f64> = samples
        .iter()
        .map(|s| {
            (s.world_from_body * nominal * s.camera_from_pad)
                .translation
                .vector
        })
        .sum::<Vector3<f64>>()
        / samples.len() as f64;
    x.fixed_rows_mut::<3>(6).copy_from(&mean_pad);
    let f = |x: &DVector<f64>| residuals(x, samples, &r_bc0, &r_wp0, &t_bc0);
    let mut lambda = 1e-3;
    let mut r = f(&x);
    let mut cost = r.norm_squared();
    for _ in 0..50 {
        // Jacobian by central differences.
        let mut j = DMatrix::zeros(r.len(), 12);
        for k in 0..12 {
            let h = 1e-6;
            let (mut xp, mut xm) = (x.clone(), x.clone());
            xp[k] += h;
            xm[k] -= h;
            let d = (f(&xp) - f(&xm)) / (2.0 * h);
            j.set_column(k, &d);
        }
        let jt = j.transpose();
        let g = &jt * &r;
        let h = &jt * &j;
        let mut improved = false;
        for _ in 0..10 {
            let mut damped = h.clone();
            for k in 0..12 {
                damped[(k, k)] += lambda * h[(k, k)].max(1e-9);
            }
            let Some(step) = damped.lu().solve(&(-&g)) else {
                lambda *= 10.0;
                continue;
            };
            let x_new = &x + &step;
            let r_new = f(&x_new);
            let c_new = r_new.norm_squared();
            if c_new < cost {
                let small = step.norm() < 1e-10;
                x = x_new;
                r = r_new;
                cost = c_new;
                lambda = (lambda / 10.0).max(1e-9);
                improved = !small;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    let r_bc = r_bc0 * exp(&Vector3::new(x[0], x[1], x[2]));
    let t_bc = Vector3::new(x[3], x[4], x[5]);
    let t_wp = Vector3::new(x[6], x[7], x[8]);
    let r_wp = r_wp0 * exp(&Vector3::new(x[9], x[10], x[11]));
    let n = samples.len() as f64;
    let (mut pos, mut rot) = (0.0, 0.0);
    for i in 0..samples.len() {
        pos += r.fixed_rows::<3>(i * 6).norm_squared() * SIGMA_POSITION_M.powi(2);
        rot += r.fixed_rows::<3>(i * 6 + 3).norm_squared() * SIGMA_ROTATION_RAD.powi(2);
    }
    let rms_position_m = (pos / n).sqrt();
    if !rms_position_m.is_finite() || rms_position_m > 0.2 {
        return Err(MountError::NoFit(rms_position_m));
    }
    Ok(MountFit {
        body_from_camera: Isometry3::from_parts(
            Translation3::from(t_bc),
            UnitQuaternion::from_rotation_matrix(&r_bc),
        ),
        world_from_pad: Isometry3::from_parts(
            Translation3::from(t_wp),
            UnitQuaternion::from_rotation_matrix(&r_wp),
        ),
        rms_position_m,
        rms_rotation_deg: (rot / n).sqrt().to_degrees(),
        samples: samples.len(),
        motion_m,
    })
}

/// Fits the mount and the frames' stamp offset together: `samples_at(ms)` gives the
/// samples with the state looked up `ms` after each frame's stamp (a driver stamping at
/// readout, an estimator's lag); the offset within `max_ms` at which the pad holds
/// stillest wins, searched coarse to fine (10, 2, 0.5 ms).
pub fn fit_mount_and_offset(
    samples_at: impl Fn(f64) -> Vec<Sample>,
    nominal: &Isometry3<f64>,
    max_ms: f64,
) -> Result<(MountFit, f64), MountError> {
    let rms =
        |ms: f64| fit_mount(&samples_at(ms), nominal).map_or(f64::INFINITY, |f| f.rms_position_m);
    let mut best = (0.0, rms(0.0));
    for step in [10.0, 2.0, 0.5] {
        let centre = best.0;
        for k in -5..=5 {
            let ms = centre + f64::from(k) * step;
            if ms.abs() <= max_ms {
                let r = rms(ms);
                if r < best.1 {
                    best = (ms, r);
                }
            }
        }
    }
    Ok((fit_mount(&samples_at(best.0), nominal)?, best.0))
}

#[cfg(test)]
#[path = "mount_test.rs"]
mod tests;
