//! The one list of payload kinds: every kind of message the stack moves, what it is made
//! of and how it travels, written once in [`for_each_payload!`](crate::for_each_payload).
//!
//! Why a list and not a trait: a driver routes any topic by name at run time, so every
//! place that turns a payload kind into code (the [`Payload`](crate::topics::Payload)
//! enum, the stage's `Message` and `OwnedMessage`, the iceoryx2 driver's typed ports, the
//! recorder's schemas and its reader) needs one `match` arm per kind. Written by hand
//! those arms were spelled out in five files (32 `Payload::` arms in the driver alone)
//! and a new payload had to find every one. Now each of those places hands a local
//! `macro_rules!` callback to [`for_each_payload!`](crate::for_each_payload), which
//! writes the arms from this list; what differs genuinely per payload (a Foxglove
//! picture, a fault that only images take) stays hand-written beside it.
//!
//! Adding a payload: its struct in [`crate::msg`] (with its versioned `#[type_name]`),
//! one line below, its topic(s) in [`crate::topics::TABLE`] (and service names in
//! [`crate::services`]), and the graph file. A test holds every name here to the type's
//! own `#[type_name]`.

/// Calls `$callback! { .. }` with every payload kind of the stack, grouped by how it is
/// made and how it travels, so that the callback can write one arm (or variant, or
/// impl) per payload from one pattern per group. The groups, in this order, each a
/// bracketed list (possibly empty) of entries separated and ended by commas:
///
/// - `structs: [ $(#[doc])* Name(Type => Owned) = "type/name", .. ]`: one `#[repr(C)]`
///   struct with a [`Header`](crate::msg::Header) in `msg`, on shared memory between
///   pipeline stages (read by stages, faults may be injected into it). `Owned` is how an
///   owned copy holds it (`Box<Type>` for the large ones, so a queue of small messages
///   stays small).
/// - `truth: [ .. ]`, the same shape: the simulator's ground truth on evaluator-only
///   topics: published on shared memory, never read by a pipeline stage, never faulted
///   (it is the world's record, not the stack's data).
/// - `slices: [ $(#[doc])* Name(Header, [Element]) = "type/name", .. ]`: a header
///   struct (with its [`Header`](crate::msg::Header) in `msg`) followed by a slice of
///   `Element`s in the same shared-memory sample (frames, maps); `"type/name"` is the
///   header's.
/// - `local: [ $(#[doc])* Name(Type) = "type/name", .. ]`: a struct that never crosses
///   shared memory (delivered inside one process by the runtime), so no port carries it
///   and no recording holds it.
/// - `bytes: [ $(#[doc])* Name = "description", .. ]`: raw bytes of an outside protocol
///   (MAVLink), carried by the stage's own I/O, no header.
///
/// Types are written as full `$crate::msg::..` paths, so a callback in any crate can use
/// them as they come. A callback matches the groups it needs and takes the others as
/// `$($x:tt)*`.
///
/// ```
/// macro_rules! names {
///     (structs: [$($(#[$d:meta])* $name:ident($t:ty => $o:ty) = $tn:literal,)*],
///      $($rest:tt)*) => {
///         const STRUCTS: &[&str] = &[$(stringify!($name)),*];
///     };
/// }
/// ipc_types::for_each_payload!(names);
/// assert!(STRUCTS.contains(&"VehicleState"));
/// ```
#[macro_export]
macro_rules! for_each_payload {
    ($callback:ident) => {
        $callback! {
            structs: [
                /// The vehicle's estimated state (px4-link).
                VehicleState($crate::msg::VehicleState => $crate::msg::VehicleState)
                    = "landing::VehicleState/v2",
                /// A visual-inertial odometry sample (sim, a tracking camera).
                VioOdometry($crate::msg::VioOdometry => $crate::msg::VioOdometry)
                    = "landing::VioOdometry/v1",
                /// A pad observation (aruco-pnp).
                PadObservation($crate::msg::PadObservation => $crate::msg::PadObservation)
                    = "landing::PadObservation/v1",
                /// A goal for the planner (fsm).
                PlannerGoal($crate::msg::PlannerGoal => $crate::msg::PlannerGoal)
                    = "landing::PlannerGoal/v1",
                /// A planned trajectory (planner); boxed when owned (1.6 kB).
                Trajectory($crate::msg::Trajectory => Box<$crate::msg::Trajectory>)
                    = "landing::Trajectory/v1",
                /// Planning statistics (planner).
                PlannerStats($crate::msg::PlannerStats => $crate::msg::PlannerStats)
                    = "landing::PlannerStats/v1",
                /// A setpoint (fsm; px4-link as sent).
                Setpoint($crate::msg::Setpoint => $crate::msg::Setpoint)
                    = "landing::Setpoint/v1",
                /// A request to the autopilot (fsm).
                LinkRequest($crate::msg::LinkRequest => $crate::msg::LinkRequest)
                    = "landing::LinkRequest/v1",
                /// A request's outcome (px4-link).
                LinkOutcome($crate::msg::LinkOutcome => $crate::msg::LinkOutcome)
                    = "landing::LinkOutcome/v1",
                /// A safety order (watchdog, operator).
                SafetyCommand($crate::msg::SafetyCommand => $crate::msg::SafetyCommand)
                    = "landing::SafetyCommand/v1",
                /// The mission status (fsm).
                FsmStatus($crate::msg::FsmStatus => $crate::msg::FsmStatus)
                    = "landing::FsmStatus/v2",
                /// The watchdog's view of the stack; boxed when owned (1.7 kB).
                WatchdogView($crate::msg::WatchdogView => Box<$crate::msg::WatchdogView>)
                    = "landing::WatchdogView/v4",
            ],
            truth: [
                /// A ground-truth event (evaluator only).
                TruthEvent($crate::msg::TruthEvent => $crate::msg::TruthEvent)
                    = "landing::TruthEvent/v2",
                /// The ground-truth state (evaluator only).
                TruthState($crate::msg::TruthState => $crate::msg::TruthState)
                    = "landing::TruthState/v3",
            ],
            slices: [
                /// A camera frame: header and pixels.
                CameraFrame($crate::msg::CameraFrameHeader, [u8])
                    = "landing::CameraFrameHeader/v1",
                /// A depth frame: header and depths.
                DepthFrame($crate::msg::DepthFrameHeader, [u16])
                    = "landing::DepthFrameHeader/v1",
                /// The occupancy window: header and cells.
                OccupancyMap($crate::msg::OccupancyMapHeader, [u8])
                    = "landing::OccupancyMapHeader/v2",
            ],
            local: [
                /// A heartbeat, death or CPU time of a supervised process (the watchdog's
                /// input, delivered inside its process by the runtime).
                ProcessEvent($crate::msg::ProcessEvent) = "landing::ProcessEvent/v2",
            ],
            bytes: [
                /// MAVLink 2 bytes: one datagram, or a chunk of a serial byte stream.
                Mavlink = "MAVLink 2",
            ],
        }
    };
}

#[cfg(test)]
#[path = "payloads_test.rs"]
mod tests;
