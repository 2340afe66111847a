#![allow(clippy::unwrap_used, clippy::expect_used)]
//! px4-link against the simulator's PX4-like autopilot, message for message, in simulated
//! time: connect, telemetry in ENU, arm, take off, OFFBOARD only after the stream, fly a
//! setpoint, failsafe on stream loss, retries and timeouts when the autopilot is silent.

mod common;

use common::{position_setpoint, scenario as scenario_named};

use ipc_types::msg::{FlightMode, LandedState, Setpoint};
use mavlink::MavHeader;
use px4_link::{LinkSettings, Outcome, Px4Link, Request};
use sim::lockstep::Simulator;

struct Flight {
    sim: Simulator,
    link: Px4Link,
    seq: u8,
    /// Drop everything the autopilot sends (a cut cable).
    deaf: bool,
}

impl Flight {
    fn new(scenario: &str) -> Self {
        Self::with_home(scenario, None)
    }

    /// `scenario` with the simulated PX4's home (SIH_LOC_H0) at `home_amsl` m.
    fn with_home(scenario: &str, home_amsl: Option<f64>) -> Self {
        let mut scn = scenario_named(scenario);
        if let Some(h) = home_amsl {
            scn.px4.sih_loc_h0 = h;
        }
        Self {
            sim: Simulator::new(&scn, 1).unwrap(),
            link: Px4Link::new(LinkSettings::default()),
            seq: 0,
            deaf: false,
        }
    }

    fn now(&self) -> u64 {
        self.sim.time_ns()
    }

    /// Runs `seconds` of simulated time; `each` is called every 20 ms (the fsm's rate).
    fn run(&mut self, seconds: f64, mut each: impl FnMut(&mut Px4Link, u64)) {
        let end = self.now() + (seconds * 1e9) as u64;
        while self.now() < end {
            let now = self.now();
            if now % 20_000_000 < 2_000_000 {
                each(&mut self.link, now);
            }
            let out: Vec<_> = self.link.poll(now).to_vec();
            for m in &out {
                let h = self.link.header(self.seq);
                self.seq = self.seq.wrapping_add(1);
                self.sim.handle_mavlink(&h, m);
            }
            self.sim.step().unwrap();
            let back = self.sim.take_mavlink();
            if !self.deaf {
                for (k, m) in back.iter().enumerate() {
                    let h = MavHeader {
                        system_id: 1,
                        component_id: 1,
                        sequence: (self.now() / 2_000_000 + k as u64) as u8,
                    };
                    self.link.on_message(self.now(), &h, m);
                }
            }
        }
    }

    fn wait_outcome(&mut self, seconds: f64) -> Vec<(Request, Outcome)> {
        let mut got = Vec::new();
        let end = self.now() + (seconds * 1e9) as u64;
        while self.now() < end && got.is_empty() {
            self.run(0.02, |_, _| {});
            got = self.link.take_outcomes();
        }
        got
    }
}

#[test]
fn it_connects_and_reports_the_vehicle_on_the_ground_in_enu() {
    let mut f = Flight::new("indoor-static");
    f.run(2.0, |_, _| {});
    let now = f.now();
    let st = f.link.status(now);
    assert!(st.connected);
    assert!(!st.armed);
    assert_eq!(st.landed, LandedState::OnGround);
    let v = f.link.vehicle_state(now).expect("state");
    assert!(v.world_from_body.translation[2].abs() < 0.1, "{v:?}");
    assert_eq!(v.link.connected, 1);
    // Level on the ground: body z (FLU up) is world z (ENU up).
    let [x, y, z, w] = v.world_from_body.rotation_xyzw;
    let q = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
    assert!((q * nalgebra::Vector3::z()).z > 0.99);
}

#[test]
fn arm_and_takeoff_are_acked_and_the_state_climbs_up_in_enu() {
    let mut f = Flight::new("indoor-static");
    f.run(1.5, |_, _| {});
    f.link.request(Request::Arm);
    assert_eq!(f.wait_outcome(3.0), vec![(Request::Arm, Outcome::Accepted)]);
    f.link.request(Request::Takeoff { altitude_m: 2.0 });
    assert_eq!(
        f.wait_outcome(3.0),
        vec![(Request::Takeoff { altitude_m: 2.0 }, Outcome::Accepted)]
    );
    f.run(8.0, |_, _| {});
    let now = f.now();
    assert!(f.link.status(now).armed);
    let z = f
        .link
        .vehicle_state(now)
        .unwrap()
        .world_from_body
        .translation[2];
    assert!((z - 2.0).abs() < 0.3, "ENU height {z}");
}

#[test]
fn the_takeoff_altitude_is_one_px4s_rule_accepts_whatever_the_home_altitude() {
    // PX4 reads NAV_TAKEOFF's param7 as AMSL and does not climb to an altitude below
    // the current one ("Already higher than takeoff altitude"): px4-link's request
    // must climb to the world height asked for with home at 488 m, 0 m and -10 m.
    for home in [488.0, 0.0, -10.0] {
        let mut f = Flight::with_home("indoor-static", Some(home));
        f.run(1.5, |_, _| {});
        f.link.request(Request::Arm);
        f.link.request(Request::Takeoff { altitude_m: 2.0 });
        let mut outcomes = Vec::new();
        while outcomes.len() < 2 && f.now() < 6_000_000_000 {
            outcomes.extend(f.wait_outcome(1.0));
        }
        assert_eq!(
            outcomes,
            vec![
                (Request::Arm, Outcome::Accepted),
                (Request::Takeoff { altitude_m: 2.0 }, Outcome::Accepted)
            ],
            "home {home}"
        );
        f.run(8.0, |_, _| {});
        let events = f.sim.commander_mut().take_events();
        assert!(
            !events.contains(&sim::px4::commander::CommanderEvent::AlreadyHigher),
            "home {home}: {events:?}"
        );
        let z = f
            .link
            .vehicle_state(f.now())
            .unwrap()
            .world_from_body
            .translation[2];
        assert!((z - 2.0).abs() < 0.3, "home {home}: height {z}");
    }
}

#[test]
fn offboard_is_asked_only_after_a_short_setpoint_stream_and_the_vehicle_flies_there() {
    let mut f = Flight::new("indoor-static");
    f.run(1.5, |_, _| {});
    // Without a stream, OFFBOARD is not even sent.
    f.link.request(Request::Offboard);
    assert_eq!(
        f.wait_outcome(1.0),
        vec![(Request::Offboard, Outcome::NoSetpointStream)]
    );
    f.link.request(Request::Arm);
    f.link.request(Request::Takeoff { altitude_m: 2.0 });
    f.run(6.0, |_, _| {});
    let _ = f.link.take_outcomes();
    let target = position_setpoint(2.0, 1.0, 2.5);
    let asked = f.now();
    f.link.request(Request::Offboard);
    let mut accepted_at = None;
    let end = f.now() + 3_000_000_000;
    while f.now() < end && accepted_at.is_none() {
        f.run(0.02, |l, now| l.set_setpoint(now, &target));
        if f.link
            .take_outcomes()
            .contains(&(Request::Offboard, Outcome::Accepted))
        {
            accepted_at = Some(f.now());
        }
    }
    let accepted_at = accepted_at.expect("OFFBOARD accepted");
    // PX4 needs one fresh setpoint; px4-link streams `offboard_stream_ns` first.
    let stream_ns = LinkSettings::default().offboard_stream_ns;
    assert!(
        (stream_ns..stream_ns + 1_000_000_000).contains(&(accepted_at - asked)),
        "sent after {} ns of stream",
        accepted_at - asked
    );
    f.run(8.0, |l, now| l.set_setpoint(now, &target));
    let now = f.now();
    assert_eq!(f.link.status(now).mode, FlightMode::Offboard);
    let p = f
        .link
        .vehicle_state(now)
        .unwrap()
        .world_from_body
        .translation;
    // East 2, north 1, up 2.5: the NED conversion is right in every axis.
    let err = ((p[0] - 2.0).powi(2) + (p[1] - 1.0).powi(2) + (p[2] - 2.5).powi(2)).sqrt();
    assert!(err < 0.2, "at {p:?}");

    // The mission stops sending setpoints: the stream stops, PX4's failsafe lands
    // (COM_OBL_RC_ACT = 4 on this airframe) ...
    // (0.3 s until px4-link stops streaming, COM_OF_LOSS_T, a 1 Hz HEARTBEAT) ...
    f.run(3.0, |_, _| {});
    assert_eq!(f.link.status(f.now()).mode, FlightMode::Land);
    // ... and disarms, and then shows the mode asked for last again, OFFBOARD (PX4's
    // user intention survives the failsafe).
    f.run(12.0, |_, _| {});
    let st = f.link.status(f.now());
    assert!(!st.armed && st.landed == LandedState::OnGround, "{st:?}");
    assert_eq!(st.mode, FlightMode::Offboard, "{st:?}");
}

#[test]
fn a_silent_autopilot_times_the_command_out_after_its_retries_and_drops_the_link() {
    let mut f = Flight::new("indoor-static");
    f.run(1.5, |_, _| {});
    f.deaf = true;
    f.link.request(Request::Arm);
    let got = f.wait_outcome(5.0);
    assert_eq!(got, vec![(Request::Arm, Outcome::TimedOut)]);
    // No heartbeat for the link's timeout: disconnected.
    f.run(
        LinkSettings::default().heartbeat_timeout_ns as f64 * 1e-9,
        |_, _| {},
    );
    assert!(!f.link.status(f.now()).connected);
}

#[test]
fn non_finite_setpoint_fields_are_never_sent() {
    let mut link = Px4Link::new(LinkSettings::default());
    let mut sp = position_setpoint(f64::NAN, 1.0, 2.0);
    sp.valid |= Setpoint::VELOCITY;
    sp.velocity = [1.0, 0.0, 0.0];
    link.set_setpoint(0, &sp);
    let out = link.poll(1_000_000).to_vec();
    let spm = out
        .iter()
        .find_map(|m| match m {
            mavlink::dialects::common::MavMessage::SET_POSITION_TARGET_LOCAL_NED(d) => {
                Some(d.clone())
            }
            _ => None,
        })
        .expect("velocity setpoint still streamed");
    for v in [
        spm.x, spm.y, spm.z, spm.vx, spm.vy, spm.vz, spm.afx, spm.afy, spm.afz, spm.yaw,
    ] {
        assert!(v.is_finite());
    }
    assert!(spm.type_mask.contains(
        mavlink::dialects::common::PositionTargetTypemask::POSITION_TARGET_TYPEMASK_X_IGNORE
    ));
    // ENU velocity east = NED y.
    assert_eq!((spm.vx, spm.vy), (0.0, 1.0));
}
