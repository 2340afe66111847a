//! px4-link as a pipeline stage: MAVLink bytes from the autopilot in (datagrams or a
//! serial byte stream), the fsm's setpoints and requests and the safety orders in;
//! MAVLink bytes to the autopilot, the vehicle state and request outcomes out. The
//! socket or serial port is the binary's; the bytes go through their wire encoding in
//! both drivers.

use ipc_types::msg::Stage as StageId;
use ipc_types::topics;
use mavlink::MavHeader;
use mavlink::dialects::common::MavMessage;
use px4_protocol::codec::{Guard, StreamDecoder};
use px4_protocol::signing::Signer;
use stage::{Counter, Input, Message, Outbox, Stage, StageError};

use crate::{LinkNode, LinkSettings};

/// How often the link is serviced when nothing arrives (resends, timeouts, setpoint
/// stream), ns.
pub const SERVICE_PERIOD_NS: u64 = 2_000_000;

/// How the autopilot's bytes are framed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Framing {
    /// Each input is one UDP datagram of whole frames.
    Datagram,
    /// Inputs are chunks of a byte stream (serial); frames may span chunks.
    Stream,
}

/// The `px4-link` node.
pub struct LinkStage {
    node: LinkNode,
    framing: Framing,
    decoder: StreamDecoder,
    /// What is acted on: the autopilot's frames only, signed when a key is set.
    guard: Guard,
    /// Datagrams from another address than the autopilot's (the UDP link hands them
    /// over on `mavlink/foreign`), never decoded.
    wrong_address: u64,
    decoded: Vec<(MavHeader, MavMessage)>,
    frame: Vec<u8>,
    counts: Counts,
    last_link: ipc_types::msg::LinkHealth,
}

#[derive(Debug, Default, Clone, Copy)]
struct Counts {
    received: u64,
    sent: u64,
    states: u64,
    outcomes: u64,
    setpoints: u64,
    requests: u64,
    safety: u64,
    vio: u64,
}

/// The link id px4-link signs with (one link per companion).
pub const LINK_ID: u8 = 1;

impl LinkStage {
    /// The one way the stage is built, wherever it runs (its process, the lockstep
    /// registry, a fuzz target): from its `[px4_link]` section, how the autopilot's bytes
    /// come (`framing`, from the link the section or a flag names), and the signing key
    /// the section names (read by the caller, which owns the files): signatures are
    /// stamped in Unix time, `unix_ns_at_zero` being the Unix time at the caller's clock's
    /// zero.
    pub fn from_config(
        cfg: &crate::config::Px4LinkConfig,
        framing: Framing,
        key: Option<px4_protocol::signing::SigningKey>,
        unix_ns_at_zero: u64,
    ) -> Self {
        let signer = key.map(|k| Signer::new(k, LINK_ID, unix_ns_at_zero));
        Self::new(cfg.settings(), framing, signer)
    }

    /// The stage of a link with `settings`, reading `framing`; with `signer`, the link
    /// is signed (MAVLink 2 signing: what goes out is signed, what comes in unsigned or
    /// badly signed is counted and dropped).
    pub fn new(settings: LinkSettings, framing: Framing, signer: Option<Signer>) -> Self {
        Self {
            guard: Guard::new(Some(settings.target), signer),
            wrong_address: 0,
            node: LinkNode::new(settings),
            framing,
            decoder: StreamDecoder::new(),
            decoded: Vec::with_capacity(8),
            frame: Vec::with_capacity(280),
            counts: Counts::default(),
            last_link: ipc_types::msg::LinkHealth::default(),
        }
    }

    /// The node, to read the link's status.
    pub fn node(&self) -> &LinkNode {
        &self.node
    }

    /// Sends what is due, then publishes outcomes and the vehicle state when due.
    fn service(&mut self, now_ns: u64, out: &mut dyn Outbox) -> Result<(), StageError> {
        let (frame, counts, guard) = (&mut self.frame, &mut self.counts, &mut self.guard);
        self.node.send_due(now_ns, |header, m| {
            frame.clear();
            guard
                .encode(frame, header, m, now_ns)
                .map_err(|e| StageError::Transport(e.to_string()))?;
            counts.sent += 1;
            out.publish(topics::MAVLINK_TO_PX4, Message::Mavlink(frame))
        })?;
        if let Some((taken_ns, mut sp)) = self.node.take_sent_setpoint() {
            // From taken in to on the wire: the driver closes the stamp when this leaves,
            // after the bytes above.
            sp.msg.push_stage(StageId::Px4Link, taken_ns, now_ns);
            out.publish(topics::PX4_SETPOINT_SENT, Message::Setpoint(&sp))?;
        }
        for o in self.node.take_outcomes() {
            out.publish(topics::PX4_OUTCOME, Message::LinkOutcome(&o))?;
            self.counts.outcomes += 1;
        }
        if let Some(mut state) = self.node.vehicle_state(now_ns) {
            let r = self.guard.rejected();
            let link = &mut state.link;
            link.signed = u32::from(self.guard.signer().is_some());
            link.wrong_address = self.wrong_address;
            link.wrong_source = r.wrong_source;
            link.unknown_id = r.unknown_id;
            link.unsigned = r.unsigned;
            link.bad_signature = r.bad_signature;
            link.replayed = r.replayed;
            out.publish(topics::VEHICLE_STATE, Message::VehicleState(&state))?;
            self.counts.states += 1;
            self.last_link = state.link;
        }
        Ok(())
    }
}

impl Stage for LinkStage {
    fn name(&self) -> &'static str {
        "px4-link"
    }

    fn tick_period_ns(&self) -> Option<u64> {
        Some(SERVICE_PERIOD_NS)
    }

    fn on_input(
        &mut self,
        now_ns: u64,
        input: Input<'_>,
        _out: &mut dyn Outbox,
    ) -> Result<(), StageError> {
        match input.msg {
            Message::Mavlink(_) if input.topic == topics::MAVLINK_FOREIGN => {
                self.wrong_address += 1;
                if self.wrong_address.is_power_of_two() {
                    tracing::warn!(
                        wrong_address = self.wrong_address,
                        "MAVLink datagrams from an address other than the autopilot's dropped"
                    );
                }
            }
            Message::Mavlink(bytes) => {
                self.decoded.clear();
                let (guard, decoded) = (&mut self.guard, &mut self.decoded);
                let errors = match self.framing {
                    Framing::Datagram => self.decoder.push_datagram(bytes, now_ns, guard, decoded),
                    Framing::Stream => self.decoder.push(bytes, now_ns, guard, decoded),
                };
                self.node.on_parse_errors(errors);
                for (h, m) in &self.decoded {
                    self.node.on_message(now_ns, h, m);
                }
                self.counts.received += self.decoded.len() as u64;
            }
            Message::Setpoint(s) => {
                self.counts.setpoints += 1;
                let before = self.node.refused_setpoints().0;
                self.node.on_setpoint(now_ns, s);
                let (refused, why) = self.node.refused_setpoints();
                if refused > before && refused.is_power_of_two() {
                    tracing::warn!(refused, ?why, "setpoint beyond the bounds refused");
                }
            }
            Message::VioOdometry(v) => {
                self.counts.vio += 1;
                self.node.on_vio(now_ns, v);
            }
            Message::LinkRequest(r) => {
                self.counts.requests += 1;
                self.node.on_request(now_ns, r);
            }
            Message::SafetyCommand(c) => {
                self.counts.safety += 1;
                self.node.on_safety(now_ns, c);
            }
            _ => {}
        }
        Ok(())
    }

    fn on_inputs_done(&mut self, now_ns: u64, out: &mut dyn Outbox) -> Result<(), StageError> {
        self.service(now_ns, out)
    }

    fn on_tick(&mut self, now_ns: u64, out: &mut dyn Outbox) -> Result<(), StageError> {
        self.service(now_ns, out)
    }

    fn counters(&self) -> Vec<Counter> {
        let c = self.counts;
        vec![
            ("received", c.received),
            ("sent", c.sent),
            ("parse_errors", u64::from(self.last_link.parse_errors)),
            ("wrong_address", self.wrong_address),
            // Not an attack: frames of other participants (a ground station, a camera
            // behind a router), ignored. The attacks are the signing counters.
            ("from_others", self.guard.rejected().wrong_source),
            ("unknown_id", self.guard.rejected().unknown_id),
            ("unsigned", self.guard.rejected().unsigned),
            ("bad_signature", self.guard.rejected().bad_signature),
            ("replayed", self.guard.rejected().replayed),
            ("messages_lost", self.last_link.messages_lost),
            ("clock_jumps", self.node.autopilot_clock().jumps()),
            ("states", c.states),
            ("outcomes", c.outcomes),
            ("setpoints", c.setpoints),
            ("setpoints_refused", self.node.refused_setpoints().0),
            ("requests", c.requests),
            ("safety", c.safety),
            ("vio", c.vio),
            ("vio_refused", self.node.vio_refused()),
        ]
    }
}

#[cfg(test)]
#[path = "stage_test.rs"]
mod tests;
