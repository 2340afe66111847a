//! Tests of `land_detector`.

use super::*;

const MS: u64 = 1_000_000;
const STEP_NS: u64 = 2 * MS;

fn params() -> AutopilotParams {
    AutopilotParams::default()
}

/// Armed, still, level, at `throttle`, with a velocity setpoint `vz_sp` (ENU).
fn input(throttle: f64, vz_sp: Option<f64>) -> LandDetectorInput {
    LandDetectorInput {
        armed: true,
        velocity: Vector3::zeros(),
        body_rates: Vector3::zeros(),
        acceleration: Some(Vector3::zeros()),
        throttle,
        velocity_setpoint_z: vz_sp,
        hover_thrust_estimate: None,
    }
}

fn in_air() -> LandDetector {
    let mut d = LandDetector::new(&params());
    d.force(true);
    d
}

/// Runs `input` from `from_ns` for `ns`; returns the first time each stage was true.
fn run(d: &mut LandDetector, from_ns: u64, ns: u64, input: &LandDetectorInput) -> [Option<u64>; 3] {
    let p = params();
    let mut first = [None; 3];
    let mut t = from_ns;
    while t <= from_ns + ns {
        let out = d.update(t, &p, input);
        for (i, on) in [out.ground_contact, out.maybe_landed, out.landed]
            .into_iter()
            .enumerate()
        {
            if on && first[i].is_none() {
                first[i] = Some(t - from_ns);
            }
        }
        t += STEP_NS;
    }
    first
}

#[test]
fn it_boots_landed_and_a_disarmed_vehicle_stays_landed() {
    let p = params();
    let mut d = LandDetector::new(&p);
    assert!(d.output().landed && d.output().ground_contact);
    let disarmed = LandDetectorInput {
        armed: false,
        velocity: Vector3::new(3.0, 0.0, -2.0),
        ..input(0.9, None)
    };
    let first = run(&mut d, 0, 2000 * MS, &disarmed);
    assert_eq!(first, [Some(0); 3], "never leaves landed while disarmed");
}

#[test]
fn minimum_thrust_a_commanded_descent_and_no_motion_land_in_three_thirds_of_lndmc_trig_time() {
    let mut d = in_air();
    // MPC_THR_MIN (what the position controller commands once in ground contact).
    let first = run(&mut d, 0, 1500 * MS, &input(0.12, Some(-0.7)));
    let third = 333 * MS;
    let [contact, maybe, landed] = first.map(|t| t.expect("reached"));
    assert!(contact.abs_diff(third) <= STEP_NS, "{contact}");
    assert!(maybe.abs_diff(2 * third) <= 2 * STEP_NS, "{maybe}");
    assert!(landed.abs_diff(3 * third) <= 3 * STEP_NS, "{landed}");
}

#[test]
fn thrust_above_the_low_throttle_share_of_hover_is_no_ground_contact() {
    let p = params();
    // 30 % of the way from MPC_THR_MIN to MPC_THR_HOVER without a valid estimate.
    let low = p.mpc_thr_min + 0.3 * (p.mpc_thr_hover - p.mpc_thr_min);
    let mut d = in_air();
    assert_eq!(
        run(&mut d, 0, 3000 * MS, &input(low + 0.01, Some(-0.7))),
        [None; 3]
    );
    // With a valid hover thrust estimate the share is 60 %.
    let mut d = in_air();
    let with_hte = LandDetectorInput {
        hover_thrust_estimate: Some(p.mpc_thr_hover),
        ..input(low + 0.01, Some(-0.7))
    };
    let [contact, maybe, landed] = run(&mut d, 0, 3000 * MS, &with_hte);
    assert!(contact.is_some(), "ground contact at 60 %");
    assert_eq!((maybe, landed), (None, None), "maybe landed needs 10 %");
}

#[test]
fn without_a_commanded_descent_low_thrust_in_flight_is_no_ground_contact() {
    let mut d = in_air();
    assert_eq!(run(&mut d, 0, 3000 * MS, &input(0.12, None)), [None; 3]);
    let mut d = in_air();
    // A slow descent setpoint (below 1.1 LNDMC_Z_VEL_MAX) is no descent either.
    assert_eq!(
        run(&mut d, 0, 3000 * MS, &input(0.12, Some(-0.25))),
        [None; 3]
    );
}

#[test]
fn vertical_speed_above_lndmc_z_vel_max_is_no_ground_contact() {
    let mut d = in_air();
    let descending = LandDetectorInput {
        velocity: Vector3::new(0.0, 0.0, -0.3),
        ..input(0.12, Some(-0.7))
    };
    assert_eq!(run(&mut d, 0, 3000 * MS, &descending), [None; 3]);
}

#[test]
fn horizontal_speed_above_lndmc_xy_vel_max_is_never_landed_as_on_a_fast_pad() {
    let mut d = in_air();
    let on_a_pad_at_2_m_s = LandDetectorInput {
        velocity: Vector3::new(2.0, 0.0, 0.0),
        ..input(0.12, Some(-0.7))
    };
    assert_eq!(run(&mut d, 0, 5000 * MS, &on_a_pad_at_2_m_s), [None; 3]);
    let mut d = in_air();
    let on_a_pad_at_1_4_m_s = LandDetectorInput {
        velocity: Vector3::new(1.0, 1.0, 0.0),
        ..input(0.12, Some(-0.7))
    };
    assert!(run(&mut d, 0, 5000 * MS, &on_a_pad_at_1_4_m_s)[2].is_some());
}

#[test]
fn rotation_or_a_free_fall_holds_off_maybe_landed() {
    let p = params();
    let mut d = in_air();
    let rolling = LandDetectorInput {
        body_rates: Vector3::new((p.lndmc_rot_max + 5.0).to_radians(), 0.0, 0.0),
        ..input(0.12, Some(-0.7))
    };
    let [contact, maybe, _] = run(&mut d, 0, 3000 * MS, &rolling);
    assert!(contact.is_some() && maybe.is_none());
    let mut d = in_air();
    let falling = LandDetectorInput {
        acceleration: Some(Vector3::new(0.0, 0.0, -9.0)),
        ..input(0.12, Some(-0.7))
    };
    let [contact, maybe, _] = run(&mut d, 0, 3000 * MS, &falling);
    assert!(contact.is_some() && maybe.is_none());
}

#[test]
fn landed_ends_at_once_when_the_thrust_rises_for_a_take_off() {
    let p = params();
    let mut d = LandDetector::new(&p);
    let idle = input(0.0, None);
    run(&mut d, 0, 500 * MS, &idle);
    assert!(
        d.output().landed,
        "on the ground at idle, no descent needed once landed"
    );
    let out = d.update(502 * MS, &p, &input(0.5, Some(1.0)));
    assert!(!out.landed && !out.maybe_landed && !out.ground_contact);
}
