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

/// Counts up from 1, a frame per step, for `frames` steps; then ends.
struct Counter {
    next: u32,
    frames: u32,
}

impl Device for Counter {
    type Frame = u32;

    fn step(&mut self, spare: &mut Option<u32>, losses: &mut Losses) -> Step<u32> {
        if self.next > self.frames {
            return Step::End(Ok(()));
        }
        // Every third frame is unreadable.
        self.next += 1;
        if self.next.is_multiple_of(3) {
            losses.unreadable += 1;
            return Step::Missed;
        }
        let _ = spare.take();
        Step::Frame(self.next - 1, monotonic_ns())
    }
}

#[test]
fn the_capture_thread_hands_over_the_newest_frame_and_counts_the_ones_it_replaced() {
    let device = Counter { next: 1, frames: 9 };
    let capture = CaptureThread::start(device, None, ThreadRole::CameraCapture).unwrap();
    // Unpaced, the nine steps are done before the first look.
    let start = std::time::Instant::now();
    while !capture.is_finished() {
        assert!(start.elapsed().as_secs() < 20, "the thread never ended");
        std::thread::sleep(Duration::from_millis(5));
    }
    let taken = capture.take(Duration::from_millis(100));
    let (frame, _) = taken.frame.unwrap();
    assert_eq!(frame, 9, "the newest");
    // Frames 1, 3, 4, 6, 7, 9 were read (2, 5, 8 unreadable): five replaced.
    let counted = capture.counters();
    assert_eq!(counted[0], ("overwritten", 5));
    assert_eq!(counted[1], ("dropped_unreadable", 3));
    assert_eq!(taken.end, Some(Ok(())));
    let again = capture.take(Duration::from_millis(1));
    assert!(again.frame.is_none() && again.end.is_none(), "each once");
    capture.stop(Duration::from_secs(5)).unwrap();
}
