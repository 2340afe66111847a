//! The OpenCV sources of camera-ingest (a camera, a GStreamer pipeline, a video file, an
//! image directory) as the iceoryx2 driver's [`External`] I/O. A capture thread
//! (runtime::capture) reads, paces recorded sources and reopens cameras with backoff, and
//! passes only the newest frame on, so the driver keeps publishing and beating the
//! heartbeat while a read blocks or a camera is gone. The frame reaches the stage
//! borrowed from the decoded image: written (copied or undistorted) once, into the
//! loaned shared-memory sample.

use std::time::Duration;

use anyhow::{Result, bail};
use camera_ingest::config::Source;
use camera_ingest::{FrameSource, ImageDir, VideoSource, header_for_mat, mat_bytes};
use ipc_types::topics;
use opencv::core::Mat;
use optics::CameraCalibration;
use runtime::capture::{Backoff, CaptureThread, Device, Losses, Pacer, Step};
use runtime::{JOIN_TIMEOUT, JoinError, ThreadRole, monotonic_ns};
use stage::{Counter, External, Flow, Input, Message, StageError};

/// The capture thread and what it handed over.
pub struct Capture {
    thread: CaptureThread<Mat>,
    /// The source as the user gave it, for error lines.
    source: String,
    /// The calibration the frames must match, and its file.
    width: u32,
    height: u32,
    camera: String,
    /// Whether a frame of the right size has been seen (the first one is checked).
    checked_size: bool,
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
        let device = CameraDevice {
            source,
            looping,
            backoff: Backoff::new(Duration::from_millis(100), Duration::from_secs(5)),
        };
        Ok(Self {
            thread: CaptureThread::start(device, pacer, ThreadRole::CameraCapture)?,
            source: spec.to_string(),
            width: calibration.width,
            height: calibration.height,
            camera: resolved.camera.display().to_string(),
            checked_size: false,
        })
    }

    /// Stops the capture thread and joins it within [`JOIN_TIMEOUT`]: before `main`
    /// returns, so OpenCV's exit handlers never run under a read. A read blocked for
    /// longer (a camera stuck in its driver) is the thread's exit code (runtime::threads).
    pub fn stop(self) -> Result<(), JoinError> {
        self.thread.stop(JOIN_TIMEOUT)
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
        let news = self.thread.take(Duration::from_nanos(timeout_ns));
        if let Some((mat, capture_ns)) = news.frame {
            let header = header_for_mat(&mat, capture_ns, 0);
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
                msg: Message::CameraFrame(&header, mat_bytes(&mat)),
            };
            let delivered = deliver(input, clock());
            // The image goes back to the thread to decode the next frame into.
            self.thread.give_back(mat);
            delivered?;
        }
        self.thread.flow(news.end)
    }

    fn send(&mut self, topic: &str, _msg: Message<'_>) -> Result<(), StageError> {
        Err(StageError::NotAnOutput {
            stage: "camera-ingest".into(),
            topic: topic.to_string(),
        })
    }

    fn counters(&self) -> Vec<Counter> {
        self.thread.counters()
    }
}

/// An OpenCV source on the capture thread: a camera reopened with backoff when lost, a
/// recording played to its end (or again, looping).
struct CameraDevice {
    source: FrameSource,
    looping: bool,
    backoff: Backoff,
}

impl Device for CameraDevice {
    type Frame = Mat;

    fn step(&mut self, spare: &mut Option<Mat>, losses: &mut Losses) -> Step<Mat> {
        match &mut self.source {
            FrameSource::Video(v) => video_step(v, self.looping, &mut self.backoff, spare, losses),
            FrameSource::Images(d) => image_step(d, self.looping, losses),
        }
    }
}

fn video_step(
    v: &mut VideoSource,
    looping: bool,
    backoff: &mut Backoff,
    spare: &mut Option<Mat>,
    losses: &mut Losses,
) -> Step<Mat> {
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
            let mut mat = spare.take().unwrap_or_default();
            match v.retrieve(&mut mat) {
                Ok(()) => {
                    backoff.reset();
                    Step::Frame(mat, capture_ns)
                }
                // A file's undecodable frame is skipped; a camera's means trouble.
                Err(e) if v.is_live() => lost(v, &e.to_string(), backoff, losses),
                Err(_) => {
                    losses.source_errors += 1;
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
        Ok(false) => lost(v, "no frame", backoff, losses),
        Err(e) => lost(v, &e.to_string(), backoff, losses),
    }
}

/// A camera that stopped delivering: close it, count it, reopen after a backoff.
fn lost(v: &mut VideoSource, why: &str, backoff: &mut Backoff, losses: &mut Losses) -> Step<Mat> {
    v.close();
    losses.source_errors += 1;
    let delay = backoff.next_delay();
    tracing::warn!(
        source = v.description(),
        error = why,
        retry_in_ms = delay.as_millis() as u64,
        "camera lost; reopening"
    );
    Step::Retry(delay)
}

fn image_step(d: &mut ImageDir, looping: bool, losses: &mut Losses) -> Step<Mat> {
    match d.next_image() {
        Some(Ok(mat)) => Step::Frame(mat, monotonic_ns()),
        Some(Err(e)) => {
            tracing::debug!(error = %e, "image skipped");
            losses.unreadable += 1;
            Step::Missed
        }
        None if looping => {
            d.rewind();
            Step::Skip
        }
        None => Step::End(Ok(())),
    }
}
