//! `landing run` in one process: the simulator and every pipeline library (px4-link,
//! aruco-pnp, depth-map, planner, fsm) stepped together on simulated time.
//!
//! Each library gets its input when the process would: camera and depth frames at their
//! publish time (capture + sensor latency), telemetry when the autopilot sends it, the
//! planner's trajectory one planner period (20 ms) after the call (the time the plan
//! really took is measured and reported, not simulated: a seed flies the same on every
//! machine). MAVLink
//! goes through its wire encoding both ways, as on a socket. The pipeline sees only
//! telemetry and sensor data; the ground truth goes to the evaluator only.

use std::collections::VecDeque;
use std::time::Instant;

use anyhow::{Context, Result};
use aruco_pnp::{Frame, PadEstimator};
use bspline::State;
use depth_map::{DepthMapper, DepthPixels, DepthView};
use fsm::Fsm;
use ipc_types::msg::{
    Header, Intrinsics, MissionState, OccupancyMapHeader, PadObservation, PixelEncoding,
    PlannerGoal, Stage, Trajectory, VehicleState,
};
use mavlink::MavHeader;
use mavlink::dialects::common::MavMessage;
use planner::PlannerNode;
use planner::map::CellView;
use px4_link::LinkNode;
use px4_protocol::codec::{decode_datagram, encode};
use sim::lockstep::Simulator;
use state_history::StateHistory;

use crate::record::{Recordable, Recorder};
use crate::run_eval::{Evaluator, Sample, distance_to_pad, is_crash};

/// The planner's tick, ns (it wakes on goals, states and maps; 50 Hz bounds it).
const PLANNER_PERIOD_NS: u64 = 20_000_000;
/// Flight-log sample period, ns.
const SAMPLE_PERIOD_NS: u64 = 50_000_000;

/// Everything the run needs besides the simulator.
pub struct Pipeline {
    /// The pad estimator (aruco-pnp).
    pub estimator: PadEstimator,
    /// The occupancy mapper (depth-map).
    pub mapper: DepthMapper,
    /// The planner.
    pub planner: PlannerNode,
    /// The mission.
    pub fsm: Fsm,
    /// px4-link (its node: requests, safety orders, setpoints, the vehicle state).
    pub link: LinkNode,
}

/// How the run ended, as the simulator saw it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum End {
    /// The fsm reached Landed.
    Landed,
    /// The fsm stopped in SafeLand or Abort and the vehicle is down and disarmed.
    SafeLanded,
    /// The simulator reported a crash.
    Crashed,
    /// The scenario's time ran out.
    Timeout,
}

impl End {
    /// The end a mission state means: Landed, or SafeLand / Abort once the vehicle is
    /// `down` (on the ground, disarmed); `None` while the mission goes on.
    pub fn reached(phase: MissionState, down: bool) -> Option<End> {
        match phase {
            MissionState::Landed => Some(End::Landed),
            MissionState::SafeLand | MissionState::Abort if down => Some(End::SafeLanded),
            _ => None,
        }
    }
}

/// What the run measured besides the flight log.
#[derive(Debug, Clone, Default)]
pub struct RunStats {
    /// Wall time of every planning call, ms.
    pub planning_ms: Vec<f64>,
    /// Plans published (first plan included).
    pub plans: u64,
    /// Pad observations delivered to the fsm.
    pub observations: u64,
    /// Camera frames processed.
    pub frames: u64,
}

/// Runs the mission to its end. `progress` is called about once per simulated second.
pub fn run(
    sim: &mut Simulator,
    pipe: &mut Pipeline,
    duration_s: f64,
    eval: &mut Evaluator,
    rec: &mut Recording,
    mut progress: impl FnMut(f64, MissionState, Option<f64>),
) -> Result<(End, RunStats)> {
    let mut stats = RunStats::default();
    let cam = sim
        .down_camera()
        .context("the scenario has no downward camera")?;
    let (cw, chh) = (cam.calibration().width, cam.calibration().height);
    let cam_len = cam.frame_len();
    let encoding = match cam.params().format {
        sim::camera::PixelFormat::Mono8 => PixelEncoding::Mono8,
        sim::camera::PixelFormat::Bgr8 => PixelEncoding::Bgr8,
    };
    let depth_cam = sim
        .depth_camera()
        .context("the scenario has no depth camera")?;
    let dp = depth_cam.params().clone();
    let (fx, fy) = dp.focal_px();
    let (cx, cy) = dp.principal_point_px();
    let intrinsics = Intrinsics { fx, fy, cx, cy };
    let depth_len = depth_cam.frame_len();

    let mut cam_pool: Vec<Vec<u8>> = (0..3).map(|_| vec![0u8; cam_len]).collect();
    let mut cam_pending: VecDeque<(Vec<u8>, u64, u64)> = VecDeque::new();
    let mut depth_pool: Vec<Vec<u16>> = (0..3).map(|_| vec![0u16; depth_len]).collect();
    let mut depth_pending: VecDeque<(Vec<u16>, u64, u64)> = VecDeque::new();
    let mut map_cells = vec![0u8; pipe.mapper.map().cell_count()];
    let mut map_header: Option<OccupancyMapHeader> = None;
    let mut history = StateHistory::new(100, 200_000_000);
    let mut wire = Vec::with_capacity(280);
    let mut decoded: Vec<(MavHeader, MavMessage)> = Vec::with_capacity(8);
    let mut autopilot_seq = 0u8;
    let mut vehicle: Option<VehicleState> = None;
    let mut goal: Option<PlannerGoal> = None;
    let mut traj_pending: VecDeque<(u64, Trajectory)> = VecDeque::new();
    let mut next_fsm = 0u64;
    let mut next_planner = 0u64;
    let mut next_sample = 0u64;
    let mut next_progress = 0u64;
    let end_ns = (duration_s * 1e9) as u64;
    let mut ended: Option<(End, u64)> = None;

    loop {
        let now = sim.time_ns();
        if let Some((end, at)) = ended {
            // A second more after the end, so the touchdown settles in the log.
            if now >= at + 1_000_000_000 {
                return Ok((end, stats));
            }
        } else if now >= end_ns {
            return Ok((End::Timeout, stats));
        }

        // Companion -> autopilot, through the wire format.
        pipe.link.send_due(now, |header, m| {
            wire.clear();
            encode(&mut wire, header, m)?;
            decoded.clear();
            decode_datagram(&wire, &mut decoded);
            for (h, msg) in &decoded {
                sim.handle_mavlink(h, msg);
            }
            anyhow::Ok(())
        })?;

        let report = sim.step()?;
        let now = sim.time_ns();
        for m in &sim.take_mavlink() {
            wire.clear();
            // The autopilot's own count, as its UDP endpoint keeps it.
            let h = MavHeader {
                system_id: 1,
                component_id: 1,
                sequence: autopilot_seq,
            };
            autopilot_seq = autopilot_seq.wrapping_add(1);
            encode(&mut wire, h, m)?;
            decoded.clear();
            pipe.link
                .on_parse_errors(decode_datagram(&wire, &mut decoded));
            for (h, msg) in &decoded {
                pipe.link.on_message(now, h, msg);
            }
        }
        for o in pipe.link.take_outcomes() {
            rec.write("/px4/outcome", now, &o)?;
            pipe.fsm.on_outcome(&o);
        }
        if let Some(state) = pipe.link.vehicle_state(now) {
            rec.write("/vehicle/state", now, &state)?;
            pipe.fsm.on_vehicle_state(now, &state);
            pipe.mapper.push_state_msg(&state);
            if let Some(tp) = depth_map::timed_pose_of(&state) {
                history.push(tp);
            }
            vehicle = Some(state);
        }
        for t in &report.truth {
            rec.write("/sim/truth", now, t)?;
            eval.on_truth(t, pipe.fsm.state());
            if ended.is_none() && is_crash(t) {
                ended = Some((End::Crashed, now));
            }
        }

        // Sensors: rendered at capture, handed over at publish time.
        if report.camera_due {
            let mut buf = cam_pool.pop().unwrap_or_else(|| vec![0u8; cam_len]);
            match sim.render_camera_into(&mut buf)? {
                Some(shot) => cam_pending.push_back((buf, shot.capture_ns, shot.publish_ns)),
                None => cam_pool.push(buf),
            }
        }
        while cam_pending.front().is_some_and(|f| f.2 <= now) {
            let Some((buf, capture_ns, _)) = cam_pending.pop_front() else {
                break;
            };
            let frame = Frame {
                width: cw,
                height: chh,
                stride: cw * encoding.bytes_per_pixel() as u32,
                encoding,
                data: &buf,
                undistorted: false,
            };
            let body = history.at(capture_ns).ok();
            stats.frames += 1;
            if let Ok(Some(est)) = pipe.estimator.process(&frame, capture_ns, body.as_ref()) {
                let mut msg = Header::captured_at(capture_ns);
                msg.push_stage(Stage::ArucoPnp, now, now);
                if let Some(obs) = est.observation(msg) {
                    rec.write("/pad/observation", now, &obs)?;
                    deliver_observation(pipe, now, &obs, &mut stats);
                }
            }
            cam_pool.push(buf);
        }
        if report.depth_due {
            let mut buf = depth_pool.pop().unwrap_or_else(|| vec![0u16; depth_len]);
            match sim.render_depth_into(&mut buf) {
                Some(shot) => depth_pending.push_back((buf, shot.capture_ns, shot.publish_ns)),
                None => depth_pool.push(buf),
            }
        }
        while depth_pending.front().is_some_and(|f| f.2 <= now) {
            let Some((buf, capture_ns, _)) = depth_pending.pop_front() else {
                break;
            };
            let view = DepthView::new(
                dp.width,
                dp.height,
                intrinsics,
                DepthPixels::U16 {
                    data: &buf,
                    scale_m: sim::depth::DEPTH_SCALE_M as f32,
                },
            )?;
            if pipe.mapper.process(&view, capture_ns).is_ok()
                && let Ok(h) = pipe.mapper.map().write_wire(&mut map_cells)
            {
                map_header = Some(h);
            }
            depth_pool.push(buf);
        }

        // The fsm at its rate (`[fsm] rate_hz`).
        if now >= next_fsm {
            next_fsm = now + pipe.fsm.tick_period_ns();
            let o = pipe.fsm.tick(now);
            if let Some(sp) = o.setpoint {
                rec.write("/fsm/setpoint", now, &sp)?;
                pipe.link.on_setpoint(now, &sp);
            }
            for r in &o.requests {
                rec.write("/px4/request", now, r)?;
                pipe.link.on_request(now, r);
            }
            if let Some(g) = o.goal {
                rec.write("/planner/goal", now, &g)?;
                goal = Some(g);
            }
            if let Some(st) = o.status {
                rec.write("/fsm/status", now, &st)?;
                if ended.is_none() {
                    let down = sim.world().contact() != sim::quadrotor::ContactState::Airborne
                        && !sim.world().armed();
                    ended = End::reached(pipe.fsm.state(), down).map(|e| (e, now));
                }
            }
        }

        // The planner; its output arrives one planner period later.
        if now >= next_planner {
            next_planner = now + PLANNER_PERIOD_NS;
            if let Some((v, state)) = vehicle
                .as_ref()
                .and_then(|v| Some((v, State::from_vehicle(v)?)))
            {
                let view = map_header
                    .as_ref()
                    .and_then(|h| CellView::new(h, &map_cells));
                let t0 = Instant::now();
                let o = pipe
                    .planner
                    .step(now, &state, goal.as_ref(), view.as_ref(), &v.msg);
                let ms = t0.elapsed().as_secs_f64() * 1e3;
                if let Some(mut st) = o.stats {
                    st.planning_ms = ms;
                    rec.write("/planner/stats", now, &st)?;
                    stats.planning_ms.push(ms);
                }
                if let Some(t) = o.trajectory {
                    stats.plans += 1;
                    // One planner period later: the plan's wall time is reported, not
                    // simulated, so a seed gives the same flight on every machine.
                    let ready = now + PLANNER_PERIOD_NS;
                    traj_pending.push_back((ready, t));
                }
            }
        }
        while traj_pending.front().is_some_and(|t| t.0 <= now) {
            if let Some((_, t)) = traj_pending.pop_front() {
                rec.write("/planner/trajectory", now, &t)?;
                pipe.fsm.on_trajectory(&t);
            }
        }

        if now >= next_sample {
            next_sample = now + SAMPLE_PERIOD_NS;
            eval.sample(Sample::of(sim, pipe.fsm.state()));
        }
        if now >= next_progress {
            next_progress = now + 1_000_000_000;
            let d = distance_to_pad(&sim::lockstep::truth_state(sim, now));
            progress(now as f64 * 1e-9, pipe.fsm.state(), d);
        }
    }
}

fn deliver_observation(pipe: &mut Pipeline, now: u64, obs: &PadObservation, stats: &mut RunStats) {
    stats.observations += 1;
    pipe.fsm.on_observation(now, obs);
}

/// An optional MCAP recording of every message the stages exchange (simulated time).
pub struct Recording(pub Option<Recorder>);

impl Recording {
    /// Records `msg` on `topic` when recording.
    pub fn write<T: Recordable>(&mut self, topic: &str, now_ns: u64, msg: &T) -> Result<()> {
        if let Some(r) = &mut self.0 {
            r.write_message(topic, now_ns, msg)?;
        }
        Ok(())
    }
}
