//! The pad estimator as a pipeline stage: every vehicle state into the history, each
//! camera frame (the newest, by the graph's policy) to a pad observation.

use ipc_types::msg::{CameraFrameHeader, Header, PixelEncoding, Stage as StageId};
use ipc_types::topics;
use stage::{Counter, Input, Message, Outbox, Stage, StageError};
use state_history::{HistoryError, StateHistory, timed_pose_of};

use optics::{CameraCalibration, PadModel};

use crate::{ArucoConfig, EstimateError, Frame, PadEstimator, down_camera_from_body};

/// How many vehicle states are kept (2 s at 50 Hz).
const STATE_HISTORY: usize = 100;

/// The `aruco-pnp` node.
pub struct ArucoStage {
    estimator: PadEstimator,
    history: StateHistory,
    counts: Counts,
    /// A frame newer than every state by more than the allowance (the autopilot's
    /// telemetry late on a loaded machine): held until a state at or after its capture
    /// comes, or the next frame does. Placed by a pose from before it, it would carry
    /// the vehicle's motion since; placed by none, it is no use to the fsm.
    held: Option<CameraFrameHeader>,
    held_pixels: Vec<u8>,
}

#[derive(Debug, Default, Clone, Copy)]
struct Counts {
    no_pad: u64,
    bad_frames: u64,
    no_state: u64,
    bad_states: u64,
    non_finite: u64,
    held: u64,
}

impl ArucoStage {
    /// The one way the stage is built, wherever it runs (its process, the lockstep
    /// registry, a benchmark, `landing pad detect`, a fuzz target): from its
    /// `[aruco_pnp]` section and the camera and pad it works with (on a vehicle the files
    /// the section names; in simulation the scenario's). Two places building it with
    /// their own arguments is how lockstep and the deployment drift apart.
    pub fn from_config(
        cfg: &ArucoConfig,
        camera: CameraCalibration,
        pad: PadModel,
    ) -> Result<Self, EstimateError> {
        let estimator = PadEstimator::new(
            camera,
            pad,
            down_camera_from_body(cfg.camera_position_in_body_m),
            cfg.settings(),
        )?;
        Ok(Self::new(estimator, cfg.max_state_age_ms * 1_000_000))
    }

    /// The estimator, for tools that hand it frames themselves (a benchmark, one image).
    pub fn estimator_mut(&mut self) -> &mut PadEstimator {
        &mut self.estimator
    }

    /// The stage of `estimator`; a frame whose capture time is more than
    /// `max_state_age_ns` past the newest vehicle state gets no pose prior. Built by
    /// [`Self::from_config`] (tests build it here with estimators of their own).
    pub fn new(estimator: PadEstimator, max_state_age_ns: u64) -> Self {
        Self {
            estimator,
            history: StateHistory::new(STATE_HISTORY, max_state_age_ns),
            counts: Counts::default(),
            held: None,
            held_pixels: Vec::new(),
        }
    }

    /// The held frame, processed now (with whatever the history can say of it).
    fn release(&mut self, now_ns: u64, out: &mut dyn Outbox) -> Result<(), StageError> {
        let Some(header) = self.held.take() else {
            return Ok(());
        };
        let pixels = std::mem::take(&mut self.held_pixels);
        let r = self.frame(now_ns, &header, &pixels, out, false);
        self.held_pixels = pixels;
        r
    }

    fn frame(
        &mut self,
        now_ns: u64,
        header: &CameraFrameHeader,
        pixels: &[u8],
        out: &mut dyn Outbox,
        may_hold: bool,
    ) -> Result<(), StageError> {
        let Some(frame) = frame_of(header, pixels) else {
            self.counts.bad_frames += 1;
            return Ok(());
        };
        let body = self.history.at(header.msg.capture_ns);
        if may_hold && matches!(body, Err(HistoryError::Stale(_))) {
            self.held = Some(*header);
            self.held_pixels.clear();
            self.held_pixels.extend_from_slice(pixels);
            self.counts.held += 1;
            return Ok(());
        }
        let body = body.ok();
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
            Message::VehicleState(v) => {
                let Some(p) = timed_pose_of(v) else {
                    self.counts.bad_states += 1;
                    return Ok(());
                };
                // px4-link repeats its last state while the telemetry is silent: the
                // same stamp, nothing new.
                let repeat = self
                    .history
                    .latest()
                    .is_some_and(|l| l.time_ns == p.time_ns);
                if !repeat && !self.history.push(p) {
                    self.counts.bad_states += 1;
                }
                let newest = self.history.latest().map_or(0, |l| l.time_ns);
                if self.held.is_some_and(|h| newest >= h.msg.capture_ns) {
                    self.release(now_ns, out)?;
                }
            }
            Message::CameraFrame(h, pixels) => {
                // The next frame: the held one goes first, placed as well as it can be.
                self.release(now_ns, out)?;
                self.frame(now_ns, h, pixels, out, true)?;
            }
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
            ("held", c.held),
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
