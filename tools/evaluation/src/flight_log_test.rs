//! Tests of `flight_log`.

use super::*;

/// Samples every `dt` s of a piecewise-linear flight: 1 s on the ground, 2 s climbing to
/// 2 m, 2 s flying +4 m along x, 2 s descending to touch down at t = 7 s, then 1 s riding
/// on the pad. The pad vehicle stands for 1 s, then drives +x at 1 m/s.
pub(crate) fn synthetic_log(dt: f64) -> FlightLog {
    let mut samples = Vec::new();
    let n = (8.0 / dt).round() as usize;
    for i in 0..=n {
        let t = i as f64 * dt;
        let (uav, vel, phase) = if t <= 1.0 {
            ([0.0, 0.0, 0.0], [0.0; 3], "Idle")
        } else if t <= 3.0 {
            ([0.0, 0.0, t - 1.0], [0.0, 0.0, 1.0], "Takeoff")
        } else if t <= 5.0 {
            ([2.0 * (t - 3.0), 0.0, 2.0], [2.0, 0.0, 0.0], "Track")
        } else if t <= 7.0 {
            ([4.0, 0.0, 2.0 - (t - 5.0)], [0.0, 0.0, -1.0], "Descend")
        } else {
            ([4.0 + (t - 7.0), 0.0, 0.0], [1.0, 0.0, 0.0], "Landed")
        };
        let pad_x = (t - 1.0).max(0.0) - 2.0;
        let ugv_v = if t < 1.0 { 0.0 } else { 1.0 };
        samples.push(FlightSample {
            t_s: t,
            uav,
            ugv_pad: Some([pad_x, 0.5, 0.0]),
            phase: phase.to_string(),
            uav_velocity: vel,
            ugv_velocity: Some([ugv_v, 0.0, 0.0]),
        });
    }
    FlightLog {
        scenario: "synthetic".to_string(),
        seed: 7,
        samples,
        obstacles: vec![([1.0, 1.0, 0.0], [1.6, 2.2, 1.2])],
        contact: None,
        touchdown: Some(Touchdown {
            t_s: 7.0,
            uav: [4.0, 0.0, 0.0],
            pad: [4.0, 0.5, 0.0],
            error_m: 0.5,
            rel_speed_mps: 0.3,
            on_pad: true,
        }),
    }
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-9
}

#[test]
fn distance_and_flight_time_run_from_take_off_to_touchdown() {
    let log = synthetic_log(0.25);
    let s = RunSummary::from_log(&log, Outcome::Landed, &[], 0, None);
    assert!(close(s.distance_m, 8.0), "{}", s.distance_m);
    assert!(close(s.flight_time_s, 6.0), "{}", s.flight_time_s);
    assert!(close(s.uav_avg_speed_kmh, 8.0 / 6.0 * 3.6));
    assert!(close(s.uav_max_speed_kmh, 2.0 * 3.6));
    assert_eq!(s.touchdown_error_m, Some(0.5));
    assert_eq!(s.touchdown_rel_speed_mps, Some(0.3));
}

#[test]
fn target_speed_averages_only_while_the_pad_vehicle_moves() {
    let log = synthetic_log(0.25);
    let s = RunSummary::from_log(&log, Outcome::Landed, &[], 0, None);
    assert_eq!(
        s.target_speed_kmh.map(|v| (v * 1e6).round() / 1e6),
        Some(3.6)
    );
}

#[test]
fn target_speed_falls_back_to_pad_positions_without_velocities() {
    let mut log = synthetic_log(0.25);
    for s in &mut log.samples {
        s.ugv_velocity = None;
    }
    let v = log.target_speed_mps().unwrap_or(-1.0);
    assert!((v - 1.0).abs() < 1e-9, "{v}");
}

#[test]
fn a_scenario_without_pad_vehicle_has_no_target_speed() {
    let mut log = synthetic_log(0.25);
    for s in &mut log.samples {
        s.ugv_pad = None;
        s.ugv_velocity = None;
    }
    assert_eq!(log.target_speed_mps(), None);
}

#[test]
fn planning_times_give_median_and_maximum() {
    let log = synthetic_log(0.25);
    let s = RunSummary::from_log(
        &log,
        Outcome::Landed,
        &[4.0, 1.0, f64::NAN, 3.0, 100.0, 2.0],
        4,
        Some(0),
    );
    assert_eq!(s.planning_time_ms_p50, Some(3.0));
    assert_eq!(s.planning_time_ms_max, Some(100.0));
    assert_eq!(s.replans, 4);
}

#[test]
fn json_has_exactly_the_agreed_fields_and_null_where_not_applicable() {
    let mut log = synthetic_log(0.5);
    log.touchdown = None;
    let s = RunSummary::from_log(&log, Outcome::Timeout, &[], 0, None);
    let v = serde_json::to_value(&s).unwrap_or_default();
    let obj = v.as_object().cloned().unwrap_or_default();
    let mut keys: Vec<&str> = obj.keys().map(String::as_str).collect();
    keys.sort_unstable();
    let mut want = vec![
        "scenario",
        "seed",
        "outcome",
        "touchdown_error_m",
        "touchdown_rel_speed_mps",
        "touchdown_vertical_speed_mps",
        "touchdown_horizontal_speed_mps",
        "touchdown_tilt_deg",
        "referee",
        "flight_time_s",
        "distance_m",
        "target_speed_kmh",
        "uav_max_speed_kmh",
        "uav_avg_speed_kmh",
        "planning_time_ms_p50",
        "planning_time_ms_max",
        "replans",
        "collisions",
        "faults",
    ];
    want.sort_unstable();
    assert_eq!(keys, want);
    assert_eq!(obj["outcome"], "timeout");
    assert!(obj["touchdown_error_m"].is_null());
    assert!(obj["collisions"].is_null());
    assert_eq!(
        obj["faults"],
        serde_json::json!([]),
        "no fault: an empty list"
    );
    assert!(obj["planning_time_ms_p50"].is_null());
    // Without a touchdown the flight runs to the end of the log.
    assert!(close(s.flight_time_s, 7.0), "{}", s.flight_time_s);
}

#[test]
fn outcomes_are_named_in_snake_case() {
    for (o, name) in [
        (Outcome::Landed, "landed"),
        (Outcome::SafeLanded, "safe_landed"),
        (Outcome::Crashed, "crashed"),
        (Outcome::Timeout, "timeout"),
        (Outcome::Interrupted, "interrupted"),
        (Outcome::ProcessDied, "process_died"),
    ] {
        assert_eq!(
            serde_json::to_value(o).unwrap_or_default(),
            serde_json::Value::from(name)
        );
        assert_eq!(o.to_string(), name);
    }
}

#[test]
fn a_vehicle_that_never_takes_off_flew_nothing() {
    let mut log = synthetic_log(0.5);
    for s in &mut log.samples {
        s.uav = [0.0; 3];
    }
    log.touchdown = None;
    let s = RunSummary::from_log(&log, Outcome::Timeout, &[], 0, None);
    assert_eq!(s.distance_m, 0.0);
    assert_eq!(s.flight_time_s, 0.0);
    assert_eq!(s.uav_avg_speed_kmh, 0.0);
}

#[test]
fn the_terminal_summary_names_outcome_error_and_speeds() {
    let log = synthetic_log(0.25);
    let s = RunSummary::from_log(&log, Outcome::Landed, &[2.4], 5, Some(0));
    let text = s.to_string();
    assert!(text.contains("synthetic (seed 7)"), "{text}");
    assert!(text.contains("LANDED"), "{text}");
    assert!(text.contains("error 0.500 m"), "{text}");
    assert!(text.contains("max 7.2 km/h"), "{text}");
    assert!(text.contains("target 3.6 km/h"), "{text}");
    assert!(text.contains("5 replans"), "{text}");
    assert!(text.contains("collisions  0"), "{text}");
    assert!(text.lines().count() >= 6, "{text}");
}
