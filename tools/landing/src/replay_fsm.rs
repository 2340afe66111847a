//! `landing replay --stage fsm`: the mission state machine run again on a recording's
//! inputs, its transitions compared with the flight's.
//!
//! The fsm steps on its own clock, at once on a pad observation while following it, and
//! at once on a safety order. Every step the flight's fsm made shows as the fsm's stamp
//! (its enter: the step's time) on what it published then: setpoints, statuses, goals,
//! requests. The replay builds a new fsm stage as `landing run` builds it, hands it every
//! input its publisher had sent before a step (the input's last stamp's exit), and steps
//! it at exactly the flight's step times. The transitions are compared as the statuses
//! show them: a status carries the number of transitions so far (its sequence), the last
//! one's from, to, time and reason; so transition k of the flight is compared with
//! transition k of the replay, every field, time included.

use std::collections::{BTreeMap, BTreeSet};

use anyhow::{Result, bail};
use ipc_types::msg::{
    FsmStatus, Header, LinkOutcome, MissionState, PadObservation, SafetyCommand, Stage as StageId,
    Trajectory, VehicleState, WatchdogView,
};
use ipc_types::topics;
use stage::{Input, Message, Outbox, SliceHeader, SliceMut, StageError};

use crate::replay_cmd::{Flight, ReplayArgs, ReplayReport};

/// An input of the fsm as recorded.
enum FsmInput {
    State(VehicleState),
    Observation(PadObservation),
    Trajectory(Trajectory),
    Outcome(LinkOutcome),
    Safety(SafetyCommand),
    View(WatchdogView),
}

impl FsmInput {
    /// The input as the stage takes it.
    fn input(&self) -> Input<'_> {
        let (topic, msg) = match self {
            Self::State(s) => (topics::VEHICLE_STATE, Message::VehicleState(s)),
            Self::Observation(o) => (topics::PAD_OBSERVATION, Message::PadObservation(o)),
            Self::Trajectory(t) => (topics::PLANNER_TRAJECTORY, Message::Trajectory(t)),
            Self::Outcome(o) => (topics::PX4_OUTCOME, Message::LinkOutcome(o)),
            Self::Safety(c) => (topics::SAFETY_COMMAND, Message::SafetyCommand(c)),
            Self::View(w) => (topics::WATCHDOG_VIEW, Message::WatchdogView(w)),
        };
        Input { topic, msg }
    }
}

/// A transition as a status shows it.
#[derive(Debug, Clone, PartialEq)]
struct Shown {
    from: u32,
    to: u32,
    at_ns: u64,
    reason: String,
}

impl Shown {
    fn describe(&self) -> String {
        let name = |s: u32| MissionState::from_raw(s).map_or("unknown", MissionState::name);
        format!(
            "{} -> {} at {} ns ({})",
            name(self.from),
            name(self.to),
            self.at_ns,
            self.reason
        )
    }
}

/// The transitions statuses show, by their number (the status's sequence).
#[derive(Default)]
struct Transitions(BTreeMap<u64, Shown>);

impl Transitions {
    fn add(&mut self, seq: u64, shown: Shown) {
        if seq > 0 {
            self.0.entry(seq).or_insert(shown);
        }
    }

    fn add_status(&mut self, s: &FsmStatus) {
        self.add(
            s.msg.seq,
            Shown {
                from: s.previous,
                to: s.state,
                at_ns: s.since_ns,
                reason: s.reason.as_str().to_string(),
            },
        );
    }
}

/// Collects the statuses the replayed fsm publishes.
#[derive(Default)]
struct Statuses(Transitions);

impl Outbox for Statuses {
    fn publish(&mut self, _topic: &str, msg: Message<'_>) -> Result<(), StageError> {
        if let Message::FsmStatus(s) = msg {
            self.0.add_status(s);
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

/// When the publisher let a message out: its last stamp's exit. A message with no stamp
/// (px4-link's outcomes before they were stamped) counts from its capture time, when it
/// was made: the recorder's log time is when the recorder's round began, which can be
/// before a message taken in that round was published.
pub(crate) fn sent_at(h: &Header, log_time: u64) -> u64 {
    match h.stages().last() {
        Some(s) => s.exit_ns,
        None if h.capture_ns > 0 => h.capture_ns,
        None => log_time,
    }
}

/// Replays the fsm of the recording `args.file`.
pub fn replay(args: &ReplayArgs) -> Result<ReplayReport> {
    let mut inputs: Vec<(u64, FsmInput)> = vec![];
    let mut steps: BTreeSet<u64> = BTreeSet::new();
    let mut flown = Transitions::default();
    let summary = recorder::read_recording(&args.file, |m| {
        if m.encoding != "json" {
            return Ok(());
        }
        let topic = m.topic.trim_start_matches('/');
        let published_by_fsm = [
            topics::FSM_SETPOINT,
            topics::FSM_STATUS,
            topics::PLANNER_GOAL,
            topics::PX4_REQUEST,
        ]
        .contains(&topic);
        let is_input = [
            topics::VEHICLE_STATE,
            topics::PAD_OBSERVATION,
            topics::PLANNER_TRAJECTORY,
            topics::PX4_OUTCOME,
            topics::SAFETY_COMMAND,
            topics::WATCHDOG_VIEW,
        ]
        .contains(&topic);
        if !published_by_fsm && !is_input {
            return Ok(());
        }
        let h = m.header()?;
        if published_by_fsm && let Some(t) = crate::replay_cmd::enter_of(&h, StageId::Fsm) {
            steps.insert(t);
        }
        let input = match topic {
            topics::VEHICLE_STATE => FsmInput::State(m.decode()?),
            topics::PAD_OBSERVATION => FsmInput::Observation(m.decode()?),
            topics::PLANNER_TRAJECTORY => FsmInput::Trajectory(m.decode()?),
            topics::PX4_OUTCOME => FsmInput::Outcome(m.decode()?),
            topics::SAFETY_COMMAND => FsmInput::Safety(m.decode()?),
            // The fsm reads only that a view came (the watchdog lives).
            topics::WATCHDOG_VIEW => FsmInput::View(WatchdogView {
                msg: h,
                ..WatchdogView::default()
            }),
            topics::FSM_STATUS => {
                flown.add_status(&m.decode()?);
                return Ok(());
            }
            _ => return Ok(()),
        };
        inputs.push((sent_at(&h, m.log_time), input));
        Ok(())
    })?;
    let flight = Flight::of(args, &summary)?;
    if steps.is_empty() {
        bail!(
            "{}: nothing the fsm published (fsm/status, fsm/setpoint, planner/goal, px4/request)",
            args.file.display()
        );
    }
    let Some(mut stage) = flight.stage("fsm")? else {
        bail!("no stage for fsm");
    };
    // In the order they were sent; a stable sort keeps the file's order at a tie.
    inputs.sort_by_key(|(at, _)| *at);
    let mut out = Statuses::default();
    let mut next = inputs.iter().peekable();
    let mut handed = 0u64;
    for &t in &steps {
        // Everything sent by the step, at its sending time (the fsm reads the inputs'
        // own capture times; the arrival only bounds them). A safety order steps the fsm
        // itself when it arrives: it is handed at the first step after it was sent,
        // which it then is.
        let mut stepped = false;
        while let Some((at, input)) = next.peek()
            && *at <= t
        {
            if matches!(input, FsmInput::Safety(_)) {
                stage.on_input(t, input.input(), &mut out)?;
                stepped = true;
            } else {
                stage.on_input(*at, input.input(), &mut out)?;
            }
            handed += 1;
            next.next();
        }
        if !stepped {
            stage.on_tick(t, &mut out)?;
        }
    }
    let replayed = out.0;
    let mut report = ReplayReport {
        stage: "fsm".into(),
        inputs: handed,
        recorded: flown.0.len() as u64,
        replayed: replayed.0.len() as u64,
        identical: 0,
        different: 0,
        differences: vec![],
        missing: vec![],
        extra: replayed
            .0
            .keys()
            .filter(|k| !flown.0.contains_key(k))
            .count() as u64,
        flown: flown
            .0
            .iter()
            .map(|(k, f)| format!("{k}: {}", f.describe()))
            .collect(),
    };
    for (k, f) in &flown.0 {
        match replayed.0.get(k) {
            Some(r) if r == f => report.identical += 1,
            Some(r) => {
                report.different += 1;
                if report.differences.len() < 10 {
                    report.differences.push(format!(
                        "transition {k}: {} replayed, {} in flight",
                        r.describe(),
                        f.describe()
                    ));
                }
            }
            None => report.missing.push(*k),
        }
    }
    Ok(report)
}
