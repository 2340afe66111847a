#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test
//! The recorder process stopped both ways: SIGTERM finishes the file (summary and
//! index); SIGKILL leaves a file that reads back to within its flush period of the kill.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use ipc_types::msg::{CameraFrameHeader, Header, PixelEncoding, VehicleState};
use ipc_types::services;
use runtime::{Ipc, IpcPrefix, monotonic_ns};

fn deploy() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy")
}

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("landing-recorder-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn start(prefix: &IpcPrefix, out: &Path) -> Child {
    Command::new(env!("CARGO_BIN_EXE_recorder"))
        .args(["--ipc-prefix", prefix.as_str(), "--deploy-dir"])
        .arg(deploy())
        .arg("--out")
        .arg(out)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap()
}

/// Publishes states at 50 Hz and small camera frames at 25 Hz for `seconds`; returns
/// the monotonic time of each state sent, by sequence number (index 0 = seq 1).
fn publish(prefix: &IpcPrefix, seconds: f64) -> Vec<u64> {
    let ipc = Ipc::open("recorder-test-pub", prefix).unwrap();
    let mut states = ipc
        .publisher::<VehicleState>(services::VEHICLE_STATE)
        .unwrap();
    let (w, h) = (64u32, 48u32);
    let len = (w * h) as usize;
    let mut camera = ipc
        .slice_publisher::<u8, CameraFrameHeader>(services::CAMERA_FRAME, len)
        .unwrap();
    // Let the recorder find the new publishers.
    std::thread::sleep(Duration::from_millis(500));
    let pixels: Vec<u8> = (0..len).map(|i| (i % 253) as u8).collect();
    let mut sent = vec![];
    let start = Instant::now();
    let mut k = 0u64;
    while start.elapsed().as_secs_f64() < seconds {
        k += 1;
        std::thread::sleep(Duration::from_millis(20));
        let s = VehicleState {
            msg: Header {
                seq: k,
                ..Header::captured_at(monotonic_ns())
            },
            ..VehicleState::default()
        };
        states.send(s.msg, &s).unwrap();
        sent.push(monotonic_ns());
        if k.is_multiple_of(2) {
            let mut sample = camera.loan_uninit(len).unwrap();
            *sample.user_header_mut() = CameraFrameHeader {
                msg: Header::captured_at(monotonic_ns()),
                width: w,
                height: h,
                stride: w,
                encoding: PixelEncoding::Mono8 as u32,
                ..CameraFrameHeader::default()
            };
            camera.send(sample.write_from_slice(&pixels)).unwrap();
        }
    }
    sent
}

/// The state sequence numbers in the recording, and the read's summary.
fn states_in(path: &Path) -> (Vec<u64>, recorder::ReadSummary, u64) {
    let mut seqs = vec![];
    let mut images = 0;
    let summary = recorder::read_messages(path, &mut |m| {
        if m.topic == "/vehicle/state" {
            let v: serde_json::Value = serde_json::from_slice(m.data).unwrap();
            seqs.push(v["msg"]["seq"].as_u64().unwrap());
        }
        if m.topic == "/camera/frame" {
            images += 1;
        }
    })
    .unwrap();
    (seqs, summary, images)
}

#[test]
fn a_recorder_stopped_with_sigterm_finishes_the_file_with_every_message() {
    let prefix = IpcPrefix::unique("rec-term");
    let out = temp("term.mcap");
    let mut child = start(&prefix, &out);
    std::thread::sleep(Duration::from_millis(300));
    let sent = publish(&prefix, 1.5);
    std::thread::sleep(Duration::from_millis(200));
    // SAFETY: signalling our own child.
    unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
    let status = child.wait().unwrap();
    assert!(status.success(), "{status}");
    let (seqs, summary, images) = states_in(&out);
    assert!(summary.complete, "finished: {summary:?}");
    assert_eq!(summary.broken, None);
    assert_eq!(seqs, (1..=sent.len() as u64).collect::<Vec<_>>());
    assert!(images >= sent.len() as u64 / 2 - 1, "{images} images");
    let meta = &summary.metadata["landing"];
    assert!(!meta["git_revision"].is_empty());
    assert!(meta["graph"].contains("[[node]]"));
}

#[test]
fn a_recorder_killed_mid_run_leaves_a_file_that_reads_to_its_last_flush() {
    let prefix = IpcPrefix::unique("rec-kill");
    let out = temp("kill.mcap");
    let mut child = start(&prefix, &out);
    std::thread::sleep(Duration::from_millis(300));
    let sent = publish(&prefix, 3.5);
    let killed_at = monotonic_ns();
    // SAFETY: signalling our own child.
    unsafe { libc::kill(child.id() as i32, libc::SIGKILL) };
    let _ = child.wait();
    // As landing-clean.service does before a restart: the dead node's shared memory.
    runtime::ipc::clean(&prefix).unwrap();
    let (seqs, summary, _) = states_in(&out);
    assert!(!summary.complete, "a killed writer writes no summary");
    // What is there is the run from its start, without a gap.
    assert_eq!(seqs, (1..=seqs.len() as u64).collect::<Vec<_>>());
    // Flushed at least every second: all states sent up to 1 s before the kill (and
    // some scheduling slack) are in the file.
    let due = sent
        .iter()
        .filter(|t| **t + 1_300_000_000 <= killed_at)
        .count();
    assert!(
        seqs.len() >= due,
        "{} of {} states read back; {due} were sent more than 1.3 s before the kill ({:?})",
        seqs.len(),
        sent.len(),
        summary.broken
    );
    // `landing mcap info` and the other readers name the damage, if any, by offset.
    if let Some(b) = &summary.broken {
        assert!(b.offset > 0 && b.offset <= b.size, "{b}");
    }
}
