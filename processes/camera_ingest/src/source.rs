//! Where frames come from: the `--source` text, and the OpenCV readers for real cameras
//! (V4L2, GStreamer), video files and image directories.
//!
//! The readers return frames and say when a read failed; whether to wait, retry or give
//! up is the caller's decision (with [`crate::pacing`]), because it needs the clock.

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use ipc_types::msg::{CameraFrameHeader, Header, PixelEncoding};
use opencv::core::{CV_8UC1, CV_8UC3, Mat};
use opencv::imgcodecs;
use opencv::prelude::*;
use opencv::videoio::{self, VideoCapture};

/// What `--source` accepts, for error messages.
pub const ALLOWED_SOURCES: &str = "sim, v4l2:/dev/videoN, gst:<GStreamer pipeline ending in appsink>, file:<video file or image directory>";

/// File extensions read from an image directory (others, such as notes, are ignored).
const IMAGE_EXTENSIONS: &[&str] = &[
    "png", "jpg", "jpeg", "bmp", "pgm", "ppm", "pnm", "tif", "tiff", "webp",
];

/// Why a source could not be named, opened or read.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    /// The `--source` text has a scheme this process does not know, or nothing after it.
    #[error("unknown --source `{0}` (allowed: {ALLOWED_SOURCES})")]
    UnknownScheme(String),
    /// A file or directory that does not exist.
    #[error("{0}: not found")]
    NotFound(PathBuf),
    /// A directory without a single image file.
    #[error("{0}: no image files (looked for {exts})", exts = IMAGE_EXTENSIONS.join(", "))]
    EmptyDirectory(PathBuf),
    /// The directory could not be listed.
    #[error("{path}: cannot list: {reason}")]
    ListDirectory {
        /// The directory.
        path: PathBuf,
        /// The I/O error.
        reason: String,
    },
    /// OpenCV could not open the camera, pipeline or file.
    #[error("{0}: OpenCV could not open it")]
    Open(String),
    /// A read from an open camera failed (it disconnected, or its driver stalled).
    #[error("{0}: read failed")]
    ReadFailed(String),
    /// An image file that could not be decoded.
    #[error("{0}: not a readable image")]
    Unreadable(PathBuf),
    /// An OpenCV call failed.
    #[error("{what}: OpenCV: {reason}")]
    OpenCv {
        /// The source.
        what: String,
        /// OpenCV's message.
        reason: String,
    },
}

/// Where frames come from, as `--source` names it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SourceSpec {
    /// The simulator's `landing/sim/camera` topic.
    Sim,
    /// A V4L2 device, e.g. `/dev/video0` (a USB camera).
    V4l2(String),
    /// A GStreamer pipeline ending in `appsink` (the Jetson CSI camera through
    /// `nvarguscamerasrc`).
    Gst(String),
    /// A video file or a directory of images, played back.
    File(PathBuf),
}

impl FromStr for SourceSpec {
    type Err = SourceError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let unknown = || SourceError::UnknownScheme(s.to_string());
        if s == "sim" {
            return Ok(Self::Sim);
        }
        let (scheme, rest) = s.split_once(':').ok_or_else(unknown)?;
        if rest.trim().is_empty() {
            return Err(unknown());
        }
        match scheme {
            "v4l2" => Ok(Self::V4l2(rest.to_string())),
            "gst" => Ok(Self::Gst(rest.to_string())),
            "file" => Ok(Self::File(PathBuf::from(rest))),
            _ => Err(unknown()),
        }
    }
}

impl fmt::Display for SourceSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Sim => write!(f, "sim"),
            Self::V4l2(d) => write!(f, "v4l2:{d}"),
            Self::Gst(p) => write!(f, "gst:{p}"),
            Self::File(p) => write!(f, "file:{}", p.display()),
        }
    }
}

fn cv_err(what: &str) -> impl Fn(opencv::Error) -> SourceError + '_ {
    move |e| SourceError::OpenCv {
        what: what.to_string(),
        reason: e.message,
    }
}

/// How a [`VideoSource`] opens its capture; kept so that it can reopen after a failure.
#[derive(Debug, Clone, PartialEq)]
enum VideoKind {
    V4l2 {
        device: String,
        size: Option<(u32, u32)>,
        fps: Option<f64>,
    },
    Gst {
        pipeline: String,
    },
    File {
        path: PathBuf,
    },
}

/// A camera, pipeline or video file read through OpenCV's `VideoCapture`.
///
/// Reading is split into [`grab`](Self::grab) and [`retrieve`](Self::retrieve) so that the
/// caller can take the capture time right after the grab, before the frame is decoded.
pub struct VideoSource {
    kind: VideoKind,
    description: String,
    capture: Option<VideoCapture>,
}

impl fmt::Debug for VideoSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("VideoSource")
            .field("source", &self.description)
            .field("open", &self.capture.is_some())
            .finish()
    }
}

impl VideoSource {
    /// A V4L2 device, asked for `size` (the calibration's) and `fps` when given, since a
    /// calibration only holds for the mode it was made in.
    pub fn v4l2(device: &str, size: Option<(u32, u32)>, fps: Option<f64>) -> Self {
        Self {
            kind: VideoKind::V4l2 {
                device: device.to_string(),
                size,
                fps,
            },
            description: format!("v4l2:{device}"),
            capture: None,
        }
    }

    /// A GStreamer pipeline ending in `appsink`.
    pub fn gst(pipeline: &str) -> Self {
        Self {
            kind: VideoKind::Gst {
                pipeline: pipeline.to_string(),
            },
            description: format!("gst:{pipeline}"),
            capture: None,
        }
    }

    /// A video file.
    pub fn file(path: &Path) -> Self {
        Self {
            kind: VideoKind::File {
                path: path.to_path_buf(),
            },
            description: format!("file:{}", path.display()),
            capture: None,
        }
    }

    /// The source as `--source` names it, for logs.
    pub fn description(&self) -> &str {
        &self.description
    }

    /// True for cameras (a failed read means a disconnection), false for files (a failed
    /// read means the end).
    pub fn is_live(&self) -> bool {
        !matches!(self.kind, VideoKind::File { .. })
    }

    /// Whether the capture is open.
    pub fn is_open(&self) -> bool {
        self.capture.is_some()
    }

    /// Opens (or reopens) the capture.
    pub fn open(&mut self) -> Result<(), SourceError> {
        self.close();
        let what = self.description.clone();
        let err = cv_err(&what);
        let mut capture = match &self.kind {
            VideoKind::V4l2 { device, .. } => {
                VideoCapture::from_file(device, videoio::CAP_V4L2).map_err(&err)?
            }
            VideoKind::Gst { pipeline } => {
                VideoCapture::from_file(pipeline, videoio::CAP_GSTREAMER).map_err(&err)?
            }
            VideoKind::File { path } => {
                if !path.exists() {
                    return Err(SourceError::NotFound(path.clone()));
                }
                VideoCapture::from_file(path, videoio::CAP_ANY).map_err(&err)?
            }
        };
        if !capture.is_opened().map_err(&err)? {
            return Err(SourceError::Open(self.description.clone()));
        }
        if let VideoKind::V4l2 { size, fps, .. } = &self.kind {
            // Requests only: the driver picks the nearest mode, and the first frame's size
            // is checked against the calibration.
            if let Some((w, h)) = size {
                capture
                    .set(videoio::CAP_PROP_FRAME_WIDTH, f64::from(*w))
                    .map_err(&err)?;
                capture
                    .set(videoio::CAP_PROP_FRAME_HEIGHT, f64::from(*h))
                    .map_err(&err)?;
            }
            if let Some(fps) = fps {
                capture.set(videoio::CAP_PROP_FPS, *fps).map_err(&err)?;
            }
        }
        self.capture = Some(capture);
        Ok(())
    }

    /// Releases the capture (a camera that failed is closed before it is reopened).
    pub fn close(&mut self) {
        if let Some(mut c) = self.capture.take() {
            let _ = c.release();
        }
    }

    /// The rate the source declares (a video file's recorded rate), if it declares one.
    pub fn declared_rate_hz(&self) -> Option<f64> {
        let fps = self.capture.as_ref()?.get(videoio::CAP_PROP_FPS).ok()?;
        (fps.is_finite() && fps > 0.0).then_some(fps)
    }

    /// Grabs the next frame without decoding it. `Ok(false)`: no frame (a file ended, a
    /// camera stopped delivering).
    pub fn grab(&mut self) -> Result<bool, SourceError> {
        let what = &self.description;
        match self.capture.as_mut() {
            Some(c) => c.grab().map_err(cv_err(what)),
            None => Err(SourceError::ReadFailed(what.clone())),
        }
    }

    /// Decodes the grabbed frame into `frame` (reusing its buffer when the size fits).
    pub fn retrieve(&mut self, frame: &mut Mat) -> Result<(), SourceError> {
        let what = &self.description;
        let c = self
            .capture
            .as_mut()
            .ok_or_else(|| SourceError::ReadFailed(what.clone()))?;
        if c.retrieve_def(frame).map_err(cv_err(what))? && !frame.empty() {
            Ok(())
        } else {
            Err(SourceError::ReadFailed(what.clone()))
        }
    }
}

/// A directory of images played as a camera, in file-name order (`frame_0001.png`, ...).
#[derive(Debug, Clone)]
pub struct ImageDir {
    dir: PathBuf,
    files: Vec<PathBuf>,
    next: usize,
    unreadable: u64,
}

impl ImageDir {
    /// Lists the image files of `dir`, sorted by name.
    pub fn open(dir: &Path) -> Result<Self, SourceError> {
        if !dir.is_dir() {
            return Err(SourceError::NotFound(dir.to_path_buf()));
        }
        let entries = std::fs::read_dir(dir).map_err(|e| SourceError::ListDirectory {
            path: dir.to_path_buf(),
            reason: e.to_string(),
        })?;
        let mut files: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.is_file() && is_image_name(p))
            .collect();
        files.sort_by(|a, b| a.file_name().cmp(&b.file_name()));
        if files.is_empty() {
            return Err(SourceError::EmptyDirectory(dir.to_path_buf()));
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            files,
            next: 0,
            unreadable: 0,
        })
    }

    /// The directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The image files, in playing order.
    pub fn files(&self) -> &[PathBuf] {
        &self.files
    }

    /// The next image, decoded as 8-bit grey or BGR; `None` after the last one. A file that
    /// cannot be decoded is counted and returned as an error; the next call moves on.
    pub fn next_image(&mut self) -> Option<Result<Mat, SourceError>> {
        let path = self.files.get(self.next)?;
        self.next += 1;
        let image = imgcodecs::imread(path, imgcodecs::IMREAD_ANYCOLOR);
        match image {
            Ok(m) if !m.empty() => Some(Ok(m)),
            _ => {
                self.unreadable += 1;
                Some(Err(SourceError::Unreadable(path.clone())))
            }
        }
    }

    /// Starts again from the first image (looping playback).
    pub fn rewind(&mut self) {
        self.next = 0;
    }

    /// Files that could not be decoded so far.
    pub fn unreadable(&self) -> u64 {
        self.unreadable
    }
}

fn is_image_name(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| IMAGE_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
}

/// An OpenCV-backed source: a capture (camera, pipeline, video file) or an image
/// directory.
#[derive(Debug)]
pub enum FrameSource {
    /// Read through `VideoCapture`.
    Video(VideoSource),
    /// Read with `imread`, one file per frame.
    Images(ImageDir),
}

impl FrameSource {
    /// The reader for `spec`, not yet opened (cameras open, and reopen, in the capture
    /// loop). `size` and `fps` are what a V4L2 camera is asked for. A `file:` that is a
    /// directory plays its images; any other file is a video. `sim` has no OpenCV reader.
    pub fn for_spec(
        spec: &SourceSpec,
        size: Option<(u32, u32)>,
        fps: Option<f64>,
    ) -> Result<Self, SourceError> {
        Ok(match spec {
            SourceSpec::Sim => return Err(SourceError::UnknownScheme("sim".into())),
            SourceSpec::V4l2(device) => Self::Video(VideoSource::v4l2(device, size, fps)),
            SourceSpec::Gst(pipeline) => Self::Video(VideoSource::gst(pipeline)),
            SourceSpec::File(path) if path.is_dir() => Self::Images(ImageDir::open(path)?),
            SourceSpec::File(path) if path.exists() => Self::Video(VideoSource::file(path)),
            SourceSpec::File(path) => return Err(SourceError::NotFound(path.clone())),
        })
    }

    /// True for cameras: a failed read is a disconnection to retry, not the end.
    pub fn is_live(&self) -> bool {
        match self {
            Self::Video(v) => v.is_live(),
            Self::Images(_) => false,
        }
    }
}

/// The header describing an OpenCV image captured at `capture_ns`, so that captured frames
/// go through the same checks ([`crate::Ingest::admit`]) as the simulator's. 8-bit grey and
/// BGR images are described as such; anything else (16-bit, 4 channels) gets encoding 0
/// and a non-contiguous view stride 0, which the check rejects and counts.
pub fn header_for_mat(mat: &Mat, capture_ns: u64, camera_id: u32) -> CameraFrameHeader {
    let (width, height) = (mat.cols().max(0) as u32, mat.rows().max(0) as u32);
    let encoding = match mat.typ() {
        t if t == CV_8UC1 => Some(PixelEncoding::Mono8),
        t if t == CV_8UC3 => Some(PixelEncoding::Bgr8),
        _ => None,
    };
    let stride = match encoding {
        Some(e) if mat.is_continuous() => width * e.bytes_per_pixel() as u32,
        _ => 0,
    };
    CameraFrameHeader {
        msg: Header::captured_at(capture_ns),
        width,
        height,
        stride,
        encoding: encoding.map_or(0, |e| e as u32),
        camera_id,
        undistorted: 0,
        exposure_ns: 0,
    }
}

/// The pixels of an OpenCV image as bytes; empty for a non-contiguous view (whose header
/// [`header_for_mat`] already marks as unusable).
pub fn mat_bytes(mat: &Mat) -> &[u8] {
    mat.data_bytes().unwrap_or(&[])
}

#[cfg(test)]
#[path = "source_test.rs"]
mod tests;
