//! `landing replay --stage planner`: the trajectory planner run again on a recording's
//! goals, vehicle states and maps, every trajectory it publishes compared, control point
//! for control point, with the one the flight's planner published.
//!
//! The planner decides on its own clock (every 20 ms) from the newest goal, state and
//! map. A decision that planned shows as the planner's stamp (its enter: the decision's
//! time) on the statistics and the trajectory it published; the replay builds a new stage
//! as `landing run` builds it, hands it every input sent by a decision's time (the
//! input's last stamp's exit; maps with their cells from `/map/occupancy`,
//! `foxglove.VoxelGrid`) and decides at exactly those times. Decisions that planned
//! nothing leave no trace and are not replayed: the planner keeps no state of them.

use std::collections::BTreeMap;

use anyhow::{Result, bail};
use ipc_types::msg::{OccupancyMapHeader, PlannerGoal, Stage as StageId, Trajectory, VehicleState};
use ipc_types::topics;
use serde_json::Value;
use stage::{Input, Message, Outbox, SliceHeader, SliceMut, StageError};

use crate::replay_cmd::{Flight, ReplayArgs, ReplayReport, first_difference};
use crate::replay_fsm::sent_at;
use recorder::RecordedMaps;

/// The trajectories the replayed stage publishes.
#[derive(Default)]
struct Trajectories(Vec<Trajectory>);

impl Outbox for Trajectories {
    fn publish(&mut self, _topic: &str, msg: Message<'_>) -> Result<(), StageError> {
        if let Message::Trajectory(t) = msg {
            self.0.push(*t);
        }
        Ok(())
    }

    fn publish_slice(
        &mut self,
        _topic: &str,
        _len: usize,
        _fill: &mut dyn FnMut(SliceMut<'_>) -> Option<SliceHeader>,
    ) -> Result<bool, StageError> {
        Ok(false)
    }
}

/// One input of the replay.
enum Event {
    State(VehicleState),
    Goal(PlannerGoal),
    Map(OccupancyMapHeader, Vec<u8>),
}

/// A trajectory's results as JSON, without its header's stage stamps.
fn results(v: &Value) -> Value {
    let mut v = v.clone();
    let capture = v["msg"]["capture_ns"].clone();
    if let Some(m) = v.as_object_mut() {
        m.remove("msg");
    }
    v["capture_ns"] = capture;
    v
}

/// Replays the planner on the recording `args.file`.
pub fn replay(args: &ReplayArgs) -> Result<ReplayReport> {
    let mut events: Vec<(u64, Event)> = vec![];
    // Each decision that planned: its time, and the capture time of the vehicle state it
    // planned from (its outputs' headers derive from that state's).
    let mut steps: BTreeMap<u64, u64> = BTreeMap::new();
    // The flight's trajectories in order, as JSON.
    let mut flown: Vec<Value> = vec![];
    let mut maps = RecordedMaps::default();
    let summary = recorder::read_recording(&args.file, |m| {
        let topic = m.topic.trim_start_matches('/');
        if maps.take(m)? {
            return Ok(());
        }
        if m.encoding != "json" {
            return Ok(());
        }
        let v: Value = match topic {
            t if t == topics::VEHICLE_STATE
                || t == topics::PLANNER_GOAL
                || t == topics::PLANNER_TRAJECTORY
                || t == topics::PLANNER_STATS =>
            {
                serde_json::from_slice(m.data)?
            }
            _ => return Ok(()),
        };
        let h = m.header()?;
        let at = sent_at(&h, m.log_time);
        match topic {
            t if t == topics::VEHICLE_STATE => {
                events.push((at, Event::State(m.decode()?)));
            }
            t if t == topics::PLANNER_GOAL => events.push((at, Event::Goal(m.decode()?))),
            t if t == topics::PLANNER_TRAJECTORY => {
                if let Some(s) = crate::replay_cmd::enter_of(&h, StageId::Planner) {
                    steps.insert(s, h.capture_ns);
                }
                flown.push(results(&v));
            }
            t if t == topics::PLANNER_STATS => {
                if let Some(s) = crate::replay_cmd::enter_of(&h, StageId::Planner) {
                    steps.insert(s, h.capture_ns);
                }
            }
            _ => {}
        }
        Ok(())
    })?;
    let flight = Flight::of(args, &summary)?;
    if maps.grids == 0 {
        bail!(
            "{}: no map cells (/map/occupancy, foxglove.VoxelGrid): recorded before the recorder kept them",
            args.file.display()
        );
    }
    if steps.is_empty() {
        bail!("{}: the planner published nothing", args.file.display());
    }
    for m in maps.maps {
        if let Some(cells) = m.cells {
            events.push((
                sent_at(&m.header.msg, m.log_time),
                Event::Map(m.header, cells),
            ));
        }
    }
    let Some(mut stage) = flight.stage("planner")? else {
        bail!("no stage for planner");
    };
    events.sort_by_key(|(at, _)| *at);
    // States apart: a state published at the very instant of a decision (lockstep) may
    // or may not have reached it; the decision's outputs say which one it used.
    let (states, others): (Vec<_>, Vec<_>) = events
        .into_iter()
        .partition(|(_, e)| matches!(e, Event::State(_)));
    let mut out = Trajectories::default();
    let mut next_state = states.iter().peekable();
    let mut next_other = others.iter().peekable();
    let mut inputs = 0u64;
    for (&t, &used) in &steps {
        let mut hand = |at: u64, e: &Event| -> Result<()> {
            let (topic, msg) = match e {
                Event::State(s) => (topics::VEHICLE_STATE, Message::VehicleState(s)),
                Event::Goal(g) => (topics::PLANNER_GOAL, Message::PlannerGoal(g)),
                Event::Map(h, c) => (topics::MAP_OCCUPANCY, Message::OccupancyMap(h, c)),
            };
            stage.on_input(at, Input { topic, msg }, &mut out)?;
            inputs += 1;
            Ok(())
        };
        while let Some((at, e)) = next_other.peek()
            && *at <= t
        {
            hand(*at, e)?;
            next_other.next();
        }
        while let Some((at, e @ Event::State(s))) = next_state.peek()
            && *at <= t
            && (used == 0 || s.msg.capture_ns <= used)
        {
            hand(*at, e)?;
            next_state.next();
        }
        stage.on_tick(t, &mut out)?;
    }
    let replayed: Vec<Value> = out
        .0
        .iter()
        .map(|t| serde_json::to_value(t).map(|v| results(&v)))
        .collect::<Result<_, _>>()?;
    let mut report = ReplayReport {
        stage: "planner".into(),
        inputs,
        recorded: flown.len() as u64,
        replayed: replayed.len() as u64,
        identical: 0,
        different: 0,
        differences: vec![],
        missing: vec![],
        extra: replayed.len().saturating_sub(flown.len()) as u64,
        flown: vec![],
    };
    for (i, f) in flown.iter().enumerate() {
        match replayed.get(i) {
            None => report.missing.push(f["capture_ns"].as_u64().unwrap_or(0)),
            Some(r) => match first_difference(r, f, "") {
                None => report.identical += 1,
                Some(d) => {
                    report.different += 1;
                    if report.differences.len() < 10 {
                        report.differences.push(format!("trajectory {i}: {d}"));
                    }
                }
            },
        }
    }
    Ok(report)
}
