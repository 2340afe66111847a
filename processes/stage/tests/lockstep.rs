//! The lockstep driver's rules, with small stages: outputs arrive after the producer's
//! modelled latency, a `newest` input hands over only the newest waiting message, a
//! delayed edge is seen in a later pass of the same instant, and a node may not read
//! ground truth.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test

use std::cell::RefCell;
use std::rc::Rc;

use ipc_types::msg::{PlannerGoal, Setpoint};
use ipc_types::topics;
use stage::lockstep::{InputSpec, Lockstep, LockstepError, NodeSpec};
use stage::{Counter, Input, Message, Outbox, Stage, StageError};

/// Publishes a goal (its `seq` = the tick count) on every tick.
struct Ticker {
    period_ns: u64,
    n: u64,
}

impl Stage for Ticker {
    fn name(&self) -> &'static str {
        "ticker"
    }
    fn tick_period_ns(&self) -> Option<u64> {
        Some(self.period_ns)
    }
    fn on_input(&mut self, _: u64, _: Input<'_>, _: &mut dyn Outbox) -> Result<(), StageError> {
        Ok(())
    }
    fn on_tick(&mut self, _now: u64, out: &mut dyn Outbox) -> Result<(), StageError> {
        self.n += 1;
        let mut g = PlannerGoal::default();
        g.msg.seq = self.n;
        out.publish(topics::PLANNER_GOAL, Message::PlannerGoal(&g))
    }
    fn counters(&self) -> Vec<Counter> {
        vec![("ticks", self.n)]
    }
}

/// Records (time, goal seq) of every goal it gets and answers with a setpoint.
struct Echo {
    seen: Rc<RefCell<Vec<(u64, u64)>>>,
}

impl Stage for Echo {
    fn name(&self) -> &'static str {
        "echo"
    }
    fn on_input(
        &mut self,
        now: u64,
        input: Input<'_>,
        out: &mut dyn Outbox,
    ) -> Result<(), StageError> {
        if let Message::PlannerGoal(g) = input.msg {
            self.seen.borrow_mut().push((now, g.msg.seq));
            out.publish(
                topics::FSM_SETPOINT,
                Message::Setpoint(&Setpoint::default()),
            )?;
        }
        Ok(())
    }
    fn counters(&self) -> Vec<Counter> {
        vec![]
    }
}

fn spec(name: &str, inputs: &[(&str, bool, bool)], outputs: &[&str], latency_ns: u64) -> NodeSpec {
    NodeSpec {
        name: name.into(),
        inputs: inputs
            .iter()
            .map(|(t, newest, delay)| InputSpec {
                topic: (*t).into(),
                newest: *newest,
                delay: *delay,
                depth: None,
            })
            .collect(),
        outputs: outputs.iter().map(|o| (*o).into()).collect(),
        latency_ns,
        periodic: None,
    }
}

#[test]
fn outputs_arrive_after_the_producers_latency() {
    let seen = Rc::new(RefCell::new(Vec::new()));
    let mut d = Lockstep::new(vec![
        (
            spec("ticker", &[], &[topics::PLANNER_GOAL], 5_000_000),
            Box::new(Ticker {
                period_ns: 20_000_000,
                n: 0,
            }) as Box<dyn Stage>,
        ),
        (
            spec(
                "echo",
                &[(topics::PLANNER_GOAL, false, false)],
                &[topics::FSM_SETPOINT],
                0,
            ),
            Box::new(Echo { seen: seen.clone() }),
        ),
    ])
    .unwrap();
    let mut published = Vec::new();
    while d.now_ns() < 60_000_000 {
        d.step(&mut |p| published.push((p.now_ns, p.topic.to_string())))
            .unwrap();
    }
    assert_eq!(
        seen.borrow()[..3],
        [(5_000_000, 1), (25_000_000, 2), (45_000_000, 3)]
    );
    assert!(published.contains(&(5_000_000, topics::FSM_SETPOINT.to_string())));
}

#[test]
fn a_newest_input_skips_what_a_newer_message_replaced() {
    let seen = Rc::new(RefCell::new(Vec::new()));
    // Two tickers at the same instant, one reader that wants only the newest goal.
    let mut d = Lockstep::new(vec![
        (
            spec("ticker", &[], &[topics::PLANNER_GOAL], 0),
            Box::new(Ticker {
                period_ns: 10,
                n: 0,
            }) as Box<dyn Stage>,
        ),
        (
            spec(
                "echo",
                &[(topics::PLANNER_GOAL, true, true)],
                &[topics::FSM_SETPOINT],
                0,
            ),
            Box::new(Echo { seen: seen.clone() }),
        ),
    ])
    .unwrap();
    for _ in 0..3 {
        d.step(&mut |_| {}).unwrap();
    }
    // One goal per instant, each seen in a later pass of its instant (a delayed edge).
    assert_eq!(seen.borrow()[..], [(0, 1), (10, 2), (20, 3)]);
    assert_eq!(d.skipped("echo"), 0);
    d.inject(
        topics::PLANNER_GOAL,
        Message::PlannerGoal(&PlannerGoal::default()),
    );
    d.inject(
        topics::PLANNER_GOAL,
        Message::PlannerGoal(&PlannerGoal::default()),
    );
    d.step(&mut |_| {}).unwrap();
    assert_eq!(
        d.skipped("echo"),
        1,
        "two injected, one ticked: the newest only"
    );
}

#[test]
fn a_node_reading_ground_truth_is_refused() {
    let e = Lockstep::new(vec![(
        spec("echo", &[(topics::SIM_TRUTH, false, false)], &[], 0),
        Box::new(Echo {
            seen: Rc::default(),
        }) as Box<dyn Stage>,
    )])
    .expect_err("refused");
    assert!(matches!(e, LockstepError::EvaluatorOnly { .. }), "{e}");
}

#[test]
fn a_stage_publishing_outside_its_outputs_fails_the_run() {
    let mut d = Lockstep::new(vec![(
        spec("ticker", &[], &[], 0),
        Box::new(Ticker {
            period_ns: 10,
            n: 0,
        }) as Box<dyn Stage>,
    )])
    .unwrap();
    let e = d.step(&mut |_| {}).expect_err("refused");
    assert!(e.to_string().contains("not one of its outputs"), "{e}");
}

#[test]
fn ticks_given_by_time_come_at_those_times_beside_the_period_and_once_per_instant() {
    // A ticker with a 20 ms period, ticked also at 7 ms, 20 ms (a period tick already)
    // and 33 ms: a recorded step schedule replayed.
    let seen = Rc::new(RefCell::new(Vec::new()));
    let mut d = Lockstep::new(vec![
        (
            spec("ticker", &[], &[topics::PLANNER_GOAL], 0),
            Box::new(Ticker {
                period_ns: 20_000_000,
                n: 0,
            }) as Box<dyn Stage>,
        ),
        (
            spec(
                "echo",
                &[(topics::PLANNER_GOAL, false, false)],
                &[topics::FSM_SETPOINT],
                0,
            ),
            Box::new(Echo { seen: seen.clone() }),
        ),
    ])
    .unwrap();
    for t in [7_000_000, 20_000_000, 33_000_000] {
        assert!(d.tick_at("ticker", t));
    }
    assert!(!d.tick_at("nobody", 1));
    while d.now_ns() < 40_000_000 {
        d.step(&mut |_| {}).unwrap();
    }
    let times: Vec<u64> = seen.borrow().iter().map(|(t, _)| *t).collect();
    assert_eq!(
        times,
        [0, 7_000_000, 20_000_000, 33_000_000, 40_000_000],
        "{:?}",
        seen.borrow()
    );
}
