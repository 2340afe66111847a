//! PX4's multicopter land detector (v1.16 `modules/land_detector/`,
//! `MulticopterLandDetector.cpp` and `LandDetector.cpp`): whether the vehicle has
//! landed, judged as PX4 judges it, from its own state estimate and the thrust it
//! commands, never from the true contact.
//!
//! Three stages, each a [`Hysteresis`] that turns true after its condition held
//! LNDMC_TRIG_TIME / 3 (and false at once), evaluated in this order every update:
//!
//! 1. ground contact: the thrust setpoint is low (at most MPC_THR_MIN plus 30 % of the
//!    way to the hover thrust, 60 % once the hover thrust estimate is valid), the
//!    estimated vertical speed is below LNDMC_Z_VEL_MAX (2.5 times that once landed),
//!    the estimated horizontal speed is at most LNDMC_XY_VEL_MAX, and, until maybe
//!    landed, a descent is commanded (a velocity setpoint down faster than 1.1
//!    LNDMC_Z_VEL_MAX);
//! 2. maybe landed: ground contact, the thrust setpoint at most MPC_THR_MIN plus 10 %
//!    of the way to the hover thrust, no free fall (specific force below 2 m/s^2 for
//!    0.3 s), and the roll-pitch rate below LNDMC_ROT_MAX (2.5 times that once landed);
//! 3. landed: maybe landed.
//!
//! Disarmed, every stage's condition is true: PX4 boots landed, and so does this one.
//! Between stage 1 and 2 the position controller cuts the thrust to its minimum
//! (`Autopilot`), which is what lets stage 2 pass on a real touchdown.
//!
//! The horizontal speed rule is PX4's and is kept: on a moving pad the estimated
//! horizontal velocity is the pad's, so PX4 never detects a landing on a pad moving
//! faster than LNDMC_XY_VEL_MAX (1.5 m/s by default; the paper's pad speeds are below
//! it; a faster pad needs the parameter raised, as it would on the real vehicle).
//!
//! Not modelled (no sensor for them here): the distance-to-ground checks (no range
//! finder: PX4 skips them), the vertical speed from the altitude derivative (the
//! estimate always has a vertical velocity), the 8 s minimum-thrust rule used without
//! one, and the manual-thrust thresholds (the autopilot always controls climb rate).

use nalgebra::Vector3;

use crate::autopilot_params::AutopilotParams;
use crate::hysteresis::Hysteresis;
use crate::quadrotor::GRAVITY_M_S2;

/// How long a specific force below [`FREEFALL_SPECIFIC_FORCE_M_S2`] must last to be a
/// free fall, ns (PX4 FREEFALL_TRIGGER_TIME_US).
const FREEFALL_TRIGGER_NS: u64 = 300_000_000;

/// Specific force below which the vehicle is falling freely, m/s^2 (PX4: 2).
const FREEFALL_SPECIFIC_FORCE_M_S2: f64 = 2.0;

/// How long a valid hover thrust estimate counts as valid, ns (PX4: 1 s).
const HTE_FRESH_NS: u64 = 1_000_000_000;

/// Factor widening the speed and rate thresholds once landed (PX4: 2.5).
const LANDED_WIDENING: f64 = 2.5;

/// What the land detector says, as PX4's `vehicle_land_detected`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LandDetected {
    /// Stage 1: touching the ground, possibly still with weight on the rotors.
    pub ground_contact: bool,
    /// Stage 2: probably landed (the controllers stop integrating).
    pub maybe_landed: bool,
    /// Stage 3: landed (the commander's on-ground state, auto-disarm).
    pub landed: bool,
    /// The vehicle is falling freely.
    pub freefall: bool,
    /// A descent is commanded.
    pub in_descend: bool,
    /// The thrust setpoint is low enough for ground contact.
    pub has_low_throttle: bool,
    /// The estimated vertical speed is too high for ground contact.
    pub vertical_movement: bool,
    /// The estimated horizontal speed is too high for ground contact.
    pub horizontal_movement: bool,
    /// The roll-pitch rate is too high for maybe landed.
    pub rotational_movement: bool,
}

impl LandDetected {
    /// PX4's boot state: on the ground.
    pub fn on_ground() -> Self {
        Self {
            ground_contact: true,
            maybe_landed: true,
            landed: true,
            freefall: false,
            in_descend: false,
            has_low_throttle: false,
            vertical_movement: false,
            horizontal_movement: false,
            rotational_movement: false,
        }
    }
}

/// What the land detector reads each update: the autopilot's own estimate and
/// commands, nothing true.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LandDetectorInput {
    /// Motors armed.
    pub armed: bool,
    /// Estimated velocity, world ENU, m/s.
    pub velocity: Vector3<f64>,
    /// Estimated body rates, FLU, rad/s.
    pub body_rates: Vector3<f64>,
    /// Estimated acceleration, world ENU, m/s^2 (None when unknown: no free fall).
    pub acceleration: Option<Vector3<f64>>,
    /// Collective thrust setpoint along body z, normalized.
    pub throttle: f64,
    /// The trajectory setpoint's vertical velocity, ENU (up positive), m/s.
    pub velocity_setpoint_z: Option<f64>,
    /// The hover thrust estimate if it is valid now (with MPC_USE_HTE = 1).
    pub hover_thrust_estimate: Option<f64>,
}

/// PX4's multicopter land detector (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct LandDetector {
    freefall: Hysteresis,
    ground_contact: Hysteresis,
    maybe_landed: Hysteresis,
    landed: Hysteresis,
    /// The hover thrust the thresholds use: MPC_THR_HOVER until the estimator
    /// publishes a valid estimate, then its latest valid one.
    hover_throttle: f64,
    hte_last_valid_ns: Option<u64>,
    hte_valid: bool,
    in_descend: bool,
    out: LandDetected,
}

impl LandDetector {
    /// Boots landed, as PX4, with PX4's stage times for `p`.
    pub fn new(p: &AutopilotParams) -> Self {
        let stage_ns = (p.lndmc_trig_time / 3.0 * 1e9).round() as u64;
        let stage = |state| {
            let mut h = Hysteresis::new(state);
            h.set_time_from(false, stage_ns);
            h
        };
        let mut freefall = Hysteresis::new(false);
        freefall.set_time_from(false, FREEFALL_TRIGGER_NS);
        Self {
            freefall,
            ground_contact: stage(true),
            maybe_landed: stage(true),
            landed: stage(true),
            hover_throttle: p.mpc_thr_hover,
            hte_last_valid_ns: None,
            hte_valid: false,
            in_descend: false,
            out: LandDetected::on_ground(),
        }
    }

    /// The latest output.
    pub fn output(&self) -> &LandDetected {
        &self.out
    }

    /// Puts every stage in the air (`in_air`) or on the ground at once: for a vehicle
    /// the simulator places somewhere, as if the detector had long settled there.
    pub fn force(&mut self, in_air: bool) {
        for h in [
            &mut self.ground_contact,
            &mut self.maybe_landed,
            &mut self.landed,
        ] {
            h.force(!in_air);
        }
        self.freefall.force(false);
        self.in_descend = false;
        self.out = if in_air {
            LandDetected {
                ground_contact: false,
                maybe_landed: false,
                landed: false,
                ..LandDetected::on_ground()
            }
        } else {
            LandDetected::on_ground()
        };
    }

    /// Runs the three stages at `now_ns` (see the module docs).
    pub fn update(
        &mut self,
        now_ns: u64,
        p: &AutopilotParams,
        input: &LandDetectorInput,
    ) -> LandDetected {
        if p.mpc_use_hte == 1
            && let Some(h) = input.hover_thrust_estimate
            && h.is_finite()
        {
            self.hover_throttle = h;
            self.hte_last_valid_ns = Some(now_ns);
        }
        let throttle = if input.throttle.is_finite() {
            input.throttle
        } else {
            1.0
        };
        let freefall = input.acceleration.is_some_and(|a| {
            (a + Vector3::new(0.0, 0.0, GRAVITY_M_S2)).norm() < FREEFALL_SPECIFIC_FORCE_M_S2
        });
        self.freefall.set_state_and_update(freefall, now_ns);

        let ground_contact = self.ground_contact_now(now_ns, p, input, throttle);
        self.ground_contact
            .set_state_and_update(ground_contact, now_ns);

        let min_throttle = p.mpc_thr_min + (self.hover_throttle - p.mpc_thr_min) * 0.1;
        let mut max_rotation = p.lndmc_rot_max.to_radians();
        if self.landed.state() {
            max_rotation *= LANDED_WIDENING;
        }
        let rotational_movement = input.body_rates.xy().norm() > max_rotation;
        let maybe_landed = !input.armed
            || (throttle <= min_throttle
                && !self.freefall.state()
                && !rotational_movement
                && self.ground_contact.state());
        self.maybe_landed.set_state_and_update(maybe_landed, now_ns);

        let landed = !input.armed || self.maybe_landed.state();
        self.landed.set_state_and_update(landed, now_ns);

        self.out = LandDetected {
            ground_contact: self.ground_contact.state(),
            maybe_landed: self.maybe_landed.state(),
            landed: self.landed.state(),
            freefall: self.freefall.state(),
            in_descend: self.in_descend,
            rotational_movement,
            ..self.out
        };
        self.out
    }

    /// Stage 1's condition now (PX4 `_get_ground_contact_state`); records the
    /// movement flags.
    fn ground_contact_now(
        &mut self,
        now_ns: u64,
        p: &AutopilotParams,
        input: &LandDetectorInput,
        throttle: f64,
    ) -> bool {
        let mut vz_max = p.lndmc_z_vel_max;
        if self.landed.state() {
            vz_max *= LANDED_WIDENING;
        }
        // Still only below the threshold: a non-finite speed counts as movement.
        let vertically_still = input.velocity.z.abs() < vz_max;
        let vertical_movement = !vertically_still;
        let horizontal_movement = input.velocity.xy().norm() > p.lndmc_xy_vel_max;

        let hte_valid_now = self
            .hte_last_valid_ns
            .is_some_and(|t| now_ns.saturating_sub(t) < HTE_FRESH_NS);
        // Keep a valid hover thrust through a descent even if it lapses there.
        if !self.in_descend || hte_valid_now {
            self.hte_valid = hte_valid_now;
        }
        let share = if self.hte_valid { 0.6 } else { 0.3 };
        let low_throttle = p.mpc_thr_min + (self.hover_throttle - p.mpc_thr_min) * share;
        let has_low_throttle = throttle <= low_throttle;

        // A descent is a velocity setpoint down faster than 1.1 LNDMC_Z_VEL_MAX.
        self.in_descend = input
            .velocity_setpoint_z
            .is_some_and(|vz| vz.is_finite() && -vz >= 1.1 * p.lndmc_z_vel_max);
        let mut contact = has_low_throttle;
        // Ground contact needs a commanded descent until maybe landed.
        if !self.maybe_landed.state() && !self.landed.state() {
            contact &= self.in_descend;
        }
        self.out.has_low_throttle = has_low_throttle;
        self.out.vertical_movement = vertical_movement;
        self.out.horizontal_movement = horizontal_movement;
        !input.armed || (contact && !horizontal_movement && !vertical_movement)
    }
}

#[cfg(test)]
#[path = "land_detector_test.rs"]
mod tests;
