use std::time::Duration;

use super::*;

const MS: u64 = 1_000_000;

#[test]
fn a_pacer_spaces_frames_by_the_period() {
    let mut p = Pacer::from_rate_hz(10.0).unwrap();
    assert_eq!(p.period_ns(), 100 * MS);
    let mut now = 5 * MS;
    let mut emitted = Vec::new();
    for _ in 0..5 {
        now += p.delay_ns(now);
        emitted.push(now);
        p.emitted(now);
        now += 3 * MS; // decoding and publishing take a little time
    }
    let gaps: Vec<u64> = emitted.windows(2).map(|w| w[1] - w[0]).collect();
    assert_eq!(gaps, vec![100 * MS; 4]);
}

#[test]
fn a_pacer_that_fell_behind_resumes_without_a_burst() {
    let mut p = Pacer::from_rate_hz(10.0).unwrap();
    p.emitted(0);
    // Descheduled for a second: the next frame goes at once, the one after a period later.
    let now = 1_000 * MS;
    assert_eq!(p.delay_ns(now), 0);
    p.emitted(now);
    assert_eq!(p.delay_ns(now), 100 * MS);
}

#[test]
fn a_pacer_keeps_its_schedule_through_a_slightly_late_frame() {
    let mut p = Pacer::from_rate_hz(10.0).unwrap();
    p.emitted(0);
    p.emitted(130 * MS); // 30 ms late
    assert_eq!(p.delay_ns(130 * MS), 70 * MS, "the next is due at 200 ms");
}

#[test]
fn a_pacer_needs_a_positive_finite_rate() {
    assert!(Pacer::from_rate_hz(0.0).is_none());
    assert!(Pacer::from_rate_hz(-5.0).is_none());
    assert!(Pacer::from_rate_hz(f64::NAN).is_none());
    assert!(Pacer::from_rate_hz(f64::INFINITY).is_none());
}

#[test]
fn backoff_doubles_up_to_its_cap_and_starts_over_after_a_success() {
    let mut b = Backoff::new(Duration::from_millis(100), Duration::from_millis(500));
    let delays: Vec<u128> = (0..5).map(|_| b.next_delay().as_millis()).collect();
    assert_eq!(delays, vec![100, 200, 400, 500, 500]);
    b.reset();
    assert_eq!(b.next_delay(), Duration::from_millis(100));
}

#[test]
fn a_rate_limit_lets_one_line_through_per_interval() {
    let mut r = RateLimit::new(Duration::from_secs(1));
    assert!(r.ready(10 * MS));
    assert!(!r.ready(500 * MS));
    assert!(!r.ready(1_009 * MS));
    assert!(r.ready(1_010 * MS));
    assert!(!r.ready(1_500 * MS));
}
