//! The `[fsm]` section of the stack configuration: the mission and its gates. Defaults
//! follow the paper where it gives a number (commit height 0.6 m) and are otherwise set
//! for a 450 mm quadrotor with a downward camera.

use serde::Deserialize;
use stack_config::{Invalid, Validate, check_range};

/// What the fsm reads from `landing.toml`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FsmConfig {
    /// Start the mission as soon as the link is up (else wait for an operator start).
    pub autostart: bool,
    /// Setpoint rate, Hz (the issue asks for 50).
    pub rate_hz: f64,
    /// Where to climb to and wait for the pad, world ENU, m (the paper's preset point).
    pub preset_m: [f64; 3],
    /// Distance to the preset point that counts as arrived, m.
    pub preset_tolerance_m: f64,
    /// WaitForPad: after this long without the pad, climb to widen the camera's view, s.
    pub search_after_s: f64,
    /// WaitForPad: climb at most this much above the preset point, m.
    pub search_climb_m: f64,
    /// Never wait for the pad higher than this, m: above it the camera cannot resolve
    /// the pad's largest marker (`optics::PadModel::detection_depth_m`). A preset
    /// point higher up is flown to at this height, and the search climb stops here.
    /// Unset (the default), `landing run` derives it from the scenario's camera and pad
    /// and hands it to the fsm process as `--search-height-max`; on a vehicle set it for
    /// the camera it flies (focal length x largest marker / 15 px).
    pub search_height_max_m: Option<f64>,
    /// Highest take-off altitude, climbed to in OFFBOARD; the planner flies the rest, m.
    pub takeoff_altitude_m: f64,
    /// Take-off climb speed of the setpoint ramp, m/s (PX4's MPC_TKO_SPEED is 1.5).
    pub takeoff_climb_m_s: f64,
    /// Highest tracking height above the pad, m.
    pub track_height_max_m: f64,
    /// Closer than this (horizontally) the vehicle flies pad-relative setpoints instead
    /// of planner trajectories: over the pad vehicle the map shows the vehicle itself.
    pub direct_range_m: f64,
    /// Speed used to predict the rendezvous time (distance / this), m/s.
    pub approach_speed_m_s: f64,
    /// A pad faster than this, m/s, is chased with pad-relative setpoints at any range:
    /// the planner's trajectories (its `max_vel`) cannot catch it, and a road vehicle's
    /// own path is the free space to fly in. Lost at this speed, the vehicle keeps its
    /// height while it follows (climbing, the pad's markers would shrink out of range).
    pub chase_speed_m_s: f64,
    /// Chasing, within `direct_range_m` of the pad, each metre off it adds this much
    /// velocity per second (1/s^2), in the pad's heading frame: an integral that holds
    /// station over the pad against the relative wind and a curve's pull.
    pub chase_trim_gain: f64,
    /// Below the chase speed, descending and touching down until the drop, each metre off
    /// the pad adds this much velocity per second (1/s^2), in the pad's heading frame: in
    /// wind the autopilot held the vehicle 5-7 cm downwind of the pad for seconds at the
    /// flare height, until the drop's gate widened to let it go from there. 0 = off.
    pub flare_trim_gain: f64,
    /// Horizontal error below which descent may start, m.
    pub align_m: f64,
    /// Horizontal speed relative to the pad below which descent may start, m/s.
    pub align_speed_m_s: f64,
    /// How long both alignment gates must hold before descent, s.
    pub align_hold_s: f64,
    /// Descent rate while tracking, m/s.
    pub descend_rate_m_s: f64,
    /// Height above the pad below which the vehicle commits to touchdown, m (paper 0.6).
    pub commit_height_m: f64,
    /// Horizontal error allowed at the commit, m.
    pub land_align_m: f64,
    /// Horizontal speed relative to the pad allowed at the commit, m/s.
    pub land_speed_gate_m_s: f64,
    /// Touchdown descent rate, m/s.
    pub land_rate_m_s: f64,
    /// Land: height above the pad where the vehicle waits to be right over it, m.
    pub flare_height_m: f64,
    /// Land: horizontal error below which the vehicle drops from the flare height, below
    /// the chase speed, m: the offset the drop begins from is most of a paper-speed
    /// touchdown's error beyond the camera's calibration.
    pub flare_align_m: f64,
    /// The same above the chase speed, m: the highspeed scenarios were flown at 0.025, and
    /// at the road's speed a longer wait costs road, not centimetres.
    pub chase_flare_align_m: f64,
    /// Land: over this long at the flare height the drop's gate widens from
    /// `flare_align_m` (chasing `chase_flare_align_m`) to `land_align_m` (quadratically:
    /// tight at first), s: a vehicle that cannot get that close (a steady turn, gusts)
    /// drops a little wider rather than time out.
    pub flare_relax_s: f64,
    /// Land, below the chase speed: the drop waits until the camera reads the vehicle
    /// moving over the pad slower than this, m/s (widening with the wait as the offset's
    /// gate does, to `land_speed_gate_m_s`): the fall is open loop, and the pad filter's
    /// velocity lags a braking just begun.
    pub flare_settle_m_s: f64,
    /// Land, below the chase speed: the drop also waits until the offset the vehicle will
    /// have at contact is within the gate: the camera's offset plus its relative velocity
    /// times this long (the fall), s. 0 = the offset now alone. The vehicle swings over
    /// the pad at +-10 cm/s, about 1 Hz, and the 0.4 s fall is open loop.
    pub flare_fall_s: f64,
    /// How far back the line through the camera's relative measurements reaches, s: a
    /// longer line reads the relative velocity steadier and later.
    pub relative_window_s: f64,
    /// Land: descent rate of the final drop, m/s.
    pub drop_rate_m_s: f64,
    /// Land, below the chase speed: the drop waits while the pad accelerates more than
    /// this (braking, changing lane), m/s^2: the vehicle follows a changing velocity
    /// late, and a drop begun in a braking ends past the pad.
    pub flare_accel_max_m_s2: f64,
    /// ... and until the pad has stayed under that acceleration this long, s: a lane
    /// change's acceleration turns over in its middle, where the pad moves sideways
    /// fastest, and a drop begun there ends 10-13 cm off.
    pub flare_quiet_s: f64,
    /// Descend and Land, below the chase speed: share of the pad's estimated
    /// acceleration fed forward to the autopilot (0 = none, 1 = all of it).
    pub pad_accel_gain: f64,
    /// Land: the oldest pad observation the touchdown may steer by, s. Older, the vehicle
    /// drops at once if it is low and was aligned, else goes around: the filter's
    /// extrapolation is no pad to land on.
    pub land_max_pad_age_s: f64,
    /// Descend and Land below the chase speed: velocity added per metre of horizontal
    /// error over the pad, 1/s, on top of the autopilot's own position gain (0 = the
    /// autopilot's alone). The vehicle trails a pad changing speed by the acceleration the
    /// feed-forward misses over the loop's stiffness; this is the part of it the fsm owns.
    pub relative_gain: f64,
    /// The same above the chase speed, 1/s: the highspeed scenarios were flown at 1.0.
    pub chase_relative_gain: f64,
    /// The same through the drop, below the chase speed, 1/s (0 = the vehicle only matches
    /// the pad's velocity once the drop has begun): the wind carries a falling vehicle off
    /// while its lean catches up with the thrust the drop takes away.
    pub drop_relative_gain: f64,
    /// Land: acceleration feed-forward per m/s of horizontal velocity error (the
    /// pad-relative velocity wanted minus the vehicle's), 1/s. PX4's velocity loop alone
    /// (MPC_XY_VEL_P_ACC 1.8) lets a 0.2 m/s error stand for half a second, long enough to
    /// drift 10 cm during the touchdown (0 = PX4's alone).
    pub relative_velocity_gain: f64,
    /// Land: cap of that feed-forward, m/s^2. Each m/s^2 tilts the vehicle about 6 deg,
    /// and the touchdown is judged at 15 deg.
    pub relative_accel_max_m_s2: f64,
    /// Land, below the chase speed: that feed-forward reads the pad's motion relative to
    /// the vehicle from the camera (a line through its last quarter second of relative
    /// measurements) while it has fresh ones, instead of the pad filter's velocity minus
    /// the autopilot's: the latter carries the estimator's velocity noise (3 cm/s in the
    /// simulator) twice, once filtered, once not.
    pub relative_velocity_from_camera: bool,
    /// Descend and Land, below the chase speed: the airframe's horizontal drag per
    /// m/s of airspeed over its mass, 1/s (PX4's multirotor drag coefficient,
    /// EKF2_BCOEF-like, identified from a log: the steady lean at a known speed). The
    /// swing of the drag's direction since the descent began (the pad's velocity now
    /// against its direction then, forgotten over [`DRAG_MEMORY_S`], at the speed now) is
    /// fed forward: PX4's velocity integrator holds the drag the vehicle flew with, wind
    /// and all, and lags it as a turn swings it round (8 cm behind the pad and 6 outside
    /// on paper-turn's 3 m circle). 0 = none, the default here: an airframe's own value
    /// belongs in its file (deploy/config/landing.toml sets the simulator's, 0.233;
    /// docs/fsm.md, "The drag's swing in a turn").
    ///
    /// [`DRAG_MEMORY_S`]: crate::mission::DRAG_MEMORY_S
    pub drag_per_s: f64,
    /// Horizontal error that aborts a descent or a touchdown into a climb back, m.
    pub go_around_m: f64,
    /// Go-arounds before the mission lands in place instead.
    pub max_go_arounds: u32,
    /// No pad observation for this long while tracking means the pad is lost, s.
    pub lost_after_s: f64,
    /// Lost: hold this long before climbing, s.
    pub lost_hold_s: f64,
    /// Lost: climb rate, m/s.
    pub lost_climb_m_s: f64,
    /// Lost: climb at most this much above where the pad was lost, m.
    pub lost_climb_max_m: f64,
    /// Lost: give up and land in place after this long, s.
    pub lost_timeout_s: f64,
    /// Lost: keep going with the pad's last estimated horizontal velocity this long, s:
    /// a pad on a moving vehicle is not where it was lost (0: hold where it was lost).
    pub lost_follow_s: f64,
    /// No new telemetry from a connected link this long means telemetry is lost, s: the
    /// fsm's own backstop, above the watchdog's budgets (`[watchdog.ride_through]
    /// telemetry_ms`), which judge a short outage from a lost link.
    pub telemetry_timeout_s: f64,
    /// The watchdog's view older than this (once one came) means the stack is no longer
    /// supervised: away from the pad the mission lands where it is, over it the descent
    /// goes on, s.
    pub watchdog_timeout_s: f64,
    /// Attempts per autopilot request (arm, take-off, OFFBOARD, land, disarm).
    pub request_attempts: u32,
    /// Wait between attempts, s.
    pub request_retry_s: f64,
    /// A mode change the autopilot accepted (LAND in a safe-land) is asked again only
    /// when its heartbeat has not shown the mode for this long, s: PX4 beats at 1 Hz,
    /// and px4-link answers a repeat within 2.5 s from memory.
    pub mode_timeout_s: f64,
    /// Time limit of Takeoff (arming, climbing, entering OFFBOARD), s.
    pub takeoff_timeout_s: f64,
    /// Time limit of GoToPreset, s.
    pub goto_timeout_s: f64,
    /// Time limit of WaitForPad, s.
    pub wait_timeout_s: f64,
    /// Time limit of Track, s.
    pub track_timeout_s: f64,
    /// Time limit of Descend, s.
    pub descend_timeout_s: f64,
    /// Time limit of Land (commit to disarmed), s.
    pub land_timeout_s: f64,
    /// How often the status is published without a transition, s.
    pub status_period_s: f64,
    /// How often the planner goal is re-published, s.
    pub goal_period_s: f64,
    /// The pad motion filter.
    pub pad_filter: PadFilterConfig,
    /// A mount-calibration survey over a static pad before the descent (off by default).
    pub survey: SurveyConfig,
}

/// A hover pattern over a static pad for `landing calibrate mount`: the mission's own
/// flight (a line from the preset down to the pad) shows the camera's roll and yaw on the
/// body too weakly to find them within a degree; corners of a square at two heights, the
/// vehicle yawed to either side at each, show every axis (docs/calibration.md).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SurveyConfig {
    /// Half the side of the square around the pad's centre, m; 0 (the default): no survey.
    pub half_side_m: f64,
    /// The two heights above the pad the square is flown at, m.
    pub heights_m: [f64; 2],
    /// The vehicle yaws this far from its mission heading, to the left and to the right
    /// at alternate corners, deg.
    pub yaw_deg: f64,
    /// How long to hover at each point once there, s.
    pub hold_s: f64,
    /// Within this of a point (and slower than 0.2 m/s) counts as there, m.
    pub tolerance_m: f64,
}

impl Default for SurveyConfig {
    fn default() -> Self {
        Self {
            half_side_m: 0.0,
            heights_m: [1.5, 2.5],
            yaw_deg: 40.0,
            hold_s: 2.0,
            tolerance_m: 0.15,
        }
    }
}

impl SurveyConfig {
    /// Whether a survey is flown.
    pub fn enabled(&self) -> bool {
        self.half_side_m > 0.0
    }

    /// The survey's points: (offset from the pad's centre in the world's x, y and height
    /// above the pad, m; yaw from the mission heading, rad), in flying order. Each corner
    /// is flown low then high, yawed one way then the other: the height and the heading
    /// change at every point, so the slow drift of a VIO position (a centimetre per
    /// second or so) does not line up with either and passes for no tilt.
    pub fn points(&self) -> [([f64; 3], f64); 8] {
        let a = self.half_side_m;
        let yaw = self.yaw_deg.to_radians();
        let corners = [[a, a], [-a, a], [-a, -a], [a, -a]];
        let [lo, hi] = self.heights_m;
        std::array::from_fn(|i| {
            let c = corners[i / 2];
            if i % 2 == 0 {
                ([c[0], c[1], lo], yaw)
            } else {
                ([c[0], c[1], hi], -yaw)
            }
        })
    }
}

impl Validate for SurveyConfig {
    fn validate(&self) -> Result<(), Invalid> {
        check_range("survey.half_side_m", self.half_side_m, 0.0, 5.0)?;
        for (i, h) in self.heights_m.iter().enumerate() {
            check_range(&format!("survey.heights_m[{i}]"), *h, 0.5, 20.0)?;
        }
        check_range("survey.yaw_deg", self.yaw_deg, 0.0, 90.0)?;
        check_range("survey.hold_s", self.hold_s, 0.0, 60.0)?;
        check_range("survey.tolerance_m", self.tolerance_m, 0.02, 2.0)?;
        Ok(())
    }
}

/// A command-line override of the fsm binary that cannot be taken.
#[derive(Debug, thiserror::Error)]
pub enum OverrideError {
    /// `--preset` is not three numbers.
    #[error("--preset `{0}` is not allowed (allowed: three numbers x,y,z in m)")]
    Preset(String),
    /// The overridden section does not validate.
    #[error("--preset/--commit-height/--search-height-max: fsm.{}: {}", .0.key, .0.message)]
    Invalid(Invalid),
}

impl FsmConfig {
    /// The fsm binary's overrides (`--preset x,y,z`, `--commit-height`,
    /// `--search-height-max`, which only lowers the ceiling), checked.
    pub fn with_overrides(
        mut self,
        preset: Option<&str>,
        commit_height_m: Option<f64>,
        search_height_max_m: Option<f64>,
    ) -> Result<Self, OverrideError> {
        if let Some(p) = preset {
            let v: Vec<f64> = p.split(',').filter_map(|s| s.trim().parse().ok()).collect();
            let [x, y, z] = v[..] else {
                return Err(OverrideError::Preset(p.to_string()));
            };
            self.preset_m = [x, y, z];
        }
        if let Some(h) = commit_height_m {
            self.commit_height_m = h;
        }
        if let Some(h) = search_height_max_m {
            self.lower_search_ceiling(h);
        }
        self.validate().map_err(OverrideError::Invalid)?;
        Ok(self)
    }

    /// Lowers the search ceiling to `h` (the camera's, from its calibration and the pad):
    /// the lower of the configured one and `h` holds.
    pub fn lower_search_ceiling(&mut self, h: f64) {
        self.search_height_max_m = Some(self.search_height_max_m.map_or(h, |c| c.min(h)));
    }
}

impl Default for FsmConfig {
    fn default() -> Self {
        Self {
            autostart: true,
            rate_hz: 50.0,
            preset_m: [0.0, 0.0, 2.0],
            preset_tolerance_m: 0.3,
            search_after_s: 2.0,
            search_climb_m: 1.5,
            search_height_max_m: None,
            takeoff_altitude_m: 2.0,
            takeoff_climb_m_s: 1.0,
            track_height_max_m: 3.0,
            direct_range_m: 1.5,
            approach_speed_m_s: 2.0,
            chase_speed_m_s: 2.0,
            chase_trim_gain: 0.3,
            flare_trim_gain: 0.0,
            align_m: 0.3,
            align_speed_m_s: 0.4,
            align_hold_s: 0.5,
            descend_rate_m_s: 0.4,
            commit_height_m: 0.6,
            land_align_m: 0.08,
            land_speed_gate_m_s: 0.3,
            land_rate_m_s: 0.7,
            flare_height_m: 0.25,
            flare_align_m: 0.015,
            chase_flare_align_m: 0.025,
            flare_relax_s: 4.0,
            flare_settle_m_s: 0.05,
            flare_fall_s: 0.4,
            relative_window_s: 0.25,
            drop_rate_m_s: 0.8,
            flare_accel_max_m_s2: 0.15,
            flare_quiet_s: 0.5,
            pad_accel_gain: 1.0,
            land_max_pad_age_s: 0.4,
            relative_gain: 2.0,
            chase_relative_gain: 1.0,
            drop_relative_gain: 2.0,
            relative_velocity_gain: 2.0,
            relative_velocity_from_camera: true,
            drag_per_s: 0.0,
            relative_accel_max_m_s2: 1.0,
            go_around_m: 0.4,
            max_go_arounds: 3,
            lost_after_s: 1.0,
            lost_hold_s: 1.0,
            lost_climb_m_s: 0.5,
            lost_climb_max_m: 2.0,
            lost_timeout_s: 10.0,
            lost_follow_s: 5.0,
            telemetry_timeout_s: 2.0,
            watchdog_timeout_s: 1.0,
            request_attempts: 3,
            request_retry_s: 1.0,
            mode_timeout_s: 3.0,
            takeoff_timeout_s: 30.0,
            goto_timeout_s: 90.0,
            wait_timeout_s: 120.0,
            track_timeout_s: 120.0,
            descend_timeout_s: 60.0,
            land_timeout_s: 20.0,
            status_period_s: 0.2,
            goal_period_s: 0.2,
            pad_filter: PadFilterConfig::default(),
            survey: SurveyConfig::default(),
        }
    }
}

/// The pad's constant-velocity Kalman filter.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PadFilterConfig {
    /// Position noise of an observation at the camera, m.
    pub sigma_m: f64,
    /// Added position noise per metre of camera-to-pad distance, m/m.
    pub sigma_per_m: f64,
    /// Horizontal acceleration noise of the pad vehicle (white), m/s^2.
    pub accel_noise_xy: f64,
    /// Horizontal jerk noise of the manoeuvring (constant-acceleration) model, m/s^3.
    pub jerk_noise_xy: f64,
    /// Mean time the pad vehicle cruises between manoeuvres, s (the IMM's switching).
    pub cruise_sojourn_s: f64,
    /// Mean length of a manoeuvre (a braking, a lane change), s.
    pub manoeuvre_sojourn_s: f64,
    /// Initial acceleration uncertainty, m/s^2.
    pub initial_accel_sigma: f64,
    /// Vertical acceleration noise, m/s^2.
    pub accel_noise_z: f64,
    /// Heading-rate noise (white angular acceleration), rad/s^2.
    pub yaw_accel_noise: f64,
    /// Heading noise of an observation, rad.
    pub sigma_yaw_rad: f64,
    /// Below this speed the pad's velocity is turned at its measured heading rate (a
    /// vehicle drives where it points; without it the Cartesian models trail a curve's
    /// velocity by about 2 deg), m/s; 0 (the default): never. Off, because the touchdowns
    /// were no better with it (docs/fsm.md, "Turning with the heading"). Not above the
    /// chase speed in any case: low over a fast pad the heading read swings with the
    /// vehicle's roll, and its rate times the speed would rock the vehicle.
    pub turn_with_heading_below_m_s: f64,
    /// Initial speed uncertainty, m/s (a 50 km/h vehicle: 14 m/s).
    pub initial_speed_sigma: f64,
    /// Innovation gate: normalized innovation squared above this is an outlier
    /// (16.3 = chi-square 3 dof at 99.9%).
    pub gate_chi2: f64,
    /// Consecutive outliers after which the filter restarts at the new observations.
    pub max_rejects: u32,
    /// Updates before the estimate counts as valid.
    pub min_updates: u32,
    /// Observations older than this at arrival are dropped, s.
    pub max_age_s: f64,
}

impl Default for PadFilterConfig {
    fn default() -> Self {
        Self {
            sigma_m: 0.03,
            sigma_per_m: 0.01,
            accel_noise_xy: 0.5,
            jerk_noise_xy: 1.0,
            cruise_sojourn_s: 10.0,
            manoeuvre_sojourn_s: 3.0,
            initial_accel_sigma: 1.0,
            accel_noise_z: 0.2,
            yaw_accel_noise: 0.5,
            sigma_yaw_rad: 0.03,
            turn_with_heading_below_m_s: 0.0,
            initial_speed_sigma: 14.0,
            gate_chi2: 16.3,
            max_rejects: 5,
            min_updates: 3,
            max_age_s: 0.5,
        }
    }
}

impl Validate for PadFilterConfig {
    fn validate(&self) -> Result<(), Invalid> {
        check_range("pad_filter.sigma_m", self.sigma_m, 1e-4, 1.0)?;
        check_range("pad_filter.sigma_per_m", self.sigma_per_m, 0.0, 0.5)?;
        check_range("pad_filter.accel_noise_xy", self.accel_noise_xy, 1e-3, 50.0)?;
        check_range("pad_filter.accel_noise_z", self.accel_noise_z, 1e-3, 50.0)?;
        check_range("pad_filter.jerk_noise_xy", self.jerk_noise_xy, 1e-3, 100.0)?;
        check_range(
            "pad_filter.cruise_sojourn_s",
            self.cruise_sojourn_s,
            0.1,
            1e4,
        )?;
        check_range(
            "pad_filter.manoeuvre_sojourn_s",
            self.manoeuvre_sojourn_s,
            0.1,
            1e4,
        )?;
        check_range(
            "pad_filter.initial_accel_sigma",
            self.initial_accel_sigma,
            1e-3,
            100.0,
        )?;
        check_range(
            "pad_filter.yaw_accel_noise",
            self.yaw_accel_noise,
            1e-3,
            50.0,
        )?;
        check_range("pad_filter.sigma_yaw_rad", self.sigma_yaw_rad, 1e-4, 1.0)?;
        check_range(
            "pad_filter.turn_with_heading_below_m_s",
            self.turn_with_heading_below_m_s,
            0.0,
            100.0,
        )?;
        check_range(
            "pad_filter.initial_speed_sigma",
            self.initial_speed_sigma,
            0.1,
            100.0,
        )?;
        check_range("pad_filter.gate_chi2", self.gate_chi2, 1.0, 1000.0)?;
        check_range("pad_filter.max_rejects", self.max_rejects, 1, 1000)?;
        check_range("pad_filter.min_updates", self.min_updates, 1, 100)?;
        check_range("pad_filter.max_age_s", self.max_age_s, 0.01, 10.0)?;
        Ok(())
    }
}

impl Validate for FsmConfig {
    fn validate(&self) -> Result<(), Invalid> {
        check_range("rate_hz", self.rate_hz, 20.0, 500.0)?;
        for (i, v) in self.preset_m.iter().enumerate() {
            check_range(&format!("preset_m[{i}]"), *v, -1000.0, 1000.0)?;
        }
        check_range("preset_m[2]", self.preset_m[2], 0.3, 100.0)?;
        if let Some(h) = self.search_height_max_m {
            check_range("search_height_max_m", h, 0.3, 100.0)?;
        }
        let positive = [
            ("preset_tolerance_m", self.preset_tolerance_m, 0.05, 5.0),
            ("search_after_s", self.search_after_s, 0.0, 600.0),
            ("search_climb_m", self.search_climb_m, 0.0, 50.0),
            ("takeoff_altitude_m", self.takeoff_altitude_m, 0.3, 50.0),
            ("takeoff_climb_m_s", self.takeoff_climb_m_s, 0.1, 5.0),
            ("track_height_max_m", self.track_height_max_m, 0.3, 50.0),
            ("direct_range_m", self.direct_range_m, 0.2, 20.0),
            ("approach_speed_m_s", self.approach_speed_m_s, 0.1, 30.0),
            ("chase_speed_m_s", self.chase_speed_m_s, 0.1, 100.0),
            ("chase_trim_gain", self.chase_trim_gain, 0.0, 10.0),
            ("flare_trim_gain", self.flare_trim_gain, 0.0, 10.0),
            ("align_m", self.align_m, 0.01, 5.0),
            ("align_speed_m_s", self.align_speed_m_s, 0.01, 10.0),
            ("align_hold_s", self.align_hold_s, 0.0, 10.0),
            ("descend_rate_m_s", self.descend_rate_m_s, 0.05, 3.0),
            ("commit_height_m", self.commit_height_m, 0.05, 3.0),
            ("land_align_m", self.land_align_m, 0.01, 1.0),
            ("land_speed_gate_m_s", self.land_speed_gate_m_s, 0.01, 5.0),
            ("land_rate_m_s", self.land_rate_m_s, 0.05, 3.0),
            ("go_around_m", self.go_around_m, 0.05, 5.0),
            ("flare_height_m", self.flare_height_m, 0.05, 3.0),
            ("flare_align_m", self.flare_align_m, 0.005, 1.0),
            ("chase_flare_align_m", self.chase_flare_align_m, 0.005, 1.0),
            ("flare_relax_s", self.flare_relax_s, 0.1, 60.0),
            ("flare_settle_m_s", self.flare_settle_m_s, 0.005, 5.0),
            ("flare_fall_s", self.flare_fall_s, 0.0, 2.0),
            ("relative_window_s", self.relative_window_s, 0.05, 2.0),
            ("land_max_pad_age_s", self.land_max_pad_age_s, 0.05, 5.0),
            ("drop_rate_m_s", self.drop_rate_m_s, 0.1, 3.0),
            ("flare_quiet_s", self.flare_quiet_s, 0.0, 5.0),
            (
                "flare_accel_max_m_s2",
                self.flare_accel_max_m_s2,
                0.01,
                100.0,
            ),
            ("pad_accel_gain", self.pad_accel_gain, 0.0, 1.0),
            ("drag_per_s", self.drag_per_s, 0.0, 5.0),
            ("relative_gain", self.relative_gain, 0.0, 10.0),
            ("chase_relative_gain", self.chase_relative_gain, 0.0, 10.0),
            ("drop_relative_gain", self.drop_relative_gain, 0.0, 10.0),
            (
                "relative_velocity_gain",
                self.relative_velocity_gain,
                0.0,
                10.0,
            ),
            (
                "relative_accel_max_m_s2",
                self.relative_accel_max_m_s2,
                0.0,
                5.0,
            ),
            ("lost_after_s", self.lost_after_s, 0.05, 30.0),
            ("lost_hold_s", self.lost_hold_s, 0.0, 30.0),
            ("lost_climb_m_s", self.lost_climb_m_s, 0.0, 5.0),
            ("lost_climb_max_m", self.lost_climb_max_m, 0.0, 50.0),
            ("lost_timeout_s", self.lost_timeout_s, 0.1, 600.0),
            ("lost_follow_s", self.lost_follow_s, 0.0, 60.0),
            ("telemetry_timeout_s", self.telemetry_timeout_s, 0.05, 10.0),
            ("watchdog_timeout_s", self.watchdog_timeout_s, 0.1, 60.0),
            ("request_retry_s", self.request_retry_s, 0.0, 60.0),
            ("mode_timeout_s", self.mode_timeout_s, 0.5, 60.0),
            ("takeoff_timeout_s", self.takeoff_timeout_s, 1.0, 3600.0),
            ("goto_timeout_s", self.goto_timeout_s, 1.0, 3600.0),
            ("wait_timeout_s", self.wait_timeout_s, 1.0, 3600.0),
            ("track_timeout_s", self.track_timeout_s, 1.0, 3600.0),
            ("descend_timeout_s", self.descend_timeout_s, 1.0, 3600.0),
            ("land_timeout_s", self.land_timeout_s, 1.0, 3600.0),
            ("status_period_s", self.status_period_s, 0.01, 10.0),
            ("goal_period_s", self.goal_period_s, 0.01, 10.0),
        ];
        for (key, value, lo, hi) in positive {
            check_range(key, value, lo, hi)?;
        }
        check_range("max_go_arounds", self.max_go_arounds, 0, 100)?;
        check_range("request_attempts", self.request_attempts, 1, 100)?;
        if self.land_align_m > self.go_around_m {
            return Err(Invalid::new(
                "land_align_m",
                "must not exceed go_around_m (the commit gate must be inside the abort gate)",
            ));
        }
        self.survey.validate()?;
        self.pad_filter.validate()
    }
}
