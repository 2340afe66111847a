//! The topic table: every topic's short name (what the graph, the stages and the
//! recordings call it), its iceoryx2 service and the payload it carries. The one place
//! that names a topic; `deploy/graph.toml` is checked against it by a test.

use crate::services;

/// Writes [`Payload`] and its methods from the payload list.
macro_rules! payload_enum {
    (
        structs: [$($(#[$sd:meta])* $s:ident($st:ty => $so:ty) = $sn:literal,)*],
        truth: [$($(#[$td:meta])* $t:ident($tt:ty => $to:ty) = $tn:literal,)*],
        slices: [$($(#[$cd:meta])* $c:ident($ch:ty, [$ce:ty]) = $cn:literal,)*],
        local: [$($(#[$ld:meta])* $l:ident($lt:ty) = $ln:literal,)*],
        bytes: [$($(#[$bd:meta])* $b:ident = $bn:literal,)*],
    ) => {
        /// What a topic carries: one payload kind (slices: a header type, with elements).
        /// The kinds are those of [`crate::for_each_payload!`], the one list of them.
        #[derive(Debug, Clone, Copy, PartialEq, Eq)]
        pub enum Payload {
            $($(#[$sd])* $s,)*
            $($(#[$td])* $t,)*
            $($(#[$cd])* $c,)*
            $($(#[$ld])* $l,)*
            $($(#[$bd])* $b,)*
        }

        impl Payload {
            /// Every payload kind, in the list's order.
            pub const ALL: &[Payload] = &[
                $(Self::$s,)* $(Self::$t,)* $(Self::$c,)* $(Self::$l,)* $(Self::$b,)*
            ];

            /// The versioned type name (for slices, the header's), as the graph file
            /// writes it and recordings name their schemas.
            pub fn type_name(self) -> &'static str {
                match self {
                    $(Self::$s => $sn,)*
                    $(Self::$t => $tn,)*
                    $(Self::$c => $cn,)*
                    $(Self::$l => $ln,)*
                    $(Self::$b => $bn,)*
                }
            }

            /// The slice element type, for payloads that are a header plus a slice.
            pub fn elements(self) -> Option<&'static str> {
                match self {
                    $(Self::$c => Some(stringify!($ce)),)*
                    _ => None,
                }
            }
        }
    };
}
crate::for_each_payload!(payload_enum);

/// One row of the table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TopicInfo {
    /// Short name: `camera/frame`.
    pub name: &'static str,
    /// The iceoryx2 service (`None`: not iceoryx2: MAVLink, or a camera device read by
    /// camera-ingest itself).
    pub service: Option<&'static str>,
    /// What it carries.
    pub payload: Payload,
    /// Ground truth: the evaluator reads it, no pipeline stage may.
    pub evaluator_only: bool,
}

impl TopicInfo {
    /// The channel name in recordings: `/camera/frame`.
    pub fn recording_name(&self) -> String {
        format!("/{}", self.name)
    }
}

/// Simulator camera frames.
pub const SIM_CAMERA: &str = "sim/camera";
/// Simulator depth frames.
pub const SIM_DEPTH: &str = "sim/depth";
/// Ground-truth events (evaluator only).
pub const SIM_TRUTH: &str = "sim/truth";
/// Ground-truth state (evaluator only).
pub const SIM_TRUTH_STATE: &str = "sim/truth_state";
/// MAVLink from the autopilot.
pub const MAVLINK_FROM_PX4: &str = "mavlink/from-px4";
/// MAVLink to the autopilot.
pub const MAVLINK_TO_PX4: &str = "mavlink/to-px4";
/// Datagrams on a MAVLink link from an address other than the configured peer's: a
/// stage counts them and never decodes them. Served by the UDP link, not iceoryx2.
pub const MAVLINK_FOREIGN: &str = "mavlink/foreign";
/// PX4 SITL's simulator link, PX4 to the simulator (HIL_ACTUATOR_CONTROLS, HEARTBEAT):
/// a TCP byte stream the simulator serves with `--px4-sitl`, not iceoryx2.
pub const HIL_FROM_PX4: &str = "hil/from-px4";
/// PX4 SITL's simulator link, the simulator to PX4 (HIL_SENSOR, HIL_STATE_QUATERNION).
pub const HIL_TO_PX4: &str = "hil/to-px4";
/// Frames from a camera device, a GStreamer pipeline or a recording, read by
/// camera-ingest itself (OpenCV, on its capture thread): not iceoryx2. camera-ingest
/// reads this instead of `sim/camera` when its source is not the simulator.
pub const CAMERA_DEVICE: &str = "camera/device";
/// Depth frames from a recording or a depth camera, read by depth-ingest itself (on its
/// capture thread): not iceoryx2.
pub const DEPTH_DEVICE: &str = "depth/device";
/// Camera frames as the pipeline sees them.
pub const CAMERA_FRAME: &str = "camera/frame";
/// Depth frames from a real depth camera driver (depth-map `--input depth-frame`).
pub const DEPTH_FRAME: &str = "depth/frame";
/// Pad observations.
pub const PAD_OBSERVATION: &str = "pad/observation";
/// The estimated vehicle state.
pub const VEHICLE_STATE: &str = "vehicle/state";
/// Visual-inertial odometry, for the autopilot's estimator.
pub const VIO_ODOMETRY: &str = "vio/odometry";
/// The occupancy window.
pub const MAP_OCCUPANCY: &str = "map/occupancy";
/// Planner goals.
pub const PLANNER_GOAL: &str = "planner/goal";
/// Planned trajectories.
pub const PLANNER_TRAJECTORY: &str = "planner/trajectory";
/// Planning statistics.
pub const PLANNER_STATS: &str = "planner/stats";
/// Requests to the autopilot.
pub const PX4_REQUEST: &str = "px4/request";
/// Outcomes of requests.
pub const PX4_OUTCOME: &str = "px4/outcome";
/// Setpoints.
pub const FSM_SETPOINT: &str = "fsm/setpoint";
/// Each new setpoint as px4-link put it on the MAVLink wire: its header carries the
/// camera capture it derives from and every stage's stamp up to the wire.
pub const PX4_SETPOINT_SENT: &str = "px4/setpoint_sent";
/// Mission status.
pub const FSM_STATUS: &str = "fsm/status";
/// Safety orders.
pub const SAFETY_COMMAND: &str = "safety/command";
/// The watchdog's view of the stack.
pub const WATCHDOG_VIEW: &str = "watchdog/view";
/// Heartbeats and deaths of the supervised processes, as the runtime sees them: served
/// inside the watchdog's process (heartbeat events, iceoryx2's node list), not iceoryx2.
pub const WATCHDOG_LIVENESS: &str = "watchdog/liveness";

const fn row(name: &'static str, service: &'static str, payload: Payload) -> TopicInfo {
    TopicInfo {
        name,
        service: Some(service),
        payload,
        evaluator_only: false,
    }
}

/// Every topic of the stack.
pub const TABLE: &[TopicInfo] = &[
    row(SIM_CAMERA, services::SIM_CAMERA, Payload::CameraFrame),
    row(SIM_DEPTH, services::SIM_DEPTH, Payload::DepthFrame),
    TopicInfo {
        evaluator_only: true,
        ..row(SIM_TRUTH, services::SIM_TRUTH, Payload::TruthEvent)
    },
    TopicInfo {
        evaluator_only: true,
        ..row(
            SIM_TRUTH_STATE,
            services::SIM_TRUTH_STATE,
            Payload::TruthState,
        )
    },
    TopicInfo {
        name: MAVLINK_FROM_PX4,
        service: None,
        payload: Payload::Mavlink,
        evaluator_only: false,
    },
    TopicInfo {
        name: MAVLINK_TO_PX4,
        service: None,
        payload: Payload::Mavlink,
        evaluator_only: false,
    },
    TopicInfo {
        name: MAVLINK_FOREIGN,
        service: None,
        payload: Payload::Mavlink,
        evaluator_only: false,
    },
    TopicInfo {
        name: HIL_FROM_PX4,
        service: None,
        payload: Payload::Mavlink,
        evaluator_only: false,
    },
    TopicInfo {
        name: HIL_TO_PX4,
        service: None,
        payload: Payload::Mavlink,
        evaluator_only: false,
    },
    TopicInfo {
        name: CAMERA_DEVICE,
        service: None,
        payload: Payload::CameraFrame,
        evaluator_only: false,
    },
    TopicInfo {
        name: DEPTH_DEVICE,
        service: None,
        payload: Payload::DepthFrame,
        evaluator_only: false,
    },
    row(CAMERA_FRAME, services::CAMERA_FRAME, Payload::CameraFrame),
    row(DEPTH_FRAME, services::DEPTH_FRAME, Payload::DepthFrame),
    row(
        PAD_OBSERVATION,
        services::PAD_OBSERVATION,
        Payload::PadObservation,
    ),
    row(
        VEHICLE_STATE,
        services::VEHICLE_STATE,
        Payload::VehicleState,
    ),
    row(VIO_ODOMETRY, services::VIO_ODOMETRY, Payload::VioOdometry),
    row(
        MAP_OCCUPANCY,
        services::MAP_OCCUPANCY,
        Payload::OccupancyMap,
    ),
    row(PLANNER_GOAL, services::PLANNER_GOAL, Payload::PlannerGoal),
    row(
        PLANNER_TRAJECTORY,
        services::PLANNER_TRAJECTORY,
        Payload::Trajectory,
    ),
    row(
        PLANNER_STATS,
        services::PLANNER_STATS,
        Payload::PlannerStats,
    ),
    row(PX4_REQUEST, services::PX4_REQUEST, Payload::LinkRequest),
    row(PX4_OUTCOME, services::PX4_OUTCOME, Payload::LinkOutcome),
    row(FSM_SETPOINT, services::FSM_SETPOINT, Payload::Setpoint),
    row(
        PX4_SETPOINT_SENT,
        services::PX4_SETPOINT_SENT,
        Payload::Setpoint,
    ),
    row(FSM_STATUS, services::FSM_STATUS, Payload::FsmStatus),
    row(
        SAFETY_COMMAND,
        services::SAFETY_COMMAND,
        Payload::SafetyCommand,
    ),
    row(
        WATCHDOG_VIEW,
        services::WATCHDOG_VIEW,
        Payload::WatchdogView,
    ),
    TopicInfo {
        name: WATCHDOG_LIVENESS,
        service: None,
        payload: Payload::ProcessEvent,
        evaluator_only: false,
    },
];

/// The row of `name`, if the stack has such a topic.
pub fn find(name: &str) -> Option<&'static TopicInfo> {
    TABLE.iter().find(|t| t.name == name)
}

/// The row whose iceoryx2 service is `service`.
pub fn by_service(service: &str) -> Option<&'static TopicInfo> {
    TABLE.iter().find(|t| t.service == Some(service))
}
