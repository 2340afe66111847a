//! The pad estimator as a pipeline stage: every vehicle state into the history, each
//! camera frame (the newest, by the graph's policy) to a pad observation.

use ipc_types::msg::{CameraFrameHeader, Header, PixelEncoding, Stage as StageId};
use ipc_types::topics;
use stage::{Counter, Input, Message, Outbox, Stage, StageError};
use state_history::{StateHistory, timed_pose_of};

use crate::{Frame, PadEstimator};

/// How many vehicle states are kept (2 s at 50 Hz).
const STATE_HISTORY: usize = 100;

/// The `aruco-pnp` node.
pub struct ArucoStage {
    estimator: PadEstimator,
    history: StateHistory,
    counts: Counts,
}

#[derive(Debug, Default, Clone, Copy)]
struct Counts {
    no_pad: u64,
    bad_frames: u64,
    no_state: u64,
    bad_states: u64,
    non_finite: u64,
}

impl ArucoStage {
    /// The stage of `estimator`; a frame whose capture time is more than
    /// `max_state_age_ns` past the newest vehicle state gets no pose prior.
    pub fn new(estimator: PadEstimator, max_state_age_ns: u64) -> Self {
        Self {
            estimator,
            history: StateHistory::new(STATE_HISTORY, max_state_age_ns),
            counts: Counts::default(),
        }
    }

    fn frame(
        &mut self,
        now_ns: u64,
        header: &CameraFrameHeader,
        pixels: &[u8],
        out: &mut dyn Outbox,
    ) -> Result<(), StageError> {
        let Some(frame) = frame_of(header, pixels) else {
            self.counts.bad_frames += 1;
            return Ok(());
        };
        let body = self.history.at(header.msg.capture_ns).ok();
        if body.is_none() {
            self.counts.no_state += 1;
        }
        match self
            .estimator
            .process(&frame, header.msg.capture_ns, body.as_ref())
        {
            Ok(Some(est)) => {
                let mut msg = Header::derived_from(&header.msg);
                msg.push_stage(StageId::ArucoPnp, now_ns, now_ns);
                match est.observation(msg) {
                    Some(obs) => {
                        out.publish(topics::PAD_OBSERVATION, Message::PadObservation(&obs))?
                    }
                    None => self.counts.non_finite += 1,
                }
            }
            Ok(None) => self.counts.no_pad += 1,
            Err(e) => {
                self.counts.bad_frames += 1;
                tracing::debug!(error = %e, "frame dropped");
            }
        }
        Ok(())
    }
}

impl Stage for ArucoStage {
    fn name(&self) -> &'static str {
        "aruco-pnp"
    }

    fn on_input(
        &mut self,
        now_ns: u64,
        input: Input<'_>,
        out: &mut dyn Outbox,
    ) -> Result<(), StageError> {
        match input.msg {
            Message::VehicleState(v) if !timed_pose_of(v).is_some_and(|p| self.history.push(p)) => {
                self.counts.bad_states += 1;
            }
            Message::CameraFrame(h, pixels) => self.frame(now_ns, h, pixels, out)?,
            _ => {}
        }
        Ok(())
    }

    fn counters(&self) -> Vec<Counter> {
        let e = self.estimator.counters();
        let c = self.counts;
        vec![
            ("frames", e.frames),
            ("poses", e.poses),
            ("region_searches", e.region_searches),
            ("fallbacks", e.fallbacks),
            ("no_pad", c.no_pad),
            ("bad_frames", c.bad_frames),
            ("no_state", c.no_state),
            ("bad_states", c.bad_states),
            ("non_finite", c.non_finite),
        ]
    }
}

/// The frame a message holds, if its header agrees with its bytes.
fn frame_of<'a>(header: &CameraFrameHeader, payload: &'a [u8]) -> Option<Frame<'a>> {
    let len = header.expected_len()?;
    let data = payload.get(..len)?;
    Some(Frame {
        width: header.width,
        height: header.height,
        stride: header.stride,
        encoding: PixelEncoding::from_raw(header.encoding)?,
        data,
        undistorted: header.undistorted == 1,
    })
}
