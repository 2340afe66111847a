use super::*;

const MS: u64 = 1_000_000;

/// Within the drift allowance of the test's spans (0.1 ms).
fn close(got: u64, want: u64) -> bool {
    got.abs_diff(want) <= MS / 10
}

#[test]
fn a_late_message_keeps_the_time_it_was_sent() {
    let mut c = AutopilotClock::default();
    let start = 5_000 * MS;
    // Every 10 ms, with 1 ms of path delay; the fifth one waits 80 ms for the scheduler.
    for k in 1..=20u64 {
        let boot = k * 10 * MS;
        let late = if k == 5 { 80 * MS } else { 0 };
        let arrival = start + boot + MS + late;
        let t = c.local_time(boot, arrival);
        assert!(close(t, start + boot + MS), "message {k}: {t}");
    }
}

#[test]
fn a_clock_started_late_is_found_from_the_quickest_message() {
    let mut c = AutopilotClock::default();
    // The first message came 50 ms late: its stamp is late until a quicker one comes.
    assert_eq!(c.local_time(10 * MS, 1_060 * MS), 1_060 * MS);
    assert_eq!(c.local_time(20 * MS, 1_020 * MS), 1_020 * MS);
    assert!(close(c.local_time(30 * MS, 1_090 * MS), 1_030 * MS));
}

#[test]
fn the_offset_follows_a_slow_drift_and_a_reboot() {
    let mut c = AutopilotClock::default();
    // The autopilot's clock runs 50 ppm slow: the offset rises 50 us per second.
    let mut last = 0;
    for k in 1..=600u64 {
        let boot = k * 100 * MS;
        let local = 1_000 * MS + boot + (boot as f64 * 50e-6) as u64;
        last = c.local_time(boot, local);
        assert!(
            local - last <= MS / 10,
            "at {k}: {} ns behind",
            local - last
        );
    }
    // Rebooted: its clock starts again from zero.
    let local = 1_000 * MS + 60_100 * MS;
    assert_eq!(c.local_time(10 * MS, local), local);
    assert!(c.local_time(20 * MS, local + 10 * MS) > last);
}

#[test]
fn no_stamp_is_its_arrival_and_none_is_after_it() {
    let mut c = AutopilotClock::default();
    assert_eq!(c.local_time(0, 7 * MS), 7 * MS);
    assert_eq!(c.local_time(u64::MAX, 9 * MS), 9 * MS);
    assert_eq!(c.local_time(5 * MS, 0), 0);
}

#[test]
fn an_autopilot_restarted_after_a_short_run_is_a_new_clock() {
    // Ran 0.4 s, restarted 0.2 s later: the new offset is only 0.6 s above the old one,
    // but its clock went back.
    let mut c = AutopilotClock::default();
    for k in 1..=40u64 {
        let boot = k * 10 * MS;
        assert_eq!(c.local_time(boot, 1_000 * MS + boot), 1_000 * MS + boot);
    }
    let local = 1_000 * MS + 600 * MS + 10 * MS;
    assert_eq!(c.local_time(10 * MS, local), local);
    assert_eq!(c.local_time(20 * MS, local + 10 * MS), local + 10 * MS);
}
