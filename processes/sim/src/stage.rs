//! The simulator as a stage of the lockstep driver: the world and the PX4-like
//! autopilot advance to the driver's time on each tick (one physics step of
//! [`PHYSICS_STEP_NS`]), MAVLink leaves and arrives as wire bytes, camera and depth
//! frames are rendered at capture and handed over after the sensor's latency, and the
//! ground truth goes out on the evaluator-only topics (no pipeline stage may read them;
//! the graph check refuses a node that does).

use std::collections::VecDeque;

use ipc_types::msg::{
    CameraFrameHeader, DepthFrameHeader, Header, Intrinsics, PixelEncoding, Stage as StageId,
};
use ipc_types::topics;
use mavlink::MavHeader;
use mavlink::dialects::common::MavMessage;
use px4_protocol::codec::{decode_datagram, encode};
use stage::{Counter, Input, Message, Outbox, SliceHeader, SliceMut, Stage, StageError};

use crate::camera::PixelFormat;
use crate::depth::DEPTH_SCALE_M;
use crate::lockstep::{PHYSICS_STEP_NS, Simulator, TRUTH_STATE_PERIOD_NS, truth_state};

/// A rendered frame waiting for its sensor latency.
struct Held<T> {
    pixels: Vec<T>,
    capture_ns: u64,
    publish_ns: u64,
}

/// The `sim` node in lockstep.
pub struct SimStage {
    sim: Simulator,
    /// The autopilot's own MAVLink sequence, as its UDP endpoint keeps it.
    sequence: u8,
    wire: Vec<u8>,
    decoded: Vec<(MavHeader, MavMessage)>,
    camera: VecDeque<Held<u8>>,
    depth: VecDeque<Held<u16>>,
    spare_u8: Vec<Vec<u8>>,
    spare_u16: Vec<Vec<u16>>,
    next_truth_state_ns: u64,
    counts: Counts,
}

#[derive(Debug, Default, Clone, Copy)]
struct Counts {
    steps: u64,
    camera_frames: u64,
    depth_frames: u64,
    truth_events: u64,
    mavlink_in: u64,
    mavlink_out: u64,
}

impl SimStage {
    /// The stage of `sim`.
    pub fn new(sim: Simulator) -> Self {
        Self {
            sim,
            sequence: 0,
            wire: Vec::with_capacity(280),
            decoded: Vec::with_capacity(8),
            camera: VecDeque::new(),
            depth: VecDeque::new(),
            spare_u8: Vec::new(),
            spare_u16: Vec::new(),
            next_truth_state_ns: 0,
            counts: Counts::default(),
        }
    }

    /// The simulator (the evaluator and the tests read the world through it).
    pub fn simulator(&self) -> &Simulator {
        &self.sim
    }

    /// The simulator, mutably (fault injection in tests).
    pub fn simulator_mut(&mut self) -> &mut Simulator {
        &mut self.sim
    }

    fn render(&mut self) -> Result<(), StageError> {
        if let Some(len) = self.sim.down_camera().map(|c| c.frame_len()) {
            let mut buf = self.spare_u8.pop().unwrap_or_else(|| vec![0; len]);
            buf.resize(len, 0);
            match self.sim.render_camera_into(&mut buf) {
                Ok(Some(shot)) => self.camera.push_back(Held {
                    pixels: buf,
                    capture_ns: shot.capture_ns,
                    publish_ns: shot.publish_ns,
                }),
                Ok(None) => self.spare_u8.push(buf),
                Err(e) => return Err(StageError::Failed(e.to_string())),
            }
        }
        Ok(())
    }

    fn render_depth(&mut self) {
        if let Some(len) = self.sim.depth_camera().map(|c| c.frame_len()) {
            let mut buf = self.spare_u16.pop().unwrap_or_else(|| vec![0; len]);
            buf.resize(len, 0);
            match self.sim.render_depth_into(&mut buf) {
                Some(shot) => self.depth.push_back(Held {
                    pixels: buf,
                    capture_ns: shot.capture_ns,
                    publish_ns: shot.publish_ns,
                }),
                None => self.spare_u16.push(buf),
            }
        }
    }

    /// Frames whose latency has passed, in order.
    fn release(&mut self, now_ns: u64, out: &mut dyn Outbox) -> Result<(), StageError> {
        while self.camera.front().is_some_and(|f| f.publish_ns <= now_ns) {
            let Some(f) = self.camera.pop_front() else {
                break;
            };
            let Some(cam) = self.sim.down_camera() else {
                break;
            };
            let (width, height) = (cam.calibration().width, cam.calibration().height);
            let (encoding, bpp) = match cam.params().format {
                PixelFormat::Mono8 => (PixelEncoding::Mono8, 1),
                PixelFormat::Bgr8 => (PixelEncoding::Bgr8, 3),
            };
            let mut msg = Header::captured_at(f.capture_ns);
            msg.push_stage(StageId::Sensor, f.capture_ns, f.publish_ns);
            let header = CameraFrameHeader {
                msg,
                width,
                height,
                stride: width * bpp,
                encoding: encoding as u32,
                camera_id: 0,
                undistorted: 0,
                exposure_ns: (cam.params().exposure_time_s * 1e9) as u64,
            };
            let pixels = &f.pixels;
            if out.publish_slice(topics::SIM_CAMERA, pixels.len(), &mut |buf| match buf {
                SliceMut::U8(b) => {
                    b.copy_from_slice(pixels);
                    Some(SliceHeader::CameraFrame(header))
                }
                SliceMut::U16(_) => None,
            })? {
                self.counts.camera_frames += 1;
            }
            self.spare_u8.push(f.pixels);
        }
        while self.depth.front().is_some_and(|f| f.publish_ns <= now_ns) {
            let Some(f) = self.depth.pop_front() else {
                break;
            };
            let Some(cam) = self.sim.depth_camera() else {
                break;
            };
            let p = cam.params();
            let (fx, fy) = p.focal_px();
            let (cx, cy) = p.principal_point_px();
            let mut msg = Header::captured_at(f.capture_ns);
            msg.push_stage(StageId::Sensor, f.capture_ns, f.publish_ns);
            let header = DepthFrameHeader {
                msg,
                width: p.width,
                height: p.height,
                depth_scale_m: DEPTH_SCALE_M,
                intrinsics: Intrinsics { fx, fy, cx, cy },
                camera_id: 0,
                reserved: 0,
            };
            let pixels = &f.pixels;
            if out.publish_slice(topics::SIM_DEPTH, pixels.len(), &mut |buf| match buf {
                SliceMut::U16(b) => {
                    b.copy_from_slice(pixels);
                    Some(SliceHeader::DepthFrame(header))
                }
                SliceMut::U8(_) => None,
            })? {
                self.counts.depth_frames += 1;
            }
            self.spare_u16.push(f.pixels);
        }
        Ok(())
    }
}

impl Stage for SimStage {
    fn name(&self) -> &'static str {
        "sim"
    }

    fn tick_period_ns(&self) -> Option<u64> {
        Some(PHYSICS_STEP_NS)
    }

    fn on_input(
        &mut self,
        _now_ns: u64,
        input: Input<'_>,
        _out: &mut dyn Outbox,
    ) -> Result<(), StageError> {
        if let Message::Mavlink(bytes) = input.msg {
            self.decoded.clear();
            decode_datagram(bytes, &mut self.decoded);
            for (h, m) in &self.decoded {
                self.sim.handle_mavlink(h, m);
                self.counts.mavlink_in += 1;
            }
        }
        Ok(())
    }

    fn on_tick(&mut self, now_ns: u64, out: &mut dyn Outbox) -> Result<(), StageError> {
        while self.sim.time_ns() < now_ns {
            let report = self
                .sim
                .step()
                .map_err(|e| StageError::Failed(e.to_string()))?;
            self.counts.steps += 1;
            for t in &report.truth {
                out.publish(topics::SIM_TRUTH, Message::TruthEvent(t))?;
                self.counts.truth_events += 1;
            }
            if report.camera_due {
                self.render()?;
            }
            if report.depth_due {
                self.render_depth();
            }
        }
        for m in self.sim.take_mavlink() {
            let header = MavHeader {
                system_id: 1,
                component_id: 1,
                sequence: self.sequence,
            };
            self.sequence = self.sequence.wrapping_add(1);
            self.wire.clear();
            encode(&mut self.wire, header, &m).map_err(|e| StageError::Transport(e.to_string()))?;
            out.publish(topics::MAVLINK_FROM_PX4, Message::Mavlink(&self.wire))?;
            self.counts.mavlink_out += 1;
        }
        self.release(now_ns, out)?;
        if now_ns >= self.next_truth_state_ns {
            self.next_truth_state_ns = now_ns + TRUTH_STATE_PERIOD_NS;
            let s = truth_state(&self.sim, now_ns);
            out.publish(topics::SIM_TRUTH_STATE, Message::TruthState(&s))?;
        }
        Ok(())
    }

    fn max_slice_len(&self, topic: &str) -> usize {
        match topic {
            topics::SIM_CAMERA => self.sim.down_camera().map_or(0, |c| c.frame_len()),
            topics::SIM_DEPTH => self.sim.depth_camera().map_or(0, |c| c.frame_len()),
            _ => 0,
        }
    }

    fn counters(&self) -> Vec<Counter> {
        let c = self.counts;
        vec![
            ("steps", c.steps),
            ("camera_frames", c.camera_frames),
            ("depth_frames", c.depth_frames),
            ("truth_events", c.truth_events),
            ("mavlink_in", c.mavlink_in),
            ("mavlink_out", c.mavlink_out),
        ]
    }
}
