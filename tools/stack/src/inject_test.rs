use super::*;

#[test]
fn injections_parse_a_fault_a_process_and_a_phase_or_a_time() {
    let i: Injection = "kill:fsm@track".parse().unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(i.fault, Fault::Kill);
    assert_eq!(i.process, "fsm");
    assert_eq!(i.when, When::Phase(MissionState::Track));
    assert!(i.due(3.0, MissionState::Track) && !i.due(3.0, MissionState::Land));
    let i: Injection = "stop:planner@12.5s"
        .parse()
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((i.fault, i.when), (Fault::Stop, When::At(12.5)));
    assert!(!i.due(12.0, MissionState::Track) && i.due(12.5, MissionState::Idle));
    assert_eq!(i.to_string(), "stop:planner@12.5");
}

#[test]
fn a_bad_injection_names_what_is_wrong_and_what_is_allowed() {
    for (bad, why) in [
        ("kill-fsm@track", "no ':'"),
        ("kill:fsm", "no '@'"),
        ("melt:fsm@track", "unknown fault"),
        ("kill:@track", "no process"),
        ("kill:fsm@later", "unknown time"),
        ("kill:fsm@-1", "unknown time"),
        ("kill:fsm@NaN", "unknown time"),
    ] {
        let e = bad.parse::<Injection>().err().map(|e| e.to_string());
        let e = e.unwrap_or_default();
        assert!(
            e.contains(why) && e.contains("kill, stop or restart"),
            "{bad}: {e}"
        );
    }
    for (bad, why) in [
        ("delay:fsm@track", "unknown fault"),
        ("delay:0:fsm@track", "value out of range"),
        ("drop:1.5:aruco-pnp@track", "value out of range"),
        ("drop:NaN:aruco-pnp@track", "value out of range"),
    ] {
        let e = bad.parse::<Injection>().err().map(|e| e.to_string());
        let e = e.unwrap_or_default();
        assert!(e.contains(why) && e.contains("drop:FRACTION"), "{bad}: {e}");
    }
}

#[test]
fn port_faults_parse_with_their_value() {
    let i: Injection = "delay:50:camera-ingest@track"
        .parse()
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(
        (i.fault, i.process.as_str()),
        (Fault::Delay(50.0), "camera-ingest")
    );
    assert_eq!(i.fault.order(), Some((PortFault::Delay, 50.0)));
    assert_eq!(i.fault.signal(), None);
    let i: Injection = "drop:0.5:aruco-pnp@descend"
        .parse()
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(i.fault, Fault::Drop(0.5));
    assert_eq!(i.to_string(), "drop:0.5:aruco-pnp@descend");
    let i: Injection = "corrupt:aruco-pnp@3"
        .parse()
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((i.fault, i.when), (Fault::Corrupt(None), When::At(3.0)));
    assert_eq!(i.fault.duration_s(), 0.0, "to the end of the run");
    let i: Injection = "corrupt:0.5:camera-ingest@track"
        .parse()
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(i.fault, Fault::Corrupt(Some(0.5)));
    assert_eq!(i.fault.duration_s(), 0.5);
    assert_eq!(i.to_string(), "corrupt:0.5:camera-ingest@track");
}

#[test]
fn world_faults_parse_with_their_topic_or_count() {
    let i: Injection = "cut:2:sim/camera@track"
        .parse()
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(i.fault, Fault::Cut(2.0));
    assert_eq!(i.topic.as_deref(), Some("sim/camera"));
    assert_eq!(i.fault.order(), Some((PortFault::Drop, 1.0)));
    assert_eq!(i.to_string(), "cut:2:sim/camera@track");
    let i: Injection = "garbage:5000:px4-link@descend"
        .parse()
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(
        (i.fault, i.process.as_str()),
        (Fault::Garbage(5000), "px4-link")
    );
    assert_eq!((i.fault.signal(), i.fault.order()), (None, None));
    let i: Injection = "flood:spoofed:1000:px4-link@0".parse().unwrap();
    assert_eq!(i.fault, Fault::Flood(FloodKind::Spoofed, 1000.0));
    assert_eq!(i.to_string(), "flood:spoofed:1000:px4-link@0");
    assert_eq!((i.fault.signal(), i.fault.order()), (None, None));
    for bad in [
        "cut:0:sim/camera@track",
        "garbage:1.5:px4-link@track",
        "cut:2:camera@track",
        "flood:loud:1000:px4-link@0",
        "flood:random:0:px4-link@0",
        "flood:random:1e9:px4-link@0",
    ] {
        assert!(bad.parse::<Injection>().is_err(), "{bad}");
    }
}

#[test]
fn restart_and_blank_parse_with_their_targets() {
    let i: Injection = "restart:planner@track".parse().unwrap();
    assert_eq!((i.fault, i.process.as_str()), (Fault::Restart, "planner"));
    assert_eq!(i.fault.signal(), Some(libc::SIGKILL));
    let i: Injection = "blank:2.5:sim/camera@descend".parse().unwrap();
    assert_eq!(i.fault, Fault::Blank(2.5));
    assert_eq!(i.topic.as_deref(), Some("sim/camera"));
    assert_eq!(i.fault.order(), Some((PortFault::Blank, 0.0)));
    assert!("blank:0:sim/camera@track".parse::<Injection>().is_err());
}
