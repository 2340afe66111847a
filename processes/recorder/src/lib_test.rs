use super::*;
use std::time::{Duration, UNIX_EPOCH};

#[test]
fn a_dated_recording_is_named_by_its_utc_start_and_never_reuses_a_name() {
    let dir = std::env::temp_dir().join(format!("landing-dated-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    // 2026-11-26 20:15:00 UTC; 2000-02-29 (a leap day) 23:59:59.
    let at = UNIX_EPOCH + Duration::from_secs(1_795_724_100);
    let first = dated_path(&dir, at).unwrap();
    assert_eq!(first, dir.join("20261126T201500Z.mcap"));
    std::fs::write(&first, b"").unwrap();
    assert_eq!(
        dated_path(&dir, at).unwrap(),
        dir.join("20261126T201500Z-1.mcap")
    );
    let leap = UNIX_EPOCH + Duration::from_secs(951_868_799);
    assert_eq!(
        dated_path(&dir, leap).unwrap(),
        dir.join("20000229T235959Z.mcap")
    );
    let _ = std::fs::remove_dir_all(&dir);
}
