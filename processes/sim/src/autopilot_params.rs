//! The autopilot's parameters, named after PX4's: the controller's gains and limits, the
//! hover thrust estimator's and the land detector's. Below the three of them
//! ([`crate::autopilot`], [`crate::hover_thrust`], [`crate::land_detector`]), which all
//! read them.

use nalgebra::Vector3;
use serde::Deserialize;

use crate::params::{self, ParamError};
use crate::quadrotor::AirframeParams;

/// Controller parameters, named after their PX4 counterparts.
///
/// In TOML the PX4 spelling is used (`MPC_XY_P = 0.95`); missing fields keep
/// their default, unknown ones are rejected. Velocity gains are PX4's `_ACC`
/// parameters (PX4 >= 1.12), i.e. the MPC_XY_VEL_P/I/D of older releases
/// expressed as acceleration per velocity error.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default, rename_all = "SCREAMING_SNAKE_CASE")]
pub struct AutopilotParams {
    /// Horizontal position gain, 1/s (PX4 default 0.95).
    pub mpc_xy_p: f64,
    /// Vertical position gain, 1/s (PX4 default 1.0).
    pub mpc_z_p: f64,
    /// Horizontal velocity P gain, m/s^2 per m/s (PX4 default 1.8).
    pub mpc_xy_vel_p_acc: f64,
    /// Horizontal velocity I gain, m/s^3 per m/s (PX4 default 0.4).
    pub mpc_xy_vel_i_acc: f64,
    /// Horizontal velocity D gain, m/s per m/s (PX4 default 0.2).
    pub mpc_xy_vel_d_acc: f64,
    /// Vertical velocity P gain (PX4 default 4.0).
    pub mpc_z_vel_p_acc: f64,
    /// Vertical velocity I gain (PX4 default 2.0).
    pub mpc_z_vel_i_acc: f64,
    /// Vertical velocity D gain (PX4 default 0.0).
    pub mpc_z_vel_d_acc: f64,
    /// Horizontal speed limit, m/s (PX4 default 12).
    pub mpc_xy_vel_max: f64,
    /// Climb speed limit, m/s (PX4 default 3).
    pub mpc_z_vel_max_up: f64,
    /// Descent speed limit, m/s (PX4 default 1.5).
    pub mpc_z_vel_max_dn: f64,
    /// Horizontal acceleration limit, m/s^2 (PX4 default 5; here applied to
    /// the total acceleration setpoint, where PX4 applies it in its trajectory
    /// generators).
    pub mpc_acc_hor_max: f64,
    /// Upward acceleration limit, m/s^2 (PX4 default 4; here on the commanded
    /// vertical acceleration, the velocity integrator comes on top).
    pub mpc_acc_up_max: f64,
    /// Downward acceleration limit, m/s^2 (PX4 default 3; like the upward one).
    pub mpc_acc_down_max: f64,
    /// Maximum tilt in flight, deg (PX4 default 45).
    pub mpc_tiltmax_air: f64,
    /// Normalized thrust that hovers the vehicle as its airframe file says (PX4
    /// MPC_THR_HOVER): the controller starts from it, the hover thrust estimator
    /// corrects it in flight.
    pub mpc_thr_hover: f64,
    /// Minimum collective thrust in flight (PX4 default 0.12).
    pub mpc_thr_min: f64,
    /// Maximum collective thrust (PX4 default 1.0).
    pub mpc_thr_max: f64,
    /// Horizontal thrust margin kept when vertical control saturates (PX4 default 0.3).
    pub mpc_thr_xy_marg: f64,
    /// Cut-off of the velocity-derivative low-pass for the D term, Hz (PX4 default 5).
    pub mpc_veld_lp: f64,
    /// Roll attitude gain, 1/s (PX4 default 6.5).
    pub mc_roll_p: f64,
    /// Pitch attitude gain, 1/s (PX4 default 6.5).
    pub mc_pitch_p: f64,
    /// Yaw attitude gain, 1/s (PX4 default 2.8).
    pub mc_yaw_p: f64,
    /// Yaw priority relative to roll/pitch in the attitude error, 0..1 (PX4 default 0.4).
    pub mc_yaw_weight: f64,
    /// Roll rate limit, deg/s (PX4 default 220).
    pub mc_rollrate_max: f64,
    /// Pitch rate limit, deg/s (PX4 default 220).
    pub mc_pitchrate_max: f64,
    /// Yaw rate limit, deg/s (PX4 default 200).
    pub mc_yawrate_max: f64,
    /// Roll rate P gain, normalized torque per rad/s (PX4 default 0.15).
    pub mc_rollrate_p: f64,
    /// Roll rate I gain (PX4 default 0.2).
    pub mc_rollrate_i: f64,
    /// Roll rate D gain (PX4 default 0.003).
    pub mc_rollrate_d: f64,
    /// Pitch rate P gain (PX4 default 0.15).
    pub mc_pitchrate_p: f64,
    /// Pitch rate I gain (PX4 default 0.2).
    pub mc_pitchrate_i: f64,
    /// Pitch rate D gain (PX4 default 0.003).
    pub mc_pitchrate_d: f64,
    /// Yaw rate P gain (PX4 default 0.2).
    pub mc_yawrate_p: f64,
    /// Yaw rate I gain (PX4 default 0.1).
    pub mc_yawrate_i: f64,
    /// Yaw rate D gain (PX4 default 0.0).
    pub mc_yawrate_d: f64,
    /// Roll rate integrator limit, normalized torque (PX4 default 0.3).
    pub mc_rr_int_lim: f64,
    /// Pitch rate integrator limit (PX4 default 0.3).
    pub mc_pr_int_lim: f64,
    /// Yaw rate integrator limit (PX4 default 0.3).
    pub mc_yr_int_lim: f64,
    /// Cut-off of the gyro-derivative low-pass for the rate D term, Hz (PX4 default 30).
    pub imu_dgyro_cutoff: f64,
    /// 1: the position controller uses the hover thrust estimate once it is valid
    /// instead of MPC_THR_HOVER; 0: MPC_THR_HOVER only (PX4 default 1).
    pub mpc_use_hte: u8,
    /// 1: the tilt comes from the horizontal acceleration against gravity alone, so a
    /// descent's downward acceleration takes horizontal thrust away with the collective;
    /// 0: the tilt includes the vertical acceleration and the horizontal thrust is kept
    /// (PX4 MPC_ACC_DECOUPLE). PX4's default is 1; here it is 0, the value the stack
    /// asks a vehicle's PX4 for (deploy/README.md), and the one this autopilot has
    /// always flown.
    pub mpc_acc_decouple: u8,
    /// Hover thrust process noise, normalized thrust per s (PX4 HTE_HT_NOISE, 0.0036).
    pub hte_ht_noise: f64,
    /// Innovation gate of the acceleration fusion, standard deviations (PX4 HTE_ACC_GATE, 3).
    pub hte_acc_gate: f64,
    /// Initial 1-sigma hover thrust uncertainty, normalized thrust (PX4 HTE_HT_ERR_INIT, 0.1).
    pub hte_ht_err_init: f64,
    /// Horizontal speed above which measurements are de-weighted, m/s (PX4 HTE_VXY_THR, 10).
    pub hte_vxy_thr: f64,
    /// Vertical speed above which measurements are de-weighted, m/s (PX4 HTE_VZ_THR, 2).
    pub hte_vz_thr: f64,
    /// Largest deviation of the estimate from MPC_THR_HOVER (PX4 HTE_THR_RANGE, 0.2).
    pub hte_thr_range: f64,
    /// Vertical speed below which the land detector sees no vertical motion, m/s (PX4
    /// LNDMC_Z_VEL_MAX, 0.25).
    pub lndmc_z_vel_max: f64,
    /// Horizontal speed above which the land detector sees motion, m/s (PX4
    /// LNDMC_XY_VEL_MAX, 1.5).
    pub lndmc_xy_vel_max: f64,
    /// Roll-pitch rate above which the land detector sees rotation, deg/s (PX4
    /// LNDMC_ROT_MAX, 20).
    pub lndmc_rot_max: f64,
    /// Time through the three land detector stages (ground contact, maybe landed,
    /// landed), s (PX4 LNDMC_TRIG_TIME, 1).
    pub lndmc_trig_time: f64,
}

impl Default for AutopilotParams {
    /// PX4's defaults, tuned for the default (P450) airframe.
    fn default() -> Self {
        Self::tuned_for(&AirframeParams::default())
    }
}

/// Angular acceleration (rad/s^2) per unit of normalized torque about x, y, z.
///
/// The rate gains are in normalized torque, so a heavier or lighter frame
/// needs them scaled; this is how [`AutopilotParams::tuned_for`] scales them.
pub fn torque_effectiveness(airframe: &AirframeParams) -> Vector3<f64> {
    let t_max = airframe.max_thrust_per_motor_n();
    let lever = airframe.arm_length_m * std::f64::consts::FRAC_1_SQRT_2;
    let [jxx, jyy, jzz] = airframe.inertia_diag_kg_m2;
    // Each motor changes its thrust by MIX_ROLL_PITCH * t_max per unit roll/pitch.
    let roll_pitch_torque = 4.0 * MIX_ROLL_PITCH * t_max * lever;
    let yaw_torque =
        4.0 * MIX_YAW * t_max * airframe.torque_coefficient / airframe.thrust_coefficient;
    Vector3::new(
        roll_pitch_torque / jxx,
        roll_pitch_torque / jyy,
        yaw_torque / jzz,
    )
}

/// Mixer weight of roll and pitch per motor (PX4's normalized quad X: 1/sqrt 2).
pub(crate) const MIX_ROLL_PITCH: f64 = std::f64::consts::FRAC_1_SQRT_2;
/// Mixer weight of yaw per motor (PX4's normalized quad X: 1).
pub(crate) const MIX_YAW: f64 = 1.0;

impl AutopilotParams {
    /// PX4's default gains and limits, with the hover thrust taken from the
    /// airframe and the rate gains scaled so that a unit of normalized torque
    /// gives the same angular acceleration as on the P450 the defaults were
    /// chosen for (what a PX4 user tuning a new frame would end up with).
    pub fn tuned_for(airframe: &AirframeParams) -> Self {
        let reference = torque_effectiveness(&AirframeParams::default());
        let this = torque_effectiveness(airframe);
        let scale = Vector3::new(
            reference.x / this.x,
            reference.y / this.y,
            reference.z / this.z,
        );
        let scale = scale.map(|s| if s.is_finite() && s > 0.0 { s } else { 1.0 });
        Self {
            mpc_xy_p: 0.95,
            mpc_z_p: 1.0,
            mpc_xy_vel_p_acc: 1.8,
            mpc_xy_vel_i_acc: 0.4,
            mpc_xy_vel_d_acc: 0.2,
            mpc_z_vel_p_acc: 4.0,
            mpc_z_vel_i_acc: 2.0,
            mpc_z_vel_d_acc: 0.0,
            mpc_xy_vel_max: 12.0,
            mpc_z_vel_max_up: 3.0,
            mpc_z_vel_max_dn: 1.5,
            mpc_acc_hor_max: 5.0,
            mpc_acc_up_max: 4.0,
            mpc_acc_down_max: 3.0,
            mpc_tiltmax_air: 45.0,
            mpc_thr_hover: airframe.hover_thrust_normalized().clamp(0.1, 0.8),
            mpc_thr_min: 0.12,
            mpc_thr_max: 1.0,
            mpc_thr_xy_marg: 0.3,
            mpc_veld_lp: 5.0,
            mc_roll_p: 6.5,
            mc_pitch_p: 6.5,
            mc_yaw_p: 2.8,
            mc_yaw_weight: 0.4,
            mc_rollrate_max: 220.0,
            mc_pitchrate_max: 220.0,
            mc_yawrate_max: 200.0,
            mc_rollrate_p: 0.15 * scale.x,
            mc_rollrate_i: 0.2 * scale.x,
            mc_rollrate_d: 0.003 * scale.x,
            mc_pitchrate_p: 0.15 * scale.y,
            mc_pitchrate_i: 0.2 * scale.y,
            mc_pitchrate_d: 0.003 * scale.y,
            mc_yawrate_p: 0.2 * scale.z,
            mc_yawrate_i: 0.1 * scale.z,
            mc_yawrate_d: 0.0,
            mc_rr_int_lim: 0.3,
            mc_pr_int_lim: 0.3,
            mc_yr_int_lim: 0.3,
            imu_dgyro_cutoff: 30.0,
            mpc_use_hte: 1,
            mpc_acc_decouple: 0,
            hte_ht_noise: 0.0036,
            hte_acc_gate: 3.0,
            hte_ht_err_init: 0.1,
            hte_vxy_thr: 10.0,
            hte_vz_thr: 2.0,
            hte_thr_range: 0.2,
            lndmc_z_vel_max: 0.25,
            lndmc_xy_vel_max: 1.5,
            lndmc_rot_max: 20.0,
            lndmc_trig_time: 1.0,
        }
    }

    /// Gains and limits for the racer airframe in high-speed chases: tuned for
    /// [`AirframeParams::racer`], with higher speed, tilt and acceleration limits.
    pub fn racer() -> Self {
        Self {
            mpc_xy_vel_max: 20.0,
            mpc_z_vel_max_up: 5.0,
            mpc_z_vel_max_dn: 3.0,
            mpc_acc_hor_max: 12.0,
            mpc_acc_up_max: 8.0,
            mpc_acc_down_max: 5.0,
            mpc_tiltmax_air: 60.0,
            ..Self::tuned_for(&AirframeParams::racer())
        }
    }

    /// Checks every parameter, so a bad scenario is rejected before it is flown.
    pub fn validate(&self) -> Result<(), ParamError> {
        let positive = [
            ("MPC_XY_P", self.mpc_xy_p),
            ("MPC_Z_P", self.mpc_z_p),
            ("MPC_XY_VEL_P_ACC", self.mpc_xy_vel_p_acc),
            ("MPC_Z_VEL_P_ACC", self.mpc_z_vel_p_acc),
            ("MPC_XY_VEL_MAX", self.mpc_xy_vel_max),
            ("MPC_Z_VEL_MAX_UP", self.mpc_z_vel_max_up),
            ("MPC_Z_VEL_MAX_DN", self.mpc_z_vel_max_dn),
            ("MPC_ACC_HOR_MAX", self.mpc_acc_hor_max),
            ("MPC_ACC_UP_MAX", self.mpc_acc_up_max),
            ("MPC_ACC_DOWN_MAX", self.mpc_acc_down_max),
            ("MPC_VELD_LP", self.mpc_veld_lp),
            ("MC_ROLL_P", self.mc_roll_p),
            ("MC_PITCH_P", self.mc_pitch_p),
            ("MC_YAW_P", self.mc_yaw_p),
            ("MC_ROLLRATE_MAX", self.mc_rollrate_max),
            ("MC_PITCHRATE_MAX", self.mc_pitchrate_max),
            ("MC_YAWRATE_MAX", self.mc_yawrate_max),
            ("MC_ROLLRATE_P", self.mc_rollrate_p),
            ("MC_PITCHRATE_P", self.mc_pitchrate_p),
            ("MC_YAWRATE_P", self.mc_yawrate_p),
            ("IMU_DGYRO_CUTOFF", self.imu_dgyro_cutoff),
            ("LNDMC_Z_VEL_MAX", self.lndmc_z_vel_max),
            ("LNDMC_XY_VEL_MAX", self.lndmc_xy_vel_max),
            ("LNDMC_ROT_MAX", self.lndmc_rot_max),
        ];
        for (name, value) in positive {
            params::positive(name, value)?;
        }
        let non_negative = [
            ("MPC_XY_VEL_I_ACC", self.mpc_xy_vel_i_acc),
            ("MPC_XY_VEL_D_ACC", self.mpc_xy_vel_d_acc),
            ("MPC_Z_VEL_I_ACC", self.mpc_z_vel_i_acc),
            ("MPC_Z_VEL_D_ACC", self.mpc_z_vel_d_acc),
            ("MC_ROLLRATE_I", self.mc_rollrate_i),
            ("MC_ROLLRATE_D", self.mc_rollrate_d),
            ("MC_PITCHRATE_I", self.mc_pitchrate_i),
            ("MC_PITCHRATE_D", self.mc_pitchrate_d),
            ("MC_YAWRATE_I", self.mc_yawrate_i),
            ("MC_YAWRATE_D", self.mc_yawrate_d),
            ("MC_RR_INT_LIM", self.mc_rr_int_lim),
            ("MC_PR_INT_LIM", self.mc_pr_int_lim),
            ("MC_YR_INT_LIM", self.mc_yr_int_lim),
        ];
        for (name, value) in non_negative {
            params::non_negative(name, value)?;
        }
        params::in_range("MPC_TILTMAX_AIR", self.mpc_tiltmax_air, 1.0, 89.0)?;
        params::in_range("MC_YAW_WEIGHT", self.mc_yaw_weight, 0.0, 1.0)?;
        params::in_range("MPC_THR_MIN", self.mpc_thr_min, 0.0, 0.5)?;
        params::in_range("MPC_THR_MAX", self.mpc_thr_max, 0.5, 1.0)?;
        params::in_range("MPC_THR_XY_MARG", self.mpc_thr_xy_marg, 0.0, 0.5)?;
        // PX4's ranges (hover_thrust_estimator_params.yaml, land_detector_params_mc.yaml).
        params::in_range("HTE_HT_NOISE", self.hte_ht_noise, 0.0001, 1.0)?;
        params::in_range("HTE_ACC_GATE", self.hte_acc_gate, 1.0, 10.0)?;
        params::in_range("HTE_HT_ERR_INIT", self.hte_ht_err_init, 0.0, 1.0)?;
        params::in_range("HTE_VXY_THR", self.hte_vxy_thr, 1.0, 20.0)?;
        params::in_range("HTE_VZ_THR", self.hte_vz_thr, 1.0, 10.0)?;
        params::in_range("HTE_THR_RANGE", self.hte_thr_range, 0.01, 0.4)?;
        params::in_range("LNDMC_TRIG_TIME", self.lndmc_trig_time, 0.1, 10.0)?;
        if self.mpc_use_hte > 1 {
            return Err(ParamError::new(
                "MPC_USE_HTE",
                self.mpc_use_hte,
                "must be 0 (MPC_THR_HOVER only) or 1 (hover thrust estimate)",
            ));
        }
        if self.mpc_acc_decouple > 1 {
            return Err(ParamError::new(
                "MPC_ACC_DECOUPLE",
                self.mpc_acc_decouple,
                "must be 0 (tilt from the whole acceleration) or 1 (tilt against gravity alone)",
            ));
        }
        if !(self.mpc_thr_hover.is_finite()
            && self.mpc_thr_hover > self.mpc_thr_min
            && self.mpc_thr_hover < self.mpc_thr_max)
        {
            return Err(ParamError::new(
                "MPC_THR_HOVER",
                self.mpc_thr_hover,
                format!(
                    "must be between MPC_THR_MIN ({}) and MPC_THR_MAX ({})",
                    self.mpc_thr_min, self.mpc_thr_max
                ),
            ));
        }
        Ok(())
    }
}
