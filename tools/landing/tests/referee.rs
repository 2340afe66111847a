//! The referee of `landing run`, one test per rule: a simulated world is put through a
//! scripted touchdown (the vehicle placed just above a surface with the speed and tilt
//! of the case, motors off; the gear's contact physics does the rest: bounces, slides),
//! its truth events and states go to the same `Referee` and `verdict` both run modes
//! use, and the outcome must be the one the rule states.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test

use evaluation::flight_log::Outcome;
use evaluation::referee::{Referee, Rules, TouchdownLimits, verdict};
use ipc_types::msg::{FsmStatus, MissionState, Text};
use nalgebra::{UnitQuaternion, Vector3};
use optics::Board;
use sim::autopilot::Setpoint;
use sim::estimator_noise::EstimatorNoiseParams;
use sim::ground_vehicle::{GroundVehicleParams, PathParams, SpeedProfile};
use sim::lockstep::{truth_event, world_truth_state};
use sim::quadrotor::{MotorCommands, VehicleState};
use sim::world::{Aabb, World, WorldParams};

const DT_NS: u64 = 2_000_000;
const STATE_PERIOD_NS: u64 = 50_000_000;

/// The shipped board (deploy/config/pad.toml) and the default limits.
fn rules() -> Rules {
    Rules {
        limits: TouchdownLimits::default(),
        board: Board {
            min_m: [-0.42, -0.42],
            max_m: [0.42, 0.42],
        },
    }
}

/// A world with a pad vehicle standing still and no estimator noise.
fn still_pad(obstacles: Vec<Aabb>) -> World {
    World::new(WorldParams {
        estimator_noise: EstimatorNoiseParams::zero(),
        ground_vehicle: Some(GroundVehicleParams {
            speed: SpeedProfile::Constant { speed_m_s: 0.0 },
            ..GroundVehicleParams::default()
        }),
        obstacles,
        ..WorldParams::default()
    })
    .unwrap()
}

fn status(state: MissionState, at_ns: u64) -> FsmStatus {
    FsmStatus {
        state: state as u32,
        since_ns: at_ns,
        reason: Text::new("scripted"),
        ..FsmStatus::default()
    }
}

/// A world, the referee watching it as `landing run` does, and a script.
struct Scripted {
    world: World,
    referee: Referee,
    next_state_ns: u64,
}

impl Scripted {
    /// The fsm is landing from the start, so every touchdown counts as flown.
    fn new(world: World) -> Self {
        let mut referee = Referee::new(0);
        referee.on_status(&status(MissionState::Land, 0));
        Self {
            world,
            referee,
            next_state_ns: 0,
        }
    }

    /// Puts the vehicle `height_m` above the pad's surface at `(x, y)` in the pad
    /// frame, moving at `velocity` (world), tilted by `tilt_deg` about body x.
    fn place_over_pad(&mut self, x: f64, y: f64, height_m: f64, velocity: [f64; 3], tilt_deg: f64) {
        let pad = self.world.pad().unwrap();
        let p = pad.world_from_pad * nalgebra::Point3::new(x, y, height_m);
        self.place(p.coords, velocity, tilt_deg);
    }

    fn place(&mut self, position: Vector3<f64>, velocity: [f64; 3], tilt_deg: f64) {
        let mut s = VehicleState::at_rest(position, 0.0);
        s.velocity = Vector3::from(velocity);
        s.world_from_body =
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), tilt_deg.to_radians());
        self.world.set_vehicle_state(s).unwrap();
    }

    /// Steps the world with the motors off for `seconds`, feeding the referee.
    fn run(&mut self, seconds: f64) {
        self.step(seconds, false);
    }

    /// Steps the world with the autopilot flying its setpoint for `seconds`.
    fn fly(&mut self, seconds: f64) {
        self.step(seconds, true);
    }

    fn step(&mut self, seconds: f64, autopilot: bool) {
        for _ in 0..(seconds * 1e9 / DT_NS as f64).round() as usize {
            let events = if autopilot {
                self.world.step(DT_NS).unwrap().to_vec()
            } else {
                self.world
                    .step_with_motors(DT_NS, &MotorCommands::default())
                    .unwrap()
                    .to_vec()
            };
            for e in &events {
                self.referee.on_truth(&truth_event(e));
            }
            if self.world.time_ns() >= self.next_state_ns {
                let now = self.world.time_ns();
                self.referee
                    .on_truth_state(&world_truth_state(&self.world, now));
                self.next_state_ns = now + STATE_PERIOD_NS;
            }
        }
    }

    /// The fsm reports Landed and the vehicle disarms; the run goes on until the
    /// referee ends it, and its verdict is returned.
    fn fsm_says_landed(mut self) -> (Outcome, String) {
        self.world.set_armed(false);
        let now = self.world.time_ns();
        self.referee.on_status(&status(MissionState::Landed, now));
        self.finish()
    }

    fn finish(mut self) -> (Outcome, String) {
        for _ in 0..100 {
            if let Some(end) = self.referee.finished() {
                let v = verdict(end, &self.referee.eval, self.referee.last_state(), &rules());
                eprintln!("{:?}: {}", v.0, v.1);
                return v;
            }
            self.run(0.1);
        }
        panic!("the referee never ended the run");
    }
}

#[test]
fn a_gentle_touchdown_at_the_centre_of_the_pad_is_landed() {
    let mut s = Scripted::new(still_pad(Vec::new()));
    s.place_over_pad(0.02, -0.01, 0.005, [0.0, 0.0, -0.4], 2.0);
    s.run(0.5);
    let (outcome, why) = s.fsm_says_landed();
    assert_eq!(outcome, Outcome::Landed, "{why}");
}

#[test]
fn a_touchdown_beside_the_pad_is_off_pad() {
    let mut s = Scripted::new(still_pad(Vec::new()));
    let pad = s.world.pad().unwrap().world_from_pad.translation.vector;
    // 1.2 m beside the pad's centre, just above the ground.
    s.place(
        Vector3::new(pad.x, pad.y + 1.2, 0.005),
        [0.0, 0.0, -0.4],
        0.0,
    );
    s.run(0.5);
    let (outcome, why) = s.fsm_says_landed();
    assert_eq!(outcome, Outcome::OffPad, "{why}");
    assert!(why.contains("on the ground"), "{why}");
}

#[test]
fn a_touchdown_with_a_foot_over_the_boards_edge_is_off_pad() {
    // The centre 0.33 m from the pad's centre: every foot on the vehicle's 1 m roof (the
    // simulator calls it on the pad), but the outer feet, 0.12 m further out, are beyond
    // the 0.42 m board.
    let mut s = Scripted::new(still_pad(Vec::new()));
    s.place_over_pad(0.0, 0.33, 0.005, [0.0, 0.0, -0.4], 0.0);
    s.run(0.5);
    let touchdown = s.referee.eval.final_touchdown().copied().unwrap();
    assert!(
        touchdown.on_pad,
        "the simulator's surface is the pad: {touchdown:?}"
    );
    let (outcome, why) = s.fsm_says_landed();
    assert_eq!(outcome, Outcome::OffPad, "{why}");
    assert!(why.contains("beyond the board's edge"), "{why}");
}

#[test]
fn a_touchdown_too_fast_sideways_is_a_hard_landing() {
    let mut s = Scripted::new(still_pad(Vec::new()));
    s.place_over_pad(0.0, 0.0, 0.005, [0.8, 0.0, -0.3], 0.0);
    s.run(0.5);
    let (outcome, why) = s.fsm_says_landed();
    assert_eq!(outcome, Outcome::HardLanding, "{why}");
    assert!(why.contains("horizontal speed 0.8"), "{why}");
}

#[test]
fn a_touchdown_too_fast_downward_or_too_tilted_is_a_hard_landing() {
    let mut s = Scripted::new(still_pad(Vec::new()));
    s.place_over_pad(0.0, 0.0, 0.005, [0.0, 0.0, -1.6], 0.0);
    s.run(0.5);
    let (outcome, why) = s.fsm_says_landed();
    assert_eq!(outcome, Outcome::HardLanding, "{why}");
    assert!(why.contains("vertical speed"), "{why}");

    let mut s = Scripted::new(still_pad(Vec::new()));
    s.place_over_pad(0.0, 0.0, 0.005, [0.0, 0.0, -0.3], 20.0);
    s.run(0.5);
    let (outcome, why) = s.fsm_says_landed();
    assert_eq!(outcome, Outcome::HardLanding, "{why}");
    // The tilt at first contact: the low foot touches as the vehicle starts to level.
    assert!(
        why.contains("tilt 19.") || why.contains("tilt 20."),
        "{why}"
    );
}

#[test]
fn a_hard_sideways_hit_at_the_roofs_edge_tumbles_off_the_pad_and_is_crashed() {
    let mut s = Scripted::new(still_pad(Vec::new()));
    // Hits the roof near its edge at 2.5 m/s down and 5 m/s sideways: the feet still on
    // the roof grip while the others go over the edge, and the vehicle tumbles off.
    s.place_over_pad(0.0, 0.3, 0.005, [0.0, 5.0, -2.5], 0.0);
    s.run(0.05);
    let first = s.referee.eval.flown_touchdowns().next().copied().unwrap();
    assert!(first.on_pad, "{first:?}");
    let (outcome, why) = s.finish();
    assert_eq!(outcome, Outcome::Crashed, "{why}");
}

#[test]
fn a_touch_on_the_pad_a_lift_off_and_a_landing_beside_it_is_judged_by_the_final_touchdown() {
    let mut s = Scripted::new(still_pad(Vec::new()));
    s.place_over_pad(0.0, 0.0, 0.005, [0.0, 0.0, -0.3], 0.0);
    s.run(0.5);
    assert!(s.referee.eval.final_touchdown().unwrap().on_pad);
    // The autopilot lifts it off, flies it 1.5 m beside the pad and sets it down there.
    let pad = s.world.pad().unwrap().world_from_pad.translation.vector;
    s.world.set_armed(true);
    s.world.set_setpoint(Setpoint::position(
        Vector3::new(pad.x + 1.5, pad.y, 1.0),
        0.0,
    ));
    s.fly(5.0);
    let mut down = Setpoint::position(Vector3::new(pad.x + 1.5, pad.y, 0.0), 0.0);
    down.position[2] = None;
    down.velocity[2] = Some(-0.3);
    s.world.set_setpoint(down);
    s.fly(5.0);
    let last = s.referee.eval.final_touchdown().copied().unwrap();
    assert!(!last.on_pad, "{last:?}");
    assert!(last.vertical_mps < 0.5, "{last:?}");
    let (outcome, why) = s.fsm_says_landed();
    assert_eq!(outcome, Outcome::OffPad, "{why}");
}

#[test]
fn a_landing_on_the_pad_that_then_slides_off_its_braking_vehicle_is_not_landed() {
    // The vehicle drives at 3 m/s and brakes to a stop at 8 m/s^2 after 1 s, harder than
    // the gear's friction (mu g = 4.9 m/s^2) can hold the quadrotor.
    let mut s = Scripted::new(
        World::new(WorldParams {
            estimator_noise: EstimatorNoiseParams::zero(),
            ground_vehicle: Some(GroundVehicleParams {
                speed: SpeedProfile::PiecewiseLinear {
                    points: vec![[0.0, 3.0], [1.0, 3.0], [1.375, 0.0]],
                },
                ..GroundVehicleParams::default()
            }),
            ..WorldParams::default()
        })
        .unwrap(),
    );
    s.place_over_pad(0.3, 0.0, 0.005, [3.0, 0.0, -0.2], 0.0);
    s.run(0.9);
    let touchdown = s.referee.eval.final_touchdown().copied().unwrap();
    assert!(touchdown.on_pad, "{touchdown:?}");
    assert_eq!(s.world.resting_on_pad(), Some(true), "it rides the pad");
    s.run(2.0);
    assert_ne!(s.world.resting_on_pad(), Some(true), "it slid off the roof");
    let (outcome, why) = s.fsm_says_landed();
    assert_ne!(outcome, Outcome::Landed, "{why}");
    eprintln!("slid off: {outcome:?}, {why}");
}

#[test]
fn a_vehicle_at_rest_off_centre_on_a_pad_driving_a_circle_is_landed() {
    // The pad turns at 0.75 rad/s (1.5 m/s on a 2 m circle): a point 0.25 m from its
    // centre moves 0.19 m/s relative to the centre, and a vehicle resting there is at
    // rest on the pad all the same.
    let mut s = Scripted::new(
        World::new(WorldParams {
            estimator_noise: EstimatorNoiseParams::zero(),
            ground_vehicle: Some(GroundVehicleParams {
                path: PathParams::Circle {
                    centre_m: [0.0, 0.0],
                    radius_m: 2.0,
                    start_angle_rad: 0.0,
                    clockwise: false,
                },
                speed: SpeedProfile::Constant { speed_m_s: 1.5 },
                ..GroundVehicleParams::default()
            }),
            ..WorldParams::default()
        })
        .unwrap(),
    );
    // The pad vehicle drives off from a standstill; a second later it is at speed.
    s.run(1.0);
    let pad = s.world.pad().unwrap();
    let at = pad.world_from_pad * nalgebra::Point3::new(0.25, 0.0, 0.0);
    let v = pad.velocity_at(&at.coords);
    assert!(pad.angular_velocity.z > 0.7, "{:?}", pad.angular_velocity);
    s.place_over_pad(0.25, 0.0, 0.005, [v.x, v.y, -0.2], 0.0);
    s.run(1.0);
    let (outcome, why) = s.fsm_says_landed();
    assert_eq!(outcome, Outcome::Landed, "{why}");
}

#[test]
fn touching_an_obstacle_ends_the_run_as_crashed_even_if_the_vehicle_lands_after() {
    let obstacle = Aabb {
        min_m: [4.0, -0.5, 0.0],
        max_m: [4.6, 0.5, 1.2],
    };
    let mut s = Scripted::new(still_pad(vec![obstacle]));
    // Grazes the box's top edge while falling past it.
    s.place(Vector3::new(3.8, 0.0, 1.3), [0.0, 0.0, -0.2], 0.0);
    s.run(1.0);
    assert!(s.referee.eval.collisions >= 1);
    let (outcome, why) = s.finish();
    assert_eq!(outcome, Outcome::Crashed, "{why}");
    assert!(why.contains("obstacle"), "{why}");
}
