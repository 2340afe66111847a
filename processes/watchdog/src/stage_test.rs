use super::*;
use ipc_types::msg::{FsmStatus, ProcessEvent, ProcessEventKind, Text, VehicleState};
use stage::{SliceHeader, SliceMut};

/// The sequence numbers published, by topic.
#[derive(Default)]
struct Sent {
    views: Vec<u64>,
    orders: Vec<u64>,
}

impl Outbox for Sent {
    fn publish(&mut self, _topic: &str, msg: Message<'_>) -> Result<(), StageError> {
        match msg {
            Message::WatchdogView(v) => self.views.push(v.msg.seq),
            Message::SafetyCommand(c) => self.orders.push(c.msg.seq),
            _ => {}
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

#[test]
fn views_and_safety_orders_are_numbered_each_on_their_own_without_gaps() {
    let mut st = WatchdogStage::from_config(
        &WatchdogStageConfig::default(),
        &[("fsm".to_string(), 500.0)],
    )
    .unwrap();
    let mut out = Sent::default();
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
    assert!(out.orders.len() >= 2, "orders {:?}", out.orders);
    assert!(out.views.len() > out.orders.len(), "views {:?}", out.views);
    for seqs in [&out.views, &out.orders] {
        let expected: Vec<u64> = (1..=seqs.len() as u64).collect();
        assert_eq!(seqs, &expected);
    }
}
