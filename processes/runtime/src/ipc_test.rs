//! Tests of `ipc`.

use super::*;

#[test]
fn prefixes_reject_path_characters() {
    assert!(IpcPrefix::new("run_1-a.b").is_ok());
    assert!(IpcPrefix::new("../x").is_err());
    assert!(IpcPrefix::new("").is_err());
    assert!(IpcPrefix::new(&"a".repeat(33)).is_err());
    assert!(IpcPrefix::new(IpcPrefix::unique("some test!").as_str()).is_ok());
}

#[test]
fn the_periodic_waiter_learns_the_period_despite_bursts_and_drops() {
    let mut w = PeriodicWait::new(Duration::from_micros(200), Duration::from_millis(1));
    let mut t = 1_000_000_000u64;
    for i in 0..20u64 {
        // 30 Hz, with a burst (a second sample read 5 us later) every 4th frame and a
        // dropped frame every 7th.
        t += if i % 7 == 6 { 66_666_667 } else { 33_333_333 };
        w.on_arrival(t);
        if i % 4 == 0 {
            w.on_arrival(t + 5_000);
            t += 5_000;
        }
    }
    let p = w.period().expect("a period").as_secs_f64();
    assert!((p - 1.0 / 30.0).abs() < 0.001, "period {p}");
}

#[test]
fn sequence_gaps_are_counted_and_a_sequence_that_starts_over_is_a_restart() {
    let (last, gaps, restarts) = (Cell::new(0), Cell::new(0), Cell::new(0));
    for s in [1, 2, 5, 6, 9, 1, 2, 3] {
        track_seq(&last, &gaps, &restarts, s);
    }
    assert_eq!((gaps.get(), restarts.get()), (4, 1));
}

#[test]
fn a_message_sent_in_one_node_arrives_in_another_with_its_header() {
    let prefix = IpcPrefix::unique("pubsub");
    let a = Ipc::open("a", &prefix).expect("node a");
    let b = Ipc::open("b", &prefix).expect("node b");
    let sub = b
        .subscriber::<ipc_types::msg::PlannerGoal>("t/goal")
        .expect("subscriber");
    let mut publ = a
        .publisher::<ipc_types::msg::PlannerGoal>("t/goal")
        .expect("publisher");
    let goal = ipc_types::msg::PlannerGoal {
        position: [1.0, 2.0, 3.0],
        ..Default::default()
    };
    publ.send(Header::captured_at(42), &goal).expect("send");
    publ.send(Header::captured_at(43), &goal).expect("send");
    let s = sub.latest().expect("receive").expect("a sample");
    assert_eq!(s.position, [1.0, 2.0, 3.0]);
    assert_eq!(s.user_header().seq, 2);
    assert_eq!(s.user_header().capture_ns, 43);
}

#[test]
fn two_prefixes_never_see_each_other() {
    let a = Ipc::open("a", &IpcPrefix::unique("iso")).expect("node a");
    let b = Ipc::open("b", &IpcPrefix::unique("iso")).expect("node b");
    let sub = b.subscriber::<u64>("t/iso").expect("subscriber");
    let mut publ = a.publisher::<u64>("t/iso").expect("publisher");
    publ.send(Header::default(), &7).expect("send");
    assert!(sub.receive().expect("receive").is_none());
}

#[test]
fn the_wait_loop_wakes_on_data_and_reports_a_missed_heartbeat() {
    let prefix = IpcPrefix::unique("wait");
    let a = Ipc::open("worker", &prefix).expect("node");
    let w = Ipc::open("watcher", &prefix).expect("node");
    let hb_listener = w
        .heartbeat_listener("worker", Duration::from_millis(30))
        .expect("hb listener");
    let mut hb = a.heartbeat(Duration::from_millis(30)).expect("hb");
    let sub = w.subscriber::<u64>("t/wait").expect("sub");
    let mut publ = a.publisher::<u64>("t/wait").expect("pub");
    hb.beat().expect("beat");
    publ.send(Header::default(), &5).expect("send");
    let mut got_data = false;
    let mut missed = false;
    let exit = run_wait_loop(
        &[sub.listener()],
        &[(&hb_listener, Duration::from_millis(30))],
        Some(Duration::from_secs(2)),
        |wake| {
            match wake {
                Wake::Data(0) => {
                    got_data = matches!(sub.receive(), Ok(Some(s)) if *s == 5);
                }
                Wake::DeadlineMissed(0) => missed = true,
                Wake::Tick => return false,
                _ => {}
            }
            !(got_data && missed)
        },
    )
    .expect("loop");
    assert_eq!(exit, LoopExit::Stopped);
    assert!(got_data, "data wake-up");
    assert!(missed, "the worker stopped beating, so its deadline passed");
}

#[test]
fn a_bad_prefix_is_a_prefix_error_that_says_what_is_allowed() {
    let e = IpcPrefix::new("../x").expect_err("rejected");
    assert_eq!(e, PrefixError("../x".into()));
    assert!(e.to_string().contains("allowed: 1 to 32 characters"), "{e}");
}

#[test]
fn a_service_opened_with_another_type_is_an_open_error_naming_the_service() {
    let prefix = IpcPrefix::unique("types");
    let a = Ipc::open("a", &prefix).expect("node");
    let _publisher = a.publisher::<u64>("t/typed").expect("publisher");
    let Err(e) = a.subscriber::<u32>("t/typed") else {
        panic!("a type mismatch must be refused")
    };
    assert!(matches!(e, ServiceError::Open { .. }), "{e:?}");
    assert!(
        e.to_string().starts_with("iceoryx2 service `t/typed`: "),
        "{e}"
    );
}

#[test]
fn a_loan_beyond_the_maximum_is_a_loan_error_naming_the_service() {
    let prefix = IpcPrefix::unique("loan");
    let a = Ipc::open("a", &prefix).expect("node");
    let mut frames = a
        .slice_publisher::<u8, ipc_types::msg::CameraFrameHeader>("t/frames", 4)
        .expect("publisher");
    let Err(e) = frames.loan(8) else {
        panic!("too large a loan must be refused")
    };
    assert!(
        e.to_string()
            .starts_with("iceoryx2 `t/frames`: loan failed: "),
        "{e}"
    );
}

#[test]
fn a_second_process_of_a_node_on_a_prefix_in_use_is_refused_naming_the_prefix() {
    let prefix = IpcPrefix::unique("excl");
    let first = Ipc::open_exclusive("fsm", &prefix).expect("first");
    let Err(e) = Ipc::open_exclusive("fsm", &prefix) else {
        panic!("the second was not refused");
    };
    let msg = e.to_string();
    assert!(msg.contains(prefix.as_str()), "{msg}");
    assert!(msg.contains("one stack per prefix"), "{msg}");
    assert!(
        msg.contains(&format!("pid {}", std::process::id())),
        "{msg}"
    );
    // Another node, or another prefix, is free; so is the name once the first is gone.
    let _planner = Ipc::open_exclusive("planner", &prefix).expect("another node");
    let _elsewhere =
        Ipc::open_exclusive("fsm", &IpcPrefix::unique("excl")).expect("another prefix");
    drop(first);
    let _again = Ipc::open_exclusive("fsm", &prefix).expect("free again");
}

#[test]
fn a_deep_subscriber_keeps_sixteen_messages_where_a_default_one_keeps_four() {
    let prefix = IpcPrefix::unique("depth");
    let a = Ipc::open("a", &prefix).expect("node");
    let shallow = a.subscriber::<u64>("t/depth").expect("default subscriber");
    let deep = a
        .subscriber_with_depth::<u64>("t/depth", stage::MAX_MESSAGE_DEPTH as usize)
        .expect("deep subscriber");
    let mut publisher = a.publisher::<u64>("t/depth").expect("publisher");
    let mut send = |values: std::ops::RangeInclusive<u64>| {
        for v in values {
            publisher.send(Header::default(), &v).expect("send");
        }
    };
    send(1..=1);
    let drain = |s: &Subscriber<u64>| {
        let mut got = Vec::new();
        while let Some(m) = s.receive().expect("receive") {
            got.push(*m.payload());
        }
        (got, s.gaps())
    };
    assert_eq!(drain(&shallow), (vec![1], 0));
    assert_eq!(drain(&deep), (vec![1], 0));
    // 20 at once (a reader held off the CPU): the oldest are overwritten, and counted.
    send(2..=21);
    assert_eq!(drain(&shallow), ((18..=21).collect(), 16));
    assert_eq!(drain(&deep), ((6..=21).collect(), 4));
    let Err(e) = a.subscriber_with_depth::<u64>("t/depth", 17) else {
        panic!("a buffer deeper than the service allows must be refused")
    };
    assert!(e.to_string().contains("t/depth"), "{e}");
}

#[test]
fn a_restarted_publisher_is_counted_as_a_restart_not_as_lost_messages() {
    let prefix = IpcPrefix::unique("restart");
    let a = Ipc::open("a", &prefix).expect("node");
    let sub = a
        .subscriber_with_depth::<u64>("t/restart", stage::MAX_MESSAGE_DEPTH as usize)
        .expect("subscriber");
    let drain = |s: &Subscriber<u64>| {
        let mut got = Vec::new();
        while let Some(m) = s.receive().expect("receive") {
            got.push(*m.payload());
        }
        (got, s.gaps(), s.restarts())
    };
    let mut first = a.publisher::<u64>("t/restart").expect("publisher");
    for v in 1..=5 {
        first.send(Header::default(), &v).expect("send");
    }
    assert_eq!(drain(&sub), ((1..=5).collect(), 0, 0));
    drop(first);
    // The process died and came back: a new publisher numbers from 1 again.
    let mut again = a.publisher::<u64>("t/restart").expect("publisher again");
    for v in 6..=8 {
        again.send(Header::default(), &v).expect("send");
    }
    assert_eq!(drain(&sub), ((6..=8).collect(), 0, 1));
}
