//! Tests of `clock`.

use super::*;

#[test]
fn monotonic_clock_never_goes_backwards() {
    let a = monotonic_ns();
    let b = monotonic_ns();
    assert!(a > 0 && b >= a);
}

#[test]
fn sim_clock_moves_only_forward_and_is_shared_by_clones() {
    let c = SimClock::new(10);
    let d = c.clone();
    c.advance(5);
    assert_eq!(d.now_ns(), 15);
    d.set(3);
    assert_eq!(c.now_ns(), 15);
    d.set(40);
    assert_eq!(c.now_ns(), 40);
}
