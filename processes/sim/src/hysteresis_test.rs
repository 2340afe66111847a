//! Tests of `hysteresis`.

use super::*;

const MS: u64 = 1_000_000;

#[test]
fn a_state_changes_only_after_the_input_held_for_its_hysteresis_time() {
    let mut h = Hysteresis::new(false);
    h.set_time_from(false, 300 * MS);
    h.set_state_and_update(true, 0);
    h.set_state_and_update(true, 299 * MS);
    assert!(!h.state());
    h.set_state_and_update(true, 300 * MS);
    assert!(h.state());
}

#[test]
fn an_input_back_at_the_state_cancels_the_change() {
    let mut h = Hysteresis::new(false);
    h.set_time_from(false, 300 * MS);
    h.set_state_and_update(true, 0);
    h.set_state_and_update(false, 200 * MS);
    h.set_state_and_update(true, 250 * MS);
    h.set_state_and_update(true, 500 * MS);
    assert!(!h.state(), "the wait restarted at 250 ms");
    h.set_state_and_update(true, 550 * MS);
    assert!(h.state());
}

#[test]
fn without_a_time_the_state_follows_at_once() {
    let mut h = Hysteresis::new(true);
    h.set_time_from(false, 300 * MS);
    h.set_state_and_update(false, 10 * MS);
    assert!(!h.state(), "leaving true has no hysteresis");
    h.force(true);
    assert!(h.state());
}
