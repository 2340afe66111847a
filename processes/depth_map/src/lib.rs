//! depth-map: a probabilistic occupancy window around the vehicle, from depth frames.
//!
//! The model is EGO-Planner's grid map (see `docs/mapping.md` for where and why this
//! one differs):
//!
//! - a local window of cubic cells (0.15 m) that follows the vehicle; cells that leave
//!   it are forgotten, cells that enter it are unknown, and anything outside it reads as
//!   unknown, never as free or occupied;
//! - per frame, a ray from the camera through every k-th pixel (k = 2), cut at 5 m;
//!   cast back from its end with a 3D DDA ([`raycast::Dda`]), each cell updated at most
//!   once per frame: + hit log-odds where a ray ends on a surface, + miss log-odds where
//!   rays pass; a ray with no return (0) or a return beyond the cut frees its cells up
//!   to the cut and hits nothing;
//! - log-odds clamped to [min, max] so that the map reacts within a few frames when the
//!   world changes; occupied above a threshold;
//! - an inflated layer for the planner (cells within 0.299 m of an occupied cell).
//!
//! [`OccupancyMap`] is the map itself, which the planner queries directly in lockstep;
//! [`DepthMapper`] adds what the depth-map process does per frame (the vehicle pose at
//! the frame's capture time from the state history, the camera mount, following the
//! vehicle, inflation) and its counters. No IPC, no clock, no sleeping, and no
//! allocation after construction: the `depth-map` binary binds this to iceoryx2, and
//! `landing map` / `landing bench depth` call it directly.

pub mod config;
pub mod frame;
mod inflate;
pub mod map;
pub mod raycast;
pub mod stage;

pub use stage::DepthStage;

use ipc_types::msg::VehicleState;
use nalgebra::{Isometry3, Point3};
use state_history::{HistoryError, StateHistory, TimedPose};
use thiserror::Error;

pub use config::{DepthMapConfig, Input};
pub use frame::{DepthPixels, DepthView};
pub use map::{Census, IntegrateStats, LogOdds, MapSettings, OccupancyMap, RaySettings};

/// Why a frame (or a setting) was not used. Every frame-level error leaves the map as
/// it was.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum DepthError {
    /// A setting is out of range.
    #[error("depth map settings: {0}")]
    Settings(String),
    /// The frame is not the size the map was built for.
    #[error("depth frame is {got_w}x{got_h}, the map takes {want_w}x{want_h}")]
    FrameSize {
        /// Frame width.
        got_w: u32,
        /// Frame height.
        got_h: u32,
        /// Configured width.
        want_w: u32,
        /// Configured height.
        want_h: u32,
    },
    /// The header contradicts itself (zero size, bad intrinsics or scale).
    #[error("depth frame header: {0}")]
    BadHeader(&'static str),
    /// The payload does not hold `width * height` depths.
    #[error("depth frame payload has {got} depths, the header says {width}x{height} = {want}")]
    PayloadLength {
        /// Depths in the payload.
        got: usize,
        /// Depths the header implies.
        want: usize,
        /// Header width.
        width: u32,
        /// Header height.
        height: u32,
    },
    /// No vehicle pose for the frame's capture time.
    #[error("no vehicle pose at the frame's capture time: {0}")]
    NoState(#[from] HistoryError),
    /// The camera pose has a non-finite number or a rotation that is not a unit
    /// quaternion.
    #[error("camera pose is not finite")]
    NonFinitePose,
    /// The camera is outside the window (call `recenter` first).
    #[error("the camera is outside the map window")]
    OutsideWindow,
    /// The output buffer is not one byte per cell.
    #[error("map output buffer has {got} bytes, the window has {want} cells")]
    WireSize {
        /// Buffer length.
        got: usize,
        /// Cells.
        want: usize,
    },
}

pub use optics::body_from_forward_camera;

pub use state_history::timed_pose_of;

/// What [`DepthMapper`] has seen since it was built.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counters {
    /// Frames offered to [`DepthMapper::process`] (or recorded as bad before it).
    pub frames: u64,
    /// Frames integrated into the map.
    pub integrated: u64,
    /// Frames skipped: no vehicle state received yet.
    pub no_state: u64,
    /// Frames skipped: the newest state is older than the frame by more than the
    /// allowance.
    pub stale_state: u64,
    /// Frames skipped: captured before the oldest state kept.
    pub too_old: u64,
    /// Frames skipped: wrong size, or a header inconsistent with its payload.
    pub bad_frames: u64,
    /// Frames skipped: the camera pose was not finite.
    pub bad_poses: u64,
    /// Vehicle states refused (non-finite, out of order).
    pub bad_states: u64,
    /// Times the window moved.
    pub recenters: u64,
}

/// One depth-map stage: vehicle states in, frames in, the map out.
#[derive(Debug, Clone)]
pub struct DepthMapper {
    map: OccupancyMap,
    history: StateHistory,
    body_from_camera: Isometry3<f64>,
    counters: Counters,
}

/// How many vehicle states are kept (2 s at 50 Hz; frames are tens of ms old).
pub const STATE_HISTORY: usize = 100;

impl DepthMapper {
    /// A mapper with `settings`, a camera mounted at `body_from_camera`, which skips
    /// frames newer than the newest vehicle state by more than `max_state_age_ns`.
    pub fn new(
        settings: MapSettings,
        body_from_camera: Isometry3<f64>,
        max_state_age_ns: u64,
    ) -> Result<Self, DepthError> {
        Ok(Self {
            map: OccupancyMap::new(settings)?,
            history: StateHistory::new(STATE_HISTORY, max_state_age_ns),
            body_from_camera,
            counters: Counters::default(),
        })
    }

    /// The mapper the `[depth_map]` section describes.
    pub fn from_config(c: &DepthMapConfig) -> Result<Self, DepthError> {
        Self::new(
            c.map_settings(),
            c.body_from_camera(),
            c.max_state_age_ms * 1_000_000,
        )
    }

    /// Adds a vehicle state; refused (and counted) when non-finite or out of order.
    pub fn push_state(&mut self, state: TimedPose) -> bool {
        let ok = self.history.push(state);
        if !ok {
            self.counters.bad_states += 1;
        }
        ok
    }

    /// Adds a vehicle state message ([`timed_pose_of`]).
    pub fn push_state_msg(&mut self, v: &VehicleState) -> bool {
        match timed_pose_of(v) {
            Some(s) => self.push_state(s),
            None => {
                self.counters.bad_states += 1;
                false
            }
        }
    }

    /// Counts a frame that could not even be read (its header contradicts its payload).
    pub fn record_bad_frame(&mut self) {
        self.counters.frames += 1;
        self.counters.bad_frames += 1;
    }

    /// Integrates one frame captured at `capture_ns`: the vehicle pose interpolated at
    /// that time, the window moved to follow it, the rays cast, the map inflated.
    /// Skipped (counted, map unchanged) when no state covers the capture time or the
    /// frame or pose is unusable.
    pub fn process(
        &mut self,
        frame: &DepthView<'_>,
        capture_ns: u64,
    ) -> Result<IntegrateStats, DepthError> {
        self.counters.frames += 1;
        let body = match self.history.at(capture_ns) {
            Ok(b) => b,
            Err(e) => {
                match e {
                    HistoryError::Empty => self.counters.no_state += 1,
                    HistoryError::Stale(_) => self.counters.stale_state += 1,
                    HistoryError::TooOld(_) => self.counters.too_old += 1,
                }
                return Err(e.into());
            }
        };
        let world_from_camera = body * self.body_from_camera;
        let result = self
            .map
            .recenter(&Point3::from(body.translation.vector))
            .and_then(|moved| {
                let stats = self.map.integrate(frame, &world_from_camera, capture_ns)?;
                Ok((moved, stats))
            });
        match result {
            Ok((moved, stats)) => {
                self.counters.recenters += u64::from(moved);
                self.counters.integrated += 1;
                if !self.map.inflation_is_current() {
                    self.map.inflate();
                }
                Ok(stats)
            }
            Err(e) => {
                match e {
                    DepthError::NonFinitePose | DepthError::OutsideWindow => {
                        self.counters.bad_poses += 1
                    }
                    _ => self.counters.bad_frames += 1,
                }
                Err(e)
            }
        }
    }

    /// Capture time of the newest vehicle state the pose at `capture_ns` depends on
    /// ([`StateHistory::newest_used_ns`]; 0: none yet).
    pub fn state_used_ns(&self, capture_ns: u64) -> u64 {
        self.history.newest_used_ns(capture_ns).unwrap_or(0)
    }

    /// The map, for queries and publishing.
    pub fn map(&self) -> &OccupancyMap {
        &self.map
    }

    /// The map, mutably (to re-centre or inflate it outside `process`).
    pub fn map_mut(&mut self) -> &mut OccupancyMap {
        &mut self.map
    }

    /// The counters.
    pub fn counters(&self) -> Counters {
        self.counters
    }

    /// The camera mount in use.
    pub fn body_from_camera(&self) -> Isometry3<f64> {
        self.body_from_camera
    }
}

#[cfg(test)]
#[path = "lib_test.rs"]
mod tests;
