#![allow(clippy::unwrap_used, clippy::expect_used)]
//! `LinkNode` (the px4-link process without its I/O) against the simulator's PX4-like
//! autopilot in lockstep, as `landing run` composes them: request ids come back in the
//! outcomes, a safety order clears the queue and lands at once, and the autopilot's
//! injected faults (scenario `[faults]`) give the outcomes and link health the mission
//! must handle: arming denied, arming refused for a while, OFFBOARD denied, telemetry
//! gone silent.

mod common;

use common::{position_setpoint, scenario};

use ipc_types::msg::{
    FlightMode, Header, LandedState, LinkOutcome, LinkOutcomeKind, LinkRequest, LinkRequestKind,
    SafetyAction, SafetyCommand, Setpoint, Text, VehicleState,
};
use mavlink::MavHeader;
use mavlink::dialects::common::{MavCmd, MavMessage, MavResult};
use px4_link::node::SAFETY_REQUEST_ID;
use px4_link::{LinkNode, LinkSettings};
use sim::lockstep::Simulator;
use sim::px4::commander::Faults;

struct Bench {
    sim: Simulator,
    node: LinkNode,
    seq: u8,
    outcomes: Vec<LinkOutcome>,
    states: Vec<VehicleState>,
    /// Commands sent to the autopilot, with when (SET_MESSAGE_INTERVAL left out).
    commands: Vec<(u64, MavCmd)>,
    setpoint: Option<Setpoint>,
    setpoint_given_ns: Option<u64>,
}

impl Bench {
    fn new(faults: Faults) -> Self {
        let mut scn = scenario("indoor-static");
        scn.scenario.faults = faults;
        Self {
            sim: Simulator::new(&scn, 1).unwrap(),
            node: LinkNode::new(LinkSettings::default()),
            seq: 0,
            outcomes: Vec::new(),
            states: Vec::new(),
            commands: Vec::new(),
            setpoint: None,
            setpoint_given_ns: None,
        }
    }

    fn now(&self) -> u64 {
        self.sim.time_ns()
    }

    /// One 2 ms step: the fsm's setpoint every 20 ms (from the step it is set), the node's output to the autopilot,
    /// physics, the autopilot's output to the node, outcomes and states collected.
    fn step(&mut self) {
        let now = self.now();
        if let Some(sp) = self.setpoint
            && self.setpoint_given_ns.is_none_or(|t| now - t >= 20_000_000)
        {
            self.node.on_setpoint(now, &sp);
            self.setpoint_given_ns = Some(now);
        }
        let (sim, commands) = (&mut self.sim, &mut self.commands);
        let sent = self.node.send_due(now, |h, m| {
            if let MavMessage::COMMAND_LONG(c) = m
                && c.command != MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL
            {
                commands.push((now, c.command));
            }
            sim.handle_mavlink(&h, m);
            Ok::<(), std::convert::Infallible>(())
        });
        let Ok(()) = sent;
        self.sim.step().unwrap();
        let now = self.now();
        for m in self.sim.take_mavlink() {
            let h = MavHeader {
                system_id: 1,
                component_id: 1,
                sequence: self.seq,
            };
            self.seq = self.seq.wrapping_add(1);
            self.node.on_message(now, &h, &m);
        }
        self.outcomes.extend(self.node.take_outcomes());
        if let Some(s) = self.node.vehicle_state(now) {
            self.states.push(s);
        }
    }

    fn run(&mut self, seconds: f64) {
        let end = self.now() + (seconds * 1e9) as u64;
        while self.now() < end {
            self.step();
        }
    }

    fn ask(&mut self, id: u64, kind: LinkRequestKind) {
        let r = LinkRequest {
            msg: Header::default(),
            id,
            kind: kind as u32,
            reserved: 0,
            altitude_m: 2.0,
        };
        self.node.on_request(self.now(), &r);
        self.outcomes.extend(self.node.take_outcomes());
    }

    fn safety(&mut self, action: SafetyAction) {
        let c = SafetyCommand {
            msg: Header::default(),
            action: action as u32,
            reserved: 0,
            source: Text::new("test"),
            reason: Text::new("test"),
        };
        self.node.on_safety(self.now(), &c);
        self.outcomes.extend(self.node.take_outcomes());
    }

    /// Runs until the outcome for `id` arrives (at most `seconds`), and returns it.
    fn answer(&mut self, id: u64, seconds: f64) -> LinkOutcome {
        let end = self.now() + (seconds * 1e9) as u64;
        loop {
            if let Some(o) = self.outcomes.iter().find(|o| o.id == id) {
                return *o;
            }
            assert!(self.now() < end, "no outcome for {id}: {:?}", self.outcomes);
            self.step();
        }
    }

    fn sends_of(&self, command: MavCmd) -> usize {
        self.commands.iter().filter(|(_, c)| *c == command).count()
    }

    fn latest(&self) -> VehicleState {
        *self.states.last().expect("a vehicle state")
    }
}

fn kind(o: &LinkOutcome) -> LinkOutcomeKind {
    LinkOutcomeKind::from_raw(o.outcome)
}

#[test]
fn request_ids_come_back_in_the_outcomes_through_a_whole_flight() {
    let mut b = Bench::new(Faults::default());
    b.run(1.5);
    b.ask(10, LinkRequestKind::Arm);
    b.ask(11, LinkRequestKind::Takeoff);
    b.ask(12, LinkRequestKind::Offboard); // no stream yet
    let mut bad = LinkRequest {
        id: 13,
        kind: 99,
        ..LinkRequest::default()
    };
    b.node.on_request(b.now(), &bad);
    bad.id = 14;
    bad.kind = LinkRequestKind::Takeoff as u32;
    bad.altitude_m = -1.0;
    b.node.on_request(b.now(), &bad);
    b.outcomes.extend(b.node.take_outcomes());
    b.answer(12, 3.0);
    b.run(6.0);
    b.setpoint = Some(position_setpoint(1.0, 0.5, 2.0));
    b.ask(15, LinkRequestKind::Offboard);
    b.answer(15, 3.0);
    let got: Vec<_> = b.outcomes.iter().map(|o| (o.id, o.kind, kind(o))).collect();
    assert_eq!(
        got,
        vec![
            (13, 99, LinkOutcomeKind::Invalid),
            (
                14,
                LinkRequestKind::Takeoff as u32,
                LinkOutcomeKind::Invalid
            ),
            (10, LinkRequestKind::Arm as u32, LinkOutcomeKind::Accepted),
            (
                11,
                LinkRequestKind::Takeoff as u32,
                LinkOutcomeKind::Accepted
            ),
            (
                12,
                LinkRequestKind::Offboard as u32,
                LinkOutcomeKind::NoSetpointStream
            ),
            (
                15,
                LinkRequestKind::Offboard as u32,
                LinkOutcomeKind::Accepted
            ),
        ]
    );
    b.run(3.0);
    assert_eq!(
        FlightMode::from_raw(b.latest().flight_mode),
        FlightMode::Offboard
    );
}

#[test]
fn a_safety_land_cancels_the_queued_requests_and_lands_at_once() {
    let mut b = Bench::new(Faults::default());
    b.run(1.5);
    b.ask(1, LinkRequestKind::Arm);
    b.ask(2, LinkRequestKind::Takeoff);
    b.answer(2, 3.0);
    b.run(5.0);
    assert!(b.latest().world_from_body.translation[2] > 1.7);
    // OFFBOARD waits a second for the stream; HOLD waits behind it.
    b.setpoint = Some(position_setpoint(0.0, 0.0, 2.0));
    b.ask(3, LinkRequestKind::Offboard);
    b.ask(4, LinkRequestKind::Hold);
    b.run(0.2);
    let ordered = b.now();
    b.safety(SafetyAction::SafeLand);
    b.step();
    let cancelled: Vec<_> = b
        .outcomes
        .iter()
        .filter(|o| o.result == MavResult::MAV_RESULT_CANCELLED as u32)
        .map(|o| (o.id, kind(o)))
        .collect();
    assert_eq!(
        cancelled,
        vec![
            (3, LinkOutcomeKind::Rejected),
            (4, LinkOutcomeKind::Rejected)
        ]
    );
    let after: Vec<_> = b.commands.iter().filter(|(t, _)| *t >= ordered).collect();
    assert_eq!(
        after.first().map(|(t, c)| (*t, *c)),
        Some((ordered, MavCmd::MAV_CMD_NAV_LAND)),
        "NAV_LAND on the very next poll: {after:?}"
    );
    let land = b.answer(SAFETY_REQUEST_ID, 1.0);
    assert_eq!(land.kind, LinkRequestKind::Land as u32);
    assert_eq!(kind(&land), LinkOutcomeKind::Accepted);
    assert!(
        land.msg.capture_ns - ordered < 50_000_000,
        "acked within 50 ms"
    );
    assert_eq!(
        b.sim.commander().mode(),
        sim::px4::commander::FlightMode::AutoLand
    );
    b.run(1.1); // the mode reaches the vehicle state with the next 1 Hz HEARTBEAT
    assert_eq!(
        FlightMode::from_raw(b.latest().flight_mode),
        FlightMode::Land
    );
    assert_eq!(
        b.sends_of(MavCmd::MAV_CMD_DO_SET_MODE),
        0,
        "no OFFBOARD/HOLD sent"
    );
    b.run(6.0);
    assert_eq!(
        LandedState::from_raw(b.latest().landed_state),
        LandedState::OnGround
    );
}

#[test]
fn a_temporarily_rejected_arm_is_resent_and_accepted_once_the_autopilot_is_ready() {
    let mut b = Bench::new(Faults {
        reject_arming_times: 2,
        ..Faults::default()
    });
    b.run(1.5);
    let asked = b.now();
    b.ask(1, LinkRequestKind::Arm);
    let o = b.answer(1, 3.0);
    assert_eq!(kind(&o), LinkOutcomeKind::Accepted);
    assert_eq!(b.sends_of(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM), 3);
    // Resent after the command timeout each time (0.5 s), not at once.
    let took = o.msg.capture_ns - asked;
    assert!((1_000_000_000..1_100_000_000).contains(&took), "{took} ns");
    b.run(1.1); // HEARTBEAT, which carries the armed flag, comes at 1 Hz
    assert_eq!(b.latest().armed, 1);
}

#[test]
fn an_arm_refused_for_good_ends_rejected_after_the_configured_attempts() {
    // PX4 answers every arming refusal TEMPORARILY_REJECTED, never DENIED: a check
    // that never passes looks like one that passes later, until the attempts run out.
    let mut b = Bench::new(Faults {
        reject_arming: true,
        ..Faults::default()
    });
    b.run(1.5);
    b.ask(1, LinkRequestKind::Arm);
    let o = b.answer(1, 5.0);
    assert_eq!(kind(&o), LinkOutcomeKind::Rejected);
    assert_eq!(o.result, MavResult::MAV_RESULT_TEMPORARILY_REJECTED as u32);
    b.run(3.0);
    assert_eq!(
        b.sends_of(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM),
        LinkSettings::default().command_attempts as usize
    );
}

#[test]
fn a_refused_offboard_is_rejected_after_the_attempts_and_the_vehicle_keeps_holding() {
    let mut b = Bench::new(Faults {
        reject_offboard: true,
        ..Faults::default()
    });
    b.run(1.5);
    b.ask(1, LinkRequestKind::Arm);
    b.ask(2, LinkRequestKind::Takeoff);
    b.answer(2, 3.0);
    b.run(5.0);
    b.setpoint = Some(position_setpoint(1.0, 0.0, 2.0));
    b.ask(3, LinkRequestKind::Offboard);
    let o = b.answer(3, 5.0);
    assert_eq!(kind(&o), LinkOutcomeKind::Rejected);
    assert_eq!(o.result, MavResult::MAV_RESULT_TEMPORARILY_REJECTED as u32);
    assert_eq!(
        b.sends_of(MavCmd::MAV_CMD_DO_SET_MODE),
        LinkSettings::default().command_attempts as usize
    );
    b.run(2.0);
    assert_eq!(
        FlightMode::from_raw(b.latest().flight_mode),
        FlightMode::Hold
    );
}

#[test]
fn when_telemetry_stops_the_state_shows_disconnected_with_stale_stamps() {
    let stop_s = 6.0;
    let mut b = Bench::new(Faults {
        telemetry_stop_s: Some(stop_s),
        ..Faults::default()
    });
    b.run(1.5);
    b.ask(1, LinkRequestKind::Arm);
    b.ask(2, LinkRequestKind::Takeoff);
    b.answer(2, 3.0);
    b.run(stop_s - 1.5 - 0.5); // just before the stop
    assert_eq!(b.latest().link.connected, 1);
    let stop_ns = (stop_s * 1e9) as u64;
    let timeout = LinkSettings::default().heartbeat_timeout_ns;
    b.run(0.7);
    // Still "connected" inside the heartbeat timeout, but the stamps stopped advancing.
    assert!(b.node.status(b.now()).connected);
    let last = b.latest();
    assert_eq!(last.link.connected, 1);
    assert!(last.msg.capture_ns <= stop_ns);
    assert!(b.now() - last.msg.capture_ns >= 190_000_000);
    // Past the heartbeat timeout (heartbeats come at 1 Hz): disconnected.
    b.run(timeout as f64 * 1e-9 - 0.1);
    assert!(!b.node.status(b.now()).connected);
    assert_eq!(b.latest().link.connected, 0);
    let silent_since = b.latest().link.last_heartbeat_ns;
    assert!(silent_since <= stop_ns);
    assert!(b.now() - silent_since > timeout);
    // The topic keeps going (10 Hz), saying disconnected, with the old stamps.
    b.states.clear();
    b.run(1.0);
    assert!(
        (9..=11).contains(&b.states.len()),
        "{} states",
        b.states.len()
    );
    for s in &b.states {
        assert_eq!(s.link.connected, 0);
        assert!(s.msg.capture_ns <= stop_ns);
        // Measured (the stamp) before it arrived, by the link's delay.
        assert!(s.msg.capture_ns <= s.link.last_telemetry_ns);
        assert!(s.link.last_telemetry_ns - s.msg.capture_ns < 20_000_000);
    }
    // Commands still reach the autopilot, but no answer comes back: the mission sees a
    // time-out although the vehicle obeys.
    b.ask(3, LinkRequestKind::Land);
    let o = b.answer(3, 3.0);
    assert_eq!(kind(&o), LinkOutcomeKind::TimedOut);
    assert_eq!(
        b.sim.commander().mode(),
        sim::px4::commander::FlightMode::AutoLand
    );
}
