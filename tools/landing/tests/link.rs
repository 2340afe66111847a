//! `landing link setup-signing` against the simulated autopilot as a process: the key
//! goes in, the autopilot's heartbeats come back signed with it, and an autopilot that
//! already signs with another key is reported, not silently re-keyed.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test

mod common;
use std::net::UdpSocket;
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

fn free_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

fn sim_binary() -> PathBuf {
    Path::new(env!("CARGO_BIN_EXE_landing")).with_file_name("sim")
}

struct Sim(Child);

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A config in `dir` whose px4-link listens on `link` and finds the autopilot at `sim`,
/// with the key file `key` (empty: none).
fn config(dir: &Path, name: &str, link: u16, sim: u16, key: &str) -> PathBuf {
    let shipped = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy/config/landing.toml"),
    )
    .unwrap();
    let text = shipped
        .replace(
            "link = \"udp:127.0.0.1:14540\"",
            &format!("link = \"udp:127.0.0.1:{link}\""),
        )
        .replace(
            "remote = \"127.0.0.1:14580\"",
            &format!("remote = \"127.0.0.1:{sim}\"\nsigning_key = \"{key}\""),
        );
    assert_ne!(text, shipped);
    common::write_config(dir, name, &text)
}

#[test]
fn setup_signing_installs_the_key_and_the_autopilot_then_signs_with_it() {
    let dir = std::env::temp_dir().join(format!("landing-link-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (sim_port, link_port) = (free_port(), free_port());
    let _sim = Sim(Command::new(sim_binary())
        .args(["--scenario", "indoor-static", "--duration-s", "60"])
        .args(["--mavlink-listen", &format!("127.0.0.1:{sim_port}")])
        .args(["--mavlink-remote", &format!("127.0.0.1:{link_port}")])
        .args(["--ipc-prefix", &format!("linktest{}_", std::process::id())])
        .env("LANDING_LOG", "warn")
        .stderr(Stdio::null())
        .spawn()
        .unwrap());
    std::thread::sleep(std::time::Duration::from_millis(500));

    // No key named: one line saying what to set.
    let none = config(&dir, "none.toml", link_port, sim_port, "");
    let o = common::landing(&["link", "setup-signing", "--config", none.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("signing_key is empty"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");

    // --generate makes the key (owner-only) and installs it.
    let cfg = config(&dir, "signed.toml", link_port, sim_port, "mavlink.key");
    let o = common::landing(&[
        "link",
        "setup-signing",
        "--config",
        cfg.to_str().unwrap(),
        "--generate",
    ]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.contains("signs with the key"), "{out}");
    let mode = std::fs::metadata(dir.join("mavlink.key"))
        .unwrap()
        .permissions()
        .mode();
    assert_eq!(mode & 0o777, 0o600);

    // Another key: the autopilot (signing now) refuses it, and the tool says so.
    let other = config(&dir, "other.toml", link_port, sim_port, "other.key");
    let o = common::landing(&[
        "link",
        "setup-signing",
        "--config",
        other.to_str().unwrap(),
        "--generate",
        "--timeout-s",
        "2",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("did not take the key"), "{err}");

    // A key file others may read is refused before anything is sent.
    std::fs::set_permissions(
        dir.join("mavlink.key"),
        std::fs::Permissions::from_mode(0o644),
    )
    .unwrap();
    let o = common::landing(&["link", "setup-signing", "--config", cfg.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("chmod 600"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

#[test]
fn a_signed_link_flies_the_mission_and_a_key_others_may_read_stops_the_run_in_one_line() {
    let dir = std::env::temp_dir().join(format!("landing-link-run-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let key = dir.join("mavlink.key");
    std::fs::write(&key, format!("{}\n", "5a".repeat(32))).unwrap();
    std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o600)).unwrap();
    let cfg = config(&dir, "signed.toml", 14540, 14580, "mavlink.key");
    let o = common::landing(&[
        "run",
        "--scenario",
        "indoor-static",
        "--config",
        cfg.to_str().unwrap(),
    ]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{out}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(out.contains("LANDED on the pad"), "{out}");

    std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o640)).unwrap();
    let o = common::landing(&[
        "run",
        "--scenario",
        "indoor-static",
        "--config",
        cfg.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("px4_link.signing_key") && err.contains("chmod 600"),
        "{err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}
