//! PX4's hover thrust estimator (v1.16 `modules/mc_hover_thrust_estimator/`), so the
//! simulated autopilot, like PX4, does not need to know its vehicle's mass: it starts
//! from MPC_THR_HOVER (the airframe file's) and learns the thrust that really hovers.
//!
//! The filter (`zero_order_hover_thrust_ekf.cpp`) has one state, the hover thrust
//! `Th`, constant but for process noise HTE_HT_NOISE. Its measurement is the upward
//! acceleration, predicted from the allocated upward thrust `T` as `g T / Th - g`.
//! The measurement noise is learnt from the residuals (2 s time constant, kept within
//! 1..400 (m/s^2)^2); an innovation beyond HTE_ACC_GATE standard deviations is not
//! fused, and when rejections pile up on one side (their signed test ratio, low-passed
//! over 1 s, beyond 0.2) the state variance is bumped so a sudden change (a dropped
//! payload) is followed. The estimate stays within HTE_THR_RANGE of MPC_THR_HOVER.
//!
//! The module (`MulticopterHoverThrustEstimator.cpp`) runs the filter only while armed
//! and in the air (in the air: not landed, and once more than 1 m above the ground;
//! the land detector's flag alone does not guarantee the vehicle is off the ground),
//! scales the measurement noise up in fast vertical (above HTE_VZ_THR) or horizontal
//! (above HTE_VXY_THR) flight where drag biases it, and calls the estimate valid once
//! its variance is below 0.001 with a passing test ratio, held 2 s. Disarmed, it
//! restarts from MPC_THR_HOVER.
//!
//! PX4 runs it on each local position of its EKF (100 Hz: EKF2_PREDICT_US = 10 ms);
//! here it runs every [`HTE_PERIOD_S`] on the estimate's velocity change over that
//! period (what the EKF's vertical acceleration integrates to) and the mean allocated
//! thrust over it.

use nalgebra::Vector3;

use crate::autopilot_params::AutopilotParams;
use crate::hysteresis::Hysteresis;
use crate::quadrotor::GRAVITY_M_S2;

/// Period of the estimator, s: PX4's EKF2 output rate (EKF2_PREDICT_US = 10 ms).
pub const HTE_PERIOD_S: f64 = 0.01;

/// Height above the ground (the take-off point's) beyond which the vehicle counts as in
/// the air for the estimator, m (PX4: `dist_bottom > 1`).
const IN_AIR_HEIGHT_M: f64 = 1.0;

/// How long the validity test must pass before the estimate is used, ns (PX4: 2 s).
const VALID_HOLD_NS: u64 = 2_000_000_000;

/// Largest variance of a valid estimate, normalized thrust^2 (PX4: 0.001).
const VALID_VARIANCE: f64 = 0.001;

/// Initial (and reset) acceleration noise variance, (m/s^2)^2 (PX4 `resetAccelNoise`).
const INITIAL_ACC_VAR: f64 = 5.0;

/// Time constant of the measurement noise learning, s (PX4: 2).
const NOISE_LEARNING_TIME_CONSTANT_S: f64 = 2.0;

/// Time constant of the residual and test-ratio low-passes, s (PX4: 1).
const LPF_TIME_CONSTANT_S: f64 = 1.0;

/// Low-passed signed test ratio beyond which rejections mean the hover thrust moved
/// (PX4: 0.2).
const LARGE_OFFSET_TEST_RATIO: f64 = 0.2;

/// PX4's `ZeroOrderHoverThrustEkf`: the one-state filter (see the module docs).
#[derive(Debug, Clone, PartialEq)]
struct HoverThrustEkf {
    hover_thrust: f64,
    hover_thrust_min: f64,
    hover_thrust_max: f64,
    gate_size: f64,
    state_var: f64,
    process_var: f64,
    acc_var: f64,
    acc_var_scale: f64,
    dt: f64,
    innovation_test_ratio: f64,
    residual_lpf: f64,
    signed_innovation_test_ratio_lpf: f64,
}

impl HoverThrustEkf {
    /// The filter at MPC_THR_HOVER with PX4's initial uncertainties, within
    /// HTE_THR_RANGE of it.
    fn new(p: &AutopilotParams) -> Self {
        let range = p.hte_thr_range;
        Self {
            hover_thrust: p.mpc_thr_hover.clamp(0.1, 0.9),
            hover_thrust_min: (p.mpc_thr_hover - range).clamp(0.0, 0.8),
            hover_thrust_max: (p.mpc_thr_hover + range).clamp(0.2, 0.9),
            gate_size: p.hte_acc_gate,
            state_var: p.hte_ht_err_init * p.hte_ht_err_init,
            process_var: p.hte_ht_noise * p.hte_ht_noise,
            acc_var: INITIAL_ACC_VAR,
            acc_var_scale: 1.0,
            dt: HTE_PERIOD_S,
            innovation_test_ratio: 0.0,
            residual_lpf: 0.0,
            signed_innovation_test_ratio_lpf: 0.0,
        }
    }

    /// The state is constant: only its variance grows (PX4 scales by dt^2).
    fn predict(&mut self, dt: f64) {
        self.state_var += self.process_var * dt * dt;
        self.dt = dt;
    }

    fn predicted_acc_up(&self, thrust_up: f64) -> f64 {
        GRAVITY_M_S2 * thrust_up / self.hover_thrust - GRAVITY_M_S2
    }

    /// Fuses one upward acceleration measured while `thrust_up` was allocated.
    fn fuse_acc_up(&mut self, acc_up: f64, thrust_up: f64) {
        let h = -GRAVITY_M_S2 * thrust_up / (self.hover_thrust * self.hover_thrust);
        let r = self.acc_var * self.acc_var_scale;
        let innovation_var = (h * self.state_var * h + r).max(r);
        let innovation = acc_up - self.predicted_acc_up(thrust_up);
        let gain = self.state_var * h / innovation_var;
        let test_ratio =
            innovation * innovation / (self.gate_size * self.gate_size * innovation_var);
        let mut residual = innovation;
        if test_ratio < 1.0 {
            self.hover_thrust = (self.hover_thrust + gain * innovation)
                .clamp(self.hover_thrust_min, self.hover_thrust_max);
            self.state_var = ((1.0 - gain * h) * self.state_var).clamp(1e-10, 1.0);
            residual = acc_up - self.predicted_acc_up(thrust_up);
        } else if self.signed_innovation_test_ratio_lpf.abs() > LARGE_OFFSET_TEST_RATIO {
            // Rejected for a while, on one side: the hover thrust changed suddenly.
            self.state_var += 1e3 * self.process_var * self.dt * self.dt;
        }
        let alpha = self.dt / (LPF_TIME_CONSTANT_S + self.dt);
        self.residual_lpf = (1.0 - alpha) * self.residual_lpf + alpha * residual;
        let signed = (innovation.signum() * test_ratio).clamp(-1.0, 1.0);
        self.signed_innovation_test_ratio_lpf =
            (1.0 - alpha) * self.signed_innovation_test_ratio_lpf + alpha * signed;
        let alpha = self.dt / (NOISE_LEARNING_TIME_CONSTANT_S + self.dt);
        let unbiased = residual - self.residual_lpf;
        self.acc_var = ((1.0 - alpha) * self.acc_var
            + alpha * (unbiased * unbiased + h * self.state_var * h))
            .clamp(1.0, 400.0);
        self.innovation_test_ratio = test_ratio;
    }
}

/// What the estimator reads each autopilot update.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HoverThrustInput {
    /// Motors armed.
    pub armed: bool,
    /// The land detector's `landed`.
    pub landed: bool,
    /// Estimated height above the take-off point's ground, m (PX4's `dist_bottom`
    /// without a range sensor).
    pub height_m: f64,
    /// Estimated velocity, world ENU, m/s.
    pub velocity: Vector3<f64>,
    /// Allocated thrust's upward component over the last update, normalized (the
    /// motors' mean times the cosine of the tilt).
    pub thrust_up: f64,
}

/// PX4's hover thrust estimator module (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct HoverThrustEstimator {
    ekf: HoverThrustEkf,
    in_air: bool,
    valid: bool,
    valid_hysteresis: Hysteresis,
    /// Time, estimated upward velocity and thrust integral since the last run.
    window_s: f64,
    window_thrust: f64,
    window_start_vz: Option<f64>,
}

impl HoverThrustEstimator {
    /// Starts from MPC_THR_HOVER, not valid, on the ground.
    pub fn new(p: &AutopilotParams) -> Self {
        let mut valid_hysteresis = Hysteresis::new(false);
        valid_hysteresis.set_time_from(false, VALID_HOLD_NS);
        Self {
            ekf: HoverThrustEkf::new(p),
            in_air: false,
            valid: false,
            valid_hysteresis,
            window_s: 0.0,
            window_thrust: 0.0,
            window_start_vz: None,
        }
    }

    /// The current estimate of the hover thrust (MPC_THR_HOVER until it learnt).
    pub fn hover_thrust(&self) -> f64 {
        self.ekf.hover_thrust
    }

    /// The estimate when PX4 would publish it as valid, else None.
    pub fn valid_estimate(&self) -> Option<f64> {
        self.valid.then_some(self.ekf.hover_thrust)
    }

    /// Variance of the estimate, normalized thrust^2.
    pub fn variance(&self) -> f64 {
        self.ekf.state_var
    }

    /// Whether the estimator counts the vehicle as in the air (it runs only then).
    pub fn in_air(&self) -> bool {
        self.in_air
    }

    /// Advances by `dt_s` at `now_ns`; runs the filter every [`HTE_PERIOD_S`].
    pub fn update(
        &mut self,
        now_ns: u64,
        dt_s: f64,
        p: &AutopilotParams,
        input: &HoverThrustInput,
    ) {
        if input.landed {
            self.in_air = false;
        } else if input.height_m > IN_AIR_HEIGHT_M {
            self.in_air = true;
        }
        let vz = input.velocity.z;
        let start_vz = *self.window_start_vz.get_or_insert(vz);
        if dt_s.is_finite() && dt_s > 0.0 && input.thrust_up.is_finite() {
            self.window_s += dt_s;
            self.window_thrust += input.thrust_up * dt_s;
        }
        if self.window_s < HTE_PERIOD_S - 1e-9 {
            return;
        }
        let dt = self.window_s;
        let acc_up = (vz - start_vz) / dt;
        let thrust_up = self.window_thrust / dt;
        self.window_s = 0.0;
        self.window_thrust = 0.0;
        self.window_start_vz = Some(vz);

        if input.armed && self.in_air && dt > 0.001 && dt < 1.0 && acc_up.is_finite() {
            self.ekf.predict(dt);
            // Drag biases the measurement in fast flight: trust it less there.
            let noise_z = ((vz.abs() - p.hte_vz_thr) + 1.0).max(1.0);
            let noise_xy = ((input.velocity.xy().norm() - p.hte_vxy_thr) + 1.0).max(1.0);
            self.ekf.acc_var_scale = noise_xy.max(noise_z);
            self.ekf.fuse_acc_up(acc_up, thrust_up);
            let mut valid = self.ekf.state_var < VALID_VARIANCE;
            // The test ratio need not pass all the time to keep a valid estimate.
            if !self.valid {
                valid = valid && self.ekf.innovation_test_ratio < 1.0;
            }
            self.valid_hysteresis.set_state_and_update(valid, now_ns);
            self.valid = self.valid_hysteresis.state();
        } else {
            self.valid_hysteresis.set_state_and_update(false, now_ns);
            if !input.armed {
                self.reset(p);
            }
            self.valid = false;
        }
    }

    /// Back to MPC_THR_HOVER with the initial uncertainties (PX4 does this while
    /// disarmed); the learnt residual filters are kept, as in PX4.
    fn reset(&mut self, p: &AutopilotParams) {
        let fresh = HoverThrustEkf::new(p);
        self.ekf.hover_thrust = fresh.hover_thrust;
        self.ekf.hover_thrust_min = fresh.hover_thrust_min;
        self.ekf.hover_thrust_max = fresh.hover_thrust_max;
        self.ekf.state_var = fresh.state_var;
        self.ekf.acc_var = fresh.acc_var;
    }
}

#[cfg(test)]
#[path = "hover_thrust_test.rs"]
mod tests;
