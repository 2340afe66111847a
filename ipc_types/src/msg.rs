//! Payloads that cross a process boundary.
//!
//! Every type here is `#[repr(C)]`, has no pointer, heap or `Drop`, and carries a versioned
//! `#[type_name]` so that two separately built binaries agree on it (iceoryx2 compares the
//! name and the size/alignment when a port opens a service). Bump the `/vN` suffix when a
//! layout changes: an old process then fails to connect instead of misreading memory.
//!
//! Enumerations that arrive from shared memory are stored as raw integers with a checked
//! accessor: another process may write any bit pattern, and reading an invalid
//! discriminant into a Rust enum would be undefined behaviour.

use iceoryx2::prelude::ZeroCopySend;

/// How many pipeline stages a message can record on its way through the graph.
pub const MAX_STAGES: usize = 8;
/// How many control points a trajectory can carry (a uniform cubic B-spline).
pub const MAX_CONTROL_POINTS: usize = 64;
/// How many marker ids a pad observation lists.
pub const MAX_MARKERS: usize = 16;
/// How many processes the watchdog reports on.
pub const MAX_WATCHED: usize = 16;
/// Length of fixed text fields (reasons, process names), bytes.
pub const TEXT_LEN: usize = 48;

/// A pipeline stage, used to tag latency stamps.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// The simulator (rendering, physics) or a real sensor driver.
    Sensor = 1,
    /// camera-ingest.
    CameraIngest = 2,
    /// aruco-pnp.
    ArucoPnp = 3,
    /// depth-map.
    DepthMap = 4,
    /// planner.
    Planner = 5,
    /// fsm.
    Fsm = 6,
    /// px4-link.
    Px4Link = 7,
    /// watchdog.
    Watchdog = 8,
    /// depth-ingest.
    DepthIngest = 9,
    /// Benchmarks and tests.
    Bench = 15,
}

impl Stage {
    /// Decodes a raw stage id; `None` for an id no stage has.
    pub fn from_raw(raw: u32) -> Option<Self> {
        Some(match raw {
            1 => Self::Sensor,
            2 => Self::CameraIngest,
            3 => Self::ArucoPnp,
            4 => Self::DepthMap,
            5 => Self::Planner,
            6 => Self::Fsm,
            7 => Self::Px4Link,
            8 => Self::Watchdog,
            9 => Self::DepthIngest,
            15 => Self::Bench,
            _ => return None,
        })
    }

    /// Short name for logs and profiles.
    pub fn name(self) -> &'static str {
        match self {
            Self::Sensor => "sensor",
            Self::CameraIngest => "camera-ingest",
            Self::ArucoPnp => "aruco-pnp",
            Self::DepthMap => "depth-map",
            Self::Planner => "planner",
            Self::Fsm => "fsm",
            Self::Px4Link => "px4-link",
            Self::Watchdog => "watchdog",
            Self::DepthIngest => "depth-ingest",
            Self::Bench => "bench",
        }
    }
}

/// When one stage took a message in and let it out, in monotonic nanoseconds.
#[repr(C)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("landing::StageStamp/v1")]
pub struct StageStamp {
    /// Raw [`Stage`] id.
    pub stage: u32,
    /// Keeps the layout free of implicit padding.
    pub reserved: u32,
    /// When the stage started on the data (monotonic ns).
    pub enter_ns: u64,
    /// When the stage published its result (monotonic ns).
    pub exit_ns: u64,
}

/// The user header of every topic: what end-to-end latency profiling needs.
///
/// `capture_ns` is the capture time of the sensor data the message derives from, carried
/// unchanged down the graph, so that any consumer can tell how old its input really is.
#[repr(C)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("landing::Header/v1")]
pub struct Header {
    /// Per-publisher sequence number, starting at 1; gaps mean drops.
    pub seq: u64,
    /// Capture time of the originating sensor data (monotonic ns); 0 when none.
    pub capture_ns: u64,
    /// Number of valid entries in `stages`.
    pub stage_count: u32,
    /// Keeps the layout free of implicit padding.
    pub reserved: u32,
    /// Stage stamps, oldest first.
    pub stages: [StageStamp; MAX_STAGES],
}

impl Header {
    /// A header for data captured at `capture_ns`, with no stage stamps yet.
    pub fn captured_at(capture_ns: u64) -> Self {
        Self {
            capture_ns,
            ..Self::default()
        }
    }

    /// A header that continues `upstream`'s history: same capture time, same stamps.
    pub fn derived_from(upstream: &Header) -> Self {
        Self {
            seq: 0,
            ..*upstream
        }
    }

    /// Records a stage; when full, the oldest stamp after the first is dropped so that both
    /// the origin and the newest stages stay visible.
    pub fn push_stage(&mut self, stage: Stage, enter_ns: u64, exit_ns: u64) {
        let stamp = StageStamp {
            stage: stage as u32,
            reserved: 0,
            enter_ns,
            exit_ns,
        };
        let n = (self.stage_count as usize).min(MAX_STAGES);
        if n < MAX_STAGES {
            self.stages[n] = stamp;
            self.stage_count = (n + 1) as u32;
        } else {
            self.stages.copy_within(2.., 1);
            self.stages[MAX_STAGES - 1] = stamp;
        }
    }

    /// Closes the newest stamp if it is still open (exit = enter: a stage pushes its stamp
    /// with the time it was called, and cannot know when the message leaves; the driver
    /// that sends it does). A closed stamp is left alone.
    pub fn close_stage(&mut self, exit_ns: u64) {
        let n = (self.stage_count as usize).min(MAX_STAGES);
        if let Some(s) = n.checked_sub(1).and_then(|i| self.stages.get_mut(i))
            && s.exit_ns == s.enter_ns
        {
            s.exit_ns = exit_ns.max(s.enter_ns);
        }
    }

    /// The valid stamps.
    pub fn stages(&self) -> &[StageStamp] {
        &self.stages[..(self.stage_count as usize).min(MAX_STAGES)]
    }
}

/// A point in a plane, metres (a landing-gear foot in the pad frame).
#[repr(C)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("landing::Point2/v1")]
pub struct Point2 {
    /// x, m.
    pub x: f64,
    /// y, m.
    pub y: f64,
}

impl From<[f64; 2]> for Point2 {
    fn from([x, y]: [f64; 2]) -> Self {
        Self { x, y }
    }
}

/// A rigid transform: translation in metres and a unit quaternion (x, y, z, w).
///
/// Named at each use by what it maps (`world_from_body`, `camera_from_pad`).
#[repr(C)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("landing::Pose/v1")]
pub struct Pose {
    /// Translation, metres.
    pub translation: [f64; 3],
    /// Rotation as a unit quaternion, (x, y, z, w).
    pub rotation_xyzw: [f64; 4],
}

impl Default for Pose {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Pose {
    /// The identity transform.
    pub const IDENTITY: Pose = Pose {
        translation: [0.0; 3],
        rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
    };

    /// True when every number is finite: consumers must not act on anything else.
    pub fn is_finite(&self) -> bool {
        self.translation
            .iter()
            .chain(&self.rotation_xyzw)
            .all(|v| v.is_finite())
    }
}

/// Pixel layout of a camera frame.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PixelEncoding {
    /// 8-bit grey.
    Mono8 = 1,
    /// 8-bit blue, green, red (OpenCV's order).
    Bgr8 = 2,
    /// 8-bit red, green, blue.
    Rgb8 = 3,
}

impl PixelEncoding {
    /// Decodes a raw encoding; `None` for an unknown one (the frame must be dropped).
    pub fn from_raw(raw: u32) -> Option<Self> {
        match raw {
            1 => Some(Self::Mono8),
            2 => Some(Self::Bgr8),
            3 => Some(Self::Rgb8),
            _ => None,
        }
    }

    /// Bytes per pixel.
    pub fn bytes_per_pixel(self) -> usize {
        match self {
            Self::Mono8 => 1,
            Self::Bgr8 | Self::Rgb8 => 3,
        }
    }
}

/// Metadata of a camera frame; the pixels are the `[u8]` slice payload behind it.
#[repr(C)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("landing::CameraFrameHeader/v1")]
pub struct CameraFrameHeader {
    /// Sequence, capture time (middle of exposure) and stage stamps.
    pub msg: Header,
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Bytes from one row to the next (>= width * bytes per pixel).
    pub stride: u32,
    /// Raw [`PixelEncoding`].
    pub encoding: u32,
    /// Which camera took the frame (0 = the downward pad camera).
    pub camera_id: u32,
    /// 1 when the pixels were already undistorted (ideal pinhole).
    pub undistorted: u32,
    /// Exposure time, ns.
    pub exposure_ns: u64,
}

impl CameraFrameHeader {
    /// The payload length this header implies, or `None` when the header is inconsistent
    /// (unknown encoding, stride shorter than a row, overflow).
    pub fn expected_len(&self) -> Option<usize> {
        let enc = PixelEncoding::from_raw(self.encoding)?;
        let row = (self.width as usize).checked_mul(enc.bytes_per_pixel())?;
        if (self.stride as usize) < row || self.width == 0 || self.height == 0 {
            return None;
        }
        (self.stride as usize).checked_mul(self.height as usize)
    }
}

/// Pinhole intrinsics, pixels.
#[repr(C)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("landing::Intrinsics/v1")]
pub struct Intrinsics {
    /// Focal length x, px.
    pub fx: f64,
    /// Focal length y, px.
    pub fy: f64,
    /// Principal point x, px.
    pub cx: f64,
    /// Principal point y, px.
    pub cy: f64,
}

/// Metadata of a depth frame; the depths are the `[u16]` slice payload behind it.
#[repr(C)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("landing::DepthFrameHeader/v1")]
pub struct DepthFrameHeader {
    /// Sequence, capture time and stage stamps.
    pub msg: Header,
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Metres per depth unit (0.001 for a D435 in its default mode).
    pub depth_scale_m: f64,
    /// Intrinsics of the depth image.
    pub intrinsics: Intrinsics,
    /// Which depth camera (0 = forward).
    pub camera_id: u32,
    /// Keeps the layout free of implicit padding.
    pub reserved: u32,
}

/// The pad pose seen in one camera frame.
#[repr(C)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("landing::PadObservation/v1")]
pub struct PadObservation {
    /// Sequence, capture time of the frame, stage stamps.
    pub msg: Header,
    /// Pad in the camera's optical frame.
    pub camera_from_pad: Pose,
    /// Pad in the world, through the vehicle state at capture time.
    pub world_from_pad: Pose,
    /// Covariance of world_from_pad, (x, y, z, roll, pitch, yaw), row-major.
    #[cfg_attr(
        feature = "serde",
        serde(serialize_with = "ser::array", deserialize_with = "de::array")
    )]
    pub covariance: [f64; 36],
    /// RMS reprojection error over all used corners, px.
    pub reprojection_error_px: f64,
    /// Number of valid entries in `marker_ids`.
    pub marker_count: u32,
    /// 1 when `world_from_pad` and its covariance hold: a vehicle state covered the
    /// capture time. 0: only `camera_from_pad` is meaningful.
    pub world_valid: u32,
    /// Ids of the markers whose corners went into the pose.
    pub marker_ids: [u32; MAX_MARKERS],
}

impl Default for PadObservation {
    fn default() -> Self {
        Self {
            msg: Header::default(),
            camera_from_pad: Pose::IDENTITY,
            world_from_pad: Pose::IDENTITY,
            covariance: [0.0; 36],
            reprojection_error_px: 0.0,
            marker_count: 0,
            world_valid: 0,
            marker_ids: [0; MAX_MARKERS],
        }
    }
}

/// PX4 flight mode as px4-link decodes it from HEARTBEAT.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FlightMode {
    /// Not known (no heartbeat yet, or a mode this stack does not name).
    Unknown = 0,
    /// Manual / stabilized / altitude / position modes: a pilot flies.
    Manual = 1,
    /// AUTO.TAKEOFF.
    Takeoff = 2,
    /// AUTO.LOITER (hold).
    Hold = 3,
    /// AUTO.LAND or AUTO.PRECLAND.
    Land = 4,
    /// OFFBOARD: this stack flies.
    Offboard = 5,
    /// AUTO.RTL.
    ReturnToLaunch = 6,
    /// AUTO.MISSION.
    Mission = 7,
}

impl FlightMode {
    /// Decodes a raw mode; unknown values read as [`FlightMode::Unknown`].
    pub fn from_raw(raw: u32) -> Self {
        match raw {
            1 => Self::Manual,
            2 => Self::Takeoff,
            3 => Self::Hold,
            4 => Self::Land,
            5 => Self::Offboard,
            6 => Self::ReturnToLaunch,
            7 => Self::Mission,
            _ => Self::Unknown,
        }
    }
}

/// Landed state as PX4's EXTENDED_SYS_STATE reports it.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LandedState {
    /// Not reported.
    Unknown = 0,
    /// On the ground.
    OnGround = 1,
    /// Flying.
    InAir = 2,
    /// Taking off.
    Takeoff = 3,
    /// Landing.
    Landing = 4,
}

impl LandedState {
    /// Decodes a raw state; unknown values read as [`LandedState::Unknown`].
    pub fn from_raw(raw: u32) -> Self {
        match raw {
            1 => Self::OnGround,
            2 => Self::InAir,
            3 => Self::Takeoff,
            4 => Self::Landing,
            _ => Self::Unknown,
        }
    }
}

/// Health of the link to the autopilot.
#[repr(C)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("landing::LinkHealth/v2")]
pub struct LinkHealth {
    /// 1 while autopilot heartbeats arrive within their timeout.
    pub connected: u32,
    /// MAVLink messages that failed to parse since start.
    pub parse_errors: u32,
    /// When the last autopilot heartbeat arrived (monotonic ns).
    pub last_heartbeat_ns: u64,
    /// When the last telemetry message arrived (monotonic ns).
    pub last_telemetry_ns: u64,
    /// Messages lost according to MAVLink sequence numbers.
    pub messages_lost: u64,
    /// 1 when the link is signed (MAVLink 2 signing, a key configured).
    #[cfg_attr(feature = "serde", serde(default))]
    pub signed: u32,
    /// Keeps the layout free of implicit padding.
    #[cfg_attr(feature = "serde", serde(default))]
    pub reserved: u32,
    /// Datagrams from an address other than the autopilot's, dropped unread.
    #[cfg_attr(feature = "serde", serde(default))]
    pub wrong_address: u64,
    /// Frames from a system or component other than the autopilot's (a ground station or
    /// a camera behind a MAVLink router), ignored: routine on a shared link, not an
    /// attack (px4-link's `from_others`).
    #[cfg_attr(feature = "serde", serde(default))]
    pub wrong_source: u64,
    /// Frames of a message id the dialect does not know, dropped.
    #[cfg_attr(feature = "serde", serde(default))]
    pub unknown_id: u64,
    /// Unsigned frames on a signed link, dropped.
    #[cfg_attr(feature = "serde", serde(default))]
    pub unsigned: u64,
    /// Frames whose signature does not match the key, dropped.
    #[cfg_attr(feature = "serde", serde(default))]
    pub bad_signature: u64,
    /// Signed frames played again (a timestamp not newer than the last), dropped.
    #[cfg_attr(feature = "serde", serde(default))]
    pub replayed: u64,
}

/// The vehicle's estimated state, as the autopilot reports it (never ground truth).
#[repr(C)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("landing::VehicleState/v2")]
pub struct VehicleState {
    /// Sequence, estimate time (`capture_ns`), stage stamps.
    pub msg: Header,
    /// Body (FLU) in the world (ENU).
    pub world_from_body: Pose,
    /// Velocity in the world frame, m/s.
    pub velocity: [f64; 3],
    /// Body rates (FLU), rad/s.
    pub body_rates: [f64; 3],
    /// 1 when armed.
    pub armed: u32,
    /// Raw [`FlightMode`].
    pub flight_mode: u32,
    /// Raw [`LandedState`].
    pub landed_state: u32,
    /// Keeps the layout free of implicit padding.
    pub reserved: u32,
    /// The autopilot link.
    pub link: LinkHealth,
}

/// A visual-inertial odometry sample (a tracking camera such as the paper's T265, or the
/// simulator's model of one), for the autopilot to fuse (px4-link forwards it as
/// MAVLink ODOMETRY). Its frame is the odometry's own: ENU-like, from where the VIO
/// started, drifting from the world; a reset makes it jump and increments the counter.
#[repr(C)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("landing::VioOdometry/v1")]
pub struct VioOdometry {
    /// Sequence, the sample's time (`capture_ns`: when its camera saw it), stage stamps.
    pub msg: Header,
    /// Body (FLU) in the odometry frame (ENU axes at its start).
    pub odom_from_body: Pose,
    /// Velocity in the odometry frame, m/s.
    pub velocity: [f64; 3],
    /// Body rates (FLU), rad/s.
    pub body_rates: [f64; 3],
    /// Variance of the position along x, y, z of the odometry frame, m^2.
    pub position_variance: [f64; 3],
    /// Variance of roll, pitch and yaw, rad^2.
    pub orientation_variance: [f64; 3],
    /// Variance of the velocity along x, y, z, (m/s)^2.
    pub velocity_variance: [f64; 3],
    /// Incremented at each reset of the odometry frame (wraps at 256 on the wire).
    pub reset_counter: u32,
    /// Confidence 0 (unknown) to 100 (best), -1 lost (MAVLink ODOMETRY's `quality`).
    pub quality: i32,
}

/// State of one occupancy cell on the wire.
#[repr(u8)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CellState {
    /// Never observed: neither free nor occupied.
    Unknown = 0,
    /// Observed free.
    Free = 1,
    /// Observed occupied.
    Occupied = 2,
    /// Not occupied (observed free or not observed), but within the inflation radius of
    /// an occupied cell: the planner must not put the vehicle's centre there.
    Inflated = 3,
}

impl CellState {
    /// Decodes a raw cell; anything unexpected is treated as unknown, never as free.
    pub fn from_raw(raw: u8) -> Self {
        match raw {
            1 => Self::Free,
            2 => Self::Occupied,
            3 => Self::Inflated,
            _ => Self::Unknown,
        }
    }
}

/// Metadata of the local occupancy window; cells are the `[u8]` slice payload behind it,
/// x fastest, then y, then z, one [`CellState`] each.
#[repr(C)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("landing::OccupancyMapHeader/v2")]
pub struct OccupancyMapHeader {
    /// Sequence, capture time of the newest depth frame integrated, stage stamps.
    pub msg: Header,
    /// World position of the window's minimum corner, m.
    pub origin: [f64; 3],
    /// Cell edge, m.
    pub resolution: f64,
    /// Inflation radius applied, m.
    pub inflation: f64,
    /// Cells along x, y, z.
    pub dims: [u32; 3],
    /// Keeps the layout free of implicit padding.
    pub reserved: u32,
    /// Capture time of the newest vehicle state the frame's pose came from (the first
    /// after its capture, interpolated towards, else the newest; 0: none): the states a
    /// replay must hand the mapper first to rebuild this map.
    #[cfg_attr(feature = "serde", serde(default))]
    pub state_ns: u64,
}

/// What the planner is asked to do.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GoalMode {
    /// Stop where you are (emergency-stop trajectory).
    Stop = 0,
    /// Fly to a fixed point.
    Point = 1,
    /// Meet a moving target at the given state (rendezvous).
    Rendezvous = 2,
}

impl GoalMode {
    /// Decodes a raw mode; unknown values read as [`GoalMode::Stop`], the safe choice.
    pub fn from_raw(raw: u32) -> Self {
        match raw {
            1 => Self::Point,
            2 => Self::Rendezvous,
            _ => Self::Stop,
        }
    }
}

/// A goal for the planner, world frame.
#[repr(C)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("landing::PlannerGoal/v1")]
pub struct PlannerGoal {
    /// Sequence, capture time of the observation behind the goal, stage stamps.
    pub msg: Header,
    /// Goal position, m.
    pub position: [f64; 3],
    /// Goal velocity, m/s (the pad's velocity for a rendezvous).
    pub velocity: [f64; 3],
    /// Goal acceleration, m/s^2.
    pub acceleration: [f64; 3],
    /// Yaw at the goal, rad (ENU, from +x toward +y).
    pub yaw: f64,
    /// Raw [`GoalMode`].
    pub mode: u32,
    /// Keeps the layout free of implicit padding.
    pub reserved: u32,
}

/// A uniform cubic B-spline trajectory in the world frame.
#[repr(C)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("landing::Trajectory/v1")]
pub struct Trajectory {
    /// Sequence, capture time of the input behind the plan, stage stamps.
    pub msg: Header,
    /// Plan id; increases with each new plan.
    pub id: u64,
    /// When the curve's parameter starts (monotonic ns).
    pub start_ns: u64,
    /// Knot interval, s.
    pub knot_interval_s: f64,
    /// Number of valid control points (>= 4 for a curve).
    pub count: u32,
    /// 1 for an emergency-stop trajectory.
    pub emergency: u32,
    /// Control points, m.
    #[cfg_attr(
        feature = "serde",
        serde(
            serialize_with = "ser::points_xyz",
            deserialize_with = "de::points_xyz"
        )
    )]
    pub control_points: [[f64; 3]; MAX_CONTROL_POINTS],
}

impl Default for Trajectory {
    fn default() -> Self {
        Self {
            msg: Header::default(),
            id: 0,
            start_ns: 0,
            knot_interval_s: 0.0,
            count: 0,
            emergency: 0,
            control_points: [[0.0; 3]; MAX_CONTROL_POINTS],
        }
    }
}

impl Trajectory {
    /// The valid control points.
    pub fn points(&self) -> &[[f64; 3]] {
        &self.control_points[..(self.count as usize).min(MAX_CONTROL_POINTS)]
    }
}

/// Planning statistics, one per planning call.
#[repr(C)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("landing::PlannerStats/v1")]
pub struct PlannerStats {
    /// Sequence, capture time of the input, stage stamps.
    pub msg: Header,
    /// Trajectory id the call produced (0 on failure).
    pub trajectory_id: u64,
    /// Unused, 0: the planner reads no clock; the call's wall time is its stage stamp in
    /// `msg` (exit - enter, closed by the driver as the statistics leave). Kept so the
    /// wire layout of v1 stays; drop it at the next version.
    pub planning_ms: f64,
    /// Optimizer iterations.
    pub iterations: u32,
    /// Rebound rounds.
    pub rebounds: u32,
    /// 1 on success.
    pub success: u32,
    /// Keeps the layout free of implicit padding.
    pub reserved: u32,
}

/// A position/velocity/acceleration/yaw setpoint for the autopilot, world ENU.
///
/// A field that is not to be controlled has its bit cleared in `valid`: NaN never goes on
/// the wire (PX4 reads NaN as "ignore", but a NaN from a bug must not look like intent).
#[repr(C)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("landing::Setpoint/v1")]
pub struct Setpoint {
    /// Sequence, capture time of the input, stage stamps.
    pub msg: Header,
    /// Position, m.
    pub position: [f64; 3],
    /// Velocity feed-forward, m/s.
    pub velocity: [f64; 3],
    /// Acceleration feed-forward, m/s^2.
    pub acceleration: [f64; 3],
    /// Yaw, rad (ENU).
    pub yaw: f64,
    /// Which fields hold: [`Setpoint::POSITION`] | [`Setpoint::VELOCITY`] | ...
    pub valid: u32,
    /// Keeps the layout free of implicit padding.
    pub reserved: u32,
}

impl Setpoint {
    /// `position` holds.
    pub const POSITION: u32 = 1;
    /// `velocity` holds.
    pub const VELOCITY: u32 = 2;
    /// `acceleration` holds.
    pub const ACCELERATION: u32 = 4;
    /// `yaw` holds.
    pub const YAW: u32 = 8;
}

/// States of the landing mission.
#[repr(u32)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum MissionState {
    /// On the ground, disarmed, waiting for the start.
    #[default]
    Idle = 0,
    /// Arming and climbing.
    Takeoff = 1,
    /// Flying to the preset search point.
    GoToPreset = 2,
    /// Hovering at the preset point until the pad is seen.
    WaitForPad = 3,
    /// Following the pad at altitude.
    Track = 4,
    /// Descending while tracking.
    Descend = 5,
    /// Committed to touchdown.
    Land = 6,
    /// On the pad, disarmed.
    Landed = 7,
    /// Pad lost: hold, climb, then give up.
    Lost = 8,
    /// Mission aborted by an operator or the watchdog.
    Abort = 9,
    /// Landing in place because something failed.
    SafeLand = 10,
}

impl MissionState {
    /// A short name, for logs and plots.
    pub fn name(self) -> &'static str {
        match self {
            Self::Idle => "idle",
            Self::Takeoff => "takeoff",
            Self::GoToPreset => "goto-preset",
            Self::WaitForPad => "wait-for-pad",
            Self::Track => "track",
            Self::Descend => "descend",
            Self::Land => "land",
            Self::Landed => "landed",
            Self::Lost => "lost",
            Self::Abort => "abort",
            Self::SafeLand => "safe-land",
        }
    }

    /// Decodes a raw state; `None` for an unknown one.
    pub fn from_raw(raw: u32) -> Option<Self> {
        Some(match raw {
            0 => Self::Idle,
            1 => Self::Takeoff,
            2 => Self::GoToPreset,
            3 => Self::WaitForPad,
            4 => Self::Track,
            5 => Self::Descend,
            6 => Self::Land,
            7 => Self::Landed,
            8 => Self::Lost,
            9 => Self::Abort,
            10 => Self::SafeLand,
            _ => return None,
        })
    }
}

/// A fixed-capacity UTF-8 text field (reasons, names), zero-padded.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("landing::Text/v1")]
pub struct Text {
    /// Used bytes.
    pub len: u32,
    /// The bytes; only `..len` are meaningful.
    pub bytes: [u8; TEXT_LEN],
}

impl Default for Text {
    fn default() -> Self {
        Self {
            len: 0,
            bytes: [0; TEXT_LEN],
        }
    }
}

impl Text {
    /// Copies `s`, cut at a character boundary to fit.
    pub fn new(s: &str) -> Self {
        let mut end = s.len().min(TEXT_LEN);
        while !s.is_char_boundary(end) {
            end -= 1;
        }
        let mut t = Self::default();
        t.bytes[..end].copy_from_slice(&s.as_bytes()[..end]);
        t.len = end as u32;
        t
    }

    /// The text; invalid UTF-8 from a misbehaving writer reads as an empty string.
    pub fn as_str(&self) -> &str {
        let n = (self.len as usize).min(TEXT_LEN);
        std::str::from_utf8(&self.bytes[..n]).unwrap_or("")
    }
}

/// The mission state machine's status, published on every transition and periodically.
#[repr(C)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("landing::FsmStatus/v2")]
pub struct FsmStatus {
    /// Sequence, time, stage stamps.
    pub msg: Header,
    /// Raw [`MissionState`], now.
    pub state: u32,
    /// Raw [`MissionState`] before the last transition.
    pub previous: u32,
    /// When the last transition happened (monotonic ns).
    pub since_ns: u64,
    /// Why the last transition happened.
    pub reason: Text,
    /// 1 while the pad filter holds a valid estimate.
    pub pad_valid: u32,
    /// Keeps the layout free of implicit padding.
    pub reserved: u32,
    /// Estimated pad position, world, m.
    pub pad_position: [f64; 3],
    /// Estimated pad velocity, world, m/s.
    pub pad_velocity: [f64; 3],
    /// Estimated pad acceleration, world, m/s^2 (the filter's models weighted; what the
    /// touchdown feeds forward): a recording shows what the drop's wait saw.
    pub pad_acceleration: [f64; 3],
}

/// What a safety command orders.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SafetyAction {
    /// Nothing (a cleared command).
    None = 0,
    /// Hold position.
    Hold = 1,
    /// Land where the vehicle is, now.
    SafeLand = 2,
    /// Stop the mission and land (operator abort).
    Abort = 3,
}

impl SafetyAction {
    /// Decodes a raw action; unknown values read as [`SafetyAction::SafeLand`], the safe
    /// reading of a command nobody can parse.
    pub fn from_raw(raw: u32) -> Self {
        match raw {
            0 => Self::None,
            1 => Self::Hold,
            3 => Self::Abort,
            _ => Self::SafeLand,
        }
    }
}

/// What the mission asks of the autopilot through px4-link.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkRequestKind {
    /// Arm the motors.
    Arm = 1,
    /// Disarm.
    Disarm = 2,
    /// AUTO.TAKEOFF to `altitude_m`.
    Takeoff = 3,
    /// OFFBOARD (px4-link sends it once its setpoint stream has run 1 s).
    Offboard = 4,
    /// AUTO.LAND.
    Land = 5,
    /// AUTO.LOITER.
    Hold = 6,
    /// Motors off now, in the air if need be (a forced disarm): the fsm saw the gear
    /// touch the pad. PX4's land detector takes a second to agree, and until then the
    /// controller tilts against feet that grip a moving pad.
    Touchdown = 7,
}

impl LinkRequestKind {
    /// Decodes a raw kind; `None` for a value no kind has (the request is refused, not
    /// guessed: arming by accident is not a safe reading).
    pub fn from_raw(raw: u32) -> Option<Self> {
        Some(match raw {
            1 => Self::Arm,
            2 => Self::Disarm,
            3 => Self::Takeoff,
            4 => Self::Offboard,
            5 => Self::Land,
            6 => Self::Hold,
            7 => Self::Touchdown,
            _ => return None,
        })
    }
}

/// A request to px4-link (fsm -> px4-link); answered by a [`LinkOutcome`] with its id.
#[repr(C)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("landing::LinkRequest/v1")]
pub struct LinkRequest {
    /// Sequence, issue time, stage stamps.
    pub msg: Header,
    /// Chosen by the requester; echoed in the outcome.
    pub id: u64,
    /// Raw [`LinkRequestKind`].
    pub kind: u32,
    /// Keeps the layout free of implicit padding.
    pub reserved: u32,
    /// Take-off height, m (Takeoff only).
    pub altitude_m: f64,
}

/// How a [`LinkRequest`] ended.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkOutcomeKind {
    /// The autopilot accepted it.
    Accepted = 1,
    /// The autopilot refused it (`result` holds PX4's MAV_RESULT).
    Rejected = 2,
    /// No answer after every retry.
    TimedOut = 3,
    /// OFFBOARD asked without a setpoint stream.
    NoSetpointStream = 4,
    /// px4-link could not read the request.
    Invalid = 5,
    /// A take-off was asked but the autopilot has reported no altitude above mean sea
    /// level (no HOME_POSITION nor GLOBAL_POSITION_INT: no global position), so no
    /// NAV_TAKEOFF altitude PX4 reads correctly can be given; nothing was sent.
    NoAltitudeReference = 6,
}

impl LinkOutcomeKind {
    /// Decodes a raw outcome; a value no kind has reads as [`LinkOutcomeKind::Invalid`]
    /// (never as accepted).
    pub fn from_raw(raw: u32) -> Self {
        match raw {
            1 => Self::Accepted,
            2 => Self::Rejected,
            3 => Self::TimedOut,
            4 => Self::NoSetpointStream,
            6 => Self::NoAltitudeReference,
            _ => Self::Invalid,
        }
    }
}

/// px4-link's answer to a [`LinkRequest`].
#[repr(C)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("landing::LinkOutcome/v1")]
pub struct LinkOutcome {
    /// Sequence, time, stage stamps.
    pub msg: Header,
    /// The request's id.
    pub id: u64,
    /// Raw [`LinkRequestKind`] of the request.
    pub kind: u32,
    /// Raw [`LinkOutcomeKind`].
    pub outcome: u32,
    /// The autopilot's MAV_RESULT when it answered.
    pub result: u32,
    /// Keeps the layout free of implicit padding.
    pub reserved: u32,
}

/// An order from the watchdog or an operator, executed at once by px4-link and fsm.
#[repr(C)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("landing::SafetyCommand/v1")]
pub struct SafetyCommand {
    /// Sequence, issue time, stage stamps.
    pub msg: Header,
    /// Raw [`SafetyAction`].
    pub action: u32,
    /// Keeps the layout free of implicit padding.
    pub reserved: u32,
    /// Who ordered it ("watchdog", "operator").
    pub source: Text,
    /// Why.
    pub reason: Text,
}

/// How the watchdog sees one process.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Liveness {
    /// No heartbeat yet.
    #[default]
    Starting = 0,
    /// Beating within its deadline.
    Alive = 1,
    /// Its heartbeat missed the deadline (a hung loop, a stopped process).
    Hung = 2,
    /// Its iceoryx2 node is dead or gone.
    Dead = 3,
}

impl Liveness {
    /// Decodes a raw value; one no state has reads as [`Liveness::Dead`], the state nobody
    /// should rely on.
    pub fn from_raw(raw: u32) -> Self {
        match raw {
            0 => Self::Starting,
            1 => Self::Alive,
            2 => Self::Hung,
            _ => Self::Dead,
        }
    }

    /// Short name for logs and `landing status`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Starting => "starting",
            Self::Alive => "alive",
            Self::Hung => "hung",
            Self::Dead => "dead",
        }
    }
}

/// Health of one supervised process as the watchdog sees it.
#[repr(C)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("landing::ProcessHealth/v3")]
pub struct ProcessHealth {
    /// Process name.
    pub name: Text,
    /// Raw [`Liveness`].
    pub liveness: u32,
    /// Heartbeat deadlines missed since start.
    pub missed_deadlines: u32,
    /// Times it came back after a death (restarted by systemd or `landing run`).
    pub restarts: u32,
    /// When its last heartbeat arrived (monotonic ns); 0 before the first.
    pub last_heartbeat_ns: u64,
    /// When it was last found hung or dead (monotonic ns); 0 when never.
    pub fault_ns: u64,
    /// The CPU time it has used since it started, ns, as last measured (0: not measured:
    /// lockstep, or no measurement yet).
    pub cpu_ns: u64,
    /// Its CPU use between the last two measurements, percent of one core.
    pub cpu_percent: f64,
    /// When it first beat after its last death (monotonic ns): back in the graph; 0 when
    /// never restarted.
    pub rejoined_ns: u64,
}

/// The watchdog's view of the whole stack.
#[repr(C)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("landing::WatchdogView/v4")]
pub struct WatchdogView {
    /// Sequence, time, stage stamps.
    pub msg: Header,
    /// Number of valid entries in `processes`.
    pub count: u32,
    /// 1 once the watchdog has ordered a safe landing.
    pub safe_land_ordered: u32,
    /// Faults found since start.
    pub faults: u32,
    /// Raw [`MissionState`] the watchdog last saw.
    pub phase: u32,
    /// When the newest fault was found (monotonic ns); 0 when none.
    pub last_fault_ns: u64,
    /// When the safe landing was ordered (monotonic ns); 0 when not.
    pub order_ns: u64,
    /// The newest fault, described.
    pub last_fault: Text,
    /// Why it was ordered, or what was done instead ("continue: ...").
    pub action: Text,
    /// Per-process health.
    pub processes: [ProcessHealth; MAX_WATCHED],
}

impl WatchdogView {
    /// The valid entries of `processes` (the first `count`, at most all of them).
    pub fn watched(&self) -> &[ProcessHealth] {
        &self.processes[..(self.count as usize).min(self.processes.len())]
    }
}

/// What a [`FaultOrder`] does to a process's outputs.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PortFault {
    /// Clears every fault.
    Clear = 0,
    /// Each output waits `value` ms before it is sent (a slow stage).
    Delay = 1,
    /// Each output is dropped with probability `value` (0..=1).
    Drop = 2,
    /// Each output's payload is overwritten with all-ones bytes after its header: NaN in
    /// every float, the largest value in every integer.
    Corrupt = 3,
    /// Each image's pixels are one mid-grey: the frames flow and show nothing (the pad
    /// hidden, the view blocked). Images only; other messages pass.
    Blank = 4,
}

impl PortFault {
    /// Decodes a raw fault; `None` for a value no fault has.
    pub fn from_raw(raw: u32) -> Option<Self> {
        Some(match raw {
            0 => Self::Clear,
            1 => Self::Delay,
            2 => Self::Drop,
            3 => Self::Corrupt,
            4 => Self::Blank,
            _ => return None,
        })
    }
}

/// A fault to inject into one process's output ports (`landing run --inject`,
/// `landing inject`). Only processes started with `LANDING_FAULT_INJECTION=1` listen:
/// a deployed stack has no such door.
#[repr(C)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("landing::FaultOrder/v2")]
pub struct FaultOrder {
    /// Sequence, issue time.
    pub msg: Header,
    /// The process whose outputs it concerns.
    pub process: Text,
    /// Raw [`PortFault`].
    pub fault: u32,
    /// Keeps the layout free of implicit padding.
    pub reserved: u32,
    /// Its parameter: delay in ms, drop probability.
    pub value: f64,
    /// The one output topic it concerns (short name); empty: every output.
    pub topic: Text,
    /// Keeps the layout free of implicit padding.
    pub reserved2: u32,
    /// How long it lasts, s; 0: until cleared.
    pub for_s: f64,
}

/// What a [`ProcessEvent`] says.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ProcessEventKind {
    /// A heartbeat arrived.
    Beat = 1,
    /// The process's iceoryx2 node is dead or gone.
    Died = 2,
    /// The process's CPU time was measured: `cpu_ns`.
    Cpu = 3,
}

impl ProcessEventKind {
    /// Decodes a raw kind; `None` for a value no kind has.
    pub fn from_raw(raw: u32) -> Option<Self> {
        match raw {
            1 => Some(Self::Beat),
            2 => Some(Self::Died),
            3 => Some(Self::Cpu),
            _ => None,
        }
    }
}

/// A supervised process's sign of life or death as the runtime sees it (a heartbeat
/// event, a dead or vanished iceoryx2 node): the watchdog stage's input. It never
/// crosses shared memory: the runtime's supervision source delivers it inside the
/// watchdog's own process.
#[repr(C)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("landing::ProcessEvent/v2")]
pub struct ProcessEvent {
    /// Sequence, time.
    pub msg: Header,
    /// The process (its graph node name).
    pub process: Text,
    /// Raw [`ProcessEventKind`].
    pub kind: u32,
    /// Keeps the layout free of implicit padding.
    pub reserved: u32,
    /// [`ProcessEventKind::Cpu`]: the CPU time the process has used since it started
    /// (user and system, every thread), ns; 0 otherwise.
    pub cpu_ns: u64,
}

/// Kinds of ground-truth events.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TruthKind {
    /// The vehicle came to rest on a surface (the pad or the ground).
    Touchdown = 1,
    /// It left a surface.
    Liftoff = 2,
    /// It hit an obstacle.
    Collision = 3,
    /// It crashed (hard impact, excessive tilt).
    Crash = 4,
}

impl TruthKind {
    /// Decodes a raw kind; `None` for an unknown one.
    pub fn from_raw(raw: u32) -> Option<Self> {
        Some(match raw {
            1 => Self::Touchdown,
            2 => Self::Liftoff,
            3 => Self::Collision,
            4 => Self::Crash,
            _ => return None,
        })
    }
}

/// Where the vehicle and the pad really are, from the simulator, on the evaluator-only
/// topic [`crate::services::SIM_TRUTH_STATE`] (plots and speeds of `landing run
/// --processes`). No pipeline process may read it.
#[repr(C)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("landing::TruthState/v3")]
pub struct TruthState {
    /// Sequence, publish time (monotonic ns), stage stamps.
    pub msg: Header,
    /// Simulated time, ns.
    pub sim_time_ns: u64,
    /// Vehicle position, world ENU, m.
    pub vehicle_position: [f64; 3],
    /// Vehicle velocity, m/s.
    pub vehicle_velocity: [f64; 3],
    /// 1 when there is a ground vehicle (the pad fields are meaningful).
    pub pad_valid: u32,
    /// 1 once the vehicle is armed (the autopilot's truth, for the flight time).
    pub armed: u32,
    /// Pad centre, world ENU, m.
    pub pad_position: [f64; 3],
    /// Pad velocity, m/s.
    pub pad_velocity: [f64; 3],
    /// The vehicle's velocity relative to the pad's surface point under it (the pad
    /// turns as its vehicle steers), world ENU, m/s (meaningful with `pad_valid`).
    pub vehicle_velocity_rel_pad: [f64; 3],
    /// Each foot of the landing gear in the pad frame (x, y), m (meaningful with
    /// `pad_valid`).
    pub gear_pad: [Point2; 4],
    /// What the vehicle rests on: [`Contact`] as raw.
    pub contact: u32,
    /// Keeps the layout free of implicit padding.
    pub reserved: u32,
}

/// What the vehicle rests on, in [`TruthState::contact`].
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Contact {
    /// In the air.
    Airborne = 0,
    /// On the ground.
    Ground = 1,
    /// On the pad (the ground vehicle's roof).
    Pad = 2,
}

impl Contact {
    /// From the raw value; `None` for an unknown one.
    pub fn from_raw(raw: u32) -> Option<Self> {
        match raw {
            0 => Some(Self::Airborne),
            1 => Some(Self::Ground),
            2 => Some(Self::Pad),
            _ => None,
        }
    }
}

/// A ground-truth event from the simulator, on the evaluator-only topic
/// ([`crate::services::SIM_TRUTH`]). No pipeline process may read it.
#[repr(C)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("landing::TruthEvent/v2")]
pub struct TruthEvent {
    /// Sequence, event time (`capture_ns`, simulated ns), stage stamps.
    pub msg: Header,
    /// Raw [`TruthKind`].
    pub kind: u32,
    /// 1 when the surface was the pad.
    pub on_pad: u32,
    /// Touchdown: position relative to the pad centre in the pad frame, m.
    pub rel_position_pad: [f64; 2],
    /// Touchdown/impact: velocity relative to the surface, m/s.
    pub rel_velocity: [f64; 3],
    /// Touchdown: each foot of the landing gear in the pad frame, m.
    pub gear_pad: [Point2; 4],
    /// Touchdown: angle between body up and the surface normal, deg.
    pub tilt_deg: f64,
    /// Collision: index of the obstacle in the scenario.
    pub obstacle_index: u32,
    /// Keeps the layout free of implicit padding.
    pub reserved: u32,
    /// Crash: why.
    pub reason: Text,
}

/// Serialization for recordings (`landing run --record`), behind the `serde` feature: the
/// recorder writes these structs as JSON so that a log viewer shows every field by name.
#[cfg(feature = "serde")]
mod ser {
    use serde::{Serialize, Serializer};

    /// Arrays longer than 32, which serde's derive does not cover, as plain sequences.
    pub(super) fn array<S: Serializer, T: Serialize, const N: usize>(
        v: &[T; N],
        s: S,
    ) -> Result<S::Ok, S::Error> {
        s.collect_seq(v)
    }

    /// A point as `{x, y, z}`.
    #[derive(Serialize)]
    struct Xyz {
        x: f64,
        y: f64,
        z: f64,
    }

    /// Points as objects `{x, y, z}`, not as arrays of arrays: log viewers' JSON Schema
    /// readers (Foxglove's) take arrays of numbers or of objects only.
    pub(super) fn points_xyz<S: Serializer, const N: usize>(
        v: &[[f64; 3]; N],
        s: S,
    ) -> Result<S::Ok, S::Error> {
        s.collect_seq(v.iter().map(|p| Xyz {
            x: p[0],
            y: p[1],
            z: p[2],
        }))
    }

    /// Text as the string it holds, not as a length and 48 bytes.
    impl Serialize for super::Text {
        fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
            s.serialize_str(self.as_str())
        }
    }
}

/// Deserialization, the inverse of [`ser`]: what the recorder wrote reads back into the
/// same structs (`landing replay`, `landing plot`). Like the derives, it is independent of
/// the format; one thing is the format's: JSON has no NaN, so a non-finite number was
/// written as `null`, and the recorder's reader (`recorder::decode`) hands a `null` that
/// stands for a number over as NaN, whichever field it is in.
#[cfg(feature = "serde")]
mod de {
    use serde::de::Error as _;
    use serde::{Deserialize, Deserializer};

    /// An array written by [`super::ser::array`] (longer than serde's derive covers).
    pub(super) fn array<'de, D, T, const N: usize>(d: D) -> Result<[T; N], D::Error>
    where
        D: Deserializer<'de>,
        T: Deserialize<'de>,
    {
        let items = Vec::<T>::deserialize(d)?;
        let len = items.len();
        <[T; N]>::try_from(items)
            .map_err(|_| D::Error::invalid_length(len, &format!("{N} items").as_str()))
    }

    /// A point written as `{x, y, z}`.
    #[derive(Deserialize)]
    struct Xyz {
        x: f64,
        y: f64,
        z: f64,
    }

    /// Points written by [`super::ser::points_xyz`].
    pub(super) fn points_xyz<'de, D, const N: usize>(d: D) -> Result<[[f64; 3]; N], D::Error>
    where
        D: Deserializer<'de>,
    {
        let points = Vec::<Xyz>::deserialize(d)?;
        let len = points.len();
        let xyz: Vec<[f64; 3]> = points.into_iter().map(|p| [p.x, p.y, p.z]).collect();
        <[[f64; 3]; N]>::try_from(xyz)
            .map_err(|_| D::Error::invalid_length(len, &format!("{N} points").as_str()))
    }

    /// Text from the string it was written as (cut to fit, as [`super::Text::new`] cuts).
    impl<'de> Deserialize<'de> for super::Text {
        fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
            Ok(Self::new(&String::deserialize(d)?))
        }
    }
}

#[cfg(test)]
#[path = "msg_test.rs"]
mod tests;
