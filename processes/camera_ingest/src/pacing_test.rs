use std::time::Duration;

use super::*;

const MS: u64 = 1_000_000;

#[test]
fn a_rate_limit_lets_one_line_through_per_interval() {
    let mut r = RateLimit::new(Duration::from_secs(1));
    assert!(r.ready(10 * MS));
    assert!(!r.ready(500 * MS));
    assert!(!r.ready(1_009 * MS));
    assert!(r.ready(1_010 * MS));
    assert!(!r.ready(1_500 * MS));
}
