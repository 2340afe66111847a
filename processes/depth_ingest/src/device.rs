//! depth-ingest's sources as the iceoryx2 driver's [`External`] I/O: a capture thread
//! (runtime::capture) reads the recording at its rate and hands over the newest frame;
//! the frame reaches the stage borrowed, with the header its source says (intrinsics,
//! depth units), stamped with the monotonic time it was played.

use std::path::PathBuf;

use anyhow::{Result, bail};
use depth_ingest::{DepthImage, DepthSourceSpec, PngDir, RsBag, Source};
use ipc_types::msg::{DepthFrameHeader, Header};
use ipc_types::topics;
use runtime::capture::{CaptureThread, Device, Losses, Pacer, Step};
use runtime::threads::SpawnError;
use runtime::{JOIN_TIMEOUT, JoinError, ThreadRole, monotonic_ns};
use stage::{Counter, External, Flow, Input, Message, StageError};

/// A source of depth frames, opened, with what its frames go out with.
pub struct DepthDevice {
    reader: Reader,
    looping: bool,
    header: DepthFrameHeader,
    rate_hz: f64,
}

enum Reader {
    /// A directory of 16-bit PNGs.
    Png(PngDir),
    /// A RealSense recording (reopened to loop).
    Bag(Box<RsBag>, PathBuf),
    /// A V4L2 device streaming Z16 (None: lost, to reopen).
    V4l2(Option<Box<depth_ingest::V4l2Depth>>, PathBuf, [u32; 3]),
    /// A RealSense through librealsense (None: lost, to reopen).
    #[cfg(feature = "realsense")]
    RealSense(Option<Box<depth_ingest::RealSense>>, RealSenseOpen),
}

/// What reopens a lost RealSense.
#[cfg(feature = "realsense")]
struct RealSenseOpen {
    target: depth_ingest::RealSenseTarget,
    mode: depth_ingest::LiveMode,
}

/// How long the capture thread waits for a V4L2 frame before it counts the device as
/// gone quiet, and how long before it opens a lost one again.
const V4L2_WAIT: std::time::Duration = std::time::Duration::from_millis(1000);
const V4L2_REOPEN: std::time::Duration = std::time::Duration::from_millis(500);

/// How long the capture thread waits for a RealSense frame before it counts the camera
/// as gone quiet (a recording: at its end).
#[cfg(feature = "realsense")]
const REALSENSE_WAIT: std::time::Duration = std::time::Duration::from_millis(1000);
/// How long before a lost RealSense is opened again.
#[cfg(feature = "realsense")]
const REALSENSE_REOPEN: std::time::Duration = std::time::Duration::from_millis(500);

impl DepthDevice {
    /// Opens the source (a bad file is a start-up error, one line) and reads what it says
    /// of its frames.
    pub fn open(source: &Source) -> Result<Self> {
        let mut header = DepthFrameHeader {
            intrinsics: source.intrinsics,
            depth_scale_m: source.depth_scale_m,
            ..DepthFrameHeader::default()
        };
        let (reader, rate_hz) = match &source.spec {
            DepthSourceSpec::File(dir) => {
                let mut dir = PngDir::open(dir)?;
                // The first image says the size; it is read again when playing.
                let mut first = DepthImage::default();
                if let Some(r) = dir.next_image(&mut first) {
                    r?;
                }
                dir.rewind();
                header.width = first.width;
                header.height = first.height;
                let rate_hz = source.rate_hz.unwrap_or(source.default_rate_hz);
                (Reader::Png(dir), rate_hz)
            }
            DepthSourceSpec::Bag(path) => {
                let bag = RsBag::open(path)?;
                let info = bag.info();
                header.width = info.width;
                header.height = info.height;
                header.intrinsics = info.intrinsics;
                header.depth_scale_m = info.depth_scale_m;
                let rate_hz = match (source.rate_hz, info.fps) {
                    (Some(r), _) => r,
                    (None, fps) if fps > 0 => f64::from(fps),
                    (None, _) => bail!(
                        "{}: the recording declares no frame rate (give --rate-hz)",
                        path.display()
                    ),
                };
                (Reader::Bag(Box::new(bag), path.clone()), rate_hz)
            }
            DepthSourceSpec::V4l2(path) => {
                let camera = depth_ingest::V4l2Depth::open(path, source.mode, V4L2_WAIT)?;
                (header.width, header.height) = camera.size();
                // The device paces itself.
                (
                    Reader::V4l2(Some(Box::new(camera)), path.clone(), source.mode),
                    0.0,
                )
            }
            #[cfg(feature = "realsense")]
            DepthSourceSpec::RealSense(target) => {
                let [width, height, fps] = source.mode;
                let mode = depth_ingest::LiveMode { width, height, fps };
                let camera = depth_ingest::RealSense::open(target, mode, source.looping)
                    .map_err(|e| anyhow::anyhow!("{}: {e}", source.spec))?;
                let info = camera.info();
                header.width = info.width;
                header.height = info.height;
                header.intrinsics = info.intrinsics;
                header.depth_scale_m = info.depth_scale_m;
                // librealsense paces the camera and plays a recording at its rate.
                let open = RealSenseOpen {
                    target: target.clone(),
                    mode,
                };
                (Reader::RealSense(Some(Box::new(camera)), open), 0.0)
            }
            #[cfg(not(feature = "realsense"))]
            DepthSourceSpec::RealSense(_) => bail!(
                "{}: this depth-ingest was built without librealsense: build it with `cargo build --release --features depth_ingest/realsense` where librealsense2 is installed (docs/jetson.md), or play a recording with bag:FILE",
                source.spec
            ),
        };
        Ok(Self {
            reader,
            looping: source.looping,
            header,
            rate_hz,
        })
    }

    /// The frames' size, px.
    pub fn size(&self) -> (u32, u32) {
        (self.header.width, self.header.height)
    }
}

impl Device for DepthDevice {
    type Frame = DepthImage;

    fn step(&mut self, spare: &mut Option<DepthImage>, losses: &mut Losses) -> Step<DepthImage> {
        let mut image = spare.take().unwrap_or_default();
        match &mut self.reader {
            Reader::Png(dir) => match dir.next_image(&mut image) {
                Some(Ok(())) => Step::Frame(image, monotonic_ns()),
                Some(Err(e)) => {
                    tracing::debug!(error = %e, "image skipped");
                    losses.unreadable += 1;
                    Step::Missed
                }
                None if self.looping => {
                    dir.rewind();
                    Step::Skip
                }
                None => Step::End(Ok(())),
            },
            Reader::Bag(bag, path) => match bag.next_image(&mut image) {
                Ok(Some(_stamp)) => Step::Frame(image, monotonic_ns()),
                Ok(None) if self.looping => match RsBag::open(path) {
                    Ok(b) => {
                        **bag = b;
                        Step::Skip
                    }
                    Err(e) => Step::End(Err(e.to_string())),
                },
                Ok(None) => Step::End(Ok(())),
                Err(e) => Step::End(Err(e.to_string())),
            },
            Reader::V4l2(camera, path, mode) => {
                let Some(cam) = camera else {
                    *spare = Some(image);
                    return match depth_ingest::V4l2Depth::open(path, *mode, V4L2_WAIT) {
                        Ok(c) => {
                            tracing::info!("V4L2 depth device reopened");
                            *camera = Some(Box::new(c));
                            Step::Skip
                        }
                        Err(e) => {
                            tracing::debug!(error = %e, "V4L2 depth device not back yet");
                            Step::Retry(V4L2_REOPEN)
                        }
                    };
                };
                match cam.next_image(&mut image) {
                    Ok(()) => Step::Frame(image, monotonic_ns()),
                    Err(depth_ingest::V4l2Error::ShortBuffer { got, want }) => {
                        tracing::debug!(got, want, "short frame skipped");
                        losses.unreadable += 1;
                        *spare = Some(image);
                        Step::Missed
                    }
                    Err(e) => {
                        // Silent for a second, or unplugged: reopen it.
                        tracing::warn!(error = %e, "V4L2 depth device lost: reopening");
                        losses.source_errors += 1;
                        *camera = None;
                        *spare = Some(image);
                        Step::Retry(V4L2_REOPEN)
                    }
                }
            }
            #[cfg(feature = "realsense")]
            Reader::RealSense(camera, open) => {
                let Some(cam) = camera else {
                    *spare = Some(image);
                    return match depth_ingest::RealSense::open(
                        &open.target,
                        open.mode,
                        self.looping,
                    ) {
                        Ok(c) => {
                            tracing::info!("RealSense reopened");
                            *camera = Some(Box::new(c));
                            Step::Skip
                        }
                        Err(e) => {
                            tracing::debug!(error = %e, "RealSense not back yet");
                            Step::Retry(REALSENSE_REOPEN)
                        }
                    };
                };
                match cam.next_image(&mut image, REALSENSE_WAIT) {
                    Ok(Some(())) => Step::Frame(image, monotonic_ns()),
                    Ok(None) if cam.is_recording() => Step::End(Ok(())),
                    Ok(None) | Err(depth_ingest::RealSenseError::Library(_)) => {
                        // A live camera gone quiet or unplugged: reopen it.
                        tracing::warn!("RealSense lost: reopening");
                        losses.source_errors += 1;
                        *camera = None;
                        *spare = Some(image);
                        Step::Retry(REALSENSE_REOPEN)
                    }
                    Err(e) => {
                        tracing::debug!(error = %e, "frame skipped");
                        losses.unreadable += 1;
                        *spare = Some(image);
                        Step::Missed
                    }
                }
            }
        }
    }
}

/// The capture thread and the header its frames go out with.
pub struct DepthCapture {
    thread: CaptureThread<DepthImage>,
    header: DepthFrameHeader,
    seq: u64,
}

impl DepthCapture {
    /// Starts reading `device` at its rate.
    pub fn start(device: DepthDevice) -> Result<Self, SpawnError> {
        let header = device.header;
        // A rate of 0 (a RealSense, which paces itself) is no pacer.
        let pacer = Pacer::from_rate_hz(device.rate_hz);
        Ok(Self {
            thread: CaptureThread::start(device, pacer, ThreadRole::DepthCapture)?,
            header,
            seq: 0,
        })
    }

    /// Stops the capture thread and joins it within [`JOIN_TIMEOUT`].
    pub fn stop(self) -> Result<(), JoinError> {
        self.thread.stop(JOIN_TIMEOUT)
    }
}

impl External for DepthCapture {
    fn topics(&self) -> &[&'static str] {
        &[topics::DEPTH_DEVICE]
    }

    fn wait(
        &mut self,
        timeout_ns: u64,
        clock: &dyn Fn() -> u64,
        deliver: &mut dyn FnMut(Input<'_>, u64) -> Result<(), StageError>,
    ) -> Result<Flow, StageError> {
        let taken = self
            .thread
            .take(std::time::Duration::from_nanos(timeout_ns));
        if let Some((image, capture_ns)) = taken.frame {
            self.seq += 1;
            let mut header = self.header;
            header.msg = Header {
                seq: self.seq,
                ..Header::captured_at(capture_ns)
            };
            header.width = image.width;
            header.height = image.height;
            let input = Input {
                topic: topics::DEPTH_DEVICE,
                msg: Message::DepthFrame(&header, &image.depths),
            };
            let delivered = deliver(input, clock());
            self.thread.give_back(image);
            delivered?;
        }
        self.thread.flow(taken.end)
    }

    fn send(&mut self, topic: &str, _msg: Message<'_>) -> Result<(), StageError> {
        Err(StageError::NotAnOutput {
            stage: "depth-ingest".into(),
            topic: topic.to_string(),
        })
    }

    fn counters(&self) -> Vec<Counter> {
        self.thread.counters()
    }
}
