//! PX4 SITL's simulator API: the vehicle's sensors as PX4 reads them from a simulator
//! (HIL_SENSOR, HIL_STATE_QUATERNION) and PX4's motor outputs (HIL_ACTUATOR_CONTROLS)
//! turned into motor commands, so that real PX4 (`make px4_sitl none_iris`) flies this
//! simulator's world in place of its own autopilot.
//!
//! What PX4 v1.16 expects (`src/modules/simulation/simulator_mavlink`): HIL_SENSOR with
//! `id` 0 carries `time_usec`, which sets PX4's clock (lockstep); the IMU is specific
//! force and body rates in FRD, the magnetometer in gauss, the barometer in hPa; PX4
//! answers each step with HIL_ACTUATOR_CONTROLS, `controls[0..3]` the motors 1..4 in
//! `[0, 1]`, `mode` carrying the armed flag (128), `flags` bit 0 lockstep.
//!
//! Pure: state in, messages out. Frames: the world is ENU and the body FLU here as
//! everywhere in the simulator; NED and FRD appear only in what goes on the wire.

use mavlink::dialects::common::{
    HIL_ACTUATOR_CONTROLS_DATA, HIL_GPS_DATA, HIL_SENSOR_DATA, HIL_STATE_QUATERNION_DATA,
    HilSensorUpdatedFlags, MavModeFlag,
};
use nalgebra::{UnitQuaternion, Vector3};
use serde::Deserialize;

use crate::params::{self, ParamError};
use crate::px4::frames::{
    self, enu_to_ned as ned_from_enu, flu_to_frd as frd_from_flu, quaternion_wxyz,
};
use crate::quadrotor::{GRAVITY_M_S2, MotorCommands, VehicleState};
use crate::rng::Pcg32;

/// PX4's lockstep step: HIL_SENSOR at 250 Hz, as Gazebo and jMAVSim send it.
pub const HIL_STEP_NS: u64 = 4_000_000;

/// HIL_SENSOR's `fields_updated` for what this simulator sends every step: accel, gyro,
/// mag, absolute pressure, pressure altitude and temperature (PX4 v1.16 reads the
/// barometer only when all of 0b1101000000000 are set).
pub fn sensor_fields() -> HilSensorUpdatedFlags {
    HilSensorUpdatedFlags::HIL_SENSOR_UPDATED_XACC
        | HilSensorUpdatedFlags::HIL_SENSOR_UPDATED_YACC
        | HilSensorUpdatedFlags::HIL_SENSOR_UPDATED_ZACC
        | HilSensorUpdatedFlags::HIL_SENSOR_UPDATED_XGYRO
        | HilSensorUpdatedFlags::HIL_SENSOR_UPDATED_YGYRO
        | HilSensorUpdatedFlags::HIL_SENSOR_UPDATED_ZGYRO
        | HilSensorUpdatedFlags::HIL_SENSOR_UPDATED_XMAG
        | HilSensorUpdatedFlags::HIL_SENSOR_UPDATED_YMAG
        | HilSensorUpdatedFlags::HIL_SENSOR_UPDATED_ZMAG
        | HilSensorUpdatedFlags::HIL_SENSOR_UPDATED_ABS_PRESSURE
        | HilSensorUpdatedFlags::HIL_SENSOR_UPDATED_PRESSURE_ALT
        | HilSensorUpdatedFlags::HIL_SENSOR_UPDATED_TEMPERATURE
}

/// The vehicle's IMU, magnetometer and barometer as PX4 receives them: white noise per
/// sample, a constant bias drawn per seed (a calibrated sensor's residual), and a delay.
/// Loaded from an airframe file's `[sensors]` (these defaults when absent).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HilSensorParams {
    /// Accelerometer white noise per sample, m/s^2 (one sigma).
    pub accel_noise_m_s2: f64,
    /// Accelerometer bias, one sigma per axis, drawn per seed, m/s^2.
    pub accel_bias_m_s2: f64,
    /// Gyroscope white noise per sample, rad/s.
    pub gyro_noise_rad_s: f64,
    /// Gyroscope bias, one sigma per axis, drawn per seed, rad/s.
    pub gyro_bias_rad_s: f64,
    /// Magnetometer white noise per sample, gauss.
    pub mag_noise_gauss: f64,
    /// Barometer white noise per sample, expressed in altitude, m.
    pub baro_noise_m: f64,
    /// How old the samples are when PX4 receives them, ms (0 to 50).
    pub delay_ms: f64,
    /// The Earth's field at the flying site, NED, gauss (Zurich's by default, as PX4's
    /// SITL worlds: 21 uT north, 1.5 uT east, 43 uT down).
    pub earth_field_ned_gauss: [f64; 3],
}

impl Default for HilSensorParams {
    /// An MPU-6000-class IMU and an MS5611-class barometer, as PX4's Gazebo iris has.
    fn default() -> Self {
        Self {
            accel_noise_m_s2: 0.03,
            accel_bias_m_s2: 0.05,
            gyro_noise_rad_s: 0.003,
            gyro_bias_rad_s: 0.002,
            mag_noise_gauss: 0.002,
            baro_noise_m: 0.1,
            delay_ms: 0.0,
            earth_field_ned_gauss: [0.21, 0.015, 0.43],
        }
    }
}

impl HilSensorParams {
    /// Checks every field.
    pub fn validate(&self) -> Result<(), ParamError> {
        params::in_range("accel_noise_m_s2", self.accel_noise_m_s2, 0.0, 5.0)?;
        params::in_range("accel_bias_m_s2", self.accel_bias_m_s2, 0.0, 2.0)?;
        params::in_range("gyro_noise_rad_s", self.gyro_noise_rad_s, 0.0, 1.0)?;
        params::in_range("gyro_bias_rad_s", self.gyro_bias_rad_s, 0.0, 0.5)?;
        params::in_range("mag_noise_gauss", self.mag_noise_gauss, 0.0, 0.5)?;
        params::in_range("baro_noise_m", self.baro_noise_m, 0.0, 10.0)?;
        params::in_range("delay_ms", self.delay_ms, 0.0, 50.0)?;
        params::finite_all("earth_field_ned_gauss", &self.earth_field_ned_gauss)?;
        let strength = Vector3::from(self.earth_field_ned_gauss).norm();
        if !(0.2..=0.7).contains(&strength) {
            return Err(ParamError::new(
                "earth_field_ned_gauss",
                format!("{:?}", self.earth_field_ned_gauss),
                "the field's strength must be 0.2 to 0.7 gauss (the Earth's is 0.25-0.65)",
            ));
        }
        Ok(())
    }
}

/// The attitude PX4 means, NED from FRD, as MAVLink's `[w, x, y, z]`.
pub fn ned_from_frd(world_from_body: &UnitQuaternion<f64>) -> [f32; 4] {
    quaternion_wxyz(&frames::ned_from_frd(world_from_body))
}

/// Pressure of the International Standard Atmosphere at `altitude_m` above mean sea
/// level, hPa (what PX4's SITL simulators send).
pub fn isa_pressure_hpa(altitude_m: f64) -> f64 {
    1013.25 * (1.0 - 2.255_77e-5 * altitude_m).powf(5.255_88)
}

/// Temperature of the standard atmosphere at `altitude_m`, deg C.
fn isa_temperature_c(altitude_m: f64) -> f64 {
    15.0 - 0.0065 * altitude_m
}

/// Motor commands from PX4's HIL_ACTUATOR_CONTROLS: motors 1..4 are `controls[0..3]` in
/// `[0, 1]` (PX4's order is this simulator's [`crate::quadrotor::QUAD_X_MOTORS`]), run
/// when the armed flag is set; anything not a number stops that motor.
pub fn motors_from_controls(msg: &HIL_ACTUATOR_CONTROLS_DATA) -> MotorCommands {
    let mut thrust = [0.0; 4];
    for (t, c) in thrust.iter_mut().zip(msg.controls.iter()) {
        let c = f64::from(*c);
        *t = if c.is_finite() {
            c.clamp(0.0, 1.0)
        } else {
            0.0
        };
    }
    MotorCommands {
        armed: msg.mode.contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED),
        thrust,
    }
}

/// The sensors PX4 reads, built from the vehicle's true motion each lockstep step.
#[derive(Debug, Clone)]
pub struct HilSensors {
    params: HilSensorParams,
    home_amsl_m: f64,
    rng: Pcg32,
    accel_bias: Vector3<f64>,
    gyro_bias: Vector3<f64>,
    /// Velocity at the previous sample (the acceleration is its difference).
    previous: Option<(u64, Vector3<f64>)>,
    /// Samples taken, waiting for the delay.
    held: std::collections::VecDeque<(u64, HIL_SENSOR_DATA)>,
}

impl HilSensors {
    /// Sensors with `params`, their biases drawn from `seed`, at a site whose ground is
    /// `home_amsl_m` above mean sea level (the world's z = 0).
    pub fn new(params: HilSensorParams, home_amsl_m: f64, seed: u64) -> Self {
        let mut rng = Pcg32::with_stream(seed, 53);
        let mut draw = |sigma: f64| Vector3::new(rng.normal(), rng.normal(), rng.normal()) * sigma;
        let accel_bias = draw(params.accel_bias_m_s2);
        let gyro_bias = draw(params.gyro_bias_rad_s);
        Self {
            params,
            home_amsl_m,
            rng: Pcg32::with_stream(seed, 59),
            accel_bias,
            gyro_bias,
            previous: None,
            held: std::collections::VecDeque::new(),
        }
    }

    /// Samples the sensors on `truth` at simulated time `now_ns` and returns the sample
    /// due now (the delay's worth older; the first ones until the delay has passed are
    /// the earliest sample), stamped `now_ns` as PX4's clock must be.
    pub fn sample(&mut self, truth: &VehicleState, now_ns: u64) -> HIL_SENSOR_DATA {
        let accel_world = match self.previous {
            Some((t, v)) if now_ns > t => (truth.velocity - v) / ((now_ns - t) as f64 * 1e-9),
            _ => Vector3::zeros(),
        };
        self.previous = Some((now_ns, truth.velocity));
        let body_from_world = truth.world_from_body.inverse();
        // Specific force: what an accelerometer feels, acceleration minus gravity.
        let specific_world = accel_world + Vector3::new(0.0, 0.0, GRAVITY_M_S2);
        let p = &self.params;
        let mut noise = |sigma: f64| {
            Vector3::new(self.rng.normal(), self.rng.normal(), self.rng.normal()) * sigma
        };
        let accel = frd_from_flu(&(body_from_world * specific_world))
            + self.accel_bias
            + noise(p.accel_noise_m_s2);
        let gyro = frd_from_flu(&truth.body_rates) + self.gyro_bias + noise(p.gyro_noise_rad_s);
        // The field in FRD: NED -> ENU -> FLU -> FRD.
        let field_enu = frames::ned_to_enu(&Vector3::from(p.earth_field_ned_gauss));
        let mag = frd_from_flu(&(body_from_world * field_enu)) + noise(p.mag_noise_gauss);
        let altitude = self.home_amsl_m + truth.position.z + p.baro_noise_m * self.rng.normal();
        let sample = HIL_SENSOR_DATA {
            time_usec: now_ns / 1000,
            xacc: accel.x as f32,
            yacc: accel.y as f32,
            zacc: accel.z as f32,
            xgyro: gyro.x as f32,
            ygyro: gyro.y as f32,
            zgyro: gyro.z as f32,
            xmag: mag.x as f32,
            ymag: mag.y as f32,
            zmag: mag.z as f32,
            abs_pressure: isa_pressure_hpa(altitude) as f32,
            diff_pressure: 0.0,
            pressure_alt: altitude as f32,
            temperature: isa_temperature_c(altitude) as f32,
            fields_updated: sensor_fields(),
            id: 0,
        };
        let delay_ns = (self.params.delay_ms * 1e6) as u64;
        self.held.push_back((now_ns + delay_ns, sample));
        // The newest sample that is due (the oldest one until the first is).
        while self.held.get(1).is_some_and(|(t, _)| *t <= now_ns) {
            self.held.pop_front();
        }
        // Never empty here: the sample just taken is in it.
        let mut due = self
            .held
            .front()
            .map_or_else(HIL_SENSOR_DATA::default, |(_, s)| s.clone());
        due.time_usec = now_ns / 1000;
        due
    }
}

/// The ground truth PX4 may log beside its estimate (HIL_STATE_QUATERNION), at a site
/// `home_amsl_m` above mean sea level; latitude and longitude are left 0 (PX4 SITL only
/// logs this message; a scenario's `[gps]` fix goes in HIL_GPS).
pub fn state_quaternion(
    truth: &VehicleState,
    accel_world: &Vector3<f64>,
    home_amsl_m: f64,
    now_ns: u64,
) -> HIL_STATE_QUATERNION_DATA {
    let rates = frd_from_flu(&truth.body_rates);
    let v = ned_from_enu(&truth.velocity) * 100.0;
    let g = ned_from_enu(accel_world) / GRAVITY_M_S2 * 1000.0;
    let cm = |x: f64| x.round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16;
    HIL_STATE_QUATERNION_DATA {
        time_usec: now_ns / 1000,
        attitude_quaternion: ned_from_frd(&truth.world_from_body),
        rollspeed: rates.x as f32,
        pitchspeed: rates.y as f32,
        yawspeed: rates.z as f32,
        lat: 0,
        lon: 0,
        alt: ((home_amsl_m + truth.position.z) * 1000.0).round() as i32,
        vx: cm(v.x),
        vy: cm(v.y),
        vz: cm(v.z),
        ind_airspeed: 0,
        true_airspeed: 0,
        xacc: cm(g.x),
        yacc: cm(g.y),
        zacc: cm(g.z),
    }
}

/// A GPS receiver, for a scenario flown with one (`[gps]`; none by default: the missions
/// are GPS-denied, and PX4 then gets no HIL_GPS at all).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GpsParams {
    /// Fixes per second (0: no GPS; PX4's simulated receivers give 10).
    pub rate_hz: f64,
    /// White noise on each horizontal axis, m (one sigma; also the `eph` sent).
    pub horizontal_std_m: f64,
    /// White noise on the altitude, m (also the `epv` sent).
    pub vertical_std_m: f64,
    /// White noise on each velocity axis, m/s.
    pub velocity_std_m_s: f64,
    /// Where the world's origin is, latitude and longitude, deg (PX4 SITL's default home,
    /// Zurich).
    pub origin_deg: [f64; 2],
}

impl Default for GpsParams {
    fn default() -> Self {
        Self {
            rate_hz: 0.0,
            horizontal_std_m: 0.5,
            vertical_std_m: 0.8,
            velocity_std_m_s: 0.1,
            origin_deg: [47.397_742, 8.545_594],
        }
    }
}

impl GpsParams {
    /// Checks every field.
    pub fn validate(&self) -> Result<(), ParamError> {
        params::in_range("gps.rate_hz", self.rate_hz, 0.0, 50.0)?;
        params::in_range("gps.horizontal_std_m", self.horizontal_std_m, 0.01, 50.0)?;
        params::in_range("gps.vertical_std_m", self.vertical_std_m, 0.01, 50.0)?;
        params::in_range("gps.velocity_std_m_s", self.velocity_std_m_s, 0.0, 5.0)?;
        params::in_range("gps.origin_deg[0]", self.origin_deg[0], -85.0, 85.0)?;
        params::in_range("gps.origin_deg[1]", self.origin_deg[1], -180.0, 180.0)
    }
}

/// A GPS fix of `truth` at `now_ns` (HIL_GPS: degE7, mm AMSL, cm/s NED, 3-D fix), from a
/// receiver with `p` at a site whose ground is `home_amsl_m` above mean sea level;
/// `noise` draws standard normals.
pub fn gps_fix(
    truth: &VehicleState,
    p: &GpsParams,
    home_amsl_m: f64,
    now_ns: u64,
    noise: &mut dyn FnMut() -> f64,
) -> HIL_GPS_DATA {
    /// WGS-84 equatorial radius, m (a flat Earth at the site is enough for a flight).
    const EARTH_RADIUS_M: f64 = 6_378_137.0;
    let east = truth.position.x + p.horizontal_std_m * noise();
    let north = truth.position.y + p.horizontal_std_m * noise();
    let up = truth.position.z + p.vertical_std_m * noise();
    let [lat0, lon0] = p.origin_deg;
    let lat = lat0 + (north / EARTH_RADIUS_M).to_degrees();
    let lon = lon0 + (east / (EARTH_RADIUS_M * lat0.to_radians().cos())).to_degrees();
    let v = ned_from_enu(&truth.velocity)
        + Vector3::new(noise(), noise(), noise()) * p.velocity_std_m_s;
    let cm_s = |x: f64| (x * 100.0).round().clamp(-32_767.0, 32_767.0) as i16;
    let ground_speed = v.xy().norm();
    let cog = v.y.atan2(v.x).to_degrees().rem_euclid(360.0);
    let cm = |x: f64| (x * 100.0).round().clamp(0.0, 65_534.0) as u16;
    HIL_GPS_DATA {
        time_usec: now_ns / 1000,
        lat: (lat * 1e7).round() as i32,
        lon: (lon * 1e7).round() as i32,
        alt: ((home_amsl_m + up) * 1000.0).round() as i32,
        eph: cm(p.horizontal_std_m),
        epv: cm(p.vertical_std_m),
        vel: cm(ground_speed),
        vn: cm_s(v.x),
        ve: cm_s(v.y),
        vd: cm_s(v.z),
        cog: (cog * 100.0).round().min(35_999.0) as u16,
        fix_type: 3,
        satellites_visible: 12,
        id: 0,
        yaw: 0,
    }
}

/// PX4's side of the lockstep as the simulator keeps it: it runs free until PX4's first
/// actuator message (PX4 boots on the simulator's clock and answers only once its
/// mixer runs), then one step per answer, as Gazebo's `mavlink_interface` does.
#[derive(Debug, Clone, Default)]
pub struct Lockstep {
    /// PX4 has answered at least once: from now on each step waits for an answer.
    started: bool,
    /// A HIL_SENSOR is out and not yet answered.
    waiting: bool,
    /// The motors as PX4 last commanded them.
    motors: MotorCommands,
    answers: u64,
}

impl Lockstep {
    /// Whether the next step may run: not while PX4 owes an answer.
    pub fn may_step(&self) -> bool {
        !(self.started && self.waiting)
    }

    /// A HIL_SENSOR went out.
    pub fn sent(&mut self) {
        self.waiting = true;
    }

    /// PX4 answered with its motor outputs.
    pub fn answered(&mut self, msg: &HIL_ACTUATOR_CONTROLS_DATA) {
        self.started = true;
        self.waiting = false;
        self.motors = motors_from_controls(msg);
        self.answers += 1;
    }

    /// The motors PX4 commands now (off before its first answer).
    pub fn motors(&self) -> &MotorCommands {
        &self.motors
    }

    /// Answers received.
    pub fn answers(&self) -> u64 {
        self.answers
    }
}

#[cfg(test)]
#[path = "hil_test.rs"]
mod tests;
