//! The per-frame step: check a source frame, then write the published frame into the
//! caller's buffer (a loaned shared-memory sample), copied or undistorted.
//!
//! Checking and writing are two calls because the caller must know the output length
//! before it can loan the buffer to write into: [`Ingest::admit`] says whether the frame is
//! usable and how long its output is, [`Ingest::write`] fills the loan.

use std::fmt;

use ipc_types::msg::{CameraFrameHeader, Header, PixelEncoding};
use optics::CameraCalibration;

use crate::undistort::{RemapError, UndistortMapsError, Undistorter};

/// What can go wrong while writing an admitted frame. Frames that are merely unusable are
/// a [`Rejection`], not an error.
#[derive(Debug, thiserror::Error)]
pub enum IngestError {
    /// The caller's output buffer does not have the admitted frame's length.
    #[error("output buffer holds {got} bytes, the frame needs {want}")]
    OutputLength {
        /// Bytes supplied.
        got: usize,
        /// Bytes the frame needs.
        want: usize,
    },
    /// The payload handed to `write` is not the one `admit` saw.
    #[error("payload holds {got} bytes, its header implies {want}")]
    InputLength {
        /// Bytes supplied.
        got: usize,
        /// Bytes the header implies.
        want: usize,
    },
    /// OpenCV failed while building the undistortion maps.
    #[error(transparent)]
    Maps(#[from] UndistortMapsError),
    /// Undistorting the frame failed: OpenCV failed, or wrote somewhere other than the
    /// caller's buffer (the frame is not published rather than published blank).
    #[error(transparent)]
    Remap(#[from] RemapError),
}

/// Why a source frame is not published. Carries numbers only, so that rejecting a frame
/// costs nothing; it is formatted only when a (rate-limited) log line is written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rejection {
    /// Zero width or height, unknown encoding, or a stride shorter than a row.
    BadHeader {
        /// Width in the header.
        width: u32,
        /// Height in the header.
        height: u32,
        /// Stride in the header.
        stride: u32,
        /// Raw encoding in the header.
        encoding: u32,
    },
    /// The header is consistent but the payload does not have the length it implies.
    PayloadLength {
        /// Bytes the header implies.
        expected: usize,
        /// Bytes the payload has.
        got: usize,
    },
    /// The frame's size is not the calibration's: the calibration does not describe it.
    Size {
        /// Frame width.
        width: u32,
        /// Frame height.
        height: u32,
        /// Calibration width.
        want_width: u32,
        /// Calibration height.
        want_height: u32,
    },
}

impl fmt::Display for Rejection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::BadHeader {
                width,
                height,
                stride,
                encoding,
            } => write!(
                f,
                "inconsistent header ({width}x{height}, stride {stride}, encoding {encoding})"
            ),
            Self::PayloadLength { expected, got } => {
                write!(
                    f,
                    "payload of {got} bytes where the header implies {expected}"
                )
            }
            Self::Size {
                width,
                height,
                want_width,
                want_height,
            } => write!(
                f,
                "frame is {width}x{height}, the calibration is {want_width}x{want_height}"
            ),
        }
    }
}

/// Frames lost outside [`Ingest::admit`], reported by the caller so that every loss is
/// counted in one place.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dropped {
    /// No buffer could be loaned: consumers hold every sample. Dropping the frame, rather
    /// than waiting, is what keeps latency from queueing up.
    NoBuffer,
    /// A written frame whose send failed.
    SendFailed,
}

/// Counts of everything that happened to frames, for logs and tests.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counters {
    /// Frames sent to the pipeline.
    pub published: u64,
    /// Frames whose header was inconsistent with itself or with the payload.
    pub dropped_bad_header: u64,
    /// Frames whose size was not the calibration's.
    pub dropped_size: u64,
    /// Frames dropped because consumers held every buffer.
    pub dropped_no_buffer: u64,
    /// Frames lost to an OpenCV or send failure.
    pub dropped_error: u64,
}

impl Counters {
    /// Frames that reached the stage but were not published. (Frames a newer one
    /// replaced before the stage saw them are the driver's `skipped`; a capture
    /// source counts its own losses.)
    pub fn dropped(&self) -> u64 {
        self.dropped_bad_header + self.dropped_size + self.dropped_no_buffer + self.dropped_error
    }
}

/// A frame that passed [`Ingest::admit`]: what its output is and how to read its input.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Admitted {
    /// The header to publish (sequence number 0: the publisher stamps it).
    pub header: CameraFrameHeader,
    /// Bytes of the output payload: the length to loan.
    pub out_len: usize,
    /// Bytes of the input payload.
    pub in_len: usize,
    /// Bytes from one input row to the next.
    pub in_stride: usize,
    /// Bytes of one row of pixels.
    pub row_len: usize,
    /// Whether the pixels go through the undistortion maps.
    pub remap: bool,
}

/// camera-ingest's per-frame logic: checks frames against their header and the
/// calibration, writes published frames (copied or undistorted) into the caller's buffer,
/// and counts every loss.
pub struct Ingest {
    calibration: CameraCalibration,
    undistorter: Option<Undistorter>,
    counters: Counters,
    /// Rows of a strided input packed tightly for `remap` (rare: producers write tight rows).
    scratch: Vec<u8>,
}

impl fmt::Debug for Ingest {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Ingest")
            .field("calibration", &self.calibration)
            .field("undistort", &self.undistorter.is_some())
            .field("counters", &self.counters)
            .finish()
    }
}

/// The most bytes per pixel any encoding has: sizes the publisher's largest loan.
const MAX_BYTES_PER_PIXEL: usize = 3;

impl Ingest {
    /// An ingest stage for frames described by `calibration`; with `undistort`, the
    /// undistortion maps are computed here, once, so each frame costs one `remap`.
    pub fn new(calibration: CameraCalibration, undistort: bool) -> Result<Self, IngestError> {
        let undistorter = if undistort {
            Some(Undistorter::new(&calibration)?)
        } else {
            None
        };
        Ok(Self {
            calibration,
            undistorter,
            counters: Counters::default(),
            scratch: Vec::new(),
        })
    }

    /// The calibration frames must match.
    pub fn calibration(&self) -> &CameraCalibration {
        &self.calibration
    }

    /// Whether published frames are undistorted.
    pub fn undistorts(&self) -> bool {
        self.undistorter.is_some()
    }

    /// The largest frame this stage can publish, bytes: what the publisher must be able
    /// to loan.
    pub fn max_frame_len(&self) -> usize {
        self.calibration.width as usize * self.calibration.height as usize * MAX_BYTES_PER_PIXEL
    }

    /// What happened to frames so far.
    pub fn counters(&self) -> &Counters {
        &self.counters
    }

    /// Checks a source frame whose payload has `payload_len` bytes. A frame that cannot be
    /// published is counted and its reason returned; nothing else happens to it.
    pub fn admit(
        &mut self,
        header: &CameraFrameHeader,
        payload_len: usize,
    ) -> Result<Admitted, Rejection> {
        let result = self.check(header, payload_len);
        match result {
            Err(Rejection::BadHeader { .. } | Rejection::PayloadLength { .. }) => {
                self.counters.dropped_bad_header += 1;
            }
            Err(Rejection::Size { .. }) => self.counters.dropped_size += 1,
            Ok(_) => {}
        }
        result
    }

    fn check(&self, header: &CameraFrameHeader, payload_len: usize) -> Result<Admitted, Rejection> {
        let bad = Rejection::BadHeader {
            width: header.width,
            height: header.height,
            stride: header.stride,
            encoding: header.encoding,
        };
        let expected = header.expected_len().ok_or(bad)?;
        let encoding = PixelEncoding::from_raw(header.encoding).ok_or(bad)?;
        if payload_len != expected {
            return Err(Rejection::PayloadLength {
                expected,
                got: payload_len,
            });
        }
        let (want_width, want_height) = (self.calibration.width, self.calibration.height);
        if (header.width, header.height) != (want_width, want_height) {
            return Err(Rejection::Size {
                width: header.width,
                height: header.height,
                want_width,
                want_height,
            });
        }
        let row_len = header.width as usize * encoding.bytes_per_pixel();
        // Frames that were undistorted upstream are not undistorted twice.
        let remap = self.undistorter.is_some() && header.undistorted == 0;
        let out = CameraFrameHeader {
            msg: Header::derived_from(&header.msg),
            width: header.width,
            height: header.height,
            stride: row_len as u32,
            encoding: header.encoding,
            camera_id: header.camera_id,
            undistorted: u32::from(remap || header.undistorted != 0),
            exposure_ns: header.exposure_ns,
        };
        Ok(Admitted {
            header: out,
            out_len: row_len * header.height as usize,
            in_len: expected,
            in_stride: header.stride as usize,
            row_len,
            remap,
        })
    }

    /// Writes an admitted frame's pixels into `out` (tightly packed rows) and returns the
    /// header to publish with it: the source's capture time and stage stamps, kept.
    pub fn write(
        &mut self,
        frame: &Admitted,
        payload: &[u8],
        out: &mut [u8],
    ) -> Result<CameraFrameHeader, IngestError> {
        match self.write_pixels(frame, payload, out) {
            Ok(()) => Ok(frame.header),
            Err(e) => {
                self.counters.dropped_error += 1;
                Err(e)
            }
        }
    }

    fn write_pixels(
        &mut self,
        frame: &Admitted,
        payload: &[u8],
        out: &mut [u8],
    ) -> Result<(), IngestError> {
        if payload.len() != frame.in_len {
            return Err(IngestError::InputLength {
                got: payload.len(),
                want: frame.in_len,
            });
        }
        if out.len() != frame.out_len {
            return Err(IngestError::OutputLength {
                got: out.len(),
                want: frame.out_len,
            });
        }
        let tight = frame.in_stride == frame.row_len;
        match (&self.undistorter, frame.remap) {
            (Some(undistorter), true) => {
                let input = if tight {
                    payload
                } else {
                    self.scratch.clear();
                    for row in payload.chunks(frame.in_stride) {
                        self.scratch.extend_from_slice(&row[..frame.row_len]);
                    }
                    &self.scratch
                };
                let channels = frame.row_len / frame.header.width as usize;
                Ok(undistorter.remap_into(input, channels, out)?)
            }
            _ if tight => {
                out.copy_from_slice(payload);
                Ok(())
            }
            _ => {
                for (dst, src) in out
                    .chunks_exact_mut(frame.row_len)
                    .zip(payload.chunks(frame.in_stride))
                {
                    dst.copy_from_slice(&src[..frame.row_len]);
                }
                Ok(())
            }
        }
    }

    /// Counts a frame the caller has sent.
    pub fn sent(&mut self) {
        self.counters.published += 1;
    }

    /// Counts frames lost outside [`admit`](Self::admit).
    pub fn record(&mut self, dropped: Dropped) {
        let c = &mut self.counters;
        match dropped {
            Dropped::NoBuffer => c.dropped_no_buffer += 1,
            Dropped::SendFailed => c.dropped_error += 1,
        }
    }
}

#[cfg(test)]
#[path = "ingest_test.rs"]
mod tests;
