//! `landing bench perception`: sim -> camera-ingest -> aruco-pnp as three OS processes
//! over iceoryx2; observation rate and frame-to-observation latency.
//!
//! The simulator is flown over MAVLink (arm, take off to 2 m next to the indoor pad) so
//! the camera sees the pad; once observations flow they are received here for
//! `--seconds` and timed from the stamps the processes leave in each header: the frame's
//! publication by camera-ingest to the observation's arrival at a consumer (this one).

use std::net::{SocketAddr, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use clap::Args;
use ipc_types::msg::{PadObservation, Stage};
use ipc_types::runtime::ipc::{Wake, run_wait_loop};
use ipc_types::runtime::{Ipc, IpcPrefix, monotonic_ns};
use ipc_types::services;
use mavlink::MavHeader;
use mavlink::dialects::common::{
    COMMAND_LONG_DATA, HEARTBEAT_DATA, MavAutopilot, MavCmd, MavMessage, MavModeFlag, MavState,
    MavType,
};
use serde_json::json;

use crate::stats::percentile;

/// Arguments of `landing bench perception`.
#[derive(Debug, Args)]
pub struct PerceptionArgs {
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
    /// Seconds of observations measured once they flow.
    #[arg(long, default_value_t = 10.0)]
    seconds: f64,
    /// Simulator scenario (the vehicle hovers at its take-off point; the pad must be in
    /// view from 2 m there).
    #[arg(long, default_value = "indoor-static")]
    scenario: String,
}

/// Child processes, killed when dropped (also on error paths).
struct Children(Vec<Child>);

impl Drop for Children {
    fn drop(&mut self) {
        for c in &mut self.0 {
            // SIGTERM first: the processes shut down cleanly and release shared memory.
            // SAFETY: signalling our own child.
            unsafe { libc::kill(c.id() as i32, libc::SIGTERM) };
        }
        let end = Instant::now() + Duration::from_secs(3);
        for c in &mut self.0 {
            while Instant::now() < end {
                if let Ok(Some(_)) = c.try_wait() {
                    break;
                }
                std::thread::sleep(Duration::from_millis(20));
            }
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

fn binary(name: &str) -> Result<PathBuf> {
    let dir = std::env::current_exe()?
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_default();
    let p = dir.join(name);
    if !p.is_file() {
        anyhow::bail!(
            "{} not found next to landing (build the workspace: cargo build --release)",
            p.display()
        );
    }
    Ok(p)
}

fn mavlink_command(sock: &UdpSocket, to: SocketAddr, seq: &mut u8, msg: &MavMessage) -> Result<()> {
    let header = MavHeader {
        system_id: 1,
        component_id: 191,
        sequence: *seq,
    };
    *seq = seq.wrapping_add(1);
    let mut buf = Vec::new();
    mavlink::write_v2_msg(&mut buf, header, msg)?;
    sock.send_to(&buf, to)?;
    Ok(())
}

fn command(cmd: MavCmd, param1: f32, param7: f32) -> MavMessage {
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        param1,
        param2: 0.0,
        param3: 0.0,
        param4: f32::NAN,
        param5: f32::NAN,
        param6: f32::NAN,
        param7,
        command: cmd,
        target_system: 1,
        target_component: 1,
        confirmation: 0,
    })
}

/// Runs the benchmark and prints the figures.
pub fn run(args: &PerceptionArgs, prefix: Option<&str>) -> Result<()> {
    if !(args.seconds.is_finite() && (1.0..=600.0).contains(&args.seconds)) {
        anyhow::bail!(
            "--seconds {} is not allowed (allowed: 1 to 600)",
            args.seconds
        );
    }
    let prefix = match prefix {
        Some(p) => IpcPrefix::new(p)?,
        None => IpcPrefix::unique("perception"),
    };
    let (sim, ingest, aruco) = (
        binary("sim")?,
        binary("camera-ingest")?,
        binary("aruco-pnp")?,
    );
    let companion = UdpSocket::bind("127.0.0.1:0")?;
    let sim_port = UdpSocket::bind("127.0.0.1:0")?.local_addr()?.port();
    let sim_addr: SocketAddr = format!("127.0.0.1:{sim_port}").parse()?;
    let ipc = Ipc::open("bench-perception", &prefix)?;
    let observations = ipc.subscriber::<PadObservation>(services::PAD_OBSERVATION)?;
    let spawn = |path: &Path, extra: &[&str]| -> Result<Child> {
        Command::new(path)
            .args(extra)
            .args(["--ipc-prefix", prefix.as_str()])
            .env("LANDING_LOG", "warn")
            .stdout(Stdio::null())
            .spawn()
            .with_context(|| format!("starting {}", path.display()))
    };
    eprintln!(
        "bench perception: starting sim ({}), camera-ingest, aruco-pnp...",
        args.scenario
    );
    let mut children = Children(Vec::new());
    children.0.push(spawn(
        &sim,
        &[
            "--scenario",
            &args.scenario,
            "--duration-s",
            "600",
            "--mavlink-listen",
            &sim_addr.to_string(),
            "--mavlink-remote",
            &companion.local_addr()?.to_string(),
        ],
    )?);
    children.0.push(spawn(&ingest, &["--source", "sim"])?);
    children.0.push(spawn(&aruco, &[])?);
    std::thread::sleep(Duration::from_millis(700));
    eprintln!("bench perception: arming and taking off to 2 m over MAVLink...");
    let mut seq = 0u8;
    let heartbeat = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_ONBOARD_CONTROLLER,
        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
        base_mode: MavModeFlag::empty(),
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    });
    mavlink_command(&companion, sim_addr, &mut seq, &heartbeat)?;
    mavlink_command(
        &companion,
        sim_addr,
        &mut seq,
        &command(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, 1.0, 0.0),
    )?;
    std::thread::sleep(Duration::from_millis(200));
    mavlink_command(
        &companion,
        sim_addr,
        &mut seq,
        &command(MavCmd::MAV_CMD_NAV_TAKEOFF, 0.0, 2.0),
    )?;

    // Wait for the pad to come into view, then measure.
    let measure_ns = (args.seconds * 1e9) as u64;
    let give_up = Instant::now() + Duration::from_secs(30);
    let mut first: Option<(u64, u64)> = None; // (local time, seq)
    let (mut latency_ms, mut aruco_ms, mut capture_ms) = (Vec::new(), Vec::new(), Vec::new());
    let mut count = 0u64;
    let mut last_seq = 0u64;
    let mut timed_out = false;
    run_wait_loop(
        &[observations.listener()],
        &[],
        Some(Duration::from_millis(100)),
        |wake| {
            let now = monotonic_ns();
            if let Wake::Data(_) = wake {
                while let Ok(Some(s)) = observations.receive() {
                    let obs = *s.payload();
                    let got = monotonic_ns();
                    let first_ns = first.get_or_insert((got, obs.msg.seq)).0;
                    if got - first_ns > measure_ns {
                        break;
                    }
                    count += 1;
                    last_seq = obs.msg.seq;
                    let stage = |st: Stage| {
                        obs.msg
                            .stages()
                            .iter()
                            .rev()
                            .find(|x| x.stage == st as u32)
                            .copied()
                    };
                    let published = stage(Stage::CameraIngest).or_else(|| stage(Stage::Sensor));
                    if let Some(p) = published {
                        latency_ms.push(got.saturating_sub(p.exit_ns) as f64 / 1e6);
                    }
                    if let Some(a) = stage(Stage::ArucoPnp) {
                        aruco_ms.push(a.exit_ns.saturating_sub(a.enter_ns) as f64 / 1e6);
                    }
                    capture_ms.push(got.saturating_sub(obs.msg.capture_ns) as f64 / 1e6);
                }
            }
            match first {
                Some((t0, _)) => now.saturating_sub(t0) <= measure_ns,
                None => {
                    timed_out = Instant::now() > give_up;
                    !timed_out
                }
            }
        },
    )?;
    drop(children);
    if timed_out || count == 0 {
        anyhow::bail!(
            "no pad observation within 30 s (is the pad in view in scenario {}?)",
            args.scenario
        );
    }
    let seconds = args.seconds;
    let rate = count as f64 / seconds;
    let skipped = last_seq.saturating_sub(first.map_or(0, |f| f.1) + count - 1);
    let out = json!({
        "observations": count,
        "rate_hz": (rate * 100.0).round() / 100.0,
        "seq_gaps": skipped,
        "latency_ms_p50": percentile(&latency_ms, 50.0),
        "latency_ms_p99": percentile(&latency_ms, 99.0),
        "aruco_ms_p50": percentile(&aruco_ms, 50.0),
        "aruco_ms_p99": percentile(&aruco_ms, 99.0),
        "capture_to_observation_ms_p50": percentile(&capture_ms, 50.0),
    });
    if args.json {
        println!("{out}");
    } else {
        println!(
            "{count} observations in {seconds:.0} s ({rate:.1} Hz); frame published -> observation received: p50 {:.3} ms, p99 {:.3} ms; aruco-pnp per frame p50 {:.3} ms, p99 {:.3} ms; capture -> observation p50 {:.1} ms (includes the simulated camera's exposure-to-publish latency)",
            percentile(&latency_ms, 50.0),
            percentile(&latency_ms, 99.0),
            percentile(&aruco_ms, 50.0),
            percentile(&aruco_ms, 99.0),
            percentile(&capture_ms, 50.0),
        );
    }
    Ok(())
}
