//! `landing bench recorder`: can the `recorder` process keep up with the pipeline, and
//! at what CPU? This process publishes what a flight publishes, at the flight's rates,
//! into a fresh iceoryx2 prefix: the simulator's camera rendering a descent onto the
//! pad, 1280x720 mono8 (the down camera's format) at 30 Hz, 640x480
//! depth at 30 Hz, the occupancy map at 30 Hz, states at 50 Hz, observations at 30 Hz,
//! setpoints at 50 Hz, trajectories, statuses and watchdog views. The real `recorder`
//! binary records them; its CPU time comes from /proc (user + system, between the first
//! and the last frame), and drops from reading the recording back: every published
//! sequence number must be in it.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use clap::Args;
use ipc_types::msg::{
    CameraFrameHeader, DepthFrameHeader, FsmStatus, Header, Intrinsics, OccupancyMapHeader,
    PadObservation, PixelEncoding, Setpoint, Trajectory, VehicleState, WatchdogView,
};
use ipc_types::services;
use optics::PadModel;
use runtime::{Ipc, IpcPrefix, monotonic_ns};
use serde::Serialize;

use stack::procs::binary;

/// Arguments of `landing bench recorder`.
#[derive(Debug, Args)]
pub struct RecorderArgs {
    /// Seconds of publishing per case.
    #[arg(long, default_value_t = 20.0)]
    seconds: f64,
    /// Print the results as JSON on stdout.
    #[arg(long)]
    json: bool,
    /// Keep the recordings in this directory (default: deleted).
    #[arg(long, value_name = "DIR")]
    keep: Option<PathBuf>,
}

/// One case's result.
#[derive(Debug, Serialize)]
pub struct CaseResult {
    /// How frames were stored and chunks compressed.
    pub case: String,
    /// Seconds published.
    pub seconds: f64,
    /// Camera frames published.
    pub frames_published: u64,
    /// Camera frames in the recording.
    pub frames_recorded: u64,
    /// Messages published on each topic that are not in the recording.
    pub dropped: BTreeMap<String, u64>,
    /// The recorder's CPU time over the publishing, percent of one core.
    pub cpu_percent_of_one_core: f64,
    /// File size, MB.
    pub file_mb: f64,
}

const W: u32 = 1280;
const H: u32 = 720;
const DEPTH_W: u32 = 640;
const DEPTH_H: u32 = 480;
const MAP_DIMS: [u32; 3] = [60, 60, 20];

/// CPU time of process `pid` so far (user + system), seconds.
fn cpu_s(pid: u32) -> Result<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat"))?;
    // Fields after the command name (which may hold spaces) in parentheses.
    let rest = stat
        .rsplit_once(')')
        .map(|(_, r)| r)
        .context("unreadable /proc stat")?;
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    // utime and stime are fields 14 and 15 of stat: 11 and 12 after the command.
    // SAFETY: sysconf has no preconditions.
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64;
    Ok((ticks(11) + ticks(12)) / hz.max(1.0))
}

fn header(seq: u64) -> Header {
    Header {
        seq,
        ..Header::captured_at(monotonic_ns())
    }
}

/// Publishes a flight's worth of topics for `seconds` into `prefix` while `pid`
/// records them; returns published counts per recorded topic and the recorder's CPU
/// share.
fn publish(
    prefix: &IpcPrefix,
    pid: u32,
    seconds: f64,
    frames: &[Vec<u8>],
) -> Result<(BTreeMap<String, u64>, f64)> {
    let ipc = Ipc::open("bench-recorder-pub", prefix)?;
    let frame_len = (W * H) as usize;
    let mut camera =
        ipc.slice_publisher::<u8, CameraFrameHeader>(services::CAMERA_FRAME, frame_len)?;
    let depth_len = (DEPTH_W * DEPTH_H) as usize;
    let mut depth = ipc.slice_publisher::<u16, DepthFrameHeader>(services::SIM_DEPTH, depth_len)?;
    let map_len = MAP_DIMS.iter().product::<u32>() as usize;
    let mut map =
        ipc.slice_publisher::<u8, OccupancyMapHeader>(services::MAP_OCCUPANCY, map_len)?;
    let mut states = ipc.publisher::<VehicleState>(services::VEHICLE_STATE)?;
    let mut observations = ipc.publisher::<PadObservation>(services::PAD_OBSERVATION)?;
    let mut setpoints = ipc.publisher::<Setpoint>(services::FSM_SETPOINT)?;
    let mut statuses = ipc.publisher::<FsmStatus>(services::FSM_STATUS)?;
    let mut trajectories = ipc.publisher::<Trajectory>(services::PLANNER_TRAJECTORY)?;
    let mut views = ipc.publisher::<WatchdogView>(services::WATCHDOG_VIEW)?;
    // Let the recorder connect to the new publishers.
    std::thread::sleep(Duration::from_millis(500));
    let depth_frame: Vec<u16> = (0..depth_len)
        .map(|i| 1500 + ((i * 7919) % 2000) as u16)
        .collect();
    let mut cells = vec![1u8; map_len];
    for (i, c) in cells.iter_mut().enumerate() {
        if i % 97 == 0 {
            *c = 2;
        }
    }
    let mut n: BTreeMap<String, u64> = BTreeMap::new();
    let mut count = |topic: &str| -> u64 {
        let c = n.entry(topic.to_string()).or_insert(0);
        *c += 1;
        *c
    };
    let start = Instant::now();
    let cpu0 = cpu_s(pid)?;
    // 1 ms steps: 50 Hz topics every 20 steps, 30 Hz every 33 (a 30.3 Hz camera).
    let mut step: u64 = 0;
    while start.elapsed().as_secs_f64() < seconds {
        step += 1;
        let next = start + Duration::from_millis(step);
        if let Some(d) = next.checked_duration_since(Instant::now()) {
            std::thread::sleep(d);
        }
        if step.is_multiple_of(20) {
            let seq = count("/vehicle/state");
            let mut s = VehicleState {
                msg: header(seq),
                ..VehicleState::default()
            };
            s.world_from_body.translation = [0.001 * step as f64, 0.0, 2.0];
            states.send(s.msg, &s)?;
            let seq = count("/fsm/setpoint");
            let sp = Setpoint {
                msg: header(seq),
                valid: Setpoint::POSITION,
                ..Setpoint::default()
            };
            setpoints.send(sp.msg, &sp)?;
        }
        if step.is_multiple_of(33) {
            let seq = count("/camera/frame/header");
            let pixels = &frames[(seq as usize) % frames.len()];
            let mut sample = camera.loan_uninit(frame_len)?;
            *sample.user_header_mut() = CameraFrameHeader {
                msg: header(seq),
                width: W,
                height: H,
                stride: W,
                encoding: PixelEncoding::Mono8 as u32,
                camera_id: 0,
                undistorted: 0,
                exposure_ns: 5_000_000,
            };
            camera.send(sample.write_from_slice(pixels))?;
            let seq = count("/sim/depth/header");
            let mut sample = depth.loan_uninit(depth_len)?;
            *sample.user_header_mut() = DepthFrameHeader {
                msg: header(seq),
                width: DEPTH_W,
                height: DEPTH_H,
                depth_scale_m: 0.001,
                intrinsics: Intrinsics::default(),
                camera_id: 1,
                reserved: 0,
            };
            depth.send(sample.write_from_slice(&depth_frame))?;
            let seq = count("/map/occupancy/header");
            let mut sample = map.loan_uninit(map_len)?;
            *sample.user_header_mut() = OccupancyMapHeader {
                msg: header(seq),
                origin: [-3.0, -3.0, 0.0],
                resolution: 0.1,
                inflation: 0.3,
                dims: MAP_DIMS,
                reserved: 0,
                state_ns: 0,
            };
            map.send(sample.write_from_slice(&cells))?;
            let seq = count("/pad/observation");
            let o = PadObservation {
                msg: header(seq),
                world_valid: 1,
                marker_count: 4,
                ..PadObservation::default()
            };
            observations.send(o.msg, &o)?;
        }
        if step.is_multiple_of(200) {
            let seq = count("/fsm/status");
            let s = FsmStatus {
                msg: header(seq),
                state: 4,
                pad_valid: 1,
                ..FsmStatus::default()
            };
            statuses.send(s.msg, &s)?;
            let seq = count("/watchdog/view");
            let v = WatchdogView {
                msg: header(seq),
                ..WatchdogView::default()
            };
            views.send(v.msg, &v)?;
        }
        if step.is_multiple_of(250) {
            let seq = count("/planner/trajectory");
            let mut t = Trajectory {
                msg: header(seq),
                count: 12,
                knot_interval_s: 0.2,
                ..Trajectory::default()
            };
            for (i, p) in t.control_points.iter_mut().take(12).enumerate() {
                *p = [0.3 * i as f64, 0.1 * i as f64, 2.0];
            }
            trajectories.send(t.msg, &t)?;
        }
    }
    // What the recorder still has queued is its work too.
    std::thread::sleep(Duration::from_millis(300));
    let cpu = cpu_s(pid)? - cpu0;
    let wall = start.elapsed().as_secs_f64();
    Ok((n, 100.0 * cpu / wall))
}

/// Sequence numbers of the stack's headers per JSON topic of the recording.
fn recorded_seqs(path: &Path) -> Result<BTreeMap<String, Vec<u64>>> {
    let mut seqs: BTreeMap<String, Vec<u64>> = BTreeMap::new();
    let summary = recorder::read_messages(path, &mut |m| {
        if m.encoding != "json" {
            return;
        }
        if let Ok(v) = serde_json::from_slice::<serde_json::Value>(m.data)
            && let Some(seq) = v["msg"]["seq"].as_u64()
        {
            seqs.entry(m.topic.to_string()).or_default().push(seq);
        }
    })?;
    if let Some(b) = summary.broken {
        bail!("{}: {b}", path.display());
    }
    Ok(seqs)
}

fn run_case(
    name: &str,
    extra: &[&str],
    args: &RecorderArgs,
    dir: &Path,
    frames: &[Vec<u8>],
) -> Result<CaseResult> {
    let prefix = IpcPrefix::unique("benchrec");
    let out = dir.join(format!("{name}.mcap"));
    let deploy = stack_config::deploy_dir();
    let mut cmd = Command::new(binary("recorder")?);
    // It stops with this process, however this one ends (a recorder left behind had
    // outlived a bench that failed).
    stack::processes::stop_with_parent(&mut cmd);
    let mut child = cmd
        .args(["--ipc-prefix", prefix.as_str(), "--deploy-dir"])
        .arg(&deploy)
        .arg("--out")
        .arg(&out)
        .args(extra)
        .stdout(Stdio::null())
        .stderr(Stdio::inherit())
        .spawn()
        .context("starting recorder")?;
    std::thread::sleep(Duration::from_millis(300));
    let published = publish(&prefix, child.id(), args.seconds, frames);
    // SAFETY: signalling our own child.
    unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
    let status = child.wait()?;
    let (published, cpu) = published?;
    if !status.success() {
        bail!("recorder exited with {status}");
    }
    let seqs = recorded_seqs(&out)?;
    let mut dropped = BTreeMap::new();
    for (topic, n) in &published {
        let got = seqs.get(topic).map_or(&[][..], Vec::as_slice);
        // Every published number once: 1..=n.
        let mut seen = vec![false; *n as usize + 1];
        for s in got {
            if let Some(x) = seen.get_mut(*s as usize) {
                *x = true;
            }
        }
        dropped.insert(
            topic.clone(),
            seen.iter().skip(1).filter(|x| !**x).count() as u64,
        );
    }
    let frames_published = published.get("/camera/frame/header").copied().unwrap_or(0);
    let file_mb = std::fs::metadata(&out).map_or(0.0, |m| m.len() as f64 / 1e6);
    if args.keep.is_none() {
        let _ = std::fs::remove_file(&out);
    }
    Ok(CaseResult {
        case: name.to_string(),
        seconds: args.seconds,
        frames_published,
        frames_recorded: frames_published
            - dropped.get("/camera/frame/header").copied().unwrap_or(0),
        dropped,
        cpu_percent_of_one_core: cpu,
        file_mb,
    })
}

/// Runs the bench: JPEG + zstd, then raw + lz4.
pub fn run(args: &RecorderArgs) -> Result<()> {
    if !(args.seconds > 0.0 && args.seconds <= 600.0) {
        bail!("--seconds {}: allowed 0 < seconds <= 600", args.seconds);
    }
    let deploy = stack_config::deploy_dir();
    let pad = PadModel::load(deploy.join("config").join("pad.toml"))?;
    eprintln!("bench recorder: rendering 30 frames at {W}x{H}...");
    let seq = crate::aruco::render("camera_down_1280x720.yaml", 30, &deploy, &pad)?;
    let frames: Vec<Vec<u8>> = seq.frames.into_iter().map(|f| f.0).collect();
    if frames.iter().any(|f| f.len() != (W * H) as usize) {
        bail!("the simulator's camera no longer renders {W}x{H} mono8: update this bench");
    }
    let tmp;
    let dir = match &args.keep {
        Some(d) => {
            std::fs::create_dir_all(d)?;
            d.as_path()
        }
        None => {
            tmp = std::env::temp_dir().join(format!("landing-bench-rec-{}", std::process::id()));
            std::fs::create_dir_all(&tmp)?;
            tmp.as_path()
        }
    };
    let cases: [(&str, &[&str]); 2] = [
        ("jpeg+zstd", &["--compression", "zstd"]),
        ("raw+lz4", &["--raw-images", "--compression", "lz4"]),
    ];
    let mut results = Vec::new();
    for (name, extra) in cases {
        eprintln!("bench recorder: {name}, {} s...", args.seconds);
        let r = run_case(name, extra, args, dir, &frames)?;
        eprintln!(
            "  {:<10} camera {}/{} frames recorded, drops {:?}, recorder CPU {:.1} % of one core, {:.1} MB",
            r.case,
            r.frames_recorded,
            r.frames_published,
            r.dropped,
            r.cpu_percent_of_one_core,
            r.file_mb
        );
        results.push(r);
    }
    if args.keep.is_none() {
        let _ = std::fs::remove_dir(dir);
    }
    if args.json {
        println!("{}", serde_json::to_string(&results)?);
    }
    Ok(())
}
