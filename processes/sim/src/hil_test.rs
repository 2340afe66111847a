use super::*;

fn quiet() -> HilSensorParams {
    HilSensorParams {
        accel_noise_m_s2: 0.0,
        accel_bias_m_s2: 0.0,
        gyro_noise_rad_s: 0.0,
        gyro_bias_rad_s: 0.0,
        mag_noise_gauss: 0.0,
        baro_noise_m: 0.0,
        ..HilSensorParams::default()
    }
}

fn at_rest(yaw_rad: f64) -> VehicleState {
    VehicleState::at_rest(Vector3::zeros(), yaw_rad)
}

#[test]
fn a_vehicle_at_rest_feels_minus_one_g_on_its_frd_z_axis() {
    let mut s = HilSensors::new(quiet(), 488.0, 1);
    s.sample(&at_rest(0.3), 0);
    let m = s.sample(&at_rest(0.3), HIL_STEP_NS);
    assert!((f64::from(m.zacc) + GRAVITY_M_S2).abs() < 1e-4, "{m:?}");
    assert!(m.xacc.abs() < 1e-4 && m.yacc.abs() < 1e-4, "{m:?}");
    assert!(m.xgyro.abs() < 1e-9 && m.zgyro.abs() < 1e-9);
    assert_eq!(m.time_usec, 4000);
    assert_eq!(m.id, 0);
    assert_eq!(m.fields_updated.bits() & 0b111_111_111, 0b111_111_111);
    assert_eq!(
        m.fields_updated.bits() & 0b1_1010_0000_0000,
        0b1_1010_0000_0000
    );
}

#[test]
fn the_barometer_reads_the_standard_atmosphere_at_the_site_altitude() {
    let mut s = HilSensors::new(quiet(), 488.0, 1);
    let m = s.sample(&at_rest(0.0), 0);
    // ISA at 488 m: 956.0 hPa.
    assert!(
        (f64::from(m.abs_pressure) - 956.0).abs() < 0.1,
        "{}",
        m.abs_pressure
    );
    assert!((f64::from(m.pressure_alt) - 488.0).abs() < 1e-3);
    let mut up = at_rest(0.0);
    up.position.z = 10.0;
    let m10 = s.sample(&up, HIL_STEP_NS);
    // About 1.13 hPa less 10 m higher.
    let drop = f64::from(m.abs_pressure - m10.abs_pressure);
    assert!((drop - 1.13).abs() < 0.05, "{drop}");
}

#[test]
fn a_vehicle_facing_north_sees_the_field_ahead_and_down() {
    let mut s = HilSensors::new(quiet(), 0.0, 1);
    // ENU yaw 90 deg: nose north.
    let m = s.sample(&at_rest(std::f64::consts::FRAC_PI_2), 0);
    assert!((f64::from(m.xmag) - 0.21).abs() < 1e-6, "{m:?}");
    // East is to the right of a north-facing nose: +y in FRD.
    assert!((f64::from(m.ymag) - 0.015).abs() < 1e-6, "{m:?}");
    assert!((f64::from(m.zmag) - 0.43).abs() < 1e-6, "{m:?}");
}

#[test]
fn a_yaw_rate_to_the_left_is_a_negative_frd_z_rate() {
    let mut s = HilSensors::new(quiet(), 0.0, 1);
    let mut v = at_rest(0.0);
    v.body_rates = Vector3::new(0.1, 0.2, 0.5);
    let m = s.sample(&v, 0);
    assert!((m.xgyro - 0.1).abs() < 1e-6 && (m.ygyro + 0.2).abs() < 1e-6);
    assert!((m.zgyro + 0.5).abs() < 1e-6);
}

#[test]
fn the_attitude_px4_reads_is_ned_from_frd() {
    // Nose east (ENU yaw 0) is NED yaw +90 deg.
    let q = ned_from_frd(&UnitQuaternion::identity());
    let h = std::f32::consts::FRAC_1_SQRT_2;
    assert!((q[0] - h).abs() < 1e-6 && (q[3] - h).abs() < 1e-6, "{q:?}");
    // Nose north is NED yaw 0.
    let q = ned_from_frd(&UnitQuaternion::from_euler_angles(
        0.0,
        0.0,
        std::f64::consts::FRAC_PI_2,
    ));
    assert!((q[0] - 1.0).abs() < 1e-6, "{q:?}");
}

#[test]
fn samples_arrive_after_the_configured_delay() {
    let params = HilSensorParams {
        delay_ms: 8.0,
        ..quiet()
    };
    let mut s = HilSensors::new(params, 0.0, 1);
    let mut v = at_rest(0.0);
    let mut readings = Vec::new();
    for k in 0..6u64 {
        v.position.z = k as f64;
        readings.push(s.sample(&v, k * HIL_STEP_NS).pressure_alt);
    }
    // Two steps (8 ms) late, stamped now.
    assert_eq!(readings, vec![0.0, 0.0, 0.0, 1.0, 2.0, 3.0]);
}

#[test]
fn biases_are_drawn_per_seed_and_noise_changes_every_sample() {
    let mut a = HilSensors::new(HilSensorParams::default(), 0.0, 1);
    let mut b = HilSensors::new(HilSensorParams::default(), 0.0, 2);
    let (a1, a2) = (
        a.sample(&at_rest(0.0), 0),
        a.sample(&at_rest(0.0), HIL_STEP_NS),
    );
    let b1 = b.sample(&at_rest(0.0), 0);
    assert_ne!(a1.xgyro, a2.xgyro);
    assert_ne!(a1.xgyro, b1.xgyro);
    for m in [a1, a2, b1] {
        assert!((f64::from(m.zacc) + GRAVITY_M_S2).abs() < 0.5, "{m:?}");
    }
}

#[test]
fn px4_controls_drive_the_motors_only_when_armed() {
    let mut msg = HIL_ACTUATOR_CONTROLS_DATA {
        controls: [0.0; 16],
        mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
        ..Default::default()
    };
    msg.controls[..4].copy_from_slice(&[0.5, 1.5, -0.2, f32::NAN]);
    let off = motors_from_controls(&msg);
    assert!(!off.armed);
    msg.mode =
        MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED | MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED;
    let on = motors_from_controls(&msg);
    assert!(on.armed);
    assert_eq!(on.thrust, [0.5, 1.0, 0.0, 0.0]);
}

#[test]
fn lockstep_runs_free_until_px4_first_answers_then_waits_for_each_answer() {
    let mut l = Lockstep::default();
    l.sent();
    assert!(
        l.may_step(),
        "before PX4's first answer the simulator runs free"
    );
    l.answered(&HIL_ACTUATOR_CONTROLS_DATA::default());
    assert!(l.may_step());
    l.sent();
    assert!(!l.may_step(), "a step waits for PX4's answer");
    l.answered(&HIL_ACTUATOR_CONTROLS_DATA::default());
    assert!(l.may_step());
    assert_eq!(l.answers(), 2);
}

#[test]
fn sensor_parameters_out_of_range_are_refused_with_the_field_named() {
    let bad = HilSensorParams {
        delay_ms: 80.0,
        ..HilSensorParams::default()
    };
    assert!(bad.validate().unwrap_err().to_string().contains("delay_ms"));
    let weak = HilSensorParams {
        earth_field_ned_gauss: [0.0, 0.0, 0.01],
        ..HilSensorParams::default()
    };
    assert!(
        weak.validate()
            .unwrap_err()
            .to_string()
            .contains("earth_field")
    );
    assert!(HilSensorParams::default().validate().is_ok());
}

#[test]
fn a_gps_fix_is_in_degrees_e7_millimetres_and_cm_s_ned() {
    let p = GpsParams {
        rate_hz: 10.0,
        ..GpsParams::default()
    };
    let mut v = at_rest(0.0);
    // 100 m north, 50 m east, 10 m up, flying north-east at 1 m/s each way.
    v.position = Vector3::new(50.0, 100.0, 10.0);
    v.velocity = Vector3::new(1.0, 1.0, 0.0);
    let fix = gps_fix(&v, &p, 488.0, 2_000_000_000, &mut || 0.0);
    let dlat = (f64::from(fix.lat) * 1e-7 - p.origin_deg[0]).to_radians() * 6_378_137.0;
    assert!((dlat - 100.0).abs() < 0.02, "{dlat}");
    assert!(fix.lon > (p.origin_deg[1] * 1e7) as i32);
    assert_eq!(fix.alt, 498_000);
    assert_eq!((fix.vn, fix.ve, fix.vd), (100, 100, 0));
    assert_eq!(fix.cog, 4500);
    assert_eq!(fix.fix_type, 3);
    assert_eq!(fix.time_usec, 2_000_000);
    assert!(GpsParams::default().validate().is_ok());
    let bad = GpsParams {
        rate_hz: -1.0,
        ..GpsParams::default()
    };
    assert!(
        bad.validate()
            .unwrap_err()
            .to_string()
            .contains("gps.rate_hz")
    );
}
