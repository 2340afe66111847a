use super::*;
use ipc_types::msg::{FsmStatus, ProcessEvent, ProcessEventKind, Text, VehicleState};
use stage::testing::Collector;

/// The sequence numbers of what was published on `topic`.
fn seqs(out: &Collector, topic: &str) -> Vec<u64> {
    out.on(topic)
        .filter_map(|m| m.as_message().header().map(|h| h.seq))
        .collect()
}

#[test]
fn views_and_safety_orders_are_numbered_each_on_their_own_without_gaps() {
    let mut st = WatchdogStage::from_config(
        &WatchdogStageConfig::default(),
        &[("fsm".to_string(), 500.0)],
    )
    .unwrap();
    let mut out = Collector::new();
    const MS: u64 = 1_000_000;
    let mut died = false;
    for k in 1..=300u64 {
        let now = k * 10 * MS;
        let mut state = VehicleState {
            landed_state: LandedState::InAir as u32,
            msg: Header::captured_at(now),
            ..VehicleState::default()
        };
        state.link.last_telemetry_ns = now;
        let msg = Message::VehicleState(&state);
        st.on_input(
            now,
            Input {
                topic: topics::VEHICLE_STATE,
                msg,
            },
            &mut out,
        )
        .unwrap();
        let status = FsmStatus {
            state: MissionState::Track as u32,
            ..FsmStatus::default()
        };
        let msg = Message::FsmStatus(&status);
        st.on_input(
            now,
            Input {
                topic: topics::FSM_STATUS,
                msg,
            },
            &mut out,
        )
        .unwrap();
        // The fsm beats for a second, then dies in the air: orders are repeated.
        let kind = if k <= 100 {
            ProcessEventKind::Beat
        } else {
            ProcessEventKind::Died
        };
        if !died {
            died = kind == ProcessEventKind::Died;
            let e = ProcessEvent {
                msg: Header::captured_at(now),
                process: Text::new("fsm"),
                kind: kind as u32,
                ..ProcessEvent::default()
            };
            let msg = Message::ProcessEvent(&e);
            st.on_input(
                now,
                Input {
                    topic: topics::WATCHDOG_LIVENESS,
                    msg,
                },
                &mut out,
            )
            .unwrap();
        }
        st.on_tick(now, &mut out).unwrap();
    }
    let (views, orders) = (
        seqs(&out, topics::WATCHDOG_VIEW),
        seqs(&out, topics::SAFETY_COMMAND),
    );
    assert!(orders.len() >= 2, "orders {orders:?}");
    assert!(views.len() > orders.len(), "views {views:?}");
    for seqs in [&views, &orders] {
        let expected: Vec<u64> = (1..=seqs.len() as u64).collect();
        assert_eq!(seqs, &expected);
    }
}
