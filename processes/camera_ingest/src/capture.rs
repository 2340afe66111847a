//! The OpenCV sources of camera-ingest (a camera, a GStreamer pipeline, a video file, an
//! image directory) as the iceoryx2 driver's [`External`] I/O. A capture thread reads,
//! paces recorded sources and reopens cameras with backoff, and passes only the newest
//! frame on, so the driver keeps publishing and beating the heartbeat while a read
//! blocks or a camera is gone. The frame reaches the stage borrowed from the decoded
//! image: written (copied or undistorted) once, into the loaned shared-memory sample.

use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::Duration;

use anyhow::{Result, bail};
use camera_ingest::config::Source;
use camera_ingest::{
    Backoff, FrameSource, ImageDir, Pacer, VideoSource, header_for_mat, mat_bytes,
};
use ipc_types::topics;
use opencv::core::Mat;
use optics::CameraCalibration;
use runtime::{JOIN_TIMEOUT, JoinError, StopFlag, ThreadRole, Worker, monotonic_ns};
use stage::{Counter, External, Flow, Input, Message, StageError};

/// The capture thread and what it handed over.
pub struct Capture {
    shared: Arc<Shared>,
    worker: Worker<()>,
    /// The source as the user gave it, for error lines.
    source: String,
    /// The calibration the frames must match, and its file.
    width: u32,
    height: u32,
    camera: String,
    /// Whether a frame of the right size has been seen (the first one is checked).
    checked_size: bool,
    counts: Counts,
}

/// What the capture side loses, before the stage sees a frame.
#[derive(Debug, Default, Clone, Copy)]
struct Counts {
    /// Frames a newer one replaced before the driver took them.
    overwritten: u64,
    /// Image files that could not be decoded.
    unreadable: u64,
    /// Capture reads that failed (disconnections), each followed by a reopen.
    source_errors: u64,
}

impl Capture {
    /// Opens a recorded source now (a bad file is a start-up error; a camera may appear
    /// later) and starts the capture thread.
    pub fn start(resolved: &Source, calibration: &CameraCalibration) -> Result<Self> {
        let (spec, rate_hz, looping) = (&resolved.spec, resolved.rate_hz, resolved.looping);
        let size = Some((calibration.width, calibration.height));
        let mut source = FrameSource::for_spec(spec, size, rate_hz)?;
        let rate = match &mut source {
            FrameSource::Video(v) if !v.is_live() => {
                v.open()?;
                match rate_hz.or_else(|| v.declared_rate_hz()) {
                    Some(r) => Some(r),
                    None => bail!(
                        "{}: the video declares no frame rate (give --rate-hz)",
                        v.description()
                    ),
                }
            }
            FrameSource::Images(d) => match rate_hz {
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
        let worker = Worker::spawn(ThreadRole::CameraCapture, move |stop| {
            capture_loop(source, pacer, looping, &worker_shared, stop);
        })?;
        Ok(Self {
            shared,
            worker,
            source: spec.to_string(),
            width: calibration.width,
            height: calibration.height,
            camera: resolved.camera.display().to_string(),
            checked_size: false,
            counts: Counts::default(),
        })
    }

    /// Stops the capture thread and joins it within [`JOIN_TIMEOUT`]: before `main`
    /// returns, so OpenCV's exit handlers never run under a read. A read blocked for
    /// longer (a camera stuck in its driver) is the thread's exit code (runtime::threads).
    pub fn stop(self) -> Result<(), JoinError> {
        self.worker.stop_and_join(JOIN_TIMEOUT)
    }
}

impl External for Capture {
    fn topics(&self) -> &[&'static str] {
        &[topics::CAMERA_DEVICE]
    }

    fn wait(
        &mut self,
        timeout_ns: u64,
        clock: &dyn Fn() -> u64,
        deliver: &mut dyn FnMut(Input<'_>, u64) -> Result<(), StageError>,
    ) -> Result<Flow, StageError> {
        let news = self.shared.take(Duration::from_nanos(timeout_ns));
        self.counts.overwritten += news.overwritten;
        self.counts.unreadable += news.unreadable;
        self.counts.source_errors += news.source_errors;
        if let Some(frame) = news.frame {
            let header = header_for_mat(&frame.mat, frame.capture_ns, 0);
            if !self.checked_size {
                if (header.width, header.height) != (self.width, self.height) {
                    return Err(StageError::Failed(format!(
                        "--source {} delivers {}x{} frames but the calibration {} is {}x{} (use a calibration made for this camera mode)",
                        self.source,
                        header.width,
                        header.height,
                        self.camera,
                        self.width,
                        self.height
                    )));
                }
                self.checked_size = true;
            }
            let input = Input {
                topic: topics::CAMERA_DEVICE,
                msg: Message::CameraFrame(&header, mat_bytes(&frame.mat)),
            };
            let delivered = deliver(input, clock());
            // The image goes back to the thread to decode the next frame into.
            self.shared.lock().spare = Some(frame.mat);
            delivered?;
        }
        match news.end {
            Some(Ok(())) => {
                tracing::info!(source = %self.source, "end of the recording");
                Ok(Flow::Ended)
            }
            Some(Err(e)) => Err(StageError::Failed(e)),
            // It said nothing and is gone: it panicked (the join names it).
            None if self.worker.is_finished() => Ok(Flow::Ended),
            None => Ok(Flow::Open),
        }
    }

    fn send(&mut self, topic: &str, _msg: Message<'_>) -> Result<(), StageError> {
        Err(StageError::NotAnOutput {
            stage: "camera-ingest".into(),
            topic: topic.to_string(),
        })
    }

    fn counters(&self) -> Vec<Counter> {
        vec![
            ("overwritten", self.counts.overwritten),
            ("dropped_unreadable", self.counts.unreadable),
            ("source_errors", self.counts.source_errors),
        ]
    }
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
