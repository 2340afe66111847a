//! `landing bench ipc`: one-way latency of a camera frame between two OS processes.
//!
//! Both transports are measured the same way: the frame is already in the producer's hands
//! (a camera driver writes it into a loaned shared-memory sample; for the socket, into a
//! buffer), the producer stamps CLOCK_MONOTONIC just before handing it over, and the
//! consumer stamps when it can read the whole frame. Both sides sleep in the kernel between
//! frames (iceoryx2: event + wait set; socket: blocking read), as the real processes do.

use std::io::{Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use iceoryx2::sample::Sample;
use ipc_types::msg::{CameraFrameHeader, Header, PixelEncoding, Stage};
use runtime::ipc::Svc;
use runtime::{Ipc, IpcPrefix, PeriodicWait, Wake, monotonic_ns, run_wait_loop};
use serde_json::json;

use evaluation::stats::percentile;

/// Frames skipped at the start of each case (page faults, connection set-up).
const WARMUP: usize = 20;

/// Arguments of `landing bench ipc`.
#[derive(Debug, Args)]
pub struct IpcArgs {
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
    /// Frames measured per transport and frame size.
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u32).range(50..=100_000))]
    frames: u32,
    /// Time between frames, microseconds (the producer sleeps in between).
    #[arg(long, default_value_t = 2000, value_parser = clap::value_parser!(u64).range(100..=1_000_000))]
    period_us: u64,
}

/// Transports compared.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Transport {
    /// iceoryx2 shared memory, zero-copy.
    Iceoryx2,
    /// A Unix domain stream socket, frame copied through the kernel.
    Unix,
}

/// Frame encodings benchmarked.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Encoding {
    /// 8-bit grey.
    Mono8,
    /// 8-bit BGR.
    Bgr8,
}

impl Encoding {
    fn pixel(self) -> PixelEncoding {
        match self {
            Self::Mono8 => PixelEncoding::Mono8,
            Self::Bgr8 => PixelEncoding::Bgr8,
        }
    }
    fn name(self) -> &'static str {
        match self {
            Self::Mono8 => "mono8",
            Self::Bgr8 => "bgr8",
        }
    }
}

/// Arguments of the hidden publishing peer.
#[derive(Debug, Args)]
pub struct PeerArgs {
    #[arg(long, value_enum)]
    transport: Transport,
    #[arg(long)]
    width: u32,
    #[arg(long)]
    height: u32,
    #[arg(long, value_enum)]
    encoding: Encoding,
    #[arg(long)]
    frames: u32,
    #[arg(long)]
    period_us: u64,
    /// iceoryx2 service name.
    #[arg(long, default_value = ipc_types::services::BENCH_FRAME)]
    service: String,
    /// Unix socket path.
    #[arg(long)]
    socket: Option<PathBuf>,
}

#[derive(Debug, Clone, Copy)]
struct Case {
    width: u32,
    height: u32,
    encoding: Encoding,
}

impl Case {
    fn len(self) -> usize {
        self.width as usize * self.height as usize * self.encoding.pixel().bytes_per_pixel()
    }
    fn key(self) -> String {
        format!("{}x{}_{}", self.width, self.height, self.encoding.name())
    }
}

const CASES: [Case; 2] = [
    Case {
        width: 640,
        height: 480,
        encoding: Encoding::Mono8,
    },
    Case {
        width: 1280,
        height: 720,
        encoding: Encoding::Bgr8,
    },
];

/// Runs the benchmark and prints the figures.
pub fn run(args: &IpcArgs, prefix_flag: Option<&str>) -> Result<()> {
    let prefix = match prefix_flag {
        Some(p) => IpcPrefix::new(p)?,
        None => IpcPrefix::unique("benchipc"),
    };
    let mut iox = serde_json::Map::new();
    let mut iox_event = serde_json::Map::new();
    let mut uds = serde_json::Map::new();
    // p50 per case: [periodic iceoryx2, socket, event-woken iceoryx2].
    let mut p50 = [[0.0; 2]; 3];
    for (ci, case) in CASES.iter().enumerate() {
        eprintln!(
            "bench ipc: iceoryx2    {} ({} frames)...",
            case.key(),
            args.frames
        );
        let lat = measure_iceoryx2(*case, args, &prefix, WaitMode::Periodic)?;
        p50[0][ci] = percentile(&lat, 50.0);
        iox.insert(case.key(), summary(&lat));
        eprintln!(
            "bench ipc: iceoryx2 (event wake-up only) {} ({} frames)...",
            case.key(),
            args.frames
        );
        let lat = measure_iceoryx2(*case, args, &prefix, WaitMode::Event)?;
        p50[2][ci] = percentile(&lat, 50.0);
        iox_event.insert(case.key(), summary(&lat));
        eprintln!(
            "bench ipc: unix socket {} ({} frames)...",
            case.key(),
            args.frames
        );
        let lat = measure_unix(*case, args)?;
        p50[1][ci] = percentile(&lat, 50.0);
        uds.insert(case.key(), summary(&lat));
    }
    // Like with like: the socket's consumer sleeps in read() until the frame is there, so
    // the headline compares it with the iceoryx2 consumer woken by its event.
    let over = |a: f64, b: f64| if b > 0.0 { a / b } else { 0.0 };
    let ratio = over(p50[1][1], p50[2][1]);
    let ratio_periodic = over(p50[1][1], p50[0][1]);
    let out = json!({
        "iceoryx2": iox,
        "unix_socket": uds,
        "iceoryx2_event_wakeup": iox_event,
        "ratio_p50_1280x720": round2(ratio),
        "ratio_p50_1280x720_periodic": round2(ratio_periodic),
        "frames_per_case": args.frames,
    });
    if args.json {
        println!("{out}");
    } else {
        println!(
            "one-way frame latency between two processes (us), both consumers woken by the data"
        );
        println!(
            "{:<16} {:>12} {:>12} {:>12} {:>12}",
            "frame", "iox2 p50", "iox2 p99", "socket p50", "socket p99"
        );
        for case in CASES {
            let k = case.key();
            let get = |m: &serde_json::Value, f: &str| m[&k][f].as_f64().unwrap_or(0.0);
            println!(
                "{:<16} {:>12.1} {:>12.1} {:>12.1} {:>12.1}",
                k,
                get(&out["iceoryx2_event_wakeup"], "p50_us"),
                get(&out["iceoryx2_event_wakeup"], "p99_us"),
                get(&out["unix_socket"], "p50_us"),
                get(&out["unix_socket"], "p99_us"),
            );
        }
        println!("socket / iceoryx2 at p50, 1280x720 bgr8: {ratio:.0}x");
        println!(
            "iceoryx2 with the runtime's periodic waiter (sleeps until just before the next \
             frame, then polls; {ratio_periodic:.0}x), p50/p99 us: {}",
            CASES
                .iter()
                .map(|c| {
                    let v = &out["iceoryx2"][c.key()];
                    format!(
                        "{} {:.1}/{:.1}",
                        c.key(),
                        v["p50_us"].as_f64().unwrap_or(0.0),
                        v["p99_us"].as_f64().unwrap_or(0.0)
                    )
                })
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    Ok(())
}

fn round2(x: f64) -> f64 {
    (x * 100.0).round() / 100.0
}

fn summary(lat_us: &[f64]) -> serde_json::Value {
    json!({
        "p50_us": round2(percentile(lat_us, 50.0)),
        "p99_us": round2(percentile(lat_us, 99.0)),
    })
}

fn spawn_peer(case: Case, args: &IpcArgs, transport: Transport, extra: &[&str]) -> Result<Child> {
    let exe = std::env::current_exe().context("cannot find the landing executable")?;
    let mut cmd = Command::new(exe);
    cmd.args(["bench", "ipc-peer", "--transport"])
        .arg(match transport {
            Transport::Iceoryx2 => "iceoryx2",
            Transport::Unix => "unix",
        })
        .args(["--width", &case.width.to_string()])
        .args(["--height", &case.height.to_string()])
        .args(["--encoding", case.encoding.name()])
        .args(["--frames", &(args.frames as usize + WARMUP).to_string()])
        .args(["--period-us", &args.period_us.to_string()])
        .args(extra)
        .stdin(Stdio::null())
        .stdout(Stdio::null());
    cmd.spawn()
        .context("cannot start the benchmark peer process")
}

fn finish_peer(mut child: Child) -> Result<()> {
    let status = child.wait().context("waiting for the benchmark peer")?;
    if !status.success() {
        bail!("the benchmark peer process failed ({status})");
    }
    Ok(())
}

/// How the consumer waits for the next frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum WaitMode {
    /// Sleep on the event until shortly before the frame is due, then poll
    /// ([`PeriodicWait`]): what the pipeline's sensor consumers do.
    Periodic,
    /// Sleep on the event until the frame arrives (wait set): the cost of a wake-up.
    Event,
}

fn measure_iceoryx2(
    case: Case,
    args: &IpcArgs,
    prefix: &IpcPrefix,
    mode: WaitMode,
) -> Result<Vec<f64>> {
    let service = format!(
        "{}/{}/{:?}",
        ipc_types::services::BENCH_FRAME,
        case.key(),
        mode
    );
    let ipc = Ipc::open("bench-ipc-sub", prefix)?;
    let sub = ipc.slice_subscriber::<u8, CameraFrameHeader>(&service)?;
    let child = spawn_peer(
        case,
        args,
        Transport::Iceoryx2,
        &["--ipc-prefix", prefix.as_str(), "--service", &service],
    )?;
    let total = args.frames as usize + WARMUP;
    let mut tally = Tally {
        expected_len: case.len(),
        lat: Vec::with_capacity(total),
        received: 0,
        bad: 0,
    };
    match mode {
        WaitMode::Periodic => {
            let mut waiter =
                PeriodicWait::new(Duration::from_micros(500), Duration::from_millis(2));
            while tally.received < total {
                let got = waiter.wait(sub.listener(), Duration::from_secs(5), || {
                    sub.receive().ok().flatten()
                });
                let Some(s) = got else { break };
                tally.on_frame(&s, monotonic_ns());
            }
            let (spin, sleep) = waiter.hits();
            tracing::info!(spin, sleep, period = ?waiter.period(), "periodic wait");
        }
        WaitMode::Event => {
            let mut last_progress = Instant::now();
            run_wait_loop(
                &[sub.listener()],
                &[],
                Some(Duration::from_millis(500)),
                |wake| {
                    if wake == Wake::Tick {
                        // The peer died or stopped early: give up after 5 s of silence.
                        return last_progress.elapsed() < Duration::from_secs(5);
                    }
                    while let Ok(Some(s)) = sub.receive() {
                        tally.on_frame(&s, monotonic_ns());
                        last_progress = Instant::now();
                    }
                    tally.received < total
                },
            )?;
        }
    }
    finish_peer(child)?;
    if tally.bad > 0 {
        bail!("{} frames arrived with a wrong size", tally.bad);
    }
    if tally.lat.len() < args.frames as usize / 2 {
        bail!(
            "only {} of {} iceoryx2 frames arrived",
            tally.lat.len(),
            args.frames
        );
    }
    Ok(tally.lat)
}

/// What the consumer saw.
struct Tally {
    expected_len: usize,
    lat: Vec<f64>,
    received: usize,
    bad: usize,
}

impl Tally {
    fn on_frame(&mut self, s: &Sample<Svc, [u8], CameraFrameHeader>, t1: u64) {
        let h = s.user_header();
        let data = s.payload();
        // Read the frame in place: one byte per page.
        let mut sum = 0u64;
        for i in (0..data.len()).step_by(4096) {
            sum = sum.wrapping_add(u64::from(data[i]));
        }
        std::hint::black_box(sum);
        if data.len() != self.expected_len || h.expected_len() != Some(data.len()) {
            self.bad += 1;
        }
        if let Some(st) = h.msg.stages().first() {
            if std::env::var("JIT").is_ok() {
                eprintln!("J {} {}", st.exit_ns, t1);
            }
            self.received += 1;
            if self.received > WARMUP {
                self.lat.push(t1.saturating_sub(st.exit_ns) as f64 / 1000.0);
            }
        }
    }
}

fn measure_unix(case: Case, args: &IpcArgs) -> Result<Vec<f64>> {
    let path = std::env::temp_dir().join(format!(
        "landing-bench-{}-{}.sock",
        std::process::id(),
        case.key()
    ));
    let _ = std::fs::remove_file(&path);
    let listener = UnixListener::bind(&path)
        .with_context(|| format!("cannot bind Unix socket {}", path.display()))?;
    let path_arg = path.to_string_lossy().to_string();
    let child = spawn_peer(case, args, Transport::Unix, &["--socket", &path_arg])?;
    let (mut stream, _) = listener.accept().context("accepting the peer")?;
    let _ = std::fs::remove_file(&path);
    let total = args.frames as usize + WARMUP;
    let mut buf = vec![0u8; 8 + case.len()];
    let mut lat = Vec::with_capacity(total);
    for i in 0..total {
        stream
            .read_exact(&mut buf)
            .context("reading a frame from the socket")?;
        let t1 = monotonic_ns();
        let mut t0 = [0u8; 8];
        t0.copy_from_slice(&buf[..8]);
        let t0 = u64::from_le_bytes(t0);
        if i >= WARMUP {
            lat.push(t1.saturating_sub(t0) as f64 / 1000.0);
        }
        stream.write_all(&[1]).context("acknowledging a frame")?;
    }
    finish_peer(child)?;
    Ok(lat)
}

/// The publishing side, in its own process.
pub fn run_peer(args: &PeerArgs, prefix_flag: Option<&str>) -> Result<()> {
    let case = Case {
        width: args.width,
        height: args.height,
        encoding: args.encoding,
    };
    let len = case.len();
    // What the "camera" produced: a fixed test pattern.
    let frame: Vec<u8> = (0..len).map(|i| (i % 251) as u8).collect();
    let period = Duration::from_micros(args.period_us);
    match args.transport {
        Transport::Iceoryx2 => {
            let prefix = IpcPrefix::from_flag_or_env(prefix_flag)?;
            let ipc = Ipc::open("bench-ipc-pub", &prefix)?;
            let mut publ = ipc.slice_publisher::<u8, CameraFrameHeader>(&args.service, len)?;
            for _ in 0..args.frames {
                std::thread::sleep(period);
                let mut sample = publ.loan_uninit(len)?;
                *sample.user_header_mut() = CameraFrameHeader {
                    msg: Header::captured_at(monotonic_ns()),
                    width: case.width,
                    height: case.height,
                    stride: case.width * case.encoding.pixel().bytes_per_pixel() as u32,
                    encoding: case.encoding.pixel() as u32,
                    camera_id: 0,
                    undistorted: 0,
                    exposure_ns: 0,
                };
                // The driver's write into the loaned shared memory (not timed).
                let mut sample = sample.write_from_slice(&frame);
                let t0 = monotonic_ns();
                sample
                    .user_header_mut()
                    .msg
                    .push_stage(Stage::Bench, t0, t0);
                publ.send(sample)?;
            }
        }
        Transport::Unix => {
            let Some(path) = &args.socket else {
                bail!("--socket is required for the unix transport");
            };
            let mut stream = UnixStream::connect(path)
                .with_context(|| format!("cannot connect to {}", path.display()))?;
            let mut ack = [0u8; 1];
            for _ in 0..args.frames {
                std::thread::sleep(period);
                let t0 = monotonic_ns();
                stream.write_all(&t0.to_le_bytes())?;
                stream.write_all(&frame)?;
                stream.read_exact(&mut ack)?;
            }
        }
    }
    Ok(())
}
