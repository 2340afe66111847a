//! Tests of `touchdown`.

use super::*;

const MS: u64 = 1_000_000;

/// A pad driving north (+y) at 1 m/s; the vehicle 0.25 m over it, 2 cm west and 3 cm
/// ahead, rolled 0.1 rad (leaning north), drops at 1.0 s and, drifting 2 cm further
/// ahead through the fall, touches down at 1.4 s. The stack's pad estimate sits 1 cm east
/// of the true pad.
fn flight() -> TouchdownSeries {
    let pad = |t: f64| [0.0, t, 0.4];
    let ahead = |t: f64| 0.03 + 0.02 * ((t - 1.0) / 0.4).clamp(0.0, 1.0);
    let vehicle = |t: f64| {
        let p = pad(t);
        let h = if t < 1.0 {
            0.25
        } else {
            0.25 - 0.625 * (t - 1.0)
        };
        [p[0] - 0.02, p[1] + ahead(t), p[2] + h]
    };
    let roll = -0.1_f64;
    let q = [(roll / 2.0).sin(), 0.0, 0.0, (roll / 2.0).cos()];
    let mut s = TouchdownSeries::default();
    for k in 0..=140 {
        let t = k as f64 / 100.0;
        let at = k * 10 * MS;
        s.truth.push((
            at,
            TruthState {
                vehicle_position: vehicle(t),
                vehicle_velocity: [0.0, 1.0, 0.0],
                pad_position: pad(t),
                pad_velocity: [0.0, 1.0, 0.0],
                pad_valid: 1,
                ..TruthState::default()
            },
        ));
        if k % 2 == 0 {
            let p = pad(t);
            let mut sp = Setpoint {
                position: [p[0] + 0.01, p[1], p[2] + 0.25],
                velocity: [0.0, 1.0, if t < 1.0 { -0.3 } else { -0.8 }],
                ..Setpoint::default()
            };
            sp.msg.capture_ns = at;
            s.setpoints.push((at, sp));
            // Measured 10 ms before it is logged, where the vehicle was then.
            let mut v = VehicleState {
                velocity: [0.0, 1.0, 0.0],
                ..VehicleState::default()
            };
            v.msg.capture_ns = at.saturating_sub(10 * MS);
            let then = vehicle((t - 0.01).max(0.0));
            v.world_from_body.translation = then;
            v.world_from_body.rotation_xyzw = q;
            s.states.push((at, v));
        }
    }
    s.events.push((
        1400 * MS,
        TruthEvent {
            kind: TruthKind::Touchdown as u32,
            on_pad: 1,
            rel_position_pad: [0.05, 0.02],
            ..TruthEvent::default()
        },
    ));
    s
}

fn close(a: [f64; 2], b: [f64; 2]) -> bool {
    (a[0] - b[0]).abs() < 1e-3 && (a[1] - b[1]).abs() < 1e-3
}

#[test]
fn a_touchdown_splits_into_the_offset_at_the_drop_what_was_read_and_the_fall() {
    let a = touchdown_anatomy(&flight(), 0.7, 0.8).expect("an anatomy");
    assert!((a.drop_lead_s - 0.4).abs() < 1e-9, "{a:?}");
    assert!((a.drop_height_m - 0.25).abs() < 1e-9, "{a:?}");
    assert!((a.pad_speed_m_s - 1.0).abs() < 1e-9, "{a:?}");
    // The road frame: x north (the pad's way), y west (its left).
    assert!(close(a.offset_at_drop_m, [0.03, 0.02]), "{a:?}");
    assert!(close(a.offset_at_contact_m, [0.05, 0.02]), "{a:?}");
    assert!(close(a.fall_drift_m, [0.02, 0.0]), "{a:?}");
    // The estimate 1 cm east of the pad reads the vehicle 1 cm further west.
    assert!(close(a.offset_read_at_drop_m, [0.03, 0.03]), "{a:?}");
    assert!(close(a.read_error_at_drop_m, [0.0, -0.01]), "{a:?}");
    assert!(close(a.rel_velocity_at_drop_m_s, [0.0, 0.0]), "{a:?}");
    let lean = G * 0.1_f64.tan();
    assert!(close(a.lean_before_drop_m_s2, [lean, 0.0]), "{a:?}");
    assert_eq!(a.touchdown_pad_m, [0.05, 0.02]);
}

#[test]
fn a_flight_without_a_touchdown_or_a_drop_is_named_for_what_it_lacks() {
    let mut s = flight();
    assert_eq!(
        touchdown_anatomy(&s, 0.8, 1.0),
        Err(AnatomyError::NoDrop(0.9)),
        "no setpoint descends faster than 0.9 m/s"
    );
    assert_eq!(
        touchdown_anatomy(&s, 0.8, 0.8),
        Err(AnatomyError::Rates {
            land: 0.8,
            drop: 0.8
        })
    );
    assert!(touchdown_anatomy(&s, 0.7, f64::NAN).is_err());
    s.events.clear();
    assert_eq!(
        touchdown_anatomy(&s, 0.7, 0.8),
        Err(AnatomyError::NoTouchdown)
    );
}

#[test]
fn a_pad_estimate_rising_does_not_hide_the_drop() {
    // The fsm rides the setpoint's descent on the pad's estimated vertical velocity: a
    // pad read rising at 0.1 m/s makes the drop's setpoints -0.7 m/s, no faster than the
    // touchdown's rate.
    let mut s = flight();
    for (t, sp) in &mut s.setpoints {
        sp.velocity[2] += 0.1;
        let mut st = FsmStatus::default();
        st.pad_velocity[2] = 0.1;
        s.statuses.push((*t, st));
    }
    let a = touchdown_anatomy(&s, 0.7, 0.8).expect("an anatomy");
    assert!((a.drop_lead_s - 0.4).abs() < 1e-9, "{a:?}");
}

/// A vehicle state at rest with attitude `q` (x, y, z, w; body FLU in world ENU).
fn attitude(q: [f64; 4]) -> VehicleState {
    let mut v = VehicleState::default();
    v.world_from_body.rotation_xyzw = q;
    v
}

#[test]
fn a_quaternion_that_is_not_finite_leans_nowhere() {
    assert_eq!(lean(&attitude([f64::NAN, 0.0, 0.0, 1.0])), None);
    assert_eq!(lean(&attitude([0.0, 0.0, 0.0, 0.0])), None);
    // Far from unit length: a writer's bug, not a pose.
    assert_eq!(lean(&attitude([0.0, 0.0, 0.0, 1.5])), None);
    // On its side: no thrust holds it up.
    let side = std::f64::consts::FRAC_PI_4;
    assert_eq!(lean(&attitude([side.sin(), 0.0, 0.0, side.cos()])), None);
    assert_eq!(lean(&attitude([0.0, 0.0, 0.0, 1.0])), Some([0.0, 0.0]));
    // Pitched nose down by 0.1 rad about body y (FLU): the up axis leans forward, +x.
    let pitch = 0.1_f64;
    let q = [0.0, (pitch / 2.0).sin(), 0.0, (pitch / 2.0).cos()];
    let l = lean(&attitude(q)).unwrap();
    assert!(
        (l[0] - G * pitch.tan()).abs() < 1e-9 && l[1].abs() < 1e-12,
        "{l:?}"
    );
    // The same pitch yawed to face north (+y): the lean turns with the heading.
    let (yaw, p) = (std::f64::consts::FRAC_PI_2, pitch / 2.0);
    let (cy, sy) = ((yaw / 2.0).cos(), (yaw / 2.0).sin());
    // q = q_yaw * q_pitch.
    let q = [-sy * p.sin(), cy * p.sin(), sy * p.cos(), cy * p.cos()];
    let l = lean(&attitude(q)).unwrap();
    assert!(
        l[0].abs() < 1e-9 && (l[1] - G * pitch.tan()).abs() < 1e-9,
        "{l:?}"
    );
}
