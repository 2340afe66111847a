//! camera-ingest as a pipeline stage: each source frame (the newest, by the graph's
//! policy) checked against its header and the calibration, then written (copied or
//! undistorted) straight into the output buffer: a loaned shared-memory sample under
//! the iceoryx2 driver, a pooled buffer in lockstep.

use ipc_types::msg::{CameraFrameHeader, Stage as StageId};
use ipc_types::topics;
use stage::{Counter, Input, Message, Outbox, SliceHeader, SliceMut, Stage, StageError};

use std::time::Duration;

use optics::CameraCalibration;

use crate::{CameraIngestConfig, Dropped, Ingest, IngestError, RateLimit, Rejection};

/// Why the newest frame was lost, kept unformatted until a log line is due.
#[derive(Debug)]
pub enum Problem {
    /// Unusable (header, size).
    Rejected(Rejection),
    /// The write failed.
    Failed(IngestError),
    /// No output buffer was free.
    NoBuffer,
}

impl std::fmt::Display for Problem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Rejected(r) => r.fmt(f),
            Self::Failed(e) => e.fmt(f),
            Self::NoBuffer => f.write_str("every output sample is held by consumers"),
        }
    }
}

/// The `camera-ingest` node.
pub struct IngestStage {
    ingest: Ingest,
    last: Option<Problem>,
    log: RateLimit,
    logged_drops: u64,
}

/// At most one `frames dropped` line per this long (driver time).
const DROP_LOG_PERIOD: Duration = Duration::from_secs(1);

impl IngestStage {
    /// The one way the stage is built, wherever it runs (its process, the lockstep
    /// registry): from its `[camera_ingest]` section and the calibration of the camera it
    /// reads (on a vehicle the file the section names; in simulation the scenario's).
    pub fn from_config(
        cfg: &CameraIngestConfig,
        calibration: CameraCalibration,
    ) -> Result<Self, IngestError> {
        Ok(Self::new(Ingest::new(calibration, cfg.undistort)?))
    }

    /// The stage of `ingest` (built by [`Self::from_config`]).
    pub fn new(ingest: Ingest) -> Self {
        Self {
            ingest,
            last: None,
            log: RateLimit::new(DROP_LOG_PERIOD),
            logged_drops: 0,
        }
    }

    /// Logs new losses, at most once per [`DROP_LOG_PERIOD`], with every counter and
    /// the latest reason (formatted only when a line goes out).
    fn log_drops(&mut self, now_ns: u64) {
        let c = *self.ingest.counters();
        if c.dropped() == self.logged_drops || !self.log.ready(now_ns) {
            return;
        }
        self.logged_drops = c.dropped();
        let last = self.last.take();
        tracing::warn!(
            published = c.published,
            dropped_bad_header = c.dropped_bad_header,
            dropped_size = c.dropped_size,
            dropped_no_buffer = c.dropped_no_buffer,
            dropped_error = c.dropped_error,
            last = %last.as_ref().map_or(String::new(), ToString::to_string),
            "frames dropped"
        );
    }

    /// The per-frame logic, to read its counters.
    pub fn ingest(&self) -> &Ingest {
        &self.ingest
    }

    /// Publishes one source frame; returns its rejection when it was unusable (a
    /// capture source checks the first one: a camera mode unlike the calibration).
    pub fn frame(
        &mut self,
        now_ns: u64,
        header: &CameraFrameHeader,
        pixels: &[u8],
        out: &mut dyn Outbox,
    ) -> Result<Option<Rejection>, StageError> {
        let admitted = match self.ingest.admit(header, pixels.len()) {
            Ok(a) => a,
            Err(r) => {
                self.last = Some(Problem::Rejected(r));
                return Ok(Some(r));
            }
        };
        let ingest = &mut self.ingest;
        let mut failed = None;
        let sent = out.publish_slice(topics::CAMERA_FRAME, admitted.out_len, &mut |buf| {
            let SliceMut::U8(buf) = buf else {
                return None;
            };
            match ingest.write(&admitted, pixels, buf) {
                Ok(mut h) => {
                    h.msg.push_stage(StageId::CameraIngest, now_ns, now_ns);
                    Some(SliceHeader::CameraFrame(h))
                }
                Err(e) => {
                    failed = Some(e);
                    None
                }
            }
        })?;
        if sent {
            self.ingest.sent();
        } else if let Some(e) = failed {
            self.last = Some(Problem::Failed(e));
        } else {
            self.ingest.record(Dropped::NoBuffer);
            self.last = Some(Problem::NoBuffer);
        }
        Ok(None)
    }
}

impl Stage for IngestStage {
    fn name(&self) -> &'static str {
        "camera-ingest"
    }

    fn on_input(
        &mut self,
        now_ns: u64,
        input: Input<'_>,
        out: &mut dyn Outbox,
    ) -> Result<(), StageError> {
        if let Message::CameraFrame(h, pixels) = input.msg {
            self.frame(now_ns, h, pixels, out)?;
            self.log_drops(now_ns);
        }
        Ok(())
    }

    fn max_slice_len(&self, topic: &str) -> usize {
        if topic == topics::CAMERA_FRAME {
            self.ingest.max_frame_len()
        } else {
            0
        }
    }

    fn counters(&self) -> Vec<Counter> {
        let c = self.ingest.counters();
        vec![
            ("published", c.published),
            ("dropped_bad_header", c.dropped_bad_header),
            ("dropped_size", c.dropped_size),
            ("dropped_no_buffer", c.dropped_no_buffer),
            ("dropped_error", c.dropped_error),
        ]
    }
}
