//! The px4-link process without its I/O: stack messages in ([`LinkRequest`],
//! [`SafetyCommand`], [`Setpoint`]), MAVLink in and out, stack messages out
//! ([`LinkOutcome`], [`VehicleState`]).
//!
//! The `px4-link` binary binds a [`LinkNode`] to a UDP socket or serial port and to
//! iceoryx2; `landing run` calls it directly next to `sim::lockstep::Simulator`, so both
//! run the same code. Time comes in as `now_ns` on every call; nothing here reads a clock.
//!
//! Every accepted [`LinkRequest`] is answered by exactly one [`LinkOutcome`] with its
//! id, in request order:
//! - accepted / rejected (PX4's MAV_RESULT) / timed out / no setpoint stream, as the
//!   autopilot answered;
//! - invalid at once when the request cannot be read (unknown kind, take-off height not
//!   finite and positive);
//! - rejected with MAV_RESULT_CANCELLED (6) when a safety order dropped it before the
//!   autopilot answered (the autopilot never saw it, or its answer no longer matters).
//!
//! A safety order's own LAND/LOITER request is answered with id [`SAFETY_REQUEST_ID`].

use std::collections::VecDeque;

use ipc_types::msg::{
    FlightMode, Header, LinkOutcome, LinkOutcomeKind, LinkRequest, LinkRequestKind, SafetyAction,
    SafetyCommand, Setpoint, Stage, VehicleState,
};
use mavlink::MavHeader;
use mavlink::dialects::common::{MavMessage, MavResult};

use crate::link::{LinkSettings, Outcome, Px4Link, Request, Status};

/// The id of the outcome answering a safety order's own request (requesters should
/// number theirs from 1).
pub const SAFETY_REQUEST_ID: u64 = 0;

/// While no new telemetry arrives, the last vehicle state is published again this often,
/// with its old stamps and the current link health, so consumers see `link.connected`
/// drop to 0 instead of a silent topic whose last sample still says connected.
pub const STALE_STATE_PERIOD_NS: u64 = 100_000_000;

/// The px4-link process as a pure state machine around [`Px4Link`].
#[derive(Debug, Clone)]
pub struct LinkNode {
    link: Px4Link,
    /// (id, raw kind) of every request inside the link, in order: the link answers
    /// them one at a time, in order, exactly once each.
    ids: VecDeque<(u64, u32)>,
    outcomes: Vec<LinkOutcome>,
    /// Latest time seen on any call (stamps outcomes taken without a time).
    now_ns: u64,
    /// Capture time and publication time of the last state handed out.
    last_state: Option<(u64, u64, u32)>,
    sequence: u8,
}

impl LinkNode {
    /// A node whose link has heard nothing yet.
    pub fn new(settings: LinkSettings) -> Self {
        Self {
            link: Px4Link::new(settings),
            ids: VecDeque::new(),
            outcomes: Vec::new(),
            now_ns: 0,
            last_state: None,
            sequence: 0,
        }
    }

    fn advance(&mut self, now_ns: u64) {
        self.now_ns = self.now_ns.max(now_ns);
    }

    /// Takes a request from the mission: queued behind earlier ones, or answered
    /// [`LinkOutcomeKind::Invalid`] at once when it cannot be read (never guessed).
    pub fn on_request(&mut self, now_ns: u64, request: &LinkRequest) {
        self.advance(now_ns);
        match to_request(request) {
            Some(q) => {
                self.ids.push_back((request.id, request.kind));
                self.link.request(q);
            }
            None => {
                tracing::warn!(
                    id = request.id,
                    kind = request.kind,
                    altitude_m = request.altitude_m,
                    "unreadable request refused"
                );
                self.outcomes.push(outcome(
                    self.now_ns,
                    request.id,
                    request.kind,
                    LinkOutcomeKind::Invalid,
                    0,
                ));
            }
        }
    }

    /// Executes a safety order at once: every queued or unanswered request is dropped
    /// (answered cancelled), then LAND (safe-land, abort) or LOITER (hold) goes out on
    /// the next [`Self::poll`]. A repeat of the order still in flight changes nothing,
    /// so a watchdog may repeat its order freely.
    pub fn on_safety(&mut self, now_ns: u64, command: &SafetyCommand) {
        self.advance(now_ns);
        let (request, kind) = match SafetyAction::from_raw(command.action) {
            SafetyAction::None => return,
            SafetyAction::Hold => (Request::Hold, LinkRequestKind::Hold),
            SafetyAction::SafeLand | SafetyAction::Abort => (Request::Land, LinkRequestKind::Land),
        };
        self.collect();
        let key = (SAFETY_REQUEST_ID, kind as u32);
        if self.ids.len() == 1 && self.ids.front() == Some(&key) {
            return;
        }
        // Done already: the autopilot is in the mode the order wants (or accepted it a
        // moment ago and its heartbeat has yet to show it) and nothing else is asked. A
        // watchdog repeats its order every 200 ms; each used to send LAND again.
        let wanted = match request {
            Request::Hold => FlightMode::Hold,
            _ => FlightMode::Land,
        };
        if self.ids.is_empty()
            && (self.link.status(now_ns).mode == wanted
                || self.link.mode_under_way(now_ns, request))
        {
            return;
        }
        tracing::warn!(
            ?request,
            source = command.source.as_str(),
            reason = command.reason.as_str(),
            dropped = self.ids.len(),
            "safety command"
        );
        self.link.clear_requests();
        for (id, kind) in self.ids.drain(..) {
            self.outcomes.push(outcome(
                self.now_ns,
                id,
                kind,
                LinkOutcomeKind::Rejected,
                MavResult::MAV_RESULT_CANCELLED as u32,
            ));
        }
        self.ids.push_back(key);
        self.link.request(request);
    }

    /// Takes the mission's newest setpoint (ENU), streamed while fresh.
    pub fn on_setpoint(&mut self, now_ns: u64, setpoint: &Setpoint) {
        self.advance(now_ns);
        self.link.set_setpoint(now_ns, setpoint);
    }

    /// VIO samples dropped because a value was not finite.
    pub fn vio_refused(&self) -> u64 {
        self.link.vio_refused()
    }

    /// Takes a VIO sample to forward (when `forward_vio` is on).
    pub fn on_vio(&mut self, now_ns: u64, vio: &ipc_types::msg::VioOdometry) {
        self.advance(now_ns);
        self.link.set_vio(vio);
    }

    /// The last new setpoint that went out since the last call, and when it was taken in.
    pub fn take_sent_setpoint(&mut self) -> Option<(u64, Setpoint)> {
        self.link.take_sent_setpoint()
    }

    /// Setpoints the bounds refused so far, and why the last one was.
    pub fn refused_setpoints(&self) -> (u64, Option<crate::link::Refusal>) {
        self.link.refused_setpoints()
    }

    /// Takes one message from the autopilot.
    pub fn on_message(&mut self, now_ns: u64, header: &MavHeader, msg: &MavMessage) {
        self.advance(now_ns);
        self.link.on_message(now_ns, header, msg);
    }

    /// Counts frames or datagrams that did not parse (reported in the link health).
    pub fn on_parse_errors(&mut self, count: u64) {
        self.link.add_parse_errors(count);
    }

    /// Advances time: what to send to the autopilot now, in order (for inspection; to send,
    /// use [`Self::send_due`], which also numbers them).
    pub fn poll(&mut self, now_ns: u64) -> &[MavMessage] {
        self.advance(now_ns);
        self.link.poll(now_ns)
    }

    /// Advances time and hands what is due for the autopilot to `send`, in order, each with
    /// its header: our ids and a sequence that counts up across calls, so the autopilot can
    /// count what it lost. Stops at the first error `send` returns.
    pub fn send_due<E>(
        &mut self,
        now_ns: u64,
        mut send: impl FnMut(MavHeader, &MavMessage) -> Result<(), E>,
    ) -> Result<(), E> {
        self.advance(now_ns);
        let base = self.link.header(0);
        for m in self.link.poll(now_ns) {
            let header = MavHeader {
                sequence: self.sequence,
                ..base
            };
            self.sequence = self.sequence.wrapping_add(1);
            send(header, m)?;
        }
        Ok(())
    }

    /// The outcomes of requests that ended since the last call, oldest first.
    pub fn take_outcomes(&mut self) -> Vec<LinkOutcome> {
        self.collect();
        std::mem::take(&mut self.outcomes)
    }

    /// Pairs the link's outcomes with the ids of the requests, in order.
    fn collect(&mut self) {
        for (request, o) in self.link.take_outcomes() {
            let Some((id, kind)) = self.ids.pop_front() else {
                // Cannot happen: every request entering the link has its id queued.
                tracing::error!(?request, ?o, "outcome without a request id");
                continue;
            };
            let (code, result) = match o {
                Outcome::Accepted => (
                    LinkOutcomeKind::Accepted,
                    MavResult::MAV_RESULT_ACCEPTED as u32,
                ),
                Outcome::Rejected(r) => (LinkOutcomeKind::Rejected, r as u32),
                Outcome::TimedOut => (LinkOutcomeKind::TimedOut, 0),
                Outcome::NoSetpointStream => (LinkOutcomeKind::NoSetpointStream, 0),
                Outcome::NoAltitudeReference => (LinkOutcomeKind::NoAltitudeReference, 0),
            };
            if code != LinkOutcomeKind::Accepted {
                tracing::info!(id, ?request, ?o, "request not accepted");
            }
            self.outcomes
                .push(outcome(self.now_ns, id, kind, code, result));
        }
    }

    /// The vehicle state to publish now, if any: when new telemetry arrived since the
    /// last one handed out, when the link's connection changed, and every
    /// [`STALE_STATE_PERIOD_NS`] otherwise. `capture_ns` is when the autopilot measured
    /// the newest telemetry (its clock mapped onto ours), `link.last_telemetry_ns` when
    /// that telemetry arrived (our clock): a state without new telemetry keeps both, and
    /// consumers judge staleness by the arrival, never by the mapped time (a mapping
    /// can be off; an arrival cannot), and by `link.connected == 0` once heartbeats
    /// stop. `None` until position and attitude have both arrived.
    pub fn vehicle_state(&mut self, now_ns: u64) -> Option<VehicleState> {
        self.advance(now_ns);
        let mut state = self.link.vehicle_state(now_ns)?;
        let capture = state.msg.capture_ns;
        let connected = state.link.connected;
        let due = match self.last_state {
            None => true,
            Some((last_capture, last_sent, last_connected)) => {
                capture != last_capture
                    || connected != last_connected
                    || now_ns.saturating_sub(last_sent) >= STALE_STATE_PERIOD_NS
            }
        };
        if !due {
            return None;
        }
        self.last_state = Some((capture, now_ns, connected));
        state.msg.push_stage(Stage::Px4Link, capture, now_ns);
        Some(state)
    }

    /// What the link knows of the autopilot now.
    pub fn status(&self, now_ns: u64) -> Status {
        self.link.status(now_ns)
    }

    /// The autopilot's clock as mapped onto ours.
    pub fn autopilot_clock(&self) -> &crate::clock::AutopilotClock {
        self.link.autopilot_clock()
    }

    /// The point the geofence is centred on (ENU).
    pub fn home(&self) -> Option<nalgebra::Vector3<f64>> {
        self.link.home()
    }
}

/// The link request a [`LinkRequest`] asks for, or `None` when it cannot be read.
pub fn to_request(r: &LinkRequest) -> Option<Request> {
    Some(match LinkRequestKind::from_raw(r.kind)? {
        LinkRequestKind::Arm => Request::Arm,
        LinkRequestKind::Disarm => Request::Disarm,
        LinkRequestKind::Touchdown => Request::ForceDisarm,
        LinkRequestKind::Takeoff => {
            if !(r.altitude_m.is_finite() && r.altitude_m > 0.0) {
                return None;
            }
            Request::Takeoff {
                altitude_m: r.altitude_m as f32,
            }
        }
        LinkRequestKind::Offboard => Request::Offboard,
        LinkRequestKind::Land => Request::Land,
        LinkRequestKind::Hold => Request::Hold,
    })
}

fn outcome(now_ns: u64, id: u64, kind: u32, code: LinkOutcomeKind, result: u32) -> LinkOutcome {
    // Stamped as every publisher's message: when it left is what a replay orders by.
    let mut msg = Header::captured_at(now_ns);
    msg.push_stage(Stage::Px4Link, now_ns, now_ns);
    LinkOutcome {
        msg,
        id,
        kind,
        outcome: code as u32,
        result,
        reserved: 0,
    }
}

#[cfg(test)]
#[path = "node_test.rs"]
mod tests;
