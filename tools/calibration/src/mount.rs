//! The down camera's mount (its rotation and offset on the body) from a flight over a
//! static pad: the pad does not move, so the body pose (the autopilot's estimate) times
//! the mount times the pad seen by the camera (PnP) must put the pad in the same place
//! at every sample. The mount and that place are fitted to all samples together
//! (Levenberg-Marquardt on the pad's positions).
//!
//! What pins what: the mount's rotation comes from how the pad moves in the camera as
//! the vehicle moves (a metre or more sideways and up and down) and yaws; its offset
//! needs the vehicle to yaw as well, so a weak prior keeps it near the drawing's
//! (`nominal`) where the flight does not show it. The pad's rotation as PnP sees it is
//! not fitted: a planar target's PnP rotation is far weaker than its position, and in
//! the simulated survey it pulled the mount a degree toward straight down (0.6 to
//! 1.3 deg off over four seeds with it, 0.1 to 0.35 deg without, with a noiseless
//! autopilot state). It is only reported, as the spread about its mean.
//!
//! The autopilot's position drifts (a VIO-fed estimate: about a centimetre per square
//! root of a second), and a tilt is told by centimetres: 1 deg is 1.7 cm per metre of
//! height. A drift that grew while the vehicle climbed would pass for a tilt, so the
//! pad's place in the estimate's world drifts too in the fit: a random walk, linear
//! between knots [`DRIFT_KNOT_S`] apart. A survey that changes height and heading at
//! every point (`[fsm.survey]`), faster than the knots, keeps the two apart.

use nalgebra::{
    DMatrix, DVector, Isometry3, Quaternion, Rotation3, Translation3, UnitQuaternion, Vector3,
    Vector4,
};

/// One moment: the body in the world (interpolated at the frame's capture time) and
/// the pad in the camera.
#[derive(Debug, Clone, Copy)]
pub struct Sample {
    /// When, s (any origin; the drift of the estimate is a function of it).
    pub at_s: f64,
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
    /// RMS of the pad's rotation (PnP) over the samples about their mean, deg: reported,
    /// not fitted.
    pub rms_rotation_deg: f64,
    /// Samples used.
    pub samples: usize,
    /// How far the vehicle moved (the largest distance between two sample positions), m.
    pub motion_m: f64,
    /// The largest drift of the autopilot's position the fit found over the flight, m.
    pub drift_max_m: f64,
}

/// Position noise of a PnP sample, m: the weight.
const SIGMA_POSITION_M: f64 = 0.02;
/// How far the offset may stray from the drawing's where the flight does not pin it, m.
const SIGMA_OFFSET_PRIOR_M: f64 = 0.05;
/// The spacing of the drift's knots, s: slower than the survey changes height and
/// heading (every 3 to 4 s).
pub const DRIFT_KNOT_S: f64 = 8.0;
/// The drift's random walk, m per square root of a second: a VIO-fed estimate's, with
/// room to spare.
const DRIFT_SIGMA_M_PER_SQRT_S: f64 = 0.015;
/// Parameters before the drift's: mount rotation, mount offset, pad position.
const BASE: usize = 9;

/// The drift's knots: where sample `at_s` falls, as (knot, weight) pairs over the
/// knots after the first (the first is the pad position itself).
struct Knots {
    t0: f64,
    count: usize,
}

impl Knots {
    fn new(samples: &[Sample]) -> Self {
        let (lo, hi) = samples
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), s| {
                (lo.min(s.at_s), hi.max(s.at_s))
            });
        let span = if hi > lo { hi - lo } else { 0.0 };
        Self {
            t0: if lo.is_finite() { lo } else { 0.0 },
            count: (span / DRIFT_KNOT_S).ceil() as usize,
        }
    }

    /// The drift's weights at `t`: knot k (1-based; knot 0 is fixed at zero) gets the
    /// returned weight, linear between neighbours.
    fn weights(&self, t: f64) -> [(usize, f64); 2] {
        let u = ((t - self.t0) / DRIFT_KNOT_S).clamp(0.0, self.count as f64);
        let k = (u.floor() as usize).min(self.count.saturating_sub(1));
        let f = u - k as f64;
        [(k, 1.0 - f), (k + 1, f)]
    }

    fn drift(&self, x: &DVector<f64>, t: f64) -> Vector3<f64> {
        self.weights(t)
            .iter()
            .filter(|(k, _)| *k > 0)
            .map(|(k, w)| {
                Vector3::new(
                    x[BASE + 3 * (k - 1)],
                    x[BASE + 3 * (k - 1) + 1],
                    x[BASE + 3 * (k - 1) + 2],
                ) * *w
            })
            .sum()
    }
}

fn exp(v: &Vector3<f64>) -> Rotation3<f64> {
    Rotation3::new(*v)
}

/// The residuals of `samples` at parameters `x` (mount rotation as a correction to
/// `r_bc0`; mount offset; pad position; the drift at the knots).
fn residuals(
    x: &DVector<f64>,
    samples: &[Sample],
    knots: &Knots,
    r_bc0: &Rotation3<f64>,
    t_bc_prior: &Vector3<f64>,
) -> DVector<f64> {
    let r_bc = r_bc0 * exp(&Vector3::new(x[0], x[1], x[2]));
    let t_bc = Vector3::new(x[3], x[4], x[5]);
    let t_wp = Vector3::new(x[6], x[7], x[8]);
    let mut r = DVector::zeros(samples.len() * 3 + 3 + 3 * knots.count);
    for (i, s) in samples.iter().enumerate() {
        let r_wb = s.world_from_body.rotation.to_rotation_matrix();
        let t_wb = s.world_from_body.translation.vector;
        let t_cp = s.camera_from_pad.translation.vector;
        let drift = knots.drift(x, s.at_s);
        let p = (r_wb * (r_bc * t_cp + t_bc) + t_wb - t_wp - drift) / SIGMA_POSITION_M;
        r.fixed_rows_mut::<3>(i * 3).copy_from(&p);
    }
    let prior = (t_bc - t_bc_prior) / SIGMA_OFFSET_PRIOR_M;
    r.fixed_rows_mut::<3>(samples.len() * 3).copy_from(&prior);
    // The random walk: each knot's step from the one before.
    let step_sigma = DRIFT_SIGMA_M_PER_SQRT_S * DRIFT_KNOT_S.sqrt();
    let at = |k: usize| {
        if k == 0 {
            Vector3::zeros()
        } else {
            Vector3::new(
                x[BASE + 3 * (k - 1)],
                x[BASE + 3 * (k - 1) + 1],
                x[BASE + 3 * (k - 1) + 2],
            )
        }
    };
    for k in 1..=knots.count {
        let step = (at(k) - at(k - 1)) / step_sigma;
        r.fixed_rows_mut::<3>(samples.len() * 3 + 3 * k)
            .copy_from(&step);
    }
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
    let knots = Knots::new(samples);
    let n_params = BASE + 3 * knots.count;
    let mut x = DVector::zeros(n_params);
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
    let f = |x: &DVector<f64>| residuals(x, samples, &knots, &r_bc0, &t_bc0);
    // The drift enters linearly: its columns of the Jacobian are its weights.
    let mut drift_columns = DMatrix::zeros(samples.len() * 3 + 3 + 3 * knots.count, n_params);
    for (i, s) in samples.iter().enumerate() {
        for (k, w) in knots.weights(s.at_s) {
            if k > 0 {
                for a in 0..3 {
                    drift_columns[(i * 3 + a, BASE + 3 * (k - 1) + a)] = -w / SIGMA_POSITION_M;
                }
            }
        }
    }
    let step_sigma = DRIFT_SIGMA_M_PER_SQRT_S * DRIFT_KNOT_S.sqrt();
    for k in 1..=knots.count {
        for a in 0..3 {
            let row = samples.len() * 3 + 3 * k + a;
            drift_columns[(row, BASE + 3 * (k - 1) + a)] = 1.0 / step_sigma;
            if k > 1 {
                drift_columns[(row, BASE + 3 * (k - 2) + a)] = -1.0 / step_sigma;
            }
        }
    }
    let mut lambda = 1e-3;
    let mut r = f(&x);
    let mut cost = r.norm_squared();
    for _ in 0..50 {
        // Jacobian by central differences, but for the drift's (linear) columns.
        let mut j = drift_columns.clone();
        for k in 0..BASE {
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
            for k in 0..n_params {
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
    let n = samples.len() as f64;
    let pos: f64 = (0..samples.len())
        .map(|i| r.fixed_rows::<3>(i * 3).norm_squared() * SIGMA_POSITION_M.powi(2))
        .sum();
    let rms_position_m = (pos / n).sqrt();
    // The pad's rotation: the mean of what each sample says (quaternions summed on one
    // hemisphere), and the spread about it.
    let mount = UnitQuaternion::from_rotation_matrix(&r_bc);
    let pad_rotations: Vec<UnitQuaternion<f64>> = samples
        .iter()
        .map(|s| s.world_from_body.rotation * mount * s.camera_from_pad.rotation)
        .collect();
    let sum = pad_rotations.iter().fold(Vector4::zeros(), |acc, q| {
        let v = q.as_ref().coords;
        if v.dot(&pad_rotations[0].as_ref().coords) < 0.0 {
            acc - v
        } else {
            acc + v
        }
    });
    let r_wp = UnitQuaternion::from_quaternion(Quaternion::from(sum));
    let rot: f64 = pad_rotations
        .iter()
        .map(|q| q.angle_to(&r_wp).powi(2))
        .sum();
    let drift_max_m = samples
        .iter()
        .map(|s| knots.drift(&x, s.at_s).norm())
        .fold(0.0, f64::max);
    if !rms_position_m.is_finite() || rms_position_m > 0.2 {
        return Err(MountError::NoFit(rms_position_m));
    }
    Ok(MountFit {
        body_from_camera: Isometry3::from_parts(Translation3::from(t_bc), mount),
        world_from_pad: Isometry3::from_parts(Translation3::from(t_wp), r_wp),
        rms_position_m,
        rms_rotation_deg: (rot / n).sqrt().to_degrees(),
        samples: samples.len(),
        motion_m,
        drift_max_m,
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
