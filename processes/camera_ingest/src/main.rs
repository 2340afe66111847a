//! `camera-ingest`: the pipeline's camera, as its own process.
//!
//! Reads the simulator's frames (`landing/sim/camera`) or a real camera, a GStreamer
//! pipeline, a video file or an image directory through OpenCV, and publishes
//! `landing/camera/frame` zero-copy: each frame is written (copied or undistorted) straight
//! into a loaned shared-memory sample. Everything per frame is library code
//! (`camera_ingest::Ingest`); this file owns the clock, the sleeping, the capture thread
//! and iceoryx2.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::Duration;

use anyhow::{Context, Result, bail};
use camera_ingest::config::IngestFileConfig;
use camera_ingest::{
    Backoff, Counters, Dropped, FrameSource, ImageDir, Ingest, IngestError, Pacer, RateLimit,
    Rejection, SourceSpec, VideoSource, header_for_mat, mat_bytes,
};
use clap::Parser;
use ipc_types::msg::{CameraFrameHeader, Stage};
use ipc_types::services;
use opencv::core::Mat;
use optics::CameraCalibration;
use runtime::{
    Heartbeat, Ipc, IpcPrefix, JOIN_TIMEOUT, LoanError, PeriodicWait, SendError, SlicePublisher,
    StopFlag, ThreadRole, Worker, monotonic_ns,
};
use stack_config::{self as config, deploy_dir};

/// The iceoryx2 node and heartbeat name.
const PROCESS: &str = "camera-ingest";

/// Publishes the landing pipeline's camera frames (landing/camera/frame) from the simulator
/// or a real camera, optionally undistorted. A consumer that lags loses old frames; nothing
/// queues latency.
#[derive(Debug, Parser)]
#[command(name = "camera-ingest", version, about)]
struct Args {
    /// Where frames come from: `sim`, `v4l2:/dev/videoN`, `gst:<pipeline ending in
    /// appsink>`, or `file:<video file or image directory>` [default: [camera_ingest]
    /// source, else sim].
    #[arg(long)]
    source: Option<String>,
    /// Camera calibration, OpenCV YAML [default: [camera_ingest] camera, else
    /// deploy/config/camera_down_640x480.yaml].
    #[arg(long)]
    camera: Option<PathBuf>,
    /// Publish undistorted frames (pinhole with the calibration's camera matrix).
    #[arg(long)]
    undistort: bool,
    /// file: playback rate (default: the video's recorded rate; required for an image
    /// directory); v4l2: the frame rate asked of the camera.
    #[arg(long)]
    rate_hz: Option<f64>,
    /// file: start again from the beginning at the end instead of exiting.
    #[arg(long = "loop")]
    looping: bool,
    /// iceoryx2 prefix (default: $LANDING_IPC_PREFIX, else [ipc] prefix, else `landing_`).
    #[arg(long)]
    ipc_prefix: Option<String>,
    /// Stack configuration file (deploy/config/landing.toml): [ipc] and [camera_ingest].
    #[arg(long)]
    config: Option<PathBuf>,
    /// The deploy directory (default: $LANDING_DEPLOY_DIR, else found above the current
    /// directory or the executable).
    #[arg(long)]
    deploy_dir: Option<PathBuf>,
}

fn main() -> ExitCode {
    runtime::process_main("info", run)
}

/// Flags, the stack file and defaults, resolved.
#[derive(Debug)]
struct Settings {
    source: SourceSpec,
    camera: PathBuf,
    undistort: bool,
    rate_hz: Option<f64>,
    looping: bool,
    prefix: IpcPrefix,
    heartbeat_period: Duration,
    heartbeat_deadline: Duration,
}

fn settings(args: &Args) -> Result<Settings> {
    let (file, config_dir) = match &args.config {
        Some(path) => (
            config::load::<IngestFileConfig>(path)?,
            path.parent().map(Path::to_path_buf).unwrap_or_default(),
        ),
        None => (
            IngestFileConfig::default(),
            args.deploy_dir
                .clone()
                .unwrap_or_else(deploy_dir)
                .join("config"),
        ),
    };
    let section = &file.camera_ingest;
    let source: SourceSpec = args.source.as_deref().unwrap_or(&section.source).parse()?;
    let camera = args
        .camera
        .clone()
        .unwrap_or_else(|| section.camera_path(&config_dir));
    if let Some(r) = args.rate_hz
        && !(r.is_finite() && (0.1..=1000.0).contains(&r))
    {
        bail!("--rate-hz {r} is not allowed (allowed: 0.1 to 1000)");
    }
    match &source {
        SourceSpec::Sim | SourceSpec::Gst(_) if args.rate_hz.is_some() => bail!(
            "--rate-hz does not apply to --source {source} (allowed with file: and v4l2: sources)"
        ),
        SourceSpec::File(_) => {}
        _ if args.looping => {
            bail!("--loop does not apply to --source {source} (allowed with file: sources)")
        }
        _ => {}
    }
    let prefix = IpcPrefix::resolve(args.ipc_prefix.as_deref(), &file.ipc.prefix)?;
    Ok(Settings {
        source,
        camera,
        undistort: args.undistort || section.undistort,
        rate_hz: args.rate_hz,
        looping: args.looping,
        prefix,
        heartbeat_period: Duration::from_millis(file.ipc.heartbeat_period_ms),
        heartbeat_deadline: Duration::from_millis(file.ipc.heartbeat_deadline_ms),
    })
}

fn run(args: &Args) -> Result<()> {
    let s = settings(args)?;
    // The calibration error names the file and the problem in one line.
    let calibration = CameraCalibration::load(&s.camera)?;
    let ingest = Ingest::new(calibration, s.undistort).context("undistortion maps")?;
    let ipc = Ipc::open(PROCESS, &s.prefix)?;
    let publisher = ipc
        .slice_publisher::<u8, CameraFrameHeader>(services::CAMERA_FRAME, ingest.max_frame_len())?;
    let heartbeat = ipc.heartbeat(s.heartbeat_deadline)?;
    tracing::info!(
        source = %s.source,
        camera = %s.camera.display(),
        width = calibration.width,
        height = calibration.height,
        undistort = s.undistort,
        prefix = s.prefix.as_str(),
        "camera-ingest running"
    );
    let mut out = Output {
        ingest,
        publisher,
        heartbeat,
        period_ns: s.heartbeat_period.as_nanos() as u64,
        next_beat_ns: 0,
        log: DropLog::new(),
    };
    let result = match &s.source {
        SourceSpec::Sim => run_sim(&ipc, &mut out),
        _ => run_capture(&ipc, &s, &mut out),
    };
    let c = out.ingest.counters();
    tracing::info!(
        published = c.published,
        dropped_bad_header = c.dropped_bad_header,
        dropped_size = c.dropped_size,
        dropped_unreadable = c.dropped_unreadable,
        dropped_no_buffer = c.dropped_no_buffer,
        dropped_error = c.dropped_error,
        skipped_stale = c.skipped_stale,
        lost_upstream = c.lost_upstream,
        source_errors = c.source_errors,
        "camera-ingest stopped"
    );
    result
}

/// The publishing side shared by both backends: the ingest stage, the port, the heartbeat
/// and the drop log.
struct Output {
    ingest: Ingest,
    publisher: SlicePublisher<u8, CameraFrameHeader>,
    heartbeat: Heartbeat,
    period_ns: u64,
    next_beat_ns: u64,
    log: DropLog,
}

/// Why the last frame was lost, kept unformatted until a log line is due.
enum Problem {
    Rejected(Rejection),
    Failed(IngestError),
    Loan(LoanError),
    Send(SendError),
}

impl std::fmt::Display for Problem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Rejected(r) => r.fmt(f),
            Self::Failed(e) => e.fmt(f),
            Self::Loan(e) => e.fmt(f),
            Self::Send(e) => e.fmt(f),
        }
    }
}

/// Logs losses at most once per second, with the counters and the latest reason.
struct DropLog {
    limit: RateLimit,
    logged: Counters,
    last: Option<Problem>,
}

impl DropLog {
    fn new() -> Self {
        Self {
            limit: RateLimit::new(Duration::from_secs(1)),
            logged: Counters::default(),
            last: None,
        }
    }

    fn maybe_log(&mut self, c: &Counters, now_ns: u64) {
        let faults = |c: &Counters| c.dropped() + c.source_errors;
        if faults(c) == faults(&self.logged) || !self.limit.ready(now_ns) {
            return;
        }
        let last = self.last.take();
        tracing::warn!(
            published = c.published,
            dropped_bad_header = c.dropped_bad_header,
            dropped_size = c.dropped_size,
            dropped_unreadable = c.dropped_unreadable,
            dropped_no_buffer = c.dropped_no_buffer,
            dropped_error = c.dropped_error,
            skipped_stale = c.skipped_stale,
            lost_upstream = c.lost_upstream,
            source_errors = c.source_errors,
            last = %last.as_ref().map_or(String::new(), ToString::to_string),
            "frames dropped"
        );
        self.logged = *c;
    }
}

impl Output {
    /// Beats the heartbeat, logs losses and checks for SIGINT/SIGTERM when a beat is due;
    /// returns false when the process must stop.
    fn housekeeping(&mut self, ipc: &Ipc) -> Result<bool> {
        let now = monotonic_ns();
        if now < self.next_beat_ns {
            return Ok(true);
        }
        self.heartbeat.beat()?;
        self.next_beat_ns = now + self.period_ns;
        self.log.maybe_log(self.ingest.counters(), now);
        if ipc.shutdown_requested() {
            tracing::info!("signal: stopping");
            return Ok(false);
        }
        Ok(true)
    }

    /// How long the loop may wait for a frame before the next beat is due.
    fn until_beat(&self) -> Duration {
        Duration::from_nanos(
            self.next_beat_ns
                .saturating_sub(monotonic_ns())
                .max(1_000_000),
        )
    }

    /// Publishes one source frame: check, loan, write in place, stamp, send. Returns the
    /// rejection when the frame was unusable (the capture loop checks the first one).
    fn publish(
        &mut self,
        header: &CameraFrameHeader,
        payload: &[u8],
        enter_ns: u64,
    ) -> Option<Rejection> {
        let admitted = match self.ingest.admit(header, payload.len()) {
            Ok(a) => a,
            Err(r) => {
                self.log.last = Some(Problem::Rejected(r));
                return Some(r);
            }
        };
        // A zeroed loan (one memset) keeps the write path free of unsafe code.
        let mut sample = match self.publisher.loan(admitted.out_len) {
            Ok(s) => s,
            Err(e) => {
                // Every sample is held by consumers: drop this frame, never wait.
                self.ingest.record(Dropped::NoBuffer);
                self.log.last = Some(Problem::Loan(e));
                return None;
            }
        };
        match self.ingest.write(&admitted, payload, sample.payload_mut()) {
            Ok(h) => {
                let out = sample.user_header_mut();
                *out = h;
                out.msg
                    .push_stage(Stage::CameraIngest, enter_ns, monotonic_ns());
            }
            Err(e) => {
                self.log.last = Some(Problem::Failed(e));
                return None;
            }
        }
        match self.publisher.send(sample) {
            Ok(_) => self.ingest.sent(),
            Err(e) => {
                self.ingest.record(Dropped::SendFailed);
                self.log.last = Some(Problem::Send(e));
            }
        }
        None
    }
}

/// The simulator backend: wait for the next frame with `PeriodicWait` (the lowest wake-up
/// latency), take the newest one only, publish it.
fn run_sim(ipc: &Ipc, out: &mut Output) -> Result<()> {
    let sub = ipc.slice_subscriber::<u8, CameraFrameHeader>(services::SIM_CAMERA)?;
    let mut wait = PeriodicWait::new(Duration::from_micros(500), Duration::from_millis(2));
    let mut gaps_seen = 0;
    while out.housekeeping(ipc)? {
        let Some(first) = wait.wait(sub.listener(), out.until_beat(), || {
            sub.receive().transpose()
        }) else {
            continue;
        };
        let enter = monotonic_ns();
        let mut sample = first?;
        let mut stale = 0;
        while let Some(newer) = sub.receive()? {
            sample = newer;
            stale += 1;
        }
        if stale > 0 {
            out.ingest.record(Dropped::Stale(stale));
        }
        let gaps = sub.gaps();
        if gaps > gaps_seen {
            out.ingest.record(Dropped::LostUpstream(gaps - gaps_seen));
            gaps_seen = gaps;
        }
        out.publish(sample.user_header(), sample.payload(), enter);
    }
    Ok(())
}

/// A frame the capture thread read, with the monotonic time it was grabbed.
struct Captured {
    mat: Mat,
    capture_ns: u64,
}

/// What the capture thread hands the publishing loop: the newest frame only (a newer one
/// overwrites it, counted), the losses it saw, and whether it ended.
#[derive(Default)]
struct Slot {
    frame: Option<Captured>,
    spare: Option<Mat>,
    overwritten: u64,
    unreadable: u64,
    source_errors: u64,
    end: Option<Result<(), String>>,
}

#[derive(Default)]
struct Shared {
    slot: Mutex<Slot>,
    ready: Condvar,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Slot> {
        self.slot.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn update(&self, f: impl FnOnce(&mut Slot)) {
        f(&mut self.lock());
        self.ready.notify_one();
    }

    /// A buffer to decode into: the one the publishing loop gave back, if any.
    fn spare(&self) -> Mat {
        self.lock().spare.take().unwrap_or_default()
    }

    fn put(&self, frame: Captured) {
        self.update(|s| {
            if let Some(old) = s.frame.replace(frame) {
                s.overwritten += 1;
                s.spare = Some(old.mat);
            }
        });
    }

    /// Waits up to `timeout` for a frame or the end; returns everything new.
    fn take(&self, timeout: Duration) -> Slot {
        let guard = self.lock();
        let (mut s, _) = self
            .ready
            .wait_timeout_while(guard, timeout, |s| s.frame.is_none() && s.end.is_none())
            .unwrap_or_else(|p| p.into_inner());
        Slot {
            frame: s.frame.take(),
            spare: None,
            overwritten: std::mem::take(&mut s.overwritten),
            unreadable: std::mem::take(&mut s.unreadable),
            source_errors: std::mem::take(&mut s.source_errors),
            end: s.end.take(),
        }
    }
}

/// The OpenCV backends: a capture thread reads (and paces, and reconnects) while this
/// thread publishes and keeps the heartbeat going, even while a camera is gone.
fn run_capture(ipc: &Ipc, s: &Settings, out: &mut Output) -> Result<()> {
    let cal = *out.ingest.calibration();
    let mut source = FrameSource::for_spec(&s.source, Some((cal.width, cal.height)), s.rate_hz)?;
    // Files open now, so a bad one is a start-up error; cameras may appear later.
    let rate = match &mut source {
        FrameSource::Video(v) if !v.is_live() => {
            v.open()?;
            match s.rate_hz.or_else(|| v.declared_rate_hz()) {
                Some(r) => Some(r),
                None => bail!(
                    "{}: the video declares no frame rate (give --rate-hz)",
                    v.description()
                ),
            }
        }
        FrameSource::Images(d) => match s.rate_hz {
            Some(r) => Some(r),
            None => bail!(
                "{}: an image directory has no recorded rate (give --rate-hz)",
                d.dir().display()
            ),
        },
        FrameSource::Video(_) => None,
    };
    let pacer = rate.and_then(Pacer::from_rate_hz);
    let shared = Arc::new(Shared::default());
    let worker_shared = Arc::clone(&shared);
    let looping = s.looping;
    let worker = Worker::spawn(ThreadRole::CameraCapture, move |stop| {
        capture_loop(source, pacer, looping, &worker_shared, stop);
    })?;

    let mut checked_size = false;
    let result = loop {
        match out.housekeeping(ipc) {
            Ok(true) => {}
            Ok(false) => break Ok(()),
            Err(e) => break Err(e),
        }
        let news = shared.take(out.until_beat());
        if news.overwritten > 0 {
            out.ingest.record(Dropped::Stale(news.overwritten));
        }
        if news.unreadable > 0 {
            out.ingest.record(Dropped::Unreadable(news.unreadable));
        }
        for _ in 0..news.source_errors {
            out.ingest.record(Dropped::SourceError);
        }
        if let Some(frame) = news.frame {
            let header = header_for_mat(&frame.mat, frame.capture_ns, 0);
            let rejected = out.publish(&header, mat_bytes(&frame.mat), frame.capture_ns);
            if !checked_size {
                if let Some(Rejection::Size { width, height, .. }) = rejected {
                    break Err(anyhow::anyhow!(
                        "--source {} delivers {width}x{height} frames but the calibration {} is {}x{} (use a calibration made for this camera mode)",
                        s.source,
                        s.camera.display(),
                        cal.width,
                        cal.height
                    ));
                }
                checked_size = rejected.is_none();
            }
            shared.lock().spare = Some(frame.mat);
        }
        match news.end {
            Some(Ok(())) => {
                tracing::info!(source = %s.source, "end of the recording");
                break Ok(());
            }
            Some(Err(e)) => break Err(anyhow::anyhow!(e)),
            // It said nothing and is gone: it panicked (the join below names it).
            None if worker.is_finished() => break Ok(()),
            None => {}
        }
    };
    // Joined before `main` returns: OpenCV's exit handlers must not run under a read. A
    // read blocked for longer (a camera stuck in its driver) ends the process with the
    // thread's exit code instead (runtime::threads).
    worker.stop_and_join(JOIN_TIMEOUT)?;
    result
}

/// What one step of the capture thread did.
enum Step {
    Frame(Captured),
    /// Nothing to publish this time (a rewind, an undecodable video frame).
    Skip,
    /// A frame's slot in the recording went by without a frame (an unreadable image).
    Missed,
    /// Wait this long before trying again (a camera to reopen).
    Retry(Duration),
    End(Result<(), String>),
}

/// The capture thread: reads, paces recorded sources, reopens cameras with backoff, and
/// hands each frame to the publishing loop. Never publishes itself (iceoryx2 ports stay on
/// one thread).
fn capture_loop(
    mut source: FrameSource,
    mut pacer: Option<Pacer>,
    looping: bool,
    shared: &Shared,
    stop: &StopFlag,
) {
    let mut backoff = Backoff::new(Duration::from_millis(100), Duration::from_secs(5));
    while !stop.is_stopped() {
        if let Some(p) = &pacer {
            let delay = p.delay_ns(monotonic_ns());
            // A slow rate (0.1 Hz) must not hold a stop for seconds.
            if delay > 0 && !stop.sleep(Duration::from_nanos(delay)) {
                break;
            }
        }
        let step = match &mut source {
            FrameSource::Video(v) => video_step(v, looping, &mut backoff, shared),
            FrameSource::Images(d) => image_step(d, looping, shared),
        };
        match step {
            Step::Frame(frame) => {
                if let Some(p) = pacer.as_mut() {
                    p.emitted(frame.capture_ns);
                }
                shared.put(frame);
            }
            Step::Skip => {}
            Step::Missed => {
                if let Some(p) = pacer.as_mut() {
                    p.emitted(monotonic_ns());
                }
            }
            Step::Retry(delay) => {
                stop.sleep(delay);
            }
            Step::End(result) => {
                shared.update(|s| s.end = Some(result));
                return;
            }
        }
    }
}

fn video_step(v: &mut VideoSource, looping: bool, backoff: &mut Backoff, shared: &Shared) -> Step {
    if !v.is_open() {
        if let Err(e) = v.open() {
            let delay = backoff.next_delay();
            tracing::warn!(
                error = %e,
                retry_in_ms = delay.as_millis() as u64,
                "cannot open the camera; retrying"
            );
            return Step::Retry(delay);
        }
        tracing::info!(source = v.description(), "camera open");
    }
    match v.grab() {
        Ok(true) => {
            let capture_ns = monotonic_ns();
            let mut mat = shared.spare();
            match v.retrieve(&mut mat) {
                Ok(()) => {
                    backoff.reset();
                    Step::Frame(Captured { mat, capture_ns })
                }
                // A file's undecodable frame is skipped; a camera's means trouble.
                Err(e) if v.is_live() => lost(v, &e.to_string(), backoff, shared),
                Err(_) => {
                    shared.update(|s| s.source_errors += 1);
                    Step::Skip
                }
            }
        }
        Ok(false) if !v.is_live() => {
            if !looping {
                return Step::End(Ok(()));
            }
            match v.open() {
                Ok(()) => Step::Skip,
                Err(e) => Step::End(Err(e.to_string())),
            }
        }
        Ok(false) => lost(v, "no frame", backoff, shared),
        Err(e) => lost(v, &e.to_string(), backoff, shared),
    }
}

/// A camera that stopped delivering: close it, count it, reopen after a backoff.
fn lost(v: &mut VideoSource, why: &str, backoff: &mut Backoff, shared: &Shared) -> Step {
    v.close();
    shared.update(|s| s.source_errors += 1);
    let delay = backoff.next_delay();
    tracing::warn!(
        source = v.description(),
        error = why,
        retry_in_ms = delay.as_millis() as u64,
        "camera lost; reopening"
    );
    Step::Retry(delay)
}

fn image_step(d: &mut ImageDir, looping: bool, shared: &Shared) -> Step {
    match d.next_image() {
        Some(Ok(mat)) => Step::Frame(Captured {
            mat,
            capture_ns: monotonic_ns(),
        }),
        Some(Err(e)) => {
            tracing::debug!(error = %e, "image skipped");
            shared.update(|s| s.unreadable += 1);
            Step::Missed
        }
        None if looping => {
            d.rewind();
            Step::Skip
        }
        None => Step::End(Ok(())),
    }
}
