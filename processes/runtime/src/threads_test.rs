#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use super::*;

#[test]
fn a_stop_ends_a_sleep_early() {
    let flag = Arc::new(StopFlag::default());
    let other = Arc::clone(&flag);
    let stopper = std::thread::spawn(move || {
        std::thread::sleep(Duration::from_millis(20));
        other.stop();
    });
    let start = Instant::now();
    assert!(
        !flag.sleep(Duration::from_secs(60)),
        "the sleep reports the stop"
    );
    assert!(start.elapsed() < Duration::from_secs(30));
    assert!(flag.is_stopped());
    assert!(
        !flag.sleep(Duration::from_secs(60)),
        "a stopped flag does not sleep"
    );
    stopper.join().unwrap();
}

#[test]
fn a_sleep_without_a_stop_lasts_its_duration() {
    let flag = StopFlag::default();
    let start = Instant::now();
    assert!(flag.sleep(Duration::from_millis(30)));
    assert!(start.elapsed() >= Duration::from_millis(30));
}

#[test]
fn a_worker_that_watches_its_flag_is_joined_with_its_result() {
    let worker = Worker::spawn(ThreadRole::CameraCapture, |stop| {
        let mut rounds = 0u32;
        while stop.sleep(Duration::from_millis(1)) {
            rounds += 1;
        }
        (std::thread::current().name().map(str::to_string), rounds)
    })
    .unwrap();
    std::thread::sleep(Duration::from_millis(20));
    let (name, _) = worker.stop_and_join(JOIN_TIMEOUT).unwrap();
    assert_eq!(name.as_deref(), Some("capture"));
}

#[test]
fn a_worker_blocked_past_the_bound_is_reported_stuck_with_its_exit_code() {
    let release = Arc::new(AtomicBool::new(false));
    let held = Arc::clone(&release);
    // Blocked in "a read" that ignores the stop flag.
    let worker = Worker::spawn(ThreadRole::CameraCapture, move |_| {
        while !held.load(Ordering::SeqCst) {
            std::thread::sleep(Duration::from_millis(1));
        }
    })
    .unwrap();
    let e = worker
        .stop_and_join(Duration::from_millis(50))
        .expect_err("the thread is blocked");
    assert!(matches!(
        e,
        JoinError::Stuck {
            role: ThreadRole::CameraCapture,
            ..
        }
    ));
    assert_eq!(e.exit_code(), 80);
    assert_eq!(
        e.to_string(),
        "the capture thread did not stop within 50 ms; exiting with code 80"
    );
    release.store(true, Ordering::SeqCst);
}

#[test]
fn a_worker_that_panicked_is_reported_with_its_exit_code() {
    let worker = Worker::spawn(ThreadRole::CameraCapture, |_| -> () {
        panic!("test panic in a worker");
    })
    .unwrap();
    let e = worker.stop_and_join(JOIN_TIMEOUT).expect_err("it panicked");
    assert!(matches!(e, JoinError::Panicked { .. }));
    assert_eq!(e.exit_code(), ThreadRole::CameraCapture.exit_code());
}

#[derive(Debug, thiserror::Error)]
#[error("capture: {0}")]
struct Wrapped(#[source] JoinError);

#[test]
fn the_exit_code_is_found_anywhere_in_the_chain_of_causes() {
    let stuck = || JoinError::Stuck {
        role: ThreadRole::CameraCapture,
        within: Duration::from_millis(1),
    };
    assert_eq!(exit_code_of(&stuck()), Some(80));
    assert_eq!(exit_code_of(&Wrapped(stuck())), Some(80));
    let other = std::io::Error::other("not a thread");
    assert_eq!(exit_code_of(&other), None);
}

#[test]
fn exit_codes_are_distinct_and_clear_of_usage_and_sysexits_codes() {
    let mut codes: Vec<u8> = ThreadRole::ALL.iter().map(|r| r.exit_code()).collect();
    assert!(codes.iter().all(|c| (80..=89).contains(c)));
    codes.sort_unstable();
    codes.dedup();
    assert_eq!(codes.len(), ThreadRole::ALL.len());
}
