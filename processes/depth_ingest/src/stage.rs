//! depth-ingest as a pipeline stage: each device frame checked (size against the
//! configured mode, depths against the header, scale and intrinsics finite and
//! positive) and copied once, into the loaned `landing/depth/frame` sample.

use ipc_types::msg::{DepthFrameHeader, Stage as StageId};
use ipc_types::topics;
use stage::{Counter, Input, Message, Outbox, SliceHeader, SliceMut, Stage, StageError};

/// Why a device frame was not published.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rejection {
    /// Its size is not the configured mode's (`[depth_ingest] width`, `height`).
    Size {
        /// The frame's.
        width: u32,
        /// The frame's.
        height: u32,
    },
    /// Its depths do not fill its header's size.
    Length,
    /// A depth scale or intrinsics that are not finite and positive.
    Calibration,
}

impl std::fmt::Display for Rejection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Size { width, height } => write!(f, "a {width}x{height} frame"),
            Self::Length => f.write_str("depths shorter than the header's size"),
            Self::Calibration => f.write_str("a depth scale or intrinsics not finite and positive"),
        }
    }
}

/// What the stage published and dropped.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Counts {
    /// Frames published.
    pub published: u64,
    /// Frames of another size than the configured one.
    pub dropped_size: u64,
    /// Frames whose depths, scale or intrinsics were unusable.
    pub dropped_bad: u64,
    /// Frames lost because every output sample was held by consumers.
    pub dropped_no_buffer: u64,
}

/// The `depth-ingest` node.
pub struct DepthIngestStage {
    width: u32,
    height: u32,
    counts: Counts,
    /// The first rejection, logged once (a device in another mode rejects every frame).
    warned: bool,
}

impl DepthIngestStage {
    /// Publishes frames of `width` x `height` (depth-map's `[depth_map]` size).
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            counts: Counts::default(),
            warned: false,
        }
    }

    /// What it published and dropped.
    pub fn counts(&self) -> Counts {
        self.counts
    }

    /// Whether `header` and `depths` make a frame this stage publishes.
    pub fn check(&self, header: &DepthFrameHeader, depths: &[u16]) -> Result<(), Rejection> {
        if (header.width, header.height) != (self.width, self.height) {
            return Err(Rejection::Size {
                width: header.width,
                height: header.height,
            });
        }
        if depths.len() < self.len() {
            return Err(Rejection::Length);
        }
        let k = &header.intrinsics;
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if ![header.depth_scale_m, k.fx, k.fy, k.cx, k.cy]
            .into_iter()
            .all(positive)
        {
            return Err(Rejection::Calibration);
        }
        Ok(())
    }

    fn len(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// Publishes one device frame; returns its rejection when it was unusable.
    pub fn frame(
        &mut self,
        now_ns: u64,
        header: &DepthFrameHeader,
        depths: &[u16],
        out: &mut dyn Outbox,
    ) -> Result<Option<Rejection>, StageError> {
        if let Err(r) = self.check(header, depths) {
            match r {
                Rejection::Size { .. } => self.counts.dropped_size += 1,
                _ => self.counts.dropped_bad += 1,
            }
            if !self.warned {
                self.warned = true;
                tracing::warn!(
                    width = self.width,
                    height = self.height,
                    "depth frames dropped: {r} (the first; counted after)"
                );
            }
            return Ok(Some(r));
        }
        let n = self.len();
        let sent = out.publish_slice(topics::DEPTH_FRAME, n, &mut |buf| {
            let SliceMut::U16(buf) = buf else {
                return None;
            };
            buf.get_mut(..n)?.copy_from_slice(depths.get(..n)?);
            let mut h = *header;
            h.msg.push_stage(StageId::DepthIngest, now_ns, now_ns);
            Some(SliceHeader::DepthFrame(h))
        })?;
        if sent {
            self.counts.published += 1;
        } else {
            self.counts.dropped_no_buffer += 1;
        }
        Ok(None)
    }
}

impl Stage for DepthIngestStage {
    fn name(&self) -> &'static str {
        "depth-ingest"
    }

    fn on_input(
        &mut self,
        now_ns: u64,
        input: Input<'_>,
        out: &mut dyn Outbox,
    ) -> Result<(), StageError> {
        if let Message::DepthFrame(h, depths) = input.msg {
            self.frame(now_ns, h, depths, out)?;
        }
        Ok(())
    }

    fn max_slice_len(&self, topic: &str) -> usize {
        if topic == topics::DEPTH_FRAME {
            self.len()
        } else {
            0
        }
    }

    fn counters(&self) -> Vec<Counter> {
        let c = &self.counts;
        vec![
            ("published", c.published),
            ("dropped_size", c.dropped_size),
            ("dropped_bad", c.dropped_bad),
            ("dropped_no_buffer", c.dropped_no_buffer),
        ]
    }
}
