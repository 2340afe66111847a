//! A V4L2 depth camera streaming Z16 (16-bit depth, one depth unit per count) through
//! the `v4l` crate: OpenCV 4.6's V4L2 backend cannot deliver Z16 (opencv issue 15533), so
//! camera-ingest's path does not serve depth. RealSense cameras show their depth node as
//! one such device under the kernel's uvcvideo driver; others (Orbbec, some ToF cameras)
//! do too.

use std::io;
use std::path::{Path, PathBuf};
use std::time::Duration;

use v4l::buffer::Type;
use v4l::io::mmap::Stream;
use v4l::io::traits::CaptureStream;
use v4l::video::Capture;
use v4l::video::capture::Parameters;
use v4l::{Device, FourCC};

use crate::png_dir::DepthImage;

/// Z16's FourCC.
const Z16: &[u8; 4] = b"Z16 ";
/// Buffers the driver fills in turn (the newest is read; the capture thread keeps only it).
const BUFFERS: u32 = 4;

/// Why a V4L2 depth device could not be opened or read.
#[derive(Debug, thiserror::Error)]
pub enum V4l2Error {
    /// The device could not be opened or set up.
    #[error("{path}: {what}: {source}")]
    Device {
        /// The device.
        path: PathBuf,
        /// What was being done.
        what: &'static str,
        /// The system's error.
        source: io::Error,
    },
    /// The device streams another format than Z16 at the size asked for.
    #[error(
        "{path}: streams {fourcc} at {width}x{height}, not Z16 at the [depth_ingest] mode: is it the depth node (v4l2-ctl --list-devices, --list-formats-ext)?"
    )]
    NotZ16 {
        /// The device.
        path: PathBuf,
        /// What it streams instead.
        fourcc: String,
        /// Its width, px.
        width: u32,
        /// Its height, px.
        height: u32,
    },
    /// A buffer shorter than the format says.
    #[error("a Z16 buffer of {got} bytes, {want} expected")]
    ShortBuffer {
        /// Bytes the driver filled.
        got: usize,
        /// Bytes a frame needs.
        want: usize,
    },
}

/// A V4L2 device streaming Z16, set to the mode asked for.
pub struct V4l2Depth {
    stream: Stream<'static>,
    width: u32,
    height: u32,
    stride: usize,
}

impl V4l2Depth {
    /// Opens `path`, asks for Z16 at `width` x `height` and `fps`, and starts streaming;
    /// a read waits at most `timeout` for a frame.
    pub fn open(
        path: &Path,
        [width, height, fps]: [u32; 3],
        timeout: Duration,
    ) -> Result<Self, V4l2Error> {
        let err = |what: &'static str| {
            move |source: io::Error| V4l2Error::Device {
                path: path.to_path_buf(),
                what,
                source,
            }
        };
        let device = Device::with_path(path).map_err(err("cannot open it"))?;
        let mut format = device.format().map_err(err("cannot read its format"))?;
        format.width = width;
        format.height = height;
        format.fourcc = FourCC::new(Z16);
        let format = device
            .set_format(&format)
            .map_err(err("cannot set its format"))?;
        if format.fourcc != FourCC::new(Z16) || format.width != width || format.height != height {
            return Err(V4l2Error::NotZ16 {
                path: path.to_path_buf(),
                fourcc: format.fourcc.str().unwrap_or("????").to_string(),
                width: format.width,
                height: format.height,
            });
        }
        // A driver that keeps its own rate says so in the frames' pace; not an error.
        if let Err(e) = device.set_params(&Parameters::with_fps(fps)) {
            tracing::warn!(error = %e, fps, "the device kept its own frame rate");
        }
        let mut stream = Stream::with_buffers(&device, Type::VideoCapture, BUFFERS)
            .map_err(err("cannot map its buffers"))?;
        stream.set_timeout(timeout);
        let stride = (format.stride as usize).max(2 * width as usize);
        Ok(Self {
            stream,
            width,
            height,
            stride,
        })
    }

    /// The frames' size, px.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// Waits for the next frame and copies its depths into `image`. A timeout is an
    /// `io::ErrorKind::TimedOut` device error.
    pub fn next_image(&mut self, image: &mut DepthImage) -> Result<(), V4l2Error> {
        let (w, h, stride) = (self.width as usize, self.height as usize, self.stride);
        let (bytes, meta) = self.stream.next().map_err(|source| V4l2Error::Device {
            path: PathBuf::new(),
            what: "no frame",
            source,
        })?;
        let used = (meta.bytesused as usize).min(bytes.len());
        unpack_z16(&bytes[..used], w, h, stride, image)
    }
}

/// Copies a Z16 frame of `w` x `h` px, rows `stride` bytes apart (a driver may pad them),
/// little-endian, into `image`.
pub fn unpack_z16(
    bytes: &[u8],
    w: usize,
    h: usize,
    stride: usize,
    image: &mut DepthImage,
) -> Result<(), V4l2Error> {
    let want = stride * h.saturating_sub(1) + 2 * w;
    if bytes.len() < want || stride < 2 * w {
        return Err(V4l2Error::ShortBuffer {
            got: bytes.len(),
            want,
        });
    }
    image.width = u32::try_from(w).unwrap_or(u32::MAX);
    image.height = u32::try_from(h).unwrap_or(u32::MAX);
    image.depths.clear();
    image.depths.reserve(w * h);
    for row in bytes.chunks(stride).take(h) {
        image.depths.extend(
            row[..2 * w]
                .chunks_exact(2)
                .map(|p| u16::from_le_bytes([p[0], p[1]])),
        );
    }
    Ok(())
}

#[cfg(test)]
#[path = "v4l2_test.rs"]
mod tests;
