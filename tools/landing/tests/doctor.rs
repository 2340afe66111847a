#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test
//! `landing doctor` against the simulator as a vehicle's autopilot (the `sim` process,
//! over real MAVLink on UDP): every check passes; then a PX4 parameter set wrong, a
//! camera that is not plugged in and a disk without room each fail, in one line naming
//! what to change, and the exit code says so.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn free_udp_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// The simulator listening on `sim_port`, sending to `link_port`, from `deploy`.
struct Sim(Child);

impl Sim {
    fn start(deploy: &Path, sim_port: u16, link_port: u16, prefix: &str) -> Self {
        let exe = Path::new(env!("CARGO_BIN_EXE_landing")).with_file_name("sim");
        let child = Command::new(exe)
            .args(["--scenario", "indoor-static", "--duration-s", "120"])
            .args(["--mavlink-listen", &format!("127.0.0.1:{sim_port}")])
            .args(["--mavlink-remote", &format!("127.0.0.1:{link_port}")])
            .args(["--ipc-prefix", prefix])
            .arg("--deploy-dir")
            .arg(deploy)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        Self(child)
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A copy of the deploy directory, its stack file pointed at the ports, changed by
/// `edit` (file name relative to the copy, text before, text after).
fn deploy_copy(tag: &str, link_port: u16, sim_port: u16, edits: &[(&str, &str, &str)]) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("doctor_{tag}_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let status = Command::new("cp")
        .arg("-r")
        .arg(workspace().join("deploy"))
        .arg(&dir)
        .status()
        .unwrap();
    assert!(status.success());
    let mut all = vec![
        (
            "config/landing.toml",
            "link = \"udp:127.0.0.1:14540\"".to_string(),
            format!("link = \"udp:127.0.0.1:{link_port}\""),
        ),
        (
            "config/landing.toml",
            "remote = \"127.0.0.1:14580\"".to_string(),
            format!("remote = \"127.0.0.1:{sim_port}\""),
        ),
    ];
    all.extend(
        edits
            .iter()
            .map(|(f, a, b)| (*f, a.to_string(), b.to_string())),
    );
    for (file, before, after) in all {
        let path = dir.join(file);
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.contains(&before), "{file} has no `{before}`");
        std::fs::write(&path, text.replacen(&before, &after, 1)).unwrap();
    }
    dir
}

fn doctor(deploy: &Path, prefix: &str, extra: &[&str]) -> (Option<i32>, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_landing"))
        .args(["--ipc-prefix", prefix, "doctor", "--config"])
        .arg(deploy.join("config/landing.toml"))
        .arg("--recordings")
        .arg(std::env::temp_dir())
        .args(extra)
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
    )
}

fn failures(out: &str) -> Vec<&str> {
    out.lines().filter(|l| l.starts_with("FAIL")).collect()
}

#[test]
fn landing_doctor_passes_against_the_simulator_as_autopilot() {
    let (link, sim_port) = (free_udp_port(), free_udp_port());
    let prefix = format!("dr_ok{}_", std::process::id());
    let deploy = deploy_copy("ok", link, sim_port, &[]);
    let _sim = Sim::start(&deploy, sim_port, link, &prefix);
    let (code, out) = doctor(&deploy, &prefix, &[]);
    println!("{out}");
    assert_eq!(code, Some(0), "{out}");
    for check in [
        "config",
        "camera",
        "depth",
        "link",
        "param COM_OBL_RC_ACT",
        "param EKF2_HGT_REF",
        "clock",
        "ipc",
        "disk",
    ] {
        assert!(
            out.lines()
                .any(|l| l.starts_with("ok") && l[4..].trim_start().starts_with(check)),
            "no passing `{check}` line:\n{out}"
        );
    }
    let _ = std::fs::remove_dir_all(&deploy);
}

#[test]
fn a_wrong_parameter_a_missing_camera_and_a_full_disk_each_fail_in_one_line_naming_the_fix() {
    let (link, sim_port) = (free_udp_port(), free_udp_port());
    let prefix = format!("dr_bad{}_", std::process::id());
    // The vehicle's PX4 left at its default offboard-loss action (0, Position), the
    // camera configured at a device that is not there.
    let deploy = deploy_copy(
        "bad",
        link,
        sim_port,
        &[
            (
                "config/airframes/p450.toml",
                "COM_OBL_RC_ACT = 4",
                "COM_OBL_RC_ACT = 0",
            ),
            (
                "config/landing.toml",
                "source = \"sim\"",
                "source = \"v4l2:/dev/video77\"",
            ),
        ],
    );
    let _sim = Sim::start(&deploy, sim_port, link, &prefix);
    // More free space asked than any disk has: the disk check's failure, as a full disk.
    let (code, out) = doctor(&deploy, &prefix, &["--min-free-gb", "1000000"]);
    println!("{out}");
    assert_eq!(code, Some(1), "{out}");
    let fails = failures(&out);
    assert_eq!(fails.len(), 3, "three failures, one line each:\n{out}");
    assert!(
        fails
            .iter()
            .any(|l| l.contains("COM_OBL_RC_ACT is 0: set it to 4 (Land)")),
        "{out}"
    );
    assert!(
        fails.iter().any(|l| l
            .contains("/dev/video77 not found: plug the camera in, or set [camera_ingest] source")),
        "{out}"
    );
    assert!(
        fails
            .iter()
            .any(|l| l.contains("GB free under") && l.contains("free space, or move --recordings")),
        "{out}"
    );
    // The rest still passes: the link, the other parameters, the clock.
    assert!(
        out.lines()
            .any(|l| l.starts_with("ok") && l.contains("TIMESYNC round trip")),
        "{out}"
    );
    let _ = std::fs::remove_dir_all(&deploy);
}
