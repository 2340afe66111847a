//! Messages as stages see them: borrowed for a call ([`Message`]), owned while a driver
//! queues them ([`OwnedMessage`]).

use ipc_types::msg::{
    CameraFrameHeader, DepthFrameHeader, FsmStatus, Header, LinkOutcome, LinkRequest,
    OccupancyMapHeader, PadObservation, PlannerGoal, PlannerStats, ProcessEvent, SafetyCommand,
    Setpoint, Trajectory, TruthEvent, TruthState, VehicleState, WatchdogView,
};
use ipc_types::topics::Payload;

/// One message of any topic, borrowed.
#[derive(Debug, Clone, Copy)]
pub enum Message<'a> {
    /// A camera frame: header and pixels.
    CameraFrame(&'a CameraFrameHeader, &'a [u8]),
    /// A depth frame: header and depths.
    DepthFrame(&'a DepthFrameHeader, &'a [u16]),
    /// The occupancy window: header and cells.
    OccupancyMap(&'a OccupancyMapHeader, &'a [u8]),
    /// The vehicle state.
    VehicleState(&'a VehicleState),
    /// A pad observation.
    PadObservation(&'a PadObservation),
    /// A planner goal.
    PlannerGoal(&'a PlannerGoal),
    /// A trajectory.
    Trajectory(&'a Trajectory),
    /// Planning statistics.
    PlannerStats(&'a PlannerStats),
    /// A setpoint.
    Setpoint(&'a Setpoint),
    /// A request to the autopilot.
    LinkRequest(&'a LinkRequest),
    /// A request's outcome.
    LinkOutcome(&'a LinkOutcome),
    /// A safety order.
    SafetyCommand(&'a SafetyCommand),
    /// The mission status.
    FsmStatus(&'a FsmStatus),
    /// The watchdog's view.
    WatchdogView(&'a WatchdogView),
    /// A heartbeat or death of a supervised process (watchdog input).
    ProcessEvent(&'a ProcessEvent),
    /// A ground-truth event (evaluator only).
    TruthEvent(&'a TruthEvent),
    /// The ground-truth state (evaluator only).
    TruthState(&'a TruthState),
    /// MAVLink bytes: one datagram, or a chunk of a byte stream.
    Mavlink(&'a [u8]),
}

impl Message<'_> {
    /// The payload kind, to check it against the topic's.
    pub fn payload(&self) -> Payload {
        match self {
            Self::CameraFrame(..) => Payload::CameraFrame,
            Self::DepthFrame(..) => Payload::DepthFrame,
            Self::OccupancyMap(..) => Payload::OccupancyMap,
            Self::VehicleState(_) => Payload::VehicleState,
            Self::PadObservation(_) => Payload::PadObservation,
            Self::PlannerGoal(_) => Payload::PlannerGoal,
            Self::Trajectory(_) => Payload::Trajectory,
            Self::PlannerStats(_) => Payload::PlannerStats,
            Self::Setpoint(_) => Payload::Setpoint,
            Self::LinkRequest(_) => Payload::LinkRequest,
            Self::LinkOutcome(_) => Payload::LinkOutcome,
            Self::SafetyCommand(_) => Payload::SafetyCommand,
            Self::FsmStatus(_) => Payload::FsmStatus,
            Self::WatchdogView(_) => Payload::WatchdogView,
            Self::ProcessEvent(_) => Payload::ProcessEvent,
            Self::TruthEvent(_) => Payload::TruthEvent,
            Self::TruthState(_) => Payload::TruthState,
            Self::Mavlink(_) => Payload::Mavlink,
        }
    }

    /// The message's header (`None` for MAVLink bytes).
    pub fn header(&self) -> Option<&Header> {
        Some(match self {
            Self::CameraFrame(h, _) => &h.msg,
            Self::DepthFrame(h, _) => &h.msg,
            Self::OccupancyMap(h, _) => &h.msg,
            Self::VehicleState(m) => &m.msg,
            Self::PadObservation(m) => &m.msg,
            Self::PlannerGoal(m) => &m.msg,
            Self::Trajectory(m) => &m.msg,
            Self::PlannerStats(m) => &m.msg,
            Self::Setpoint(m) => &m.msg,
            Self::LinkRequest(m) => &m.msg,
            Self::LinkOutcome(m) => &m.msg,
            Self::SafetyCommand(m) => &m.msg,
            Self::FsmStatus(m) => &m.msg,
            Self::WatchdogView(m) => &m.msg,
            Self::ProcessEvent(m) => &m.msg,
            Self::TruthEvent(m) => &m.msg,
            Self::TruthState(m) => &m.msg,
            Self::Mavlink(_) => return None,
        })
    }

    /// An owned copy, for a queue.
    pub fn to_owned(&self) -> OwnedMessage {
        match *self {
            Self::CameraFrame(h, p) => OwnedMessage::CameraFrame(*h, p.to_vec()),
            Self::DepthFrame(h, p) => OwnedMessage::DepthFrame(*h, p.to_vec()),
            Self::OccupancyMap(h, p) => OwnedMessage::OccupancyMap(*h, p.to_vec()),
            Self::VehicleState(m) => OwnedMessage::VehicleState(*m),
            Self::PadObservation(m) => OwnedMessage::PadObservation(*m),
            Self::PlannerGoal(m) => OwnedMessage::PlannerGoal(*m),
            Self::Trajectory(m) => OwnedMessage::Trajectory(Box::new(*m)),
            Self::PlannerStats(m) => OwnedMessage::PlannerStats(*m),
            Self::Setpoint(m) => OwnedMessage::Setpoint(*m),
            Self::LinkRequest(m) => OwnedMessage::LinkRequest(*m),
            Self::LinkOutcome(m) => OwnedMessage::LinkOutcome(*m),
            Self::SafetyCommand(m) => OwnedMessage::SafetyCommand(*m),
            Self::FsmStatus(m) => OwnedMessage::FsmStatus(*m),
            Self::WatchdogView(m) => OwnedMessage::WatchdogView(Box::new(*m)),
            Self::ProcessEvent(m) => OwnedMessage::ProcessEvent(*m),
            Self::TruthEvent(m) => OwnedMessage::TruthEvent(*m),
            Self::TruthState(m) => OwnedMessage::TruthState(*m),
            Self::Mavlink(b) => OwnedMessage::Mavlink(b.to_vec()),
        }
    }
}

/// One message of any topic, owned (a driver's queue, a recording, a test). Small
/// messages stay inline: a queue holds them behind an `Rc` anyway.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq)]
pub enum OwnedMessage {
    /// See [`Message::CameraFrame`].
    CameraFrame(CameraFrameHeader, Vec<u8>),
    /// See [`Message::DepthFrame`].
    DepthFrame(DepthFrameHeader, Vec<u16>),
    /// See [`Message::OccupancyMap`].
    OccupancyMap(OccupancyMapHeader, Vec<u8>),
    /// See [`Message::VehicleState`].
    VehicleState(VehicleState),
    /// See [`Message::PadObservation`].
    PadObservation(PadObservation),
    /// See [`Message::PlannerGoal`].
    PlannerGoal(PlannerGoal),
    /// See [`Message::Trajectory`] (boxed: 1.6 kB).
    Trajectory(Box<Trajectory>),
    /// See [`Message::PlannerStats`].
    PlannerStats(PlannerStats),
    /// See [`Message::Setpoint`].
    Setpoint(Setpoint),
    /// See [`Message::LinkRequest`].
    LinkRequest(LinkRequest),
    /// See [`Message::LinkOutcome`].
    LinkOutcome(LinkOutcome),
    /// See [`Message::SafetyCommand`].
    SafetyCommand(SafetyCommand),
    /// See [`Message::FsmStatus`].
    FsmStatus(FsmStatus),
    /// See [`Message::WatchdogView`] (boxed: 1.7 kB).
    WatchdogView(Box<WatchdogView>),
    /// See [`Message::ProcessEvent`].
    ProcessEvent(ProcessEvent),
    /// See [`Message::TruthEvent`].
    TruthEvent(TruthEvent),
    /// See [`Message::TruthState`].
    TruthState(TruthState),
    /// See [`Message::Mavlink`].
    Mavlink(Vec<u8>),
}

impl OwnedMessage {
    /// Borrowed, for a stage call.
    pub fn as_message(&self) -> Message<'_> {
        match self {
            Self::CameraFrame(h, p) => Message::CameraFrame(h, p),
            Self::DepthFrame(h, p) => Message::DepthFrame(h, p),
            Self::OccupancyMap(h, p) => Message::OccupancyMap(h, p),
            Self::VehicleState(m) => Message::VehicleState(m),
            Self::PadObservation(m) => Message::PadObservation(m),
            Self::PlannerGoal(m) => Message::PlannerGoal(m),
            Self::Trajectory(m) => Message::Trajectory(m),
            Self::PlannerStats(m) => Message::PlannerStats(m),
            Self::Setpoint(m) => Message::Setpoint(m),
            Self::LinkRequest(m) => Message::LinkRequest(m),
            Self::LinkOutcome(m) => Message::LinkOutcome(m),
            Self::SafetyCommand(m) => Message::SafetyCommand(m),
            Self::FsmStatus(m) => Message::FsmStatus(m),
            Self::WatchdogView(m) => Message::WatchdogView(m),
            Self::ProcessEvent(m) => Message::ProcessEvent(m),
            Self::TruthEvent(m) => Message::TruthEvent(m),
            Self::TruthState(m) => Message::TruthState(m),
            Self::Mavlink(b) => Message::Mavlink(b),
        }
    }

    /// The header, to stamp a stage's exit (`None` for MAVLink bytes).
    pub fn header_mut(&mut self) -> Option<&mut Header> {
        Some(match self {
            Self::CameraFrame(h, _) => &mut h.msg,
            Self::DepthFrame(h, _) => &mut h.msg,
            Self::OccupancyMap(h, _) => &mut h.msg,
            Self::VehicleState(m) => &mut m.msg,
            Self::PadObservation(m) => &mut m.msg,
            Self::PlannerGoal(m) => &mut m.msg,
            Self::Trajectory(m) => &mut m.msg,
            Self::PlannerStats(m) => &mut m.msg,
            Self::Setpoint(m) => &mut m.msg,
            Self::LinkRequest(m) => &mut m.msg,
            Self::LinkOutcome(m) => &mut m.msg,
            Self::SafetyCommand(m) => &mut m.msg,
            Self::FsmStatus(m) => &mut m.msg,
            Self::WatchdogView(m) => &mut m.msg,
            Self::ProcessEvent(m) => &mut m.msg,
            Self::TruthEvent(m) => &mut m.msg,
            Self::TruthState(m) => &mut m.msg,
            Self::Mavlink(_) => return None,
        })
    }
}

/// The output buffer [`crate::Outbox::publish_slice`] lends a stage.
#[derive(Debug)]
pub enum SliceMut<'a> {
    /// Pixels or cells.
    U8(&'a mut [u8]),
    /// Depths.
    U16(&'a mut [u16]),
}

/// The header a stage returns for a slice it filled.
#[derive(Debug, Clone, Copy)]
pub enum SliceHeader {
    /// A camera frame.
    CameraFrame(CameraFrameHeader),
    /// A depth frame.
    DepthFrame(DepthFrameHeader),
    /// The occupancy window.
    OccupancyMap(OccupancyMapHeader),
}

impl SliceHeader {
    /// The payload kind.
    pub fn payload(&self) -> Payload {
        match self {
            Self::CameraFrame(_) => Payload::CameraFrame,
            Self::DepthFrame(_) => Payload::DepthFrame,
            Self::OccupancyMap(_) => Payload::OccupancyMap,
        }
    }
}
