use super::*;

const MS: u64 = 1_000_000;
const S: u64 = 1_000_000_000;

/// A small deterministic generator for the tests' delays (uniform in [0, 1)).
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Flies `seconds` of telemetry at 80 Hz from an autopilot whose clock runs at `rate`
/// (boot seconds per local second), from `boot0` of its own boot at local time `local0`,
/// each message `2 + 6 * u` ms late and one in 50 another 300 ms (a loaded machine).
/// Returns the largest stamp error (stamp minus the true send time, each sign) after
/// `settle` s.
fn fly(
    c: &mut AutopilotClock,
    rate: f64,
    (boot0, local0): (u64, u64),
    seconds: u64,
    settle: u64,
) -> (i64, i64) {
    let mut rng = Lcg(boot0 ^ local0);
    let (mut early, mut late) = (0i64, 0i64);
    for k in 0..seconds * 80 {
        let sent_local = local0 + k * S / 80;
        let boot = boot0 + ((k * S / 80) as f64 * rate) as u64;
        let mut delay = (2.0 + 6.0 * rng.next()) * 1e6;
        if rng.next() < 0.02 {
            delay += 300e6;
        }
        let arrival = sent_local + delay as u64;
        let t = c.local_time(boot, arrival);
        assert!(t <= arrival, "message {k}: stamped after its arrival");
        if k >= settle * 80 {
            let err = t as i64 - sent_local as i64;
            early = early.min(err);
            late = late.max(err);
        }
    }
    (early, late)
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
        assert!(t.abs_diff(start + boot + MS) <= MS / 10, "message {k}: {t}");
    }
}

#[test]
fn a_clock_started_late_is_found_from_the_quickest_message() {
    let mut c = AutopilotClock::default();
    // The first message came 50 ms late: its stamp is late until a quicker one comes.
    assert_eq!(c.local_time(10 * MS, 1_060 * MS), 1_060 * MS);
    assert_eq!(c.local_time(20 * MS, 1_020 * MS), 1_020 * MS);
    assert_eq!(c.local_time(30 * MS, 1_090 * MS), 1_030 * MS);
}

#[test]
fn a_clock_that_keeps_time_is_mapped_within_the_link_s_fixed_delay() {
    let mut c = AutopilotClock::default();
    let (early, late) = fly(&mut c, 1.0, (42 * S, 3_600 * S), 120, 3);
    // The fixed 2 ms of path delay stays in the offset (one-way), nothing more.
    assert!(
        early >= -(MS as i64) && late <= 3 * MS as i64,
        "{early} .. {late} ns"
    );
    assert!((c.rate().unwrap() - 1.0).abs() < 2e-4);
    assert_eq!(c.jumps(), 0);
}

#[test]
fn a_clock_two_percent_slow_or_fast_is_followed_for_ten_minutes() {
    for rate in [0.98, 1.02, 0.989] {
        let mut c = AutopilotClock::default();
        let (early, late) = fly(&mut c, rate, (0, 3_600 * S), 600, 3);
        assert!(
            early >= -(MS as i64) && late <= 3 * MS as i64,
            "rate {rate}: {early} .. {late} ns from the true send time"
        );
        let got = c.rate().unwrap();
        assert!((got - rate).abs() < 2e-4, "rate {rate}: estimated {got}");
        assert_eq!(c.jumps(), 0, "rate {rate}");
    }
}

#[test]
fn a_rate_that_changes_is_followed_within_the_window() {
    let mut c = AutopilotClock::default();
    fly(&mut c, 1.0, (S, 3_600 * S), 30, 0);
    // The same clock now runs 1 % slow (its simulator fell behind), from where it was.
    let (early, late) = fly(&mut c, 0.99, (31 * S, 3_630 * S), 60, 12);
    assert_eq!(c.jumps(), 0);
    assert!(
        early >= -2 * (MS as i64) && late <= 3 * MS as i64,
        "{early} .. {late}"
    );
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
    assert_eq!(c.jumps(), 1);
}

#[test]
fn a_clock_that_jumps_ahead_is_a_new_clock_at_once() {
    let mut c = AutopilotClock::default();
    fly(&mut c, 1.0, (S, 3_600 * S), 5, 0);
    // 5 s of messages ended at local 3605 s, boot 6 s; now boot reads 60 s.
    let local = 3_605 * S + 3 * MS;
    assert_eq!(c.local_time(60 * S, local), local);
    assert_eq!(c.jumps(), 1);
    assert_eq!(
        c.local_time(60 * S + 10 * MS, local + 12 * MS),
        local + 10 * MS
    );
}

#[test]
fn a_clock_that_stood_still_is_a_new_clock_once_it_stays_late() {
    let mut c = AutopilotClock::default();
    fly(&mut c, 1.0, (S, 3_600 * S), 5, 0);
    // The simulator paused 3 s and goes on from boot 6 s: every message now sits 3 s
    // above the line. A second of that is not a burst from a stalled link.
    let local0 = 3_608 * S;
    for k in 0..100u64 {
        let boot = 6 * S + k * 10 * MS;
        let local = local0 + k * 10 * MS + 2 * MS;
        let t = c.local_time(boot, local);
        assert!(t <= local);
        if k >= 60 {
            assert_eq!(c.jumps(), 1, "message {k}");
            assert!(t.abs_diff(local - 2 * MS) <= 3 * MS, "message {k}: {t}");
        }
    }
}

#[test]
fn a_burst_of_messages_a_stalled_link_held_for_a_second_is_no_jump() {
    let mut c = AutopilotClock::default();
    fly(&mut c, 1.0, (S, 3_600 * S), 20, 0);
    // 1.2 s of messages queued, then delivered at once; then the stream goes on.
    let (local0, boot0) = (3_620 * S, 21 * S);
    let release = local0 + 1_200 * MS;
    for k in 0..120u64 {
        let t = c.local_time(boot0 + k * 10 * MS, release);
        assert!(
            t.abs_diff(local0 + k * 10 * MS) <= 3 * MS,
            "queued {k}: {t}"
        );
    }
    for k in 120..400u64 {
        let t = c.local_time(boot0 + k * 10 * MS, local0 + k * 10 * MS + 2 * MS);
        assert!(t.abs_diff(local0 + k * 10 * MS) <= 3 * MS, "after {k}: {t}");
    }
    assert_eq!(c.jumps(), 0);
}
