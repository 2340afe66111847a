#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::os::unix::fs::PermissionsExt;

use super::*;

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("landing-signing-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

#[test]
fn a_saved_key_is_owner_only_and_loads_back() {
    let path = temp("key");
    let key = SigningKey::from_bytes(core::array::from_fn(|i| i as u8 + 1));
    key.save(&path).unwrap();
    let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
    assert_eq!(mode, 0o600);
    assert_eq!(SigningKey::load(&path).unwrap(), key);
    // Debug never shows the bytes.
    assert_eq!(format!("{key:?}"), "SigningKey(..)");
}

#[test]
fn a_key_others_may_read_is_refused_in_one_line_naming_the_fix() {
    let path = temp("open-key");
    SigningKey::from_bytes([3; 32]).save(&path).unwrap();
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).unwrap();
    let e = SigningKey::load(&path).unwrap_err().to_string();
    assert!(e.contains("mode 644") && e.contains("chmod 600"), "{e}");
    assert!(!e.contains('\n'));
}

#[test]
fn keys_of_the_wrong_size_or_all_zeros_are_refused() {
    let path = temp("bad-key");
    for (bytes, says) in [
        (b"abcd\n".to_vec(), "5 bytes"),
        ("zz".repeat(32).into_bytes(), "not a hex byte"),
        ("00".repeat(32).into_bytes(), "all zeros"),
    ] {
        std::fs::write(&path, &bytes).unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).unwrap();
        let e = SigningKey::load(&path).unwrap_err().to_string();
        assert!(e.contains(says) || e.contains("characters"), "{e}");
    }
}

#[test]
fn timestamps_count_ten_microseconds_from_2015() {
    assert_eq!(timestamp_of_unix_ns(1_420_070_400_000_000_000), 0);
    assert_eq!(timestamp_of_unix_ns(1_420_070_401_000_000_000), 100_000);
    assert_eq!(timestamp_of_unix_ns(0), 0);
}

#[test]
fn signing_twice_in_one_tick_still_gives_newer_timestamps() {
    let mut s = Signer::new(
        SigningKey::from_bytes([5; 32]),
        0,
        1_795_000_000_000_000_000,
    );
    let a = s.timestamp(0);
    let mut f1 = vec![0xfd, 0, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0];
    let mut f2 = f1.clone();
    assert!(s.sign(&mut f1, 50, 0));
    assert!(s.sign(&mut f2, 50, 0));
    let ts = |f: &[u8]| {
        let mut b = [0u8; 8];
        b[..6].copy_from_slice(&f[13..19]);
        u64::from_le_bytes(b)
    };
    assert!(ts(&f1) >= a && ts(&f2) > ts(&f1));
    // Not a MAVLink 2 frame: untouched.
    let mut v1 = vec![0xfe, 0, 0, 1, 1, 0, 0, 0];
    assert!(!s.sign(&mut v1, 50, 0));
    assert_eq!(v1.len(), 8);
}
