use super::*;

const MS: u64 = 1_000_000;

fn process(name: &str, critical: bool) -> WatchedProcess {
    WatchedProcess {
        name: name.into(),
        deadline_ms: 500.0,
        critical,
        restart_ms: 0.0,
    }
}

fn watchdog() -> Watchdog {
    let cfg = WatchdogConfig {
        processes: vec![
            process("fsm", true),
            process("px4-link", true),
            process("planner", false),
        ],
        paths: vec![
            PathRule {
                topic: "pad/observation".into(),
                phases: vec![MissionState::Descend, MissionState::Land],
                silence: Budget::flat(300.0),
                garbage: Budget::flat(100.0),
                critical: false,
            },
            PathRule {
                topic: "fsm/setpoint".into(),
                phases: Vec::new(),
                silence: Budget::flat(200.0),
                garbage: Budget::flat(100.0),
                critical: true,
            },
        ],
        policy: Policy::default(),
    };
    Watchdog::new(cfg).unwrap_or_else(|e| panic!("{e}"))
}

/// Every process beats every 100 ms and setpoints flow at 50 Hz until `until_ms`.
fn healthy(w: &mut Watchdog, from_ms: u64, until_ms: u64) -> Vec<Outputs> {
    let mut out = Vec::new();
    for t in (from_ms..until_ms).step_by(20) {
        let now = t * MS;
        if t % 100 == 0 {
            for p in ["fsm", "px4-link", "planner"] {
                w.beat(p, now);
            }
        }
        w.message("fsm/setpoint", now, true);
        out.push(w.tick(now));
    }
    out
}

#[test]
fn a_healthy_stack_raises_nothing() {
    let mut w = watchdog();
    w.mission(MissionState::Track, true, true, 0);
    let out = healthy(&mut w, 0, 5_000);
    assert!(out.iter().all(|o| o.faults.is_empty() && o.order.is_none()));
    let v = w.view();
    assert_eq!(v.count, 3);
    assert!(
        v.processes[..3]
            .iter()
            .all(|p| p.liveness == Liveness::Alive as u32)
    );
}

#[test]
fn a_dead_fsm_in_the_air_orders_one_safe_landing_at_once() {
    let mut w = watchdog();
    w.mission(MissionState::Track, true, true, 0);
    healthy(&mut w, 0, 1_000);
    w.died("fsm", 1_010 * MS);
    let o = w.tick(1_010 * MS);
    assert_eq!(o.faults, vec![(1_010 * MS, Fault::Dead("fsm".into()))]);
    assert_eq!(o.order, Some((SafetyAction::SafeLand, "fsm died".into())));
    assert!(w.tick(1_030 * MS).order.is_none(), "ordered once");
    assert!(w.ordered() && w.view().safe_land_ordered == 1);
}

#[test]
fn a_hung_px4_link_is_found_after_its_deadline_and_not_before() {
    let mut w = watchdog();
    w.mission(MissionState::Descend, true, true, 0);
    w.beat("px4-link", 0);
    w.beat("fsm", 0);
    assert!(w.tick(500 * MS).order.is_none(), "at the deadline: not yet");
    w.beat("fsm", 400 * MS);
    let o = w.tick(501 * MS);
    assert_eq!(o.faults, vec![(501 * MS, Fault::Hung("px4-link".into()))]);
    assert_eq!(
        o.order,
        Some((SafetyAction::SafeLand, "px4-link hung".into()))
    );
    assert_eq!(w.view().processes[1].missed_deadlines, 1);
}

#[test]
fn on_the_ground_a_fault_is_reported_but_nothing_is_ordered() {
    let mut w = watchdog();
    w.mission(MissionState::Idle, false, true, 0);
    healthy(&mut w, 0, 1_000);
    w.died("fsm", 1_000 * MS);
    let o = w.tick(1_000 * MS);
    assert_eq!(o.faults.len(), 1);
    assert!(o.order.is_none(), "systemd restarts it; nothing to land");
    // Restarted: it beats again and is alive.
    w.beat("fsm", 1_300 * MS);
    assert_eq!(w.view().processes[0].liveness, Liveness::Alive as u32);
}

#[test]
fn a_non_critical_process_lost_while_tracking_lands_by_the_default_policy() {
    let mut w = watchdog();
    w.mission(MissionState::Track, true, true, 0);
    healthy(&mut w, 0, 1_000);
    w.died("planner", 1_000 * MS);
    let o = w.tick(1_000 * MS);
    assert_eq!(o.faults, vec![(1_000 * MS, Fault::Dead("planner".into()))]);
    assert_eq!(
        o.order,
        Some((SafetyAction::SafeLand, "planner died".into()))
    );
    assert_eq!(o.decisions[0].action, Action::Land);
}

#[test]
fn a_non_critical_loss_while_descending_goes_on_only_with_a_fresh_pad_estimate() {
    let mut w = watchdog();
    w.mission(MissionState::Descend, true, true, 0);
    healthy(&mut w, 0, 1_000);
    w.died("planner", 1_000 * MS);
    let o = w.tick(1_000 * MS);
    assert!(o.order.is_none(), "the fsm keeps landing on the pad");
    assert_eq!(o.decisions[0].action, Action::Continue);
    assert_eq!(
        w.view().action.as_str(),
        "planner died in descend: continue"
    );

    let mut w = watchdog();
    w.mission(MissionState::Descend, true, false, 0);
    healthy(&mut w, 0, 1_000);
    w.died("planner", 1_000 * MS);
    let o = w.tick(1_000 * MS);
    assert_eq!(o.decisions[0].action, Action::Land, "no fresh estimate");
    assert_eq!(o.decisions[0].why, "planner died in descend: land, no pad");
    assert!(w.ordered());
}

#[test]
fn a_hold_policy_holds_and_a_later_critical_loss_still_lands() {
    let mut w = Watchdog::new(WatchdogConfig {
        policy: Policy {
            by_phase: Vec::new(),
            otherwise: Action::Hold,
        },
        ..watchdog().cfg
    })
    .unwrap_or_else(|e| panic!("{e}"));
    w.mission(MissionState::Track, true, true, 0);
    healthy(&mut w, 0, 1_000);
    w.died("planner", 1_000 * MS);
    let o = w.tick(1_000 * MS);
    assert_eq!(o.order, Some((SafetyAction::Hold, "planner died".into())));
    assert!(!w.ordered());
    w.died("fsm", 1_020 * MS);
    let o = w.tick(1_020 * MS);
    assert_eq!(o.order, Some((SafetyAction::SafeLand, "fsm died".into())));
    assert!(w.ordered() && w.view().order_ns == 1_020 * MS);
}

#[test]
fn pad_observations_must_flow_only_while_descending() {
    let mut w = watchdog();
    w.mission(MissionState::Track, true, true, 0);
    let out = healthy(&mut w, 0, 2_000);
    assert!(
        out.iter().all(|o| o.faults.is_empty()),
        "not needed in Track"
    );
    w.mission(MissionState::Descend, true, true, 2_000 * MS);
    w.message("pad/observation", 2_100 * MS, true);
    assert!(
        healthy(&mut w, 2_100, 2_400)
            .iter()
            .all(|o| o.faults.is_empty())
    );
    let out = healthy(&mut w, 2_400, 2_600);
    let silent: Vec<_> = out.iter().flat_map(|o| o.faults.clone()).collect();
    assert_eq!(silent.len(), 1, "{silent:?}");
    assert_eq!(silent[0].1, Fault::Silent("pad/observation".into()));
    assert!(
        out.iter().all(|o| o.order.is_none()),
        "the fsm handles a lost pad"
    );
}

#[test]
fn setpoints_that_stop_or_turn_to_garbage_in_the_air_order_a_landing() {
    let mut w = watchdog();
    w.mission(MissionState::Track, true, true, 0);
    healthy(&mut w, 0, 1_000);
    w.message("fsm/setpoint", 1_000 * MS, false);
    let o = w.tick(1_000 * MS);
    assert_eq!(
        o.faults,
        vec![(1_000 * MS, Fault::Garbage("fsm/setpoint".into()))]
    );
    assert!(
        o.order.is_none(),
        "reported at once, a loss after its budget"
    );
    for t in (1_020..=1_100).step_by(20) {
        w.message("fsm/setpoint", t * MS, false);
        assert!(w.tick(t * MS).order.is_none(), "{t} ms: within 100 ms");
    }
    w.message("fsm/setpoint", 1_120 * MS, false);
    let o = w.tick(1_120 * MS);
    assert_eq!(
        o.order,
        Some((SafetyAction::SafeLand, "garbage on fsm/setpoint".into()))
    );

    // A moment of garbage, then good setpoints again: flown through.
    let mut w = watchdog();
    w.mission(MissionState::Track, true, true, 0);
    healthy(&mut w, 0, 1_000);
    w.message("fsm/setpoint", 1_000 * MS, false);
    w.message("fsm/setpoint", 1_060 * MS, false);
    assert!(w.tick(1_060 * MS).order.is_none());
    let out = healthy(&mut w, 1_080, 2_000);
    assert!(
        out.iter()
            .all(|o| o.order.is_none() && o.decisions.is_empty())
    );

    let mut w = watchdog();
    w.mission(MissionState::Track, true, true, 0);
    for p in ["fsm", "px4-link", "planner"] {
        w.beat(p, 0);
    }
    w.message("fsm/setpoint", 0, true);
    assert!(w.tick(200 * MS).order.is_none());
    let o = w.tick(201 * MS);
    assert_eq!(
        o.faults,
        vec![(201 * MS, Fault::Silent("fsm/setpoint".into()))]
    );
    assert!(o.order.is_some());
}

#[test]
fn a_bad_configuration_names_what_is_wrong() {
    let bad = |cfg: WatchdogConfig| Watchdog::new(cfg).err().map(|e| e.to_string());
    let e = bad(WatchdogConfig {
        processes: vec![WatchedProcess {
            deadline_ms: f64::NAN,
            ..process("fsm", true)
        }],
        ..WatchdogConfig::default()
    });
    assert_eq!(
        e.as_deref(),
        Some("heartbeat deadline of fsm: NaN ms is not a positive number of milliseconds")
    );
    let e = bad(WatchdogConfig {
        processes: vec![process("fsm", true), process("fsm", false)],
        ..WatchdogConfig::default()
    });
    assert_eq!(e.as_deref(), Some("fsm is watched twice"));
    let e = bad(WatchdogConfig {
        processes: (0..17).map(|k| process(&format!("p{k}"), false)).collect(),
        ..WatchdogConfig::default()
    });
    assert_eq!(e.as_deref(), Some("17 processes to watch: at most 16"));
}

#[test]
fn a_path_needed_always_stays_silent_across_a_phase_change() {
    let mut w = watchdog();
    w.mission(MissionState::Track, true, true, 0);
    healthy(&mut w, 0, 1_000);
    // Setpoints stop at 980 ms; the fsm changes phase at 1 100 ms (reacting to
    // something): the silence is still counted from 980 ms.
    for p in ["fsm", "px4-link", "planner"] {
        w.beat(p, 1_100 * MS);
    }
    w.mission(MissionState::Lost, true, true, 1_100 * MS);
    assert!(w.tick(1_150 * MS).faults.is_empty());
    let o = w.tick(1_190 * MS);
    assert_eq!(
        o.faults,
        vec![(1_190 * MS, Fault::Silent("fsm/setpoint".into()))]
    );
}

#[test]
fn an_order_stands_for_its_flight_and_the_next_flight_starts_without_it() {
    let mut w = watchdog();
    w.mission(MissionState::Track, true, true, 0);
    healthy(&mut w, 0, 1_000);
    w.died("fsm", 1_000 * MS);
    assert!(w.tick(1_000 * MS).order.is_some());
    assert!(w.ordered());
    // Down: the order is over, its time stays in the view.
    w.mission(MissionState::SafeLand, false, false, 5_000 * MS);
    assert!(!w.ordered());
    assert_eq!(w.view().order_ns, 1_000 * MS);
    // The fsm restarted, the next flight loses it again: a new order.
    w.beat("fsm", 6_000 * MS);
    w.mission(MissionState::Track, true, true, 7_000 * MS);
    for p in ["px4-link", "planner"] {
        w.beat(p, 7_000 * MS);
    }
    w.message("fsm/setpoint", 7_000 * MS, true);
    w.died("fsm", 7_010 * MS);
    assert_eq!(
        w.tick(7_010 * MS).order,
        Some((SafetyAction::SafeLand, "fsm died".into()))
    );
}

#[test]
fn the_view_shows_each_processs_cpu_use_between_its_last_two_measurements() {
    let mut w = watchdog();
    let health = |w: &Watchdog, name: &str| {
        let v = w.view();
        *v.processes
            .iter()
            .find(|p| p.name.as_str() == name)
            .unwrap()
    };
    assert_eq!(health(&w, "fsm").cpu_ns, 0, "not measured yet");
    w.cpu("fsm", 1_000 * MS, 40 * MS);
    assert_eq!(
        health(&w, "fsm").cpu_percent,
        0.0,
        "one measurement is no rate"
    );
    // 250 ms of CPU in a second: a quarter of a core.
    w.cpu("fsm", 2_000 * MS, 290 * MS);
    let h = health(&w, "fsm");
    assert_eq!(h.cpu_ns, 290 * MS);
    assert!((h.cpu_percent - 25.0).abs() < 1e-9, "{}", h.cpu_percent);
    assert_eq!(
        health(&w, "planner").cpu_ns,
        0,
        "another process is untouched"
    );
    // Restarted: less CPU time than before starts over rather than going negative.
    w.cpu("fsm", 3_000 * MS, 5 * MS);
    assert_eq!(health(&w, "fsm").cpu_percent, 0.0);
    // A process the watchdog does not watch is ignored.
    w.cpu("nobody", 3_000 * MS, 5 * MS);
}

/// The test's watchdog with a 600 ms restart budget for every process and telemetry
/// allowed 1500 ms of silence, 500 in the touchdown.
fn riding_through() -> Watchdog {
    let cfg = WatchdogConfig {
        processes: ["fsm", "px4-link", "planner"]
            .iter()
            .map(|n| WatchedProcess {
                restart_ms: 600.0,
                ..process(n, *n != "planner")
            })
            .collect(),
        paths: vec![PathRule {
            topic: "vehicle/state".into(),
            phases: Vec::new(),
            silence: Budget {
                by_phase: vec![(MissionState::Land, 500.0)],
                otherwise: 1500.0,
            },
            garbage: Budget::flat(1500.0),
            critical: true,
        }],
        policy: Policy::default(),
    };
    Watchdog::new(cfg).unwrap_or_else(|e| panic!("{e}"))
}

/// Every process but `except` beats at `t_ms`.
fn beat_but(w: &mut Watchdog, t_ms: u64, except: &str) {
    for p in ["fsm", "px4-link", "planner"] {
        if p != except {
            w.beat(p, t_ms * MS);
        }
    }
}

#[test]
fn a_px4_link_restarted_within_its_budget_is_no_loss() {
    let mut w = riding_through();
    w.mission(MissionState::Land, true, true, 0);
    healthy(&mut w, 0, 1_000);
    w.died("px4-link", 1_000 * MS);
    let o = w.tick(1_000 * MS);
    assert_eq!(o.faults, vec![(1_000 * MS, Fault::Dead("px4-link".into()))]);
    assert!(o.order.is_none() && o.decisions.is_empty(), "{o:?}");
    for t in (1_010..1_300).step_by(10) {
        beat_but(&mut w, t, "px4-link");
        assert!(w.tick(t * MS).order.is_none());
    }
    w.beat("px4-link", 1_300 * MS);
    let o = w.tick(1_300 * MS);
    assert_eq!(o.rejoins, vec![("px4-link".to_string(), 300.0)]);
    for t in (1_310..3_000).step_by(10) {
        beat_but(&mut w, t, "");
        let o = w.tick(t * MS);
        assert!(o.order.is_none() && o.decisions.is_empty(), "{t} ms: {o:?}");
    }
    let v = w.view();
    assert_eq!(v.processes[1].restarts, 1);
    assert_eq!(v.processes[1].liveness, Liveness::Alive as u32);
    assert!(!w.ordered());
}

#[test]
fn a_px4_link_not_back_within_its_budget_lands() {
    let mut w = riding_through();
    w.mission(MissionState::Track, true, true, 0);
    healthy(&mut w, 0, 1_000);
    w.died("px4-link", 1_000 * MS);
    for t in (1_000..1_600).step_by(10) {
        beat_but(&mut w, t, "px4-link");
        assert!(w.tick(t * MS).order.is_none(), "{t} ms: within the budget");
    }
    let o = w.tick(1_600 * MS);
    assert_eq!(
        o.order,
        Some((SafetyAction::SafeLand, "px4-link died".into()))
    );
    assert_eq!(o.decisions[0].why, "px4-link died: land (critical)");
}

#[test]
fn telemetry_silence_is_judged_by_the_budget_of_the_phase() {
    let mut w = riding_through();
    w.mission(MissionState::Track, true, true, 0);
    w.message("vehicle/state", 0, true);
    assert!(
        w.tick(1_000 * MS).faults.is_empty(),
        "1 s while tracking: ridden through"
    );
    w.message("vehicle/state", 1_000 * MS, true);
    assert!(
        w.tick(2_500 * MS).faults.is_empty(),
        "at the budget: not yet"
    );
    let o = w.tick(2_510 * MS);
    assert_eq!(
        o.faults,
        vec![(2_510 * MS, Fault::Silent("vehicle/state".into()))]
    );
    assert!(o.order.is_some());

    let mut w = riding_through();
    w.mission(MissionState::Land, true, true, 0);
    w.message("vehicle/state", 0, true);
    let o = w.tick(510 * MS);
    assert_eq!(
        o.faults,
        vec![(510 * MS, Fault::Silent("vehicle/state".into()))]
    );
    assert_eq!(
        o.order,
        Some((SafetyAction::SafeLand, "vehicle/state silent".into()))
    );
}
