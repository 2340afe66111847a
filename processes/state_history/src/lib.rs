//! The vehicle pose at a sensor frame's capture time.
//!
//! A camera frame is captured tens of milliseconds before it is processed; at 10 m/s the
//! vehicle has moved decimetres since. Sensor processes therefore keep the recent state
//! stream and ask for the pose *at the capture time*, interpolated between the two
//! states around it, instead of taking "the latest". A capture time outside what the
//! history covers (older than its oldest state, or newer than its newest by more than a
//! small extrapolation allowance) is an error the caller counts, never a guess.

use std::collections::VecDeque;

use ipc_types::msg::VehicleState;
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use thiserror::Error;

/// One state of the stream: a pose and a velocity at a time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimedPose {
    /// Time of the estimate, ns (the same clock as the frames' capture times).
    pub time_ns: u64,
    /// Body (FLU) in the world (ENU).
    pub world_from_body: Isometry3<f64>,
    /// Velocity in the world frame, m/s (used only to extrapolate a little).
    pub velocity: Vector3<f64>,
}

/// The vehicle state message as a history entry; `None` when a number is not finite or
/// the quaternion is far from unit length (a writer's bug, not a pose).
/// Every reader of the state stream (aruco-pnp, depth-map) validates it with this one
/// function.
pub fn timed_pose_of(v: &VehicleState) -> Option<TimedPose> {
    let t = v.world_from_body.translation;
    let [x, y, z, w] = v.world_from_body.rotation_xyzw;
    let q = Quaternion::new(w, x, y, z);
    let finite = t.iter().chain(&v.velocity).all(|c| c.is_finite())
        && q.coords.iter().all(|c| c.is_finite());
    if !finite || (q.norm() - 1.0).abs() > 0.01 {
        return None;
    }
    Some(TimedPose {
        time_ns: v.msg.capture_ns,
        world_from_body: Isometry3::from_parts(
            Translation3::new(t[0], t[1], t[2]),
            UnitQuaternion::from_quaternion(q),
        ),
        velocity: Vector3::from(v.velocity),
    })
}

/// Why no pose could be given for a capture time.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum HistoryError {
    /// No state has been received yet.
    #[error("no vehicle state yet")]
    Empty,
    /// The frame is older than the oldest state kept.
    #[error("frame is {0} ns older than the oldest vehicle state kept")]
    TooOld(u64),
    /// The frame is newer than the newest state by more than the allowance.
    #[error("newest vehicle state is {0} ns older than the frame")]
    Stale(u64),
}

/// A bounded window of recent states, in time order.
#[derive(Debug, Clone)]
pub struct StateHistory {
    states: VecDeque<TimedPose>,
    capacity: usize,
    max_extrapolation_ns: u64,
}

impl StateHistory {
    /// Keeps the last `capacity` states (at least 2) and extrapolates at most
    /// `max_extrapolation_ns` past the newest.
    pub fn new(capacity: usize, max_extrapolation_ns: u64) -> Self {
        let capacity = capacity.max(2);
        Self {
            states: VecDeque::with_capacity(capacity),
            capacity,
            max_extrapolation_ns,
        }
    }

    /// Adds a state. Out-of-order or non-finite states are ignored (returns false):
    /// the history must stay sorted and finite for interpolation to mean anything.
    pub fn push(&mut self, state: TimedPose) -> bool {
        let finite = state
            .world_from_body
            .translation
            .vector
            .iter()
            .all(|v| v.is_finite())
            && state
                .world_from_body
                .rotation
                .coords
                .iter()
                .all(|v| v.is_finite())
            && state.velocity.iter().all(|v| v.is_finite());
        if !finite
            || self
                .states
                .back()
                .is_some_and(|last| state.time_ns <= last.time_ns)
        {
            return false;
        }
        if self.states.len() == self.capacity {
            self.states.pop_front();
        }
        self.states.push_back(state);
        true
    }

    /// The newest state, if any.
    pub fn latest(&self) -> Option<&TimedPose> {
        self.states.back()
    }

    /// Number of states kept.
    pub fn len(&self) -> usize {
        self.states.len()
    }

    /// True when no state was received yet.
    pub fn is_empty(&self) -> bool {
        self.states.is_empty()
    }

    /// Capture time of the newest state the pose at `time_ns` depends on: the first state
    /// after it (interpolated towards), else the newest (extrapolated from). States that
    /// came later change nothing at `time_ns`; a replay needs only those up to this one.
    pub fn newest_used_ns(&self, time_ns: u64) -> Option<u64> {
        let k = self.states.partition_point(|s| s.time_ns <= time_ns);
        self.states.get(k).or(self.states.back()).map(|s| s.time_ns)
    }

    /// The pose at `time_ns`: linear in translation, spherical in rotation between the
    /// two states around it; past the newest, extrapolated with its velocity (rotation
    /// held) up to the allowance.
    pub fn at(&self, time_ns: u64) -> Result<Isometry3<f64>, HistoryError> {
        let (first, last) = match (self.states.front(), self.states.back()) {
            (Some(f), Some(l)) => (f, l),
            _ => return Err(HistoryError::Empty),
        };
        if time_ns < first.time_ns {
            return Err(HistoryError::TooOld(first.time_ns - time_ns));
        }
        if time_ns >= last.time_ns {
            let ahead = time_ns - last.time_ns;
            if ahead > self.max_extrapolation_ns {
                return Err(HistoryError::Stale(ahead));
            }
            let dt = ahead as f64 * 1e-9;
            let t = last.world_from_body.translation.vector + last.velocity * dt;
            return Ok(Isometry3::from_parts(
                Translation3::from(t),
                last.world_from_body.rotation,
            ));
        }
        // First state strictly after `time_ns`; the one before it is at or before.
        let k = self.states.partition_point(|s| s.time_ns <= time_ns);
        let (a, b) = match (self.states.get(k.wrapping_sub(1)), self.states.get(k)) {
            (Some(a), Some(b)) => (a, b),
            _ => return Err(HistoryError::Empty),
        };
        let s = (time_ns - a.time_ns) as f64 / (b.time_ns - a.time_ns) as f64;
        let t = a
            .world_from_body
            .translation
            .vector
            .lerp(&b.world_from_body.translation.vector, s);
        let r: UnitQuaternion<f64> = a
            .world_from_body
            .rotation
            .try_slerp(&b.world_from_body.rotation, s, 1e-9)
            .unwrap_or(a.world_from_body.rotation);
        Ok(Isometry3::from_parts(Translation3::from(t), r))
    }
}

#[cfg(test)]
#[path = "lib_test.rs"]
mod tests;
