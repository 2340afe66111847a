//! The occupancy mapper as a pipeline stage: every vehicle state into the history, each
//! depth frame (the newest, by the graph's policy) integrated, and a map out after each
//! frame and at least every `publish_period_ms` when frames stop (the same map again,
//! same capture time, so the planner keeps a rate it can supervise). One rule in both
//! drivers.

use ipc_types::msg::{Header, OccupancyMapHeader, Stage as StageId};
use ipc_types::topics;
use stage::{Counter, Input, Message, Outbox, SliceHeader, SliceMut, Stage, StageError};

use crate::{DepthError, DepthMapper, DepthView};

/// The `depth-map` node.
pub struct DepthStage {
    mapper: DepthMapper,
    publish_period_ns: u64,
    last_publish_ns: Option<u64>,
    /// The header of the frame the map was last updated from.
    upstream: Header,
    /// The newest state that frame's pose came from (the map header says it).
    state_ns: u64,
    counts: Counts,
    /// Why the last frame was not mapped (logged by the binary's drop log).
    last_error: Option<DepthError>,
}

#[derive(Debug, Default, Clone, Copy)]
struct Counts {
    published: u64,
    dropped_no_buffer: u64,
}

impl DepthStage {
    /// The one way the stage is built, wherever it runs (its process, the lockstep
    /// registry, a fuzz target): from its `[depth_map]` section.
    pub fn from_config(cfg: &crate::DepthMapConfig) -> Result<Self, DepthError> {
        Ok(Self::new(
            DepthMapper::from_config(cfg)?,
            cfg.publish_period_ms,
        ))
    }

    /// The stage of `mapper`, republishing every `publish_period_ms`.
    pub fn new(mapper: DepthMapper, publish_period_ms: u64) -> Self {
        Self {
            mapper,
            publish_period_ns: publish_period_ms.max(1) * 1_000_000,
            last_publish_ns: None,
            upstream: Header::default(),
            state_ns: 0,
            counts: Counts::default(),
            last_error: None,
        }
    }

    /// The mapper, to read its map and counters.
    pub fn mapper(&self) -> &DepthMapper {
        &self.mapper
    }

    /// Why the newest unmapped frame was dropped, once.
    pub fn take_error(&mut self) -> Option<DepthError> {
        self.last_error.take()
    }

    /// Writes the map straight into the output buffer; a map with a non-finite number
    /// never leaves (its geometry is finite by construction: the last line of defence).
    fn publish(&mut self, now_ns: u64, out: &mut dyn Outbox) -> Result<(), StageError> {
        let map = self.mapper.map();
        let upstream = self.upstream;
        let state_ns = self.state_ns;
        let sent = out.publish_slice(topics::MAP_OCCUPANCY, map.cell_count(), &mut |buf| {
            let SliceMut::U8(cells) = buf else {
                return None;
            };
            let wire = map.write_wire(cells).ok()?;
            let finite = wire.origin.iter().all(|v| v.is_finite())
                && wire.resolution.is_finite()
                && wire.inflation.is_finite();
            if !finite {
                return None;
            }
            let mut msg = Header::derived_from(&upstream);
            msg.push_stage(StageId::DepthMap, now_ns, now_ns);
            Some(SliceHeader::OccupancyMap(OccupancyMapHeader {
                msg,
                state_ns,
                ..wire
            }))
        })?;
        self.last_publish_ns = Some(now_ns);
        if sent {
            self.counts.published += 1;
        } else {
            self.counts.dropped_no_buffer += 1;
        }
        Ok(())
    }
}

impl Stage for DepthStage {
    fn name(&self) -> &'static str {
        "depth-map"
    }

    fn tick_period_ns(&self) -> Option<u64> {
        // Half the period: a map never waits more than 1.5 periods after the last one.
        Some((self.publish_period_ns / 2).max(1))
    }

    fn on_input(
        &mut self,
        now_ns: u64,
        input: Input<'_>,
        out: &mut dyn Outbox,
    ) -> Result<(), StageError> {
        match input.msg {
            Message::VehicleState(v) => {
                self.mapper.push_state_msg(v);
            }
            Message::DepthFrame(h, depth) => {
                let result = DepthView::from_wire(h, depth)
                    .inspect_err(|_| self.mapper.record_bad_frame())
                    .and_then(|view| self.mapper.process(&view, h.msg.capture_ns));
                match result {
                    Ok(_) => {
                        self.upstream = h.msg;
                        self.state_ns = self.mapper.state_used_ns(h.msg.capture_ns);
                        self.publish(now_ns, out)?;
                    }
                    Err(e) => self.last_error = Some(e),
                }
            }
            _ => {}
        }
        Ok(())
    }

    fn on_tick(&mut self, now_ns: u64, out: &mut dyn Outbox) -> Result<(), StageError> {
        if self
            .last_publish_ns
            .is_none_or(|t| now_ns.saturating_sub(t) >= self.publish_period_ns)
        {
            self.publish(now_ns, out)?;
        }
        Ok(())
    }

    fn max_slice_len(&self, topic: &str) -> usize {
        if topic == topics::MAP_OCCUPANCY {
            self.mapper.map().cell_count()
        } else {
            0
        }
    }

    fn counters(&self) -> Vec<Counter> {
        let c = self.mapper.counters();
        vec![
            ("frames", c.frames),
            ("integrated", c.integrated),
            ("published", self.counts.published),
            ("no_state", c.no_state),
            ("stale_state", c.stale_state),
            ("too_old", c.too_old),
            ("bad_frames", c.bad_frames),
            ("bad_poses", c.bad_poses),
            ("bad_states", c.bad_states),
            ("recenters", c.recenters),
            ("dropped_no_buffer", self.counts.dropped_no_buffer),
        ]
    }
}
