#![allow(clippy::unwrap_used, clippy::expect_used)]
//! px4-link forwards `vio/odometry` to the autopilot as MAVLink ODOMETRY: the test
//! publishes VIO samples on iceoryx2 as the simulator (or a tracking camera's driver)
//! does, plays the autopilot on a real UDP socket, and reads the ODOMETRY frames off the
//! wire: frame, covariance diagonal where PX4 v1.16 reads it, reset counter, estimator.

use std::net::UdpSocket;
use std::process::Command;
use std::time::{Duration, Instant};

use ipc_types::msg::{Header, Pose, VioOdometry};
use ipc_types::services;
use landing_tests::process::Running;
use mavlink::dialects::common::{MavEstimatorType, MavFrame, MavMessage, ODOMETRY_DATA};
use px4_protocol::codec::{Guard, StreamDecoder};
use runtime::{Ipc, IpcPrefix};

fn sample(k: u32) -> VioOdometry {
    VioOdometry {
        msg: Header::captured_at(1_000_000_000 + u64::from(k) * 33_000_000),
        odom_from_body: Pose {
            translation: [1.0 + f64::from(k), 2.0, 3.0],
            rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
        },
        velocity: [0.5, -0.25, 0.1],
        body_rates: [0.0; 3],
        position_variance: [0.01, 0.02, 0.03],
        orientation_variance: [0.001, 0.002, 0.003],
        velocity_variance: [0.004, 0.005, 0.006],
        reset_counter: k / 3,
        quality: 90,
    }
}

fn run_link(forward: bool) -> Vec<ODOMETRY_DATA> {
    let autopilot = UdpSocket::bind("127.0.0.1:0").unwrap();
    autopilot
        .set_read_timeout(Some(Duration::from_millis(50)))
        .unwrap();
    let link_port = UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let dir = std::env::temp_dir().join(format!("px4link-vio-{}-{forward}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let config = dir.join("landing.toml");
    std::fs::write(&config, format!("[px4_link]\nforward_vio = {forward}\n")).unwrap();
    let prefix = IpcPrefix::unique("px4linkvio");
    let _link = Running::start(
        "px4-link",
        Command::new(env!("CARGO_BIN_EXE_px4-link"))
            .arg("--config")
            .arg(&config)
            .args(["--link", &format!("udp:127.0.0.1:{link_port}")])
            .args(["--remote", &autopilot.local_addr().unwrap().to_string()])
            .args(["--ipc-prefix", prefix.as_str()])
            .env("LANDING_LOG", "warn"),
    );
    let ipc = Ipc::open("test-vio", &prefix).unwrap();
    let mut vio = ipc
        .publisher::<VioOdometry>(services::VIO_ODOMETRY)
        .unwrap();
    // px4-link is up once its heartbeat arrives.
    let mut buf = [0u8; 2048];
    let end = Instant::now() + Duration::from_secs(10);
    while autopilot.recv_from(&mut buf).is_err() {
        assert!(Instant::now() < end, "no datagram from px4-link in 10 s");
    }
    let (mut decoder, mut guard, mut got) = (StreamDecoder::new(), Guard::open(), Vec::new());
    let mut decoded = Vec::new();
    let mut sent = 0u32;
    let end = Instant::now() + Duration::from_secs(5);
    while Instant::now() < end && got.len() < 6 {
        if sent < 6 {
            let s = sample(sent);
            vio.send(s.msg, &s).unwrap();
            sent += 1;
        }
        if let Ok((n, _)) = autopilot.recv_from(&mut buf) {
            decoded.clear();
            decoder.push_datagram(&buf[..n], 0, &mut guard, &mut decoded);
            got.extend(decoded.iter().filter_map(|(_, m)| match m {
                MavMessage::ODOMETRY(o) => Some(o.clone()),
                _ => None,
            }));
        }
    }
    std::fs::remove_dir_all(&dir).ok();
    got
}

#[test]
fn vio_samples_go_to_the_autopilot_as_odometry_with_their_covariance_and_reset_counter() {
    let got = run_link(true);
    assert_eq!(got.len(), 6, "every sample forwarded once");
    for (k, o) in got.iter().enumerate() {
        let s = sample(k as u32);
        assert_eq!(o.time_usec, s.msg.capture_ns / 1000);
        assert_eq!(o.frame_id, MavFrame::MAV_FRAME_LOCAL_NED);
        assert_eq!(o.child_frame_id, MavFrame::MAV_FRAME_LOCAL_NED);
        assert_eq!(o.estimator_type, MavEstimatorType::MAV_ESTIMATOR_TYPE_VIO);
        // ENU (x east, y north, z up) to NED.
        assert_eq!(
            (o.x, o.y, o.z),
            (2.0, s.odom_from_body.translation[0] as f32, -3.0)
        );
        assert_eq!((o.vx, o.vy, o.vz), (-0.25, 0.5, -0.1));
        let pc = o.pose_covariance;
        assert_eq!([pc[0], pc[6], pc[11]], [0.02, 0.01, 0.03]);
        assert_eq!([pc[15], pc[18], pc[20]], [0.001, 0.002, 0.003]);
        let vc = o.velocity_covariance;
        assert_eq!([vc[0], vc[6], vc[11]], [0.005, 0.004, 0.006]);
        assert_eq!(u32::from(o.reset_counter), s.reset_counter);
        assert_eq!(o.quality, 90);
    }
}

#[test]
fn without_forward_vio_no_odometry_reaches_the_autopilot() {
    assert!(run_link(false).is_empty());
}
