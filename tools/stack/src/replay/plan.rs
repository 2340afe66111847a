//! When each replayable stage took its inputs and stepped in flight, read from the
//! stamps on what it read and published, and what of its outputs is compared. One rule
//! per stage; everything else of a replay is the same for all.
//!
//! - aruco-pnp works on each camera frame it takes: a frame at the time the flight's
//!   stage took it (its stamp's enter on the observation; else camera-ingest's exit),
//!   after every state px4-link had published by then. No steps. Observations compared
//!   by capture time.
//! - depth-map makes a map on each frame and on its clock when frames stop: each map's
//!   stamp (enter) is when. A frame is delivered at its map's time after the states its
//!   pose came from (the map names the newest, `state_ns`; recordings made before it:
//!   every state px4-link had published by then); the other maps are steps. Maps
//!   compared in order, header and every cell.
//! - planner decides on its clock from the newest of each input: a decision that planned
//!   shows as its stamp on what it published. Goals and maps are delivered when sent; a
//!   state when sent, unless it came after the state the decision planned from (then at
//!   the next decision). Decisions that planned nothing leave no trace and keep no state.
//!   Trajectories compared in order.
//! - fsm steps on its clock, at once on a pad observation while following it, and at
//!   once on a safety order: every step shows as its stamp on what it published then.
//!   Inputs are delivered when sent, a safety order at the first step after it (which it
//!   then is: no tick there). Transitions compared by number, as statuses show them.

use std::borrow::Cow;
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use anyhow::{Result, bail};
use ipc_types::msg::{MissionState, Stage as StageId};
use ipc_types::topics;
use recorder::RecordedMap;
use serde_json::Value;
use stage::OwnedMessage;

use super::{Output, Plan, Recording, results, sent_at, stamp_of};

/// What an output of `stage` is called in a difference.
pub(super) fn unit(stage: &str) -> &'static str {
    match stage {
        "aruco-pnp" => "capture",
        "depth-map" => "map",
        "planner" => "trajectory",
        _ => "transition",
    }
}

/// The flight's schedule of `stage` in `rec` (the recording `file`).
pub(super) fn plan<'a>(stage: &str, rec: &'a Recording, file: &Path) -> Result<Plan<'a>> {
    match stage {
        "aruco-pnp" => aruco(rec, file),
        "depth-map" => depth(rec, file),
        "planner" => planner(rec, file),
        _ => fsm(rec, file),
    }
}

/// The outputs of `stage` that a replay compares, from what it published (or recorded):
/// `(topic, message)` in publishing order.
pub(super) fn outputs<'a>(
    stage: &str,
    published: impl Iterator<Item = (&'a str, &'a OwnedMessage)>,
) -> Result<Vec<Output>> {
    let mut out: Vec<Output> = Vec::new();
    let mut seen = BTreeSet::new();
    for (topic, msg) in published {
        let ordinal = out.len() as u64;
        match (stage, topic, msg) {
            ("aruco-pnp", topics::PAD_OBSERVATION, OwnedMessage::PadObservation(o)) => {
                let c = o.msg.capture_ns;
                out.push(output(c, c, results(o, c)?, None));
            }
            ("depth-map", topics::MAP_OCCUPANCY, OwnedMessage::OccupancyMap(h, cells)) => {
                let c = h.msg.capture_ns;
                out.push(output(ordinal, c, results(h, c)?, Some(cells.clone())));
            }
            ("planner", topics::PLANNER_TRAJECTORY, OwnedMessage::Trajectory(t)) => {
                let c = t.msg.capture_ns;
                out.push(output(ordinal, c, results(t, c)?, None));
            }
            // A status repeats the last transition; its sequence numbers them.
            ("fsm", topics::FSM_STATUS, OwnedMessage::FsmStatus(s))
                if s.msg.seq > 0 && seen.insert(s.msg.seq) =>
            {
                let name = |r: u32| MissionState::from_raw(r).map_or("unknown", MissionState::name);
                let shown = format!(
                    "{} -> {} at {} ns ({})",
                    name(s.previous),
                    name(s.state),
                    s.since_ns,
                    s.reason.as_str()
                );
                out.push(output(
                    s.msg.seq,
                    s.msg.capture_ns,
                    Value::String(shown),
                    None,
                ));
            }
            _ => {}
        }
    }
    Ok(out)
}

fn output(key: u64, capture: u64, value: Value, cells: Option<Vec<u8>>) -> Output {
    Output {
        key,
        capture,
        value,
        cells,
    }
}

/// The recorded outputs of `stage` on `topic`.
fn recorded(stage: &str, rec: &Recording, topic: &str) -> Result<Vec<Output>> {
    outputs(stage, rec.on(topic).map(|m| (m.topic, &m.msg)))
}

fn aruco<'a>(rec: &'a Recording, file: &Path) -> Result<Plan<'a>> {
    if rec.cameras.is_empty() {
        if rec.jpeg {
            bail!(
                "{}: its camera frames are JPEG, not the frames aruco-pnp saw: record with --raw-images to replay aruco-pnp",
                file.display()
            );
        }
        bail!("{}: no camera frames (/camera/frame)", file.display());
    }
    // When the flight's stage took each frame: its stamp on the observation.
    let took: BTreeMap<u64, u64> = rec
        .on(topics::PAD_OBSERVATION)
        .filter_map(|o| {
            Some((
                o.header.capture_ns,
                stamp_of(&o.header, StageId::ArucoPnp)?.0,
            ))
        })
        .collect();
    let mut plan = Plan {
        recorded: recorded("aruco-pnp", rec, topics::PAD_OBSERVATION)?,
        ..Plan::default()
    };
    for s in rec.on(topics::VEHICLE_STATE) {
        let at = stamp_of(&s.header, StageId::Px4Link).map_or(s.log_time, |(_, exit)| exit);
        plan.deliveries
            .push((at, topics::VEHICLE_STATE, Cow::Borrowed(&s.msg)));
    }
    for f in &rec.cameras {
        let Some(h) = f.as_message().header().copied() else {
            continue;
        };
        let at = took
            .get(&h.capture_ns)
            .copied()
            .or_else(|| stamp_of(&h, StageId::CameraIngest).map(|(_, exit)| exit))
            .unwrap_or(h.capture_ns);
        plan.deliveries
            .push((at, topics::CAMERA_FRAME, Cow::Borrowed(f)));
    }
    Ok(plan)
}

/// A depth frame and the capture time of the newest state its map used.
type FrameUsed<'a> = (&'a OwnedMessage, u64);

fn depth<'a>(rec: &'a Recording, file: &Path) -> Result<Plan<'a>> {
    let maps = &rec.maps.maps;
    if maps.is_empty() {
        bail!("{}: no maps (/map/occupancy/header)", file.display());
    }
    if rec.maps.grids == 0 {
        bail!(
            "{}: no map cells (/map/occupancy, foxglove.VoxelGrid): recorded before the recorder kept them",
            file.display()
        );
    }
    if rec.depths.is_empty() {
        bail!("{}: no depth frames (/sim/depth)", file.display());
    }
    // A map the recording lost (the recorder fell behind: a gap in the publisher's
    // sequence numbers) may have integrated a frame the replay cannot tell, and every map
    // after it keeps that frame's cells: only the maps before the first loss compare.
    let (maps, lost) = before_first_loss(maps);
    let mut frames: BTreeMap<u64, &OwnedMessage> = rec
        .depths
        .iter()
        .filter_map(|f| Some((f.as_message().header()?.capture_ns, f)))
        .collect();
    let mut plan = Plan {
        lost,
        not_compared: (rec.maps.maps.len() - maps.len()) as u64,
        ..Plan::default()
    };
    for m in maps {
        let c = m.header.msg.capture_ns;
        plan.recorded.push(output(
            plan.recorded.len() as u64,
            c,
            results(&m.header, c)?,
            m.cells.clone(),
        ));
    }
    // Each map: (when, a frame first at a tie, the frame and the newest state it used).
    let mut events: Vec<(u64, u8, Option<FrameUsed<'_>>)> = Vec::new();
    for m in maps {
        let Some((at, _)) = stamp_of(&m.header.msg, StageId::DepthMap) else {
            continue;
        };
        match frames.remove(&m.header.msg.capture_ns) {
            Some(f) => events.push((at, 0, Some((f, m.header.state_ns)))),
            None => events.push((at, 1, None)),
        }
    }
    events.sort_by_key(|(at, kind, _)| (*at, *kind));
    let mut states: Vec<(u64, &super::Recorded)> = rec
        .on(topics::VEHICLE_STATE)
        .map(|s| {
            let at = stamp_of(&s.header, StageId::Px4Link).map_or(s.log_time, |(_, exit)| exit);
            (at, s)
        })
        .collect();
    states.sort_by_key(|(at, _)| *at);
    let mut states = states.into_iter().peekable();
    for (at, _, frame) in events {
        let Some((f, newest)) = frame else {
            plan.ticks.push(at);
            continue;
        };
        // The states the pose came from: up to the newest the map names, or (an older
        // recording) every one published by the stage's stamp.
        let held = |(published, s): &(u64, &super::Recorded)| match newest {
            0 => *published <= at,
            n => s.header.capture_ns <= n,
        };
        while let Some((_, s)) = states.next_if(held) {
            plan.deliveries
                .push((at, topics::VEHICLE_STATE, Cow::Borrowed(&s.msg)));
        }
        plan.deliveries
            .push((at, topics::SIM_DEPTH, Cow::Borrowed(f)));
    }
    plan.ticks.sort_unstable();
    Ok(plan)
}

/// The maps before the first one missing from the publisher's sequence, and how many the
/// sequence says are missing in all. Lockstep maps carry no sequence number (0): nothing
/// there is lost.
fn before_first_loss(maps: &[RecordedMap]) -> (&[RecordedMap], u64) {
    let seqs = || maps.iter().map(|m| m.header.msg.seq);
    let gap = |(a, b): (u64, u64)| if a > 0 && b > a { b - a - 1 } else { 0 };
    let lost = seqs().zip(seqs().skip(1)).map(gap).sum();
    let first = seqs()
        .zip(seqs().skip(1))
        .position(|p| gap(p) > 0)
        .map_or(maps.len(), |i| i + 1);
    (&maps[..first], lost)
}

fn planner<'a>(rec: &'a Recording, file: &Path) -> Result<Plan<'a>> {
    if rec.maps.grids == 0 {
        bail!(
            "{}: no map cells (/map/occupancy, foxglove.VoxelGrid): recorded before the recorder kept them",
            file.display()
        );
    }
    // Each decision that planned: its time, and the capture time of the state it planned
    // from (its outputs' headers derive from that state's).
    let steps: BTreeMap<u64, u64> = rec
        .on(topics::PLANNER_TRAJECTORY)
        .chain(rec.on(topics::PLANNER_STATS))
        .filter_map(|m| {
            Some((
                stamp_of(&m.header, StageId::Planner)?.0,
                m.header.capture_ns,
            ))
        })
        .collect();
    let Some(&last) = steps.keys().next_back() else {
        bail!("{}: the planner published nothing", file.display());
    };
    let mut plan = Plan {
        recorded: recorded("planner", rec, topics::PLANNER_TRAJECTORY)?,
        ticks: steps.keys().copied().collect(),
        ..Plan::default()
    };
    for g in rec.on(topics::PLANNER_GOAL) {
        let at = sent_at(&g.header, g.log_time);
        if at <= last {
            plan.deliveries
                .push((at, topics::PLANNER_GOAL, Cow::Borrowed(&g.msg)));
        }
    }
    for m in &rec.maps.maps {
        let (Some(cells), at) = (&m.cells, sent_at(&m.header.msg, m.log_time)) else {
            continue;
        };
        if at <= last {
            let map = OwnedMessage::OccupancyMap(m.header, cells.clone());
            plan.deliveries
                .push((at, topics::MAP_OCCUPANCY, Cow::Owned(map)));
        }
    }
    // States apart: one published at the very instant of a decision (lockstep) may or may
    // not have reached it; the decision's outputs say which one it used.
    let mut states: Vec<(u64, &super::Recorded)> = rec
        .on(topics::VEHICLE_STATE)
        .map(|s| (sent_at(&s.header, s.log_time), s))
        .collect();
    states.sort_by_key(|(at, _)| *at);
    let mut states = states.into_iter().peekable();
    let mut previous: Option<u64> = None;
    for (&t, &used) in &steps {
        while let Some((at, s)) =
            states.next_if(|(at, s)| *at <= t && (used == 0 || s.header.capture_ns <= used))
        {
            // Held back from an earlier decision: delivered after it.
            let at = previous.map_or(at, |p| at.max(p + 1));
            plan.deliveries
                .push((at, topics::VEHICLE_STATE, Cow::Borrowed(&s.msg)));
        }
        previous = Some(t);
    }
    Ok(plan)
}

fn fsm<'a>(rec: &'a Recording, file: &Path) -> Result<Plan<'a>> {
    let by_fsm = [
        topics::FSM_SETPOINT,
        topics::FSM_STATUS,
        topics::PLANNER_GOAL,
        topics::PX4_REQUEST,
    ];
    let steps: BTreeSet<u64> = rec
        .messages
        .iter()
        .filter(|m| by_fsm.contains(&m.topic))
        .filter_map(|m| Some(stamp_of(&m.header, StageId::Fsm)?.0))
        .collect();
    if steps.is_empty() {
        bail!(
            "{}: nothing the fsm published (fsm/status, fsm/setpoint, planner/goal, px4/request)",
            file.display()
        );
    }
    let read = [
        topics::VEHICLE_STATE,
        topics::PAD_OBSERVATION,
        topics::PLANNER_TRAJECTORY,
        topics::PX4_OUTCOME,
        topics::SAFETY_COMMAND,
        topics::WATCHDOG_VIEW,
    ];
    let mut inputs: Vec<(u64, &super::Recorded)> = rec
        .messages
        .iter()
        .filter(|m| read.contains(&m.topic))
        .map(|m| (sent_at(&m.header, m.log_time), m))
        .collect();
    // In the order they were sent; a stable sort keeps the file's order at a tie.
    inputs.sort_by_key(|(at, _)| *at);
    let statuses = recorded("fsm", rec, topics::FSM_STATUS)?;
    let mut plan = Plan {
        flown: statuses
            .iter()
            .map(|o| format!("{}: {}", o.key, o.value.as_str().unwrap_or_default()))
            .collect(),
        recorded: statuses,
        ..Plan::default()
    };
    let mut next = inputs.into_iter().peekable();
    for &t in &steps {
        let mut stepped = false;
        while let Some((at, m)) = next.next_if(|(at, _)| *at <= t) {
            // A safety order steps the fsm itself when it arrives: at this step.
            let safety = m.topic == topics::SAFETY_COMMAND;
            stepped |= safety;
            plan.deliveries
                .push((if safety { t } else { at }, m.topic, Cow::Borrowed(&m.msg)));
        }
        if !stepped {
            plan.ticks.push(t);
        }
    }
    Ok(plan)
}
