//! The anatomy of a touchdown, from a recording and the simulator's truth: where the
//! vehicle was over the pad when the drop began, what the stack believed then, and what
//! the fall added. A touchdown's error is the sum of those parts, and each has its own
//! remedy (the camera's calibration, the drop's gate, the pull through the fall), so a
//! tail is read part by part before anything is changed (docs/fsm.md).
//!
//! Offsets are in the road frame of the drop's start: x along the pad's velocity, y to
//! its left (the world's axes when the pad is slower than [`ROAD_SPEED_MIN_M_S`]).

use ipc_types::msg::{FsmStatus, Setpoint, TruthEvent, TruthKind, TruthState, VehicleState};
use nalgebra::Vector3;
use serde::Serialize;
use state_history::timed_pose_of;

/// Below this pad speed the road has no direction: the world's axes are used, m/s.
pub const ROAD_SPEED_MIN_M_S: f64 = 0.1;
/// How far before the contact the drop's start is looked for, s: the drop from the flare
/// height takes under a second.
pub const DROP_SEARCH_S: f64 = 2.0;
/// Over this long before the drop the held lean is averaged, s.
const LEAN_WINDOW_S: f64 = 0.3;
/// The longest a vehicle state is carried forward to a setpoint's time, s: the fsm's own
/// bound (processes/fsm/src/mission.rs).
const CARRY_MAX_S: f64 = 1.0;
const G: f64 = 9.80665;

/// A touchdown taken apart (see the module's docs for the frame). Metres, m/s, m/s^2.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TouchdownAnatomy {
    /// How long before the first contact the drop began, s.
    pub drop_lead_s: f64,
    /// The vehicle's height over the pad's centre when the drop began (truth).
    pub drop_height_m: f64,
    /// The pad's speed when the drop began (truth).
    pub pad_speed_m_s: f64,
    /// The vehicle's offset from the pad's centre when the drop began (truth).
    pub offset_at_drop_m: [f64; 2],
    /// The same offset as the stack read it: its estimated position (carried from its
    /// stamp to the setpoint's log time, as the fsm carries it to now) minus the pad's
    /// estimate the setpoint steered to.
    pub offset_read_at_drop_m: [f64; 2],
    /// Truth minus what the stack read: the camera's calibration residual and the
    /// estimate's error, which no loop over the pad can see.
    pub read_error_at_drop_m: [f64; 2],
    /// The vehicle's velocity relative to the pad when the drop began (truth).
    pub rel_velocity_at_drop_m_s: [f64; 2],
    /// The horizontal acceleration the vehicle's tilt held over the last 0.3 s before
    /// the drop (`g tan tilt`, from the estimated attitude): the wind it leaned into.
    pub lean_before_drop_m_s2: [f64; 2],
    /// What the fall added: the offset at contact minus the offset at the drop's start.
    pub fall_drift_m: [f64; 2],
    /// The vehicle's offset from the pad's centre at the first contact (truth).
    pub offset_at_contact_m: [f64; 2],
    /// The referee's touchdown point, in the pad's own frame.
    pub touchdown_pad_m: [f64; 2],
}

/// Why a touchdown could not be taken apart.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum AnatomyError {
    /// The truth has no touchdown event.
    #[error("no touchdown in the truth: the vehicle never came to rest on a surface")]
    NoTouchdown,
    /// No setpoint descended at the drop's rate before the contact.
    #[error(
        "no drop in the {DROP_SEARCH_S} s before the touchdown: no setpoint descending faster than {0} m/s relative to the pad"
    )]
    NoDrop(f64),
    /// The drop's rate is not above the touchdown's: the two cannot be told apart.
    #[error(
        "[fsm] drop_rate_m_s {drop} is not above land_rate_m_s {land}: the drop cannot be told from the descent"
    )]
    Rates {
        /// The touchdown's descent rate, m/s.
        land: f64,
        /// The drop's, m/s.
        drop: f64,
    },
    /// A series the anatomy needs is empty around the drop.
    #[error("no {0} before the drop")]
    Missing(&'static str),
}

/// The recorded series the anatomy reads, each as (log time ns, message) in log order.
#[derive(Debug, Default)]
pub struct TouchdownSeries {
    /// The simulator's truth state (`sim/truth_state`).
    pub truth: Vec<(u64, TruthState)>,
    /// The simulator's truth events (`sim/truth`).
    pub events: Vec<(u64, TruthEvent)>,
    /// The fsm's setpoints (`fsm/setpoint`).
    pub setpoints: Vec<(u64, Setpoint)>,
    /// The autopilot's estimated states (`vehicle/state`).
    pub states: Vec<(u64, VehicleState)>,
    /// The fsm's statuses (`fsm/status`): the pad's estimated vertical velocity, which
    /// the setpoint's descent rides on.
    pub statuses: Vec<(u64, FsmStatus)>,
}

/// Takes the first touchdown of `s` apart. The drop began at the first setpoint, within
/// [`DROP_SEARCH_S`] before the contact, that descends faster than halfway between the
/// touchdown's rate `land_m_s` and the drop's `drop_m_s` (`[fsm] land_rate_m_s` and
/// `drop_rate_m_s`), relative to the pad's estimated vertical velocity.
pub fn touchdown_anatomy(
    s: &TouchdownSeries,
    land_m_s: f64,
    drop_m_s: f64,
) -> Result<TouchdownAnatomy, AnatomyError> {
    // Also refuses a rate that is not a number.
    let separable = drop_m_s > land_m_s;
    if !separable {
        return Err(AnatomyError::Rates {
            land: land_m_s,
            drop: drop_m_s,
        });
    }
    let threshold = 0.5 * (land_m_s + drop_m_s);
    let (contact_t, event) = s
        .events
        .iter()
        .find(|(_, e)| e.kind == TruthKind::Touchdown as u32)
        .ok_or(AnatomyError::NoTouchdown)?;
    let search_from = contact_t.saturating_sub((DROP_SEARCH_S * 1e9) as u64);
    // The setpoint's descent is the pad's estimated vertical velocity plus the rate asked
    // for (and never below the rate alone): the smaller of the two readings is the rate.
    let descent = |t: u64, sp: &Setpoint| {
        let pad_vz = latest(&s.statuses, t).map_or(0.0, |(_, st)| st.pad_velocity[2]);
        let vz = sp.velocity[2];
        let relative = if pad_vz.is_finite() { vz - pad_vz } else { vz };
        -vz.min(relative)
    };
    let (drop_t, setpoint) = s
        .setpoints
        .iter()
        .filter(|(t, _)| (search_from..=*contact_t).contains(t))
        .find(|(t, sp)| descent(*t, sp) > threshold)
        .ok_or(AnatomyError::NoDrop(threshold))?;
    let drop_t = *drop_t;
    let missing = AnatomyError::Missing;
    let (_, at_drop) = latest(&s.truth, drop_t).ok_or(missing("truth state"))?;
    let (_, at_contact) = latest(&s.truth, *contact_t).ok_or(missing("truth state"))?;
    let (state_t, state) = latest(&s.states, drop_t).ok_or(missing("vehicle state"))?;

    let pad_v = [at_drop.pad_velocity[0], at_drop.pad_velocity[1]];
    let speed = pad_v[0].hypot(pad_v[1]);
    let along = if speed >= ROAD_SPEED_MIN_M_S {
        [pad_v[0] / speed, pad_v[1] / speed]
    } else {
        [1.0, 0.0]
    };
    let road = |w: [f64; 2]| {
        [
            w[0] * along[0] + w[1] * along[1],
            -w[0] * along[1] + w[1] * along[0],
        ]
    };
    let offset = |t: &TruthState| {
        road([
            t.vehicle_position[0] - t.pad_position[0],
            t.vehicle_position[1] - t.pad_position[1],
        ])
    };
    let offset_at_drop = offset(at_drop);
    let offset_at_contact = offset(at_contact);

    // The state carried to the setpoint's time, as the fsm carries it to now: from its
    // stamp, or from its arrival when it has none.
    let stamp = match state.msg.capture_ns {
        0 => *state_t,
        t => t.min(drop_t),
    };
    let age_s = (drop_t - stamp) as f64 * 1e-9;
    let carry = age_s.clamp(0.0, CARRY_MAX_S);
    let p = state.world_from_body.translation;
    let read = road([
        p[0] + state.velocity[0] * carry - setpoint.position[0],
        p[1] + state.velocity[1] * carry - setpoint.position[1],
    ]);

    let lean_from = drop_t.saturating_sub((LEAN_WINDOW_S * 1e9) as u64);
    let leans: Vec<[f64; 2]> = s
        .states
        .iter()
        .filter(|(t, _)| (lean_from..=drop_t).contains(t))
        .filter_map(|(_, v)| lean(v))
        .collect();
    let lean_world = mean(&leans).ok_or(AnatomyError::Missing("attitude"))?;

    let rel_v = road([
        at_drop.vehicle_velocity[0] - at_drop.pad_velocity[0],
        at_drop.vehicle_velocity[1] - at_drop.pad_velocity[1],
    ]);
    Ok(TouchdownAnatomy {
        drop_lead_s: (*contact_t as f64 - drop_t as f64) * 1e-9,
        drop_height_m: at_drop.vehicle_position[2] - at_drop.pad_position[2],
        pad_speed_m_s: speed,
        offset_at_drop_m: offset_at_drop,
        offset_read_at_drop_m: read,
        read_error_at_drop_m: [offset_at_drop[0] - read[0], offset_at_drop[1] - read[1]],
        rel_velocity_at_drop_m_s: rel_v,
        lean_before_drop_m_s2: road(lean_world),
        fall_drift_m: [
            offset_at_contact[0] - offset_at_drop[0],
            offset_at_contact[1] - offset_at_drop[1],
        ],
        offset_at_contact_m: offset_at_contact,
        touchdown_pad_m: event.rel_position_pad,
    })
}

/// The newest entry at or before `t` of a series in log order.
fn latest<T>(series: &[(u64, T)], t: u64) -> Option<&(u64, T)> {
    let after = series.partition_point(|(at, _)| *at <= t);
    after.checked_sub(1).and_then(|i| series.get(i))
}

/// The horizontal acceleration the vehicle's tilt holds at 1 g of vertical thrust: `g`
/// times its up axis' horizontal part over its vertical part. None for a state the stack
/// would not take as a pose (`state_history::timed_pose_of`: a number not finite, a
/// quaternion far from unit length) or a body on its side.
fn lean(v: &VehicleState) -> Option<[f64; 2]> {
    let up = timed_pose_of(v)?.world_from_body.rotation * Vector3::z();
    (up.z > 0.1).then(|| [G * up.x / up.z, G * up.y / up.z])
}

fn mean(v: &[[f64; 2]]) -> Option<[f64; 2]> {
    if v.is_empty() {
        return None;
    }
    let n = v.len() as f64;
    let sum = v.iter().fold([0.0, 0.0], |a, b| [a[0] + b[0], a[1] + b[1]]);
    Some([sum[0] / n, sum[1] / n])
}

#[cfg(test)]
#[path = "touchdown_test.rs"]
mod tests;
