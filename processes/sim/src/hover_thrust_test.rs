//! Tests of `hover_thrust`.

use super::*;
use crate::quadrotor::AirframeParams;
use crate::rng::Pcg32;

const DT: f64 = 0.002;

/// A vertical motion whose true hover thrust is `hover_true(t)`, flown with a thrust
/// wandering around it, seen through a noisy velocity estimate (3 cm/s, as the
/// default estimator noise); the estimator starts from MPC_THR_HOVER = `nominal`.
struct Vertical {
    p: AutopilotParams,
    hte: HoverThrustEstimator,
    rng: Pcg32,
    vz: f64,
    time_s: f64,
}

impl Vertical {
    fn new(nominal: f64) -> Self {
        let p = AutopilotParams {
            mpc_thr_hover: nominal,
            ..AutopilotParams::default()
        };
        Self {
            hte: HoverThrustEstimator::new(&p),
            p,
            rng: Pcg32::new(3),
            vz: 0.0,
            time_s: 0.0,
        }
    }

    fn fly(&mut self, seconds: f64, hover_true: f64) {
        for _ in 0..(seconds / DT).round() as usize {
            let t = self.time_s;
            let thrust = hover_true * (1.0 + 0.1 * (1.3 * t).sin() + 0.05 * (7.0 * t).sin());
            self.vz += (GRAVITY_M_S2 * thrust / hover_true - GRAVITY_M_S2) * DT;
            self.time_s += DT;
            let measured = self.vz + 0.03 * self.rng.normal();
            let input = HoverThrustInput {
                armed: true,
                landed: false,
                height_m: 5.0,
                velocity: Vector3::new(0.0, 0.0, measured),
                thrust_up: thrust,
            };
            self.hte
                .update((self.time_s * 1e9) as u64, DT, &self.p, &input);
        }
    }
}

#[test]
fn the_estimate_converges_to_the_true_hover_thrust_of_a_vehicle_10_percent_heavier_or_lighter() {
    let nominal = AirframeParams::default().hover_thrust_normalized();
    for mass_factor in [1.1, 0.9] {
        let truth = nominal * mass_factor;
        let mut v = Vertical::new(nominal);
        assert_eq!(v.hte.valid_estimate(), None);
        v.fly(10.0, truth);
        let est = v.hte.valid_estimate().expect("valid after 10 s");
        let error = (est - truth).abs() / truth;
        eprintln!(
            "mass x{mass_factor}: hover {truth:.4}, estimate {est:.4} ({:.2} %)",
            error * 100.0
        );
        assert!(error < 0.02, "{error}");
        assert!(v.hte.variance() < VALID_VARIANCE);
    }
}

#[test]
fn it_runs_only_armed_in_the_air_above_1_m_and_restarts_from_mpc_thr_hover_when_disarmed() {
    let p = AutopilotParams::default();
    let mut hte = HoverThrustEstimator::new(&p);
    let mut input = HoverThrustInput {
        armed: true,
        landed: false,
        height_m: 0.5,
        velocity: Vector3::zeros(),
        thrust_up: p.mpc_thr_hover * 1.2,
    };
    let mut t = 0;
    let mut run = |hte: &mut HoverThrustEstimator, input: &HoverThrustInput, seconds: f64| {
        for _ in 0..(seconds / DT) as usize {
            t += 2_000_000;
            hte.update(t, DT, &p, input);
        }
    };
    // Below 1 m (taking off, or a hop) it does not run.
    run(&mut hte, &input, 5.0);
    assert!(!hte.in_air());
    assert_eq!(hte.hover_thrust(), p.mpc_thr_hover);
    // Above it, it runs: steady at 20 % above MPC_THR_HOVER, the hover thrust is higher.
    input.height_m = 3.0;
    run(&mut hte, &input, 5.0);
    assert!(hte.in_air());
    assert!(
        hte.hover_thrust() > p.mpc_thr_hover + 0.05,
        "{}",
        hte.hover_thrust()
    );
    assert!(hte.valid_estimate().is_some());
    // Landed: stops and is no longer valid (it keeps what it learnt while armed).
    input.landed = true;
    run(&mut hte, &input, 0.1);
    assert!(!hte.in_air() && hte.valid_estimate().is_none());
    assert!(hte.hover_thrust() > p.mpc_thr_hover + 0.05);
    // Disarmed: back to MPC_THR_HOVER.
    input.armed = false;
    run(&mut hte, &input, 0.1);
    assert_eq!(hte.hover_thrust(), p.mpc_thr_hover);
}
