//! A RealSense camera through librealsense (the `realsense` cargo feature): live, the
//! first one plugged in or one by serial number, or a `.bag` recording that librealsense
//! plays itself (at the recorded rate). `bag:` reads recordings without librealsense;
//! this is the path a live D435 takes on the Jetson.

use std::ffi::CString;
use std::time::Duration;

use ipc_types::msg::Intrinsics;
use realsense_rust::config::Config;
use realsense_rust::context::Context;
use realsense_rust::frame::{DepthFrame, PixelKind};
use realsense_rust::kind::{Rs2Format, Rs2Option, Rs2StreamKind};
use realsense_rust::pipeline::{ActivePipeline, FrameWaitError, InactivePipeline};
use realsense_rust::prelude::FrameEx;

use crate::bag::DepthStreamInfo;
use crate::png_dir::DepthImage;
use crate::source::RealSenseTarget;

/// Why a RealSense could not be opened or read.
#[derive(Debug, thiserror::Error)]
pub enum RealSenseError {
    /// librealsense refused (no device, a device busy, a file it cannot play).
    #[error("librealsense: {0}")]
    Library(String),
    /// The device or recording has no depth stream at the mode asked for.
    #[error("no Z16 depth stream{0}")]
    NoDepthStream(String),
    /// A frame of another size or format than the stream's.
    #[error("a depth frame of {0}")]
    BadFrame(String),
}

/// The live stream asked of a camera: width, height px, rate Hz (a D435 streams Z16 at
/// 640x480 or 848x480, 6 to 90 Hz).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LiveMode {
    /// Width, px.
    pub width: u32,
    /// Height, px.
    pub height: u32,
    /// Frames per second.
    pub fps: u32,
}

/// A started librealsense pipeline and what its depth stream is.
pub struct RealSense {
    pipeline: ActivePipeline,
    info: DepthStreamInfo,
    recording: bool,
}

fn library(e: impl std::fmt::Display) -> RealSenseError {
    RealSenseError::Library(e.to_string())
}

impl RealSense {
    /// Starts the depth stream of `target` (`mode` for a live camera; a recording plays
    /// what it holds, once, or again and again when `looping`).
    pub fn open(
        target: &RealSenseTarget,
        mode: LiveMode,
        looping: bool,
    ) -> Result<Self, RealSenseError> {
        // The pipeline keeps its own reference to the context (librealsense shares it).
        let context = Context::new().map_err(library)?;
        let pipeline = InactivePipeline::try_from(&context).map_err(library)?;
        let mut config = Config::new();
        let recording = matches!(target, RealSenseTarget::Recording(_));
        match target {
            RealSenseTarget::Any => {}
            RealSenseTarget::Serial(serial) => {
                let c = CString::new(serial.as_str()).map_err(library)?;
                config.enable_device_from_serial(&c).map_err(library)?;
            }
            RealSenseTarget::Recording(path) => {
                config
                    .enable_device_from_file(path, looping)
                    .map_err(library)?;
            }
        }
        // A recording plays the streams it holds; a camera is asked for its depth mode.
        if !recording {
            config
                .enable_stream(
                    Rs2StreamKind::Depth,
                    None,
                    mode.width as usize,
                    mode.height as usize,
                    Rs2Format::Z16,
                    mode.fps as usize,
                )
                .map_err(library)?;
        }
        let pipeline = pipeline.start(Some(config)).map_err(|e| {
            if recording {
                library(e)
            } else {
                RealSenseError::NoDepthStream(format!(
                    " at {}x{} {} Hz: {e}",
                    mode.width, mode.height, mode.fps
                ))
            }
        })?;
        let profile = pipeline
            .profile()
            .streams()
            .iter()
            .find(|s| s.kind() == Rs2StreamKind::Depth && s.format() == Rs2Format::Z16)
            .ok_or_else(|| RealSenseError::NoDepthStream(String::new()))?;
        let k = profile.intrinsics().map_err(library)?;
        let depth_scale_m = pipeline
            .profile()
            .device()
            .sensors()
            .iter()
            .find_map(|s| s.get_option(Rs2Option::DepthUnits))
            .map_or(0.001, f64::from);
        let info = DepthStreamInfo {
            width: k.width() as u32,
            height: k.height() as u32,
            intrinsics: Intrinsics {
                fx: f64::from(k.fx()),
                fy: f64::from(k.fy()),
                cx: f64::from(k.ppx()),
                cy: f64::from(k.ppy()),
            },
            depth_scale_m,
            fps: u32::try_from(profile.framerate()).unwrap_or(0),
        };
        Ok(Self {
            pipeline,
            info,
            recording,
        })
    }

    /// The depth stream: size, intrinsics, depth units, rate.
    pub fn info(&self) -> DepthStreamInfo {
        self.info
    }

    /// Whether this plays a recording (its end is the end, not a lost camera).
    pub fn is_recording(&self) -> bool {
        self.recording
    }

    /// Waits up to `timeout` for the next depth frame and copies it into `image`.
    /// `Ok(None)`: no frame came (a recording at its end, a camera gone quiet).
    pub fn next_image(
        &mut self,
        image: &mut DepthImage,
        timeout: Duration,
    ) -> Result<Option<()>, RealSenseError> {
        let frames = match self.pipeline.wait(Some(timeout)) {
            Ok(f) => f,
            Err(FrameWaitError::DidTimeoutBeforeFrameArrival) => return Ok(None),
            Err(e) => return Err(library(e)),
        };
        let Some(depth) = frames.frames_of_type::<DepthFrame>().into_iter().next() else {
            return Ok(None);
        };
        if depth.stream_profile().format() != Rs2Format::Z16 {
            return Err(RealSenseError::BadFrame(format!(
                "format {:?}",
                depth.stream_profile().format()
            )));
        }
        let (w, h) = (depth.width(), depth.height());
        image.width = u32::try_from(w).map_err(|_| RealSenseError::BadFrame(format!("{w} px")))?;
        image.height = u32::try_from(h).map_err(|_| RealSenseError::BadFrame(format!("{h} px")))?;
        image.depths.clear();
        image.depths.reserve(w * h);
        for row in 0..h {
            for col in 0..w {
                match depth.get(col, row) {
                    Some(PixelKind::Z16 { depth }) => image.depths.push(*depth),
                    _ => {
                        return Err(RealSenseError::BadFrame(format!(
                            "{w}x{h} without a Z16 pixel at ({col}, {row})"
                        )));
                    }
                }
            }
        }
        Ok(Some(()))
    }
}
